"""Motion model against the physics: accel time, stop distance, axis caps, junctions, no dips."""

from __future__ import annotations

import itertools
import math

import pytest

from smoothjog.sim.motion import CYCLE_STOP, AxisLimits, Motion

# The hobby-router profile of the issue: X/Y 5000 mm/min at 500 mm/s², Z 1500 mm/min at 200 mm/s².
HOBBY = (AxisLimits(800, 5000, 500), AxisLimits(800, 5000, 500), AxisLimits(800, 1500, 200))
V_MM_S = 5000 / 60
A_MM_S2 = 500.0


def run_until(m: Motion, t_s: float) -> list[tuple[float, str]]:
    """Advance segment by segment up to t_s, collecting events."""
    events: list[tuple[float, str]] = []
    while True:
        nxt = m.next_event_s()
        if nxt is None or nxt > t_s:
            break
        events += m.advance(nxt)
    events += m.advance(t_s)
    return events


def run_to_stop(m: Motion) -> float:
    """Advance until the steppers stop; returns the cycle-stop time."""
    while True:
        nxt = m.next_event_s()
        assert nxt is not None, "motion stopped without a cycle-stop event"
        for t, name in m.advance(nxt):
            if name == CYCLE_STOP:
                return t


def test_single_axis_reaches_speed_in_v_over_a() -> None:
    m = Motion(HOBBY)
    assert m.plan_line((-300.0, 0.0, 0.0), 5000)
    m.start_cycle(0.0)
    run_until(m, 1.0)
    # After the ramp, x(T) = v * (T - t_acc / 2); solve for the ramp time.
    x_mm = -m.position_mm()[0]
    t_acc = 2 * (1.0 - x_mm / V_MM_S)
    assert t_acc == pytest.approx(V_MM_S / A_MM_S2, rel=0.02)
    assert m.realtime_rate_mm_min() == pytest.approx(5000, abs=1)


@pytest.mark.parametrize("phase", [0.0, 0.003, 0.0071])
def test_stop_distance_is_v2_over_2a_plus_committed_segments(phase: float) -> None:
    m = Motion(HOBBY)
    m.plan_line((-700.0, 0.0, 0.0), 5000)
    m.start_cycle(0.0)
    t_hold = 1.0 + phase
    run_until(m, t_hold)
    x0 = m.position_mm()[0]
    nxt = m.next_event_s()
    assert nxt is not None
    committed_s = (nxt - t_hold) + (m.queued_segments() - 1) * m.segment_s
    m.hold(t_hold)
    t_stop = run_to_stop(m)
    dist = x0 - m.position_mm()[0]
    expected = V_MM_S * committed_s + V_MM_S**2 / (2 * A_MM_S2)
    assert dist == pytest.approx(expected, rel=0.02)
    assert t_stop - t_hold == pytest.approx(committed_s + V_MM_S / A_MM_S2, rel=0.02)
    assert m.hold_complete()


def test_diagonal_feed_is_capped_along_the_vector() -> None:
    # firmware-facts §4.2: $110=$111=3000, diagonal XY at F10000 gives FS:4243; one axis gives 3000.
    axes = (AxisLimits(250, 3000, 10), AxisLimits(250, 3000, 10), AxisLimits(250, 500, 10))
    m = Motion(axes)
    m.plan_line((-1000.0, -1000.0, 0.0), 10000)
    m.start_cycle(0.0)
    run_until(m, 10.0)
    assert round(m.realtime_rate_mm_min()) == 4243
    m2 = Motion(axes)
    m2.plan_line((-1000.0, 0.0, 0.0), 10000)
    m2.start_cycle(0.0)
    run_until(m2, 10.0)
    assert round(m2.realtime_rate_mm_min()) == 3000


def test_diagonal_acceleration_is_limited_per_axis() -> None:
    # X at 500 mm/s², Z at 200 mm/s²: along (1,0,1)/√2 the cap is 200·√2 = 282.8 mm/s².
    m = Motion(HOBBY)
    m.plan_line((-50.0, 0.0, -50.0), 1000)
    m.start_cycle(0.0)
    run_until(m, 0.02)
    seg = m.trace[0]
    accel = seg.speed_mm_s / ((seg.t1_s - seg.t0_s) / 2)
    assert accel == pytest.approx(200 * math.sqrt(2), rel=0.01)


def test_fed_planner_never_dips() -> None:
    m = Motion(HOBBY)
    step_mm = 0.9
    x = 0.0
    t = 0.0
    for _ in range(15):
        x -= step_mm
        m.plan_line((x, 0.0, 0.0), 5000)
    m.start_cycle(0.0)
    while t < 3.0:
        t = m.next_event_s() or t
        m.advance(t)
        while m.planner_free() > 0:
            x -= step_mm
            m.plan_line((x, 0.0, 0.0), 5000)
    speeds = [s.speed_mm_s for s in m.trace if s.t0_s > 0.5]
    assert min(speeds) >= 0.98 * V_MM_S


