"""The handwheel end to end: reports through the real host to the simulated Grbl, in virtual time.

The hobby router has 80 steps/mm, 5000 mm/min and 500 mm/s² on X and rests homed at MPos
(-1, -1, -1) with soft limits on, so + has 1 mm of room. Grbl rounds every absolute jog target
to whole steps (lround, firmware-facts §1.5) and a jog under half a step moves nothing, so the
exact result of N detents is the step nearest start + N x step: that is what these check.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

from smoothjog.core import increments as inc
from smoothjog.core.engine import JogTuning
from smoothjog.core.intents import HandwheelIntent
from smoothjog.sim.motion import TraceSegment
from smoothjog.virtual import VirtualHost
from tests.test_engine import sent_lines
from tests.test_engine import session as engine_session

STEPS_PER_MM = 80.0
V_MM_S = 5000 / 60
A_MM_S2 = 500.0
REPORT_S = 0.020  # a pendant's report period while the wheel turns


def session() -> tuple[VirtualHost, list[str]]:
    """A handshaken hobby router, and the list every line the host sends is added to."""
    vs = engine_session()
    return vs, sent_lines(vs)


def turn(
    vs: VirtualHost,
    reports: Sequence[int],
    step_mm: float,
    mode: Literal["position", "velocity"] = "position",
) -> float:
    """Send one report every REPORT_S from now; return the time of the last one."""
    t0_s = vs.now_s
    for k, counts in enumerate(reports):
        vs.run_until(t0_s + k * REPORT_S)
        vs.set_intent(HandwheelIntent("X", counts, step_mm, mode))
    return vs.now_s


def x_at(trace: Sequence[TraceSegment], t_s: float) -> float:
    """The true X position at t_s, from the simulator's ground truth."""
    x_mm = trace[0].start_mm[0]
    for seg in trace:
        if seg.t0_s > t_s:
            break
        span_s = seg.t1_s - seg.t0_s
        f = 1.0 if span_s <= 0.0 or t_s >= seg.t1_s else (t_s - seg.t0_s) / span_s
        x_mm = seg.start_mm[0] + (seg.end_mm[0] - seg.start_mm[0]) * f
    return x_mm


def steps(x_mm: float) -> float:
    return x_mm * STEPS_PER_MM


def test_37_detents_of_a_hundredth_in_a_burst_end_on_the_nearest_step() -> None:
    """0.37 mm is 29.6 steps: the machine moves 30, as one exact jog of 0.37 mm would."""
    vs, lines = session()
    x0 = vs.rig.firmware.mpos_mm()[0]
    burst = [5, 5, 4, 3, 5, 2, 1, 5, 4, 3]  # 1-5 detents every 20 ms
    assert sum(burst) == 37
    turn(vs, burst, 0.01)
    assert vs.run_until_idle(3.0)
    x1 = vs.rig.firmware.mpos_mm()[0]
    assert steps(x1) - steps(x0) == round(steps(x0 + 0.37)) - steps(x0) == 30
    jogs = [line for line in lines if line.startswith("$J=")]
    assert 1 <= len(jogs) <= len(burst)
    engine = vs.engine
    assert engine is not None
    assert engine.stats.soft_limit_errors == 0
    assert engine.stats.stops[-1].tracked_error_steps == 0.0


def test_a_fast_spin_of_200_detents_in_half_a_second_moves_exactly_20_mm() -> None:
    vs, lines = session()
    x0 = vs.rig.firmware.mpos_mm()[0]
    turn(vs, [-8] * 25, 0.1)  # 40 mm/s of wheel: the machine keeps up
    assert vs.run_until_idle(3.0)
    assert steps(vs.rig.firmware.mpos_mm()[0]) - steps(x0) == -1600
    assert len([line for line in lines if line.startswith("$J=")]) <= 25  # not 200 lines


def test_a_spin_faster_than_the_machine_queues_every_detent_in_few_lines() -> None:
    """200 mm in 0.5 s is five times the machine's speed: every detent still runs."""
    vs, lines = session()
    x0 = vs.rig.firmware.mpos_mm()[0]
    turn(vs, [-80] * 25, 0.1)
    assert vs.run_until_idle(6.0)
    assert steps(vs.rig.firmware.mpos_mm()[0]) - steps(x0) == -16000
    assert len([line for line in lines if line.startswith("$J=")]) <= 10


def test_velocity_mode_stops_within_the_stopping_distance_of_the_wheel() -> None:
    """The wheel asks 100 mm/s for a second, more than the machine's 83: counts are dropped,
    and once it stops the machine runs at most v²/2a + v·committed on (no cancel needed)."""
    vs, _ = session()
    x0 = vs.rig.firmware.mpos_mm()[0]
    t_stop_s = turn(vs, [-20] * 50, 0.1, "velocity")
    assert vs.run_until_idle(3.0)
    x1 = vs.rig.firmware.mpos_mm()[0]
    x_stop = x_at(vs.rig.trace, t_stop_s)
    engine = vs.engine
    assert engine is not None
    bound_mm = inc.queue_target_mm(V_MM_S, A_MM_S2, JogTuning().committed_s)
    # The engine measures the lead from its position estimate, which a report can leave up to
    # a step off (it rounds to 0.001 mm; the step grid is 0.0125).
    assert 0.0 < x_stop - x1 <= bound_mm + 1 / STEPS_PER_MM
    assert x0 - x_stop > 60.0  # it followed the wheel at close to full speed
    assert engine.stats.wheel_counts_dropped > 0
    assert engine.stats.cancels == 0


def test_velocity_mode_reversal_cancels_then_goes_back() -> None:
    """A report the other way cancels what is queued (one stop handshake); the detents that
    arrive meanwhile (10 mm, within the lead) all run back from where it stopped."""
    vs, _ = session()
    t_turn_s = turn(vs, [-20] * 15, 0.1, "velocity") + REPORT_S
    vs.run_until(t_turn_s)
    turn(vs, [10] * 10, 0.1, "velocity")
    assert vs.run_until_idle(3.0)
    engine = vs.engine
    assert engine is not None
    assert engine.stats.cancels == 1
    lowest = min(seg.end_mm[0] for seg in vs.rig.trace)
    # The cancel stops it within the committed segments and braking of the reversal.
    bound_mm = inc.queue_target_mm(V_MM_S, A_MM_S2, JogTuning().committed_s)
    assert 0.0 < x_at(vs.rig.trace, t_turn_s) - lowest <= bound_mm
    assert steps(vs.rig.firmware.mpos_mm()[0]) - steps(lowest) == 800
