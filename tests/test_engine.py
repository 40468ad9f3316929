"""The jog engine against the simulator in virtual time: streaming, stopping, safety, tracking."""

from __future__ import annotations

import itertools
import math

import pytest

from smoothjog.core.engine import JogTuning, Phase, SendLine
from smoothjog.core.errors import JogBuildError
from smoothjog.core.intents import ContinuousIntent, GotoIntent, StepIntent, StopIntent
from smoothjog.core.machine import KeepOut
from smoothjog.core.responses import ErrorReply, GcodeModes
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import get_firmware_profile
from smoothjog.sim.rig import LinkModel, SimRig
from smoothjog.virtual import VirtualHost

V_MM_S = 5000 / 60  # hobby router X/Y
A_MM_S2 = 500.0
STEP_MM = 1 / 80  # hobby router X/Y steps/mm


def session(
    firmware: str = "grbl", machine: str = "hobby-router", keepouts: tuple[KeepOut, ...] = ()
) -> VirtualHost:
    fw = GrblFirmware(get_firmware_profile(firmware), machine)
    vs = VirtualHost(SimRig(fw, LinkModel()), keepouts=keepouts)
    vs.handshake()
    return vs


def sent_lines(vs: VirtualHost) -> list[str]:
    """Every line the engine sends from now on (wraps the rig)."""
    lines: list[str] = []
    original = vs.rig.host_send

    def spy(data: bytes, now_s: float) -> float:
        if data.endswith(b"\n"):
            lines.append(data.decode().strip())
        return original(data, now_s)

    vs.rig.host_send = spy  # type: ignore[method-assign]
    return lines


def gcode_words(vs: VirtualHost) -> tuple[str, ...]:
    return next(r.words for r in vs.query_line("$G") if isinstance(r, GcodeModes))


def test_every_jog_line_names_units_and_distance_mode() -> None:
    vs = session()
    lines = sent_lines(vs)
    vs.set_intent(ContinuousIntent({"X": -1.0, "Y": -0.5}, 0.7))
    vs.run_until(vs.now_s + 1.0)
    vs.set_intent(StopIntent())
    assert vs.run_until_idle(3.0)
    jogs = [line for line in lines if line.startswith("$J=")]
    assert len(jogs) > 20
    assert all(line.startswith("$J=G21G91") and "F" in line for line in jogs)
    assert "G4P0" in lines  # the stop's sync point


def test_modal_state_is_unchanged_by_a_session() -> None:
    vs = session()
    vs.query_line("G20")  # a modal state a jog line must not depend on or change
    vs.query_line("G90")
    before = gcode_words(vs)
    vs.set_intent(ContinuousIntent({"X": -1.0}, 1.0))
    vs.run_until(vs.now_s + 0.7)
    vs.set_intent(ContinuousIntent({"X": 1.0, "Z": -0.5}, 0.4))
    vs.run_until(vs.now_s + 0.3)
    vs.set_intent(StopIntent())
    assert vs.run_until_idle(3.0)
    vs.set_intent(StepIntent("Y", -2.5))
    assert vs.run_until_idle(3.0)
    assert gcode_words(vs) == before
    assert "G20" in before
    assert "G90" in before


def test_release_at_full_speed_stops_like_the_firmware_floor_with_no_restart() -> None:
    vs = session()
    vs.set_intent(ContinuousIntent({"X": -1.0}, 1.0))
    vs.run_until(vs.now_s + 1.0)
    t_release = vs.now_s
    x_release = vs.rig.firmware.mpos_mm()[0]
    vs.set_intent(ContinuousIntent({"X": 0.0}))
    assert vs.run_until_idle(3.0)
    vs.run_until(vs.now_s + 0.5)
    dist = x_release - vs.rig.firmware.mpos_mm()[0]
    # The firmware floor: ≤ 50 ms of committed segments at v, then v²/2a.
    assert dist <= V_MM_S * 0.055 + V_MM_S**2 / (2 * A_MM_S2)
    moving_after = [s for s in vs.rig.trace if s.t0_s > t_release and s.speed_mm_s > 0]
    # One continuous deceleration: no pause followed by more motion (a ghost jog).
    for a, b in itertools.pairwise(moving_after):
        assert b.t0_s - a.t1_s < 1e-9
    engine = vs.engine
    assert engine is not None
    assert engine.stats.stops[-1].cancelled
    assert engine.stats.stops[-1].tracked_error_steps <= 1.0
    assert engine.stats.recancels == 0