def test_right_angle_corner_speed_follows_junction_deviation() -> None:
    m = Motion(HOBBY, junction_deviation_mm=0.01)
    m.plan_line((-100.0, 0.0, 0.0), 5000)
    m.plan_line((-100.0, -100.0, 0.0), 5000)
    # Junction: c = 0, s = sqrt(0.5), a along (−1, −1)/√2 on X/Y limited to 500·√2.
    sin_half = math.sqrt(0.5)
    a_j = 500 * math.sqrt(2)
    v_corner = math.sqrt(a_j * 0.01 * sin_half / (1 - sin_half))
    m.start_cycle(0.0)
    run_to_stop(m)
    near_corner = [s for s in m.trace if abs(s.end_mm[0] + 100) < 1e-6 and s.end_mm[1] == 0.0]
    assert near_corner, "no segment ends at the corner"
    # The segment ending at the corner leaves at the junction speed (within one segment's ramp).
    corner_seg = near_corner[0]
    assert corner_seg.speed_mm_s <= v_corner + A_MM_S2 * m.segment_s


def test_reversal_stops_at_the_junction() -> None:
    m = Motion(HOBBY)
    m.plan_line((-20.0, 0.0, 0.0), 5000)
    m.plan_line((0.0, 0.0, 0.0), 5000)
    m.start_cycle(0.0)
    run_to_stop(m)
    assert m.position_steps() == (0, 0, 0)
    turn = next(i for i, s in enumerate(m.trace) if s.end_mm[0] == -20.0)
    assert m.trace[turn].speed_mm_s < A_MM_S2 * m.segment_s


def test_block_shorter_than_half_a_step_is_empty() -> None:
    m = Motion(HOBBY)
    assert not m.plan_line((0.0004, 0.0, 0.0), 1000)  # 0.32 steps at 800 steps/mm
    assert m.planner_free() == m.planner_blocks
    assert m.plan_line((0.0007, 0.0, 0.0), 1000)  # 0.56 steps rounds to 1


def test_block_added_after_planner_emptied_starts_from_rest() -> None:
    m = Motion(HOBBY)
    m.plan_line((-2.0, 0.0, 0.0), 5000)
    m.start_cycle(0.0)
    while not m.planner_empty():
        m.advance(m.next_event_s() or 0.0)
    t = m.trace[-1].t1_s
    m.plan_line((-4.0, 0.0, 0.0), 5000)
    run_to_stop(m)
    later = [s.speed_mm_s for s in m.trace if s.t0_s >= t]
    # Somewhere between the two blocks the machine came (almost) to rest.
    assert min(later) < A_MM_S2 * m.segment_s


def test_kill_keeps_position_and_drops_everything() -> None:
    m = Motion(HOBBY)
    m.plan_line((-100.0, 0.0, 0.0), 5000)
    m.start_cycle(0.0)
    run_until(m, 0.5)
    pos = m.position_steps()
    m.kill()
    assert not m.is_running()
    assert m.planner_free() == m.planner_blocks
    assert m.position_steps() == pos
    assert m.planner_position_mm() == m.position_mm()


def test_resume_after_run_hold_finishes_the_block() -> None:
    m = Motion(HOBBY)
    m.plan_line((-100.0, 0.0, 0.0), 5000)
    m.start_cycle(0.0)
    run_until(m, 0.5)
    m.hold(0.5)
    t = run_to_stop(m)
    assert m.hold_complete()
    m.resume(t + 1.0)
    run_to_stop(m)
    assert m.position_mm() == (-100.0, 0.0, 0.0)


def test_an_override_cut_near_a_block_end_never_brakes_harder_than_the_axis_allows() -> None:
    from tests.sim.rigtools import Host

    host = Host(machine="fast")
    fw = host.fw
    host.send("G0X-100\nG0X-200\n")
    while fw.mpos_mm()[0] > -80:
        host.run(0.002)
    host.send(b"\x97")  # rapid override 25 % close to the end of the first block
    host.run(3.0)
    accel = fw.settings[120]
    speeds = [
        (abs(s.end_mm[0] - s.start_mm[0]) / (s.t1_s - s.t0_s), s.t1_s - s.t0_s)
        for s in fw.trace
        if s.t1_s - s.t0_s > 0.005
    ]
    worst = max(
        (v0 - v1) / ((dt0 + dt1) / 2) for (v0, dt0), (v1, dt1) in itertools.pairwise(speeds)
    )
    assert worst <= accel * 1.02
    assert fw.mpos_mm()[0] == pytest.approx(-200.0, abs=0.01)  # and it still ends on target