def test_held_jog_never_dips_below_the_commanded_speed() -> None:
    vs = session()
    vs.set_intent(ContinuousIntent({"X": -1.0}, 1.0))
    t0 = vs.now_s
    vs.run_until(t0 + 4.0)
    vs.set_intent(StopIntent())
    vs.run_until_idle(3.0)
    held = [s for s in vs.rig.trace if t0 + 0.3 < s.t0_s and s.t1_s < t0 + 4.0]
    assert held
    assert min(s.speed_mm_s for s in held) >= 0.98 * V_MM_S


def test_queue_is_just_what_holding_speed_needs() -> None:
    vs = session()
    vs.set_intent(ContinuousIntent({"X": -1.0}, 1.0))
    vs.run_until(vs.now_s + 1.5)
    engine = vs.engine
    assert engine is not None
    queued = engine.view(vs.now_s).queued_mm
    stop_mm = V_MM_S**2 / (2 * A_MM_S2)
    assert stop_mm < queued < stop_mm + V_MM_S * 0.1  # v²/2a plus at most 100 ms of travel


def test_diagonal_never_runs_faster_than_asked() -> None:
    vs = session()
    lines = sent_lines(vs)
    vs.set_intent(ContinuousIntent({"X": -1.0, "Y": -1.0}, 1.0))
    vs.run_until(vs.now_s + 1.5)
    feeds = {float(line.split("F")[1]) for line in lines if line.startswith("$J=")}
    # Asked: 5000 mm/min on each axis = 7071 along the diagonal; Grbl caps the vector at
    # 5000/0.7071 = 7071, so the request fits exactly and no axis exceeds its 5000.
    assert max(feeds) <= 5000 * math.sqrt(2) + 0.01
    held = [s for s in vs.rig.trace if s.t0_s > vs.now_s - 0.5]
    for seg in held:
        dt = seg.t1_s - seg.t0_s
        vx = abs(seg.end_mm[0] - seg.start_mm[0]) / dt
        assert vx <= V_MM_S * 1.001


def test_steps_are_exact_and_tracked() -> None:
    vs = session()
    start = vs.rig.firmware.mpos_mm()
    for d in (-0.1, -0.1, -1.0, -10.0, 0.0125):
        vs.set_intent(StepIntent("X", d, 0.5))
    assert vs.run_until_idle(5.0)
    end = vs.rig.firmware.mpos_mm()
    assert end[0] - start[0] == pytest.approx(-11.1875, abs=STEP_MM / 2)
    engine = vs.engine
    assert engine is not None
    assert engine.stats.stops[-1].tracked_error_steps <= 1.0


def test_goto_moves_in_machine_coordinates() -> None:
    vs = session()
    vs.set_intent(GotoIntent({"X": -123.45, "Y": -67.8}, 0.8))
    assert vs.run_until_idle(10.0)
    pos = vs.rig.firmware.mpos_mm()
    assert pos[0] == pytest.approx(-123.45, abs=STEP_MM)
    assert pos[1] == pytest.approx(-67.8, abs=STEP_MM)


def test_jog_into_the_soft_limit_stops_at_the_edge_without_error_15() -> None:
    vs = session()  # homed at the + corner, MPos -1, soft limits on: + has 1 mm of room
    vs.set_intent(ContinuousIntent({"X": 1.0, "Y": 1.0}, 1.0))
    vs.run_until(vs.now_s + 1.0)
    vs.set_intent(StopIntent())
    assert vs.run_until_idle(3.0)
    engine = vs.engine
    assert engine is not None
    assert engine.stats.soft_limit_errors == 0
    pos = vs.rig.firmware.mpos_mm()
    assert -2 * STEP_MM <= pos[0] <= 0.0
    assert -2 * STEP_MM <= pos[1] <= 0.0


def test_keep_out_zone_is_never_entered_and_the_jog_slides_along_it() -> None:
    zone = KeepOut("vise", (-60.0, -30.0, -100.0), (-20.0, 10.0, 0.0))
    vs = session(keepouts=(zone,))
    vs.set_intent(ContinuousIntent({"X": -1.0, "Y": -0.2}, 1.0))
    vs.run_until(vs.now_s + 1.5)
    vs.set_intent(StopIntent())
    assert vs.run_until_idle(3.0)
    for seg in vs.rig.trace:
        for p in (seg.start_mm, seg.end_mm):
            assert not (-60 < p[0] < -20 and -30 < p[1] < 10), f"entered the zone at {p}"
    pos = vs.rig.firmware.mpos_mm()
    assert pos[0] == pytest.approx(-20.0, abs=2 * STEP_MM)  # stopped at the zone's face
    assert pos[1] < -1.0 - 1.0  # and slid on along -Y


@pytest.mark.parametrize("firmware", ["grbl", "grblhal", "fluidnc"])
def test_random_press_release_reverse_is_safe_on_every_firmware(firmware: str) -> None:
    from bench.fuzz import run_fuzz

    report = run_fuzz(firmware, sequences=40, seed=7)
    assert report.sequences == 40
    assert report.clean, report


def test_an_unhomed_machine_with_soft_limits_jogs_inside_the_envelope_it_believes() -> None:
    # MPos 0,0,0 is what a power-up and $X without homing look like: the machine may sit on a
    # limit switch and must be jogged off it (the pendant warns that it is unhomed).
    fw = GrblFirmware(get_firmware_profile("grbl"), "hobby-router")
    vs = VirtualHost(SimRig(fw, LinkModel()))
    vs.handshake()
    vs.query_line("G53G0X0Y0Z0")
    vs.run_until(vs.now_s + 1.0)
    engine = vs.engine
    assert engine is not None
    assert engine.can_jog() == (True, None)
    vs.set_intent(ContinuousIntent({"X": -1.0}))
    vs.run_until(vs.now_s + 0.5)
    vs.set_intent(ContinuousIntent({"X": 0.0}))
    vs.run_until(vs.now_s + 1.0)
    assert vs.rig.firmware.mpos_mm()[0] < -5.0
    # Toward + the envelope (max 0) leaves no room: nothing is sent that Grbl would refuse.
    vs.set_intent(ContinuousIntent({"X": 1.0}))
    vs.run_until(vs.now_s + 2.0)
    vs.set_intent(ContinuousIntent({"X": 0.0}))
    vs.run_until(vs.now_s + 1.0)
    assert vs.rig.firmware.mpos_mm()[0] <= 0.0
    assert not [r for _, r in vs.received if isinstance(r, ErrorReply)]


def test_alarm_state_blocks_jogging_with_a_reason() -> None:
    vs = session(machine="hobby-router")
    # A G-code move beyond the soft limit: ALARM:2, and no ok until a reset (firmware-facts §2).
    vs.rig.host_send(b"G53G0X-1000\n", vs.now_s)
    vs.run_until(vs.now_s + 1.0)
    vs.rig.host_send(b"\x18", vs.now_s)
    vs.run_until(vs.now_s + 1.0)
    engine = vs.engine
    assert engine is not None
    ok, reason = engine.can_jog()
    assert not ok
    assert reason is not None
    assert "Alarm" in reason


def test_invalid_intents_are_refused_with_a_sentence() -> None:
    vs = session()
    engine = vs.engine
    assert engine is not None
    for bad in (
        ContinuousIntent({"Q": 1.0}),
        ContinuousIntent({"X": 2.0}),
        ContinuousIntent({"X": 1.0}, 0.0),
        StepIntent("X", 500.0),
        StepIntent("X", 0.0001),
        GotoIntent({"X": math.nan}),
    ):
        with pytest.raises(JogBuildError):
            engine.set_intent(bad, vs.now_s)
    assert engine.phase is Phase.IDLE


def test_poll_output_is_deterministic() -> None:
    def run() -> list[str]:
        vs = session()
        lines = sent_lines(vs)
        vs.set_intent(ContinuousIntent({"X": -0.8, "Y": -0.3}, 0.9))
        vs.run_until(vs.now_s + 0.8)
        vs.set_intent(StopIntent())
        vs.run_until_idle(3.0)
        return lines

    assert run() == run()


def test_engine_outputs_are_lines_and_realtime_bytes_only() -> None:
    vs = session()
    engine = vs.engine
    assert engine is not None
    engine.set_intent(ContinuousIntent({"X": -1.0}), vs.now_s)
    out = engine.poll(vs.now_s)
    assert out
    assert all(isinstance(o, SendLine) or o.byte in (b"?", b"\x85") for o in out)


def test_tuning_defaults_follow_the_firmware_facts() -> None:
    tuning = JogTuning()
    assert tuning.committed_s == pytest.approx(0.05)  # 5 segments of 10 ms (firmware-facts §4.1)
    assert tuning.planner_reserve_blocks >= 1


def test_inch_reports_are_understood_and_jogs_stay_in_mm() -> None:
    vs = session()
    vs.query_line("$13=1")  # reports in inches from now on
    vs.query_line("$$")
    vs.run_until(vs.now_s + 0.3)
    engine = vs.engine
    assert engine is not None
    assert engine.model.settings.report_inches
    lines = sent_lines(vs)
    start = vs.rig.firmware.mpos_mm()
    vs.set_intent(StepIntent("X", -25.4, 0.5))
    assert vs.run_until_idle(5.0)
    assert vs.rig.firmware.mpos_mm()[0] == pytest.approx(start[0] - 25.4, abs=STEP_MM)
    mpos = engine.model.mpos_mm
    assert mpos is not None
    assert mpos[0] == pytest.approx(start[0] - 25.4, abs=0.003)  # the model holds mm
    assert all("G21" in line for line in lines if line.startswith("$J="))


def _moved_after(vs: VirtualHost, t_s: float) -> float:
    from bench import measure

    return measure.distance_after(vs.rig.trace, t_s)


def test_door_mid_jog_never_passes_the_planned_path_and_is_cancelled_on_resume() -> None:
    vs = session()
    vs.set_intent(ContinuousIntent({"X": -1.0}, 1.0))
    vs.run_until(vs.now_s + 1.0)
    engine = vs.engine
    assert engine is not None
    t_door = vs.now_s
    # What the engine has queued ahead of the machine: the door cancels it, but a line the
    # controller had already parsed keeps the target it computed before the cancel and runs to
    # it after the resume (firmware-facts §3.1), so this is as far as the machine can go.
    planned_end = engine.planned_end_mm
    assert planned_end is not None
    queued_mm = math.dist(planned_end, vs.rig.firmware.mpos_mm())
    vs.rig.host_send(b"\x84", vs.now_s)  # the safety door opens
    vs.run_until(vs.now_s + 0.5)
    assert engine.phase is Phase.IDLE
    assert any("door" in e.text for e in vs.events)
    assert vs.model.state == "Door"
    vs.rig.host_send(b"~", vs.now_s)
    vs.run_until(vs.now_s + 2.0)
    # The engine cancels what runs after the resume at the first report that shows the jog;
    # the machine never passes the end of the path smoothjog planned before the door opened.
    assert _moved_after(vs, t_door) <= queued_mm + STEP_MM
    assert vs.model.state == "Idle"
    assert not engine.busy()


def test_an_outside_hold_then_a_turn_never_enters_a_keep_out_zone() -> None:
    zone = KeepOut("vise", (-420.0, -420.0, -100.0), (-380.0, -380.0, 0.0))
    vs = session(keepouts=(zone,))
    vs.set_intent(ContinuousIntent({"X": -1.0}, 1.0))
    vs.run_until(vs.now_s + 1.2)
    vs.rig.host_send(b"!", vs.now_s)  # someone else's feed hold: acts as a jog cancel in Jog
    vs.run_until(vs.now_s + 0.3)
    vs.set_intent(ContinuousIntent({"Y": -1.0}, 1.0))
    vs.run_until(vs.now_s + 1.0)
    vs.set_intent(ContinuousIntent({"X": -1.0}, 1.0))
    vs.run_until(vs.now_s + 4.0)
    vs.set_intent(StopIntent())
    vs.run_until_idle(5.0)
    for seg in vs.rig.trace:
        for p in (seg.start_mm, seg.end_mm):
            assert not (-420 < p[0] < -380 and -420 < p[1] < -380), f"inside the vise at {p}"


def test_a_step_to_the_exact_edge_after_a_cancel_never_meets_error_15() -> None:
    vs = session()
    vs.set_intent(ContinuousIntent({"X": 1.0}, 0.05))  # toward the + edge, 1 mm away
    vs.run_until(vs.now_s + 0.25)
    vs.set_intent(StopIntent())
    assert vs.run_until_idle(3.0)
    x = vs.rig.firmware.mpos_mm()[0]
    vs.set_intent(StepIntent("X", round(-x, 3), 0.2))
    vs.run_until_idle(3.0)
    engine = vs.engine
    assert engine is not None
    assert engine.stats.soft_limit_errors == 0
    assert vs.rig.firmware.mpos_mm()[0] <= 0.0


def test_a_stick_pushed_while_a_step_settles_is_kept() -> None:
    vs = session()
    vs.set_intent(StepIntent("X", -20.0, 0.5))
    vs.run_until(vs.now_s + 0.1)
    y0 = vs.rig.firmware.mpos_mm()[1]
    vs.set_intent(ContinuousIntent({"Y": -1.0}, 0.5))
    vs.run_until(vs.now_s + 2.0)
    assert vs.rig.firmware.mpos_mm()[1] < y0 - 5.0


def test_a_very_slow_jog_still_moves() -> None:
    vs = session()
    x0 = vs.rig.firmware.mpos_mm()[0]
    vs.set_intent(ContinuousIntent({"X": -0.01}, 0.05))  # 2.5 mm/min
    vs.run_until(vs.now_s + 3.0)
    assert vs.rig.firmware.mpos_mm()[0] < x0 - 0.05
