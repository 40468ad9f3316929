"""Stops from outside smoothjog: a feed hold or 0x85 from another program, a button, a pin.

Grbl shows `Jog` throughout a jog's hold or cancel and then runs the lines still in its RX buffer
(firmware-facts §3.1-§3.2), so an Idle report may never be seen. The engine must notice the
machine falling behind what it was sent, stop, and then not move again until the user presses
anew, however often the held stick is re-sent. A pin that reads active all along is no press.
"""

from __future__ import annotations

import dataclasses

import pytest

from smoothjog.core.engine import JogTuning, Phase, bounds
from smoothjog.core.intents import ContinuousIntent, StepIntent, StopIntent
from smoothjog.core.machine import KeepOut
from tests.core.engine_harness import START_MPOS, EngineHarness, jog_target, kinds

HELD = ContinuousIntent({"X": -1.0}, 1.0)
FEED_MM_MIN = 5000.0
V_MM_S = FEED_MM_MIN / 60


def _ghost_clear(h: EngineHarness, deltas: tuple[float, ...]) -> bool:
    return h.engine.clearance.ghost_clear(deltas, h.engine.signs.rest_inside)


def _near_a_junction_at_rest(h: EngineHarness) -> bool:
    track = h.engine.track
    return bounds.near_a_junction_at_rest(track, track.x_est_mm, h.engine.tuning)


def _estimate_mm(h: EngineHarness, behind_mm: float = 0.0) -> tuple[float, ...]:
    """Where the engine believes the machine is, less behind_mm along the path."""
    track = h.engine.track
    return track.point_at(track.x_est_mm - behind_mm)


def _cruising(firmware: str = "grbl") -> EngineHarness:
    """A held X- jog at full speed for a second, one report seen at speed, a `?` just sent."""
    h = EngineHarness(limits={"firmware": firmware})
    h.rest_at(START_MPOS)
    h.intent(HELD)
    h.run(1.0)
    h.status("Jog", _estimate_mm(h), fs=(FEED_MM_MIN, 0))
    while h.engine.reports.asked_s is None:  # on to the next `?`
        h.run(h.t + 0.002)
    h.advance(0.003)  # its report comes back a round trip later
    return h


def _outside_faults(h: EngineHarness) -> list[str]:
    return [t for t in h.fault_texts() if "stopped outside smoothjog" in t]


def _assert_stopped_outside(h: EngineHarness, words: str) -> None:
    """The engine said someone else stopped the jog, in words containing `words`, and stops."""
    faults = _outside_faults(h)
    assert faults, h.fault_texts()
    assert words in faults[0]
    assert h.engine.phase is Phase.STOPPING


def test_a_jog_that_slows_behind_its_path_is_an_outside_stop_and_is_cancelled() -> None:
    h = _cruising()
    h.status("Jog", _estimate_mm(h, behind_mm=2.0), fs=(3000, 0))
    assert _outside_faults(h), h.fault_texts()
    assert "fell 1.9" in _outside_faults(h)[0]  # 2 mm less the report's wire time at speed
    assert h.engine.phase is Phase.STOPPING
    h.ok_all()
    # The machine brakes for someone else's cancel: only the sync goes, no 0x85 of its own
    # (one that reached Grbl as that cancel ends would leave it suspended, firmware-facts §3.8).
    assert kinds(h.poll()) == ["G4P0"]
    # A line that ran after that stop shows up speeding up again: that one is cancelled.
    h.status("Jog", _estimate_mm(h, behind_mm=2.0), fs=(600, 0))
    h.status("Jog", _estimate_mm(h, behind_mm=1.9), fs=(1500, 0))
    assert kinds(h.poll())[:1] == ["0x85"]


def test_an_outside_stop_seen_at_rest_in_jog_sends_no_cancel_into_its_end() -> None:
    # Jog with FS:0 short of the queued path: the outside cancel is ending (firmware-facts §3.7).
    h = _cruising()
    h.status("Jog", _estimate_mm(h, behind_mm=3.0), fs=(0, 0))
    assert _outside_faults(h), h.fault_texts()
    assert "stood still" in _outside_faults(h)[0]
    out = kinds(h.poll())
    assert "0x85" not in out
    h.ok_all()
    assert "0x85" not in kinds(h.poll())


def test_a_report_as_late_as_its_query_allows_is_no_outside_stop() -> None:
    # The report left 0.2 s after its `?` (a stalled link): it may show the machine up to
    # v x 0.2 s behind the estimate, and still be a faithful report of a running jog.
    h = _cruising()
    h.advance(0.2)
    h.engine.track.update_estimate(h.t)  # where the engine expects the machine by now
    h.status("Jog", _estimate_mm(h, behind_mm=0.9 * V_MM_S * 0.2), fs=(3000, 0))
    assert _outside_faults(h) == []
    assert h.engine.phase is Phase.JOGGING


def test_a_slower_report_close_behind_is_no_outside_stop() -> None:
    h = _cruising()
    h.status("Jog", _estimate_mm(h, behind_mm=0.2), fs=(4000, 0))
    assert h.fault_texts() == []


def test_a_jog_braking_for_the_end_of_what_was_acknowledged_is_no_outside_stop() -> None:
    # Lines late on a stalled link: no reply for a while, the estimate runs on along every
    # line sent, while the machine brakes to stop at the end of the acknowledged ones.
    h = _cruising()
    track = h.engine.track
    acked = [seg for seg in track.path if seg.acked]
    acked_end_mm = acked[-1].x0_mm + acked[-1].length_mm
    while track.x_est_mm < acked_end_mm - 0.5:
        h.advance(0.002)
        track.update_estimate(h.t)
    h.engine.reports.asked_s = h.t - 0.003  # a fresh `?`: its age explains no lag
    # Stopping from 40 mm/s takes 1.6 mm, and the acknowledged jogs hold just that: the planner
    # brakes to stop at the end of what it holds, which is at least what was acknowledged.
    v_mm_s = 40.0
    h.status("Jog", track.point_at(acked_end_mm - 1.65), fs=(v_mm_s * 60, 0))
    assert _outside_faults(h) == []


def test_a_jog_never_seen_at_speed_is_not_judged() -> None:
    # A fresh jog still accelerating (or one that never reaches its speed) lags its estimate.
    h = EngineHarness()
    h.rest_at(START_MPOS)
    h.intent(HELD)
    h.run(0.2)
    h.status("Jog", _estimate_mm(h, behind_mm=3.0), fs=(2000, 0))
    assert _outside_faults(h) == []


def _fresh_slow_link_jog(rest_at_mm: float) -> tuple[EngineHarness, float]:
    """A jog at 60 % just begun at 9600 baud (its first block long, none of it seen at speed),
    reported at rest in Jog rest_at_mm along its path; returns the harness and the first
    block's length."""
    h, first_mm = _long_block_jog(dt_floor_s=None)
    h.status("Jog", h.engine.track.point_at(rest_at_mm), fs=(0, 0))
    return h, first_mm


def test_a_fresh_jog_at_rest_inside_its_first_block_was_stopped_outside() -> None:
    # A hold 0.1 s into a jog at 9600 baud: the run was never seen at speed, yet Grbl only
    # rests at the end of what it planned (short of it by the committed segments). Unseen,
    # the next line started the machine again and it ran 18 mm (fuzz).
    h, first_mm = _fresh_slow_link_jog(1.0)
    assert first_mm > 3.5  # long enough that a rest 1 mm in is far inside it
    _assert_stopped_outside(h, "stood still")


def test_a_fresh_jog_at_rest_at_its_start_or_braking_into_its_first_blocks_end_is_not_judged() -> (
    None
):
    # At the start it has not moved yet; near the block's end its next line came late (a slow
    # link) and the planner brakes for the end of what it holds: FS reaches 0 while the
    # committed segments (2.5 mm from 50 mm/s) still run.
    h, first_mm = _fresh_slow_link_jog(0.0)
    assert h.fault_texts() == []
    h, _ = _fresh_slow_link_jog(first_mm - 2.0)
    assert h.fault_texts() == []
    assert h.engine.phase is Phase.JOGGING


def _long_block_jog(dt_floor_s: float | None = 0.3) -> tuple[EngineHarness, float]:
    """A fresh jog at 50 mm/s at 9600 baud whose blocks run dt_floor_s each (the fuzz saw 13 mm
    blocks there; None: the engine's own floor), its first `?` just asked; returns the
    harness and the first block's length."""
    tuning = JogTuning(byte_s=10 / 9600)
    if dt_floor_s is not None:
        tuning = dataclasses.replace(tuning, dt_floor_s=dt_floor_s)
    h = EngineHarness(tuning=tuning)
    h.rest_at(START_MPOS)
    h.intent(ContinuousIntent({"X": -1.0}, 0.6))
    h.run(0.08)
    while h.engine.reports.asked_s is None:
        h.run(h.t + 0.002)
    h.advance(0.003)
    return h, h.engine.track.path[0].length_mm


def _ask_again(h: EngineHarness, after_s: float) -> None:
    """Let after_s pass, then on to the engine's next `?` and a little past it."""
    h.run(h.t + after_s)
    while h.engine.reports.asked_s is None:
        h.run(h.t + 0.002)
    h.advance(0.003)


def test_a_fresh_jog_far_slower_than_its_long_block_allows_there_was_stopped_outside() -> None:
    # Inside a planned block the machine speeds up from at least rest and brakes only for its
    # end, whatever the link did: 25 mm/s 6 mm into a 15 mm block of 50 mm/s is someone else
    # braking it. Unseen (a hold at 9600 baud, between two reports), the next line started
    # the machine again and 17 mm ran (fuzz).
    h, first_mm = _long_block_jog()
    assert first_mm > 14.0
    track = h.engine.track
    h.status("Jog", track.point_at(6.0), fs=(1500, 0))
    _assert_stopped_outside(h, "ran at 1500 mm/min")


def test_a_long_block_speeding_up_cruising_or_braking_for_its_end_is_not_judged() -> None:
    # Places as measured from the block's start (>= 0) or back from its end (< 0). FS runs
    # ahead of the position by up to the committed lead (2 x 50 ms allowed): 4 mm before the
    # end it may already show the braking for that end (the next line came late).
    for at_mm, fs_mm_min in ((0.4, 1150), (6.0, 2700), (-4.0, 600)):
        h, first_mm = _long_block_jog()
        x_mm = first_mm + at_mm if at_mm < 0 else at_mm
        h.status("Jog", h.engine.track.point_at(x_mm), fs=(fs_mm_min, 0))
        assert h.fault_texts() == [], (at_mm, fs_mm_min)
        assert h.engine.phase is Phase.JOGGING


def _fresh_fast_jog() -> EngineHarness:
    """A fresh held X- jog at full speed 50 ms in, every line answered, a `?` just asked."""
    h = EngineHarness()
    h.rest_at(START_MPOS)
    h.intent(HELD)
    h.run(0.05)
    while h.engine.reports.asked_s is None:
        h.run(h.t + 0.002)
    h.advance(0.003)
    return h


def test_a_fresh_jog_braking_below_what_its_held_jogs_allow_was_stopped_outside() -> None:
    # Speeding up across its first short blocks (40 mm/s 0.3 mm in), with every jog answered
    # far beyond: the next report at 15 mm/s 1.5 mm on is someone else braking it. Unseen
    # (FluidNC, an outside 0x85), the engine sent its next line into the braking and that line
    # ran 5 mm on (fuzz).
    h = _fresh_fast_jog()
    track = h.engine.track
    held_mm = track.path[-1].x1_mm
    assert held_mm > 10.0  # answered jogs reach far beyond the reports below
    h.status("Jog", track.point_at(0.3), fs=(2400, 0))
    assert h.fault_texts() == []
    _ask_again(h, 0.04)
    h.status("Jog", track.point_at(1.8), fs=(900, 0))
    _assert_stopped_outside(h, "slowed to 900 mm/min")


def test_held_jogs_speeding_up_or_braking_for_their_end_are_not_judged() -> None:
    # From the same first report: faster later is the planner's own doing, and so is a feed
    # that braking for the end of what was answered allows (the queue ran dry).
    h = _fresh_fast_jog()
    track = h.engine.track
    h.status("Jog", track.point_at(0.3), fs=(2400, 0))
    _ask_again(h, 0.04)
    h.status("Jog", track.point_at(2.5), fs=(3600, 0))
    assert h.fault_texts() == []
    h = _fresh_fast_jog()
    track = h.engine.track
    h.status("Jog", track.point_at(0.3), fs=(2400, 0))
    end_mm = track.path[-1].x1_mm
    _ask_again(h, 0.01)  # too soon for a top-up: the end of the answered jogs is where it was
    assert track.path[-1].x1_mm == end_mm
    h.status("Jog", track.point_at(end_mm - 1.0), fs=(600, 0))  # braking for that end
    assert h.fault_texts() == []


def test_a_rest_inside_a_block_short_of_its_end_a_report_later_was_stopped_outside() -> None:
    # FS:0 1.2 mm before the block's end may be its last committed segments still running; a
    # report asked 0.15 s later that finds it still short of that end (moving off again) is
    # a machine someone else stopped there. Unseen at 9600 baud, 22 mm ran (fuzz).
    h, first_mm = _long_block_jog()
    track = h.engine.track
    h.status("Jog", track.point_at(first_mm - 1.2), fs=(0, 0))
    assert h.fault_texts() == []
    _ask_again(h, 0.15)
    h.status("Jog", track.point_at(first_mm - 1.05), fs=(1500, 0))
    faults = _outside_faults(h)
    assert faults, h.fault_texts()
    assert "rested 1.20 mm before the end" in faults[0]


def test_a_rest_inside_a_block_that_runs_on_to_its_end_is_not_judged() -> None:
    h, first_mm = _long_block_jog()
    track = h.engine.track
    h.status("Jog", track.point_at(first_mm - 1.2), fs=(0, 0))
    _ask_again(h, 0.15)
    h.status("Jog", track.point_at(first_mm + 0.3), fs=(1500, 0))  # on into the next block
    assert h.fault_texts() == []
    # Nor is a second report too soon after the first to say the committed segments ran.
    h, first_mm = _long_block_jog()
    track = h.engine.track
    h.status("Jog", track.point_at(first_mm - 1.2), fs=(0, 0))
    h.status("Jog", track.point_at(first_mm - 1.1), fs=(0, 0))
    assert h.fault_texts() == []
    assert h.engine.phase is Phase.JOGGING


def test_after_an_outside_stop_the_held_stick_does_not_move_the_machine_again() -> None:
    h = _cruising()
    h.status("Jog", _estimate_mm(h, behind_mm=2.0), fs=(0, 0))
    h.ok_all()
    h.poll()  # 0x85, G4P0
    h.ok_all()
    h.status("Idle", _estimate_mm(h))
    h.poll()
    assert h.engine.phase is Phase.IDLE
    jogs_before = len(h.jog_lines())
    for _ in range(5):  # the input re-sends the stick it still holds
        h.intent(HELD)
        h.run(h.t + 0.1)
    assert len(h.jog_lines()) == jogs_before
    assert h.engine.view(h.t).phase == "idle"
    # Released and pressed again: it jogs.
    h.intent(StopIntent())
    h.intent(HELD)
    h.run(h.t + 0.1)
    assert len(h.jog_lines()) > jogs_before


@pytest.mark.parametrize(("firmware", "cancels"), [("grblhal", True), ("grbl", False)])
def test_lines_that_run_while_their_oks_are_awaited_are_cancelled_where_0x85_flushes_rx(
    firmware: str, cancels: bool
) -> None:
    # An outside 0x85 on grblHAL empties the RX buffer: some jog lines were thrown away and
    # their oks never come, while the ones that crossed the wire after it start the machine
    # again. Waiting for every ok there let 10-28 mm run (fuzz, Wi-Fi and bridge links). On
    # Grbl the lines all survive and answer; one 0x85 after their oks throws them away
    # together (firmware-facts §3.1), so it still waits.
    h = _cruising(firmware)
    while not h.unanswered():  # a line on its way, as at any moment of a held jog
        h.advance(0.002)
        h.poll()
    h.status("Jog", _estimate_mm(h, behind_mm=2.0), fs=(0, 0))
    _assert_stopped_outside(h, "short of the path")
    h.poll()
    mark = h.mark()
    h.advance(0.02)
    h.status("Jog", _estimate_mm(h, behind_mm=2.0), fs=(0, 0))
    h.advance(0.02)
    h.status("Jog", _estimate_mm(h, behind_mm=1.9), fs=(1500, 0))  # running again
    sent = kinds(h.since(mark) + h.poll())
    assert ("0x85" in sent) is cancels, sent
    assert "G4P0" not in sent  # no sync while lines may still be answered
    assert h.unanswered()


def test_a_step_after_an_outside_stop_is_a_new_press() -> None:
    h = _cruising()
    h.status("Jog", _estimate_mm(h, behind_mm=2.0), fs=(0, 0))
    h.ok_all()
    h.poll()
    h.ok_all()
    h.status("Idle", _estimate_mm(h))
    h.poll()
    jogs_before = len(h.jog_lines())
    h.intent(StepIntent("X", -1.0))
    h.run(h.t + 0.1)
    assert len(h.jog_lines()) == jogs_before + 1


def test_a_hold_input_that_reads_active_at_rest_is_one_warning_and_jogs() -> None:
    h = EngineHarness()
    h.status("Idle", START_MPOS, pn="H")
    h.status("Idle", START_MPOS, pn="H")
    infos = [e for e in h.engine.events if e.kind == "info"]
    assert len(infos) == 1
    assert "feed-hold input active while Idle" in infos[0].text
    h.intent(HELD)
    h.run(0.3)
    h.status("Jog", _estimate_mm(h), fs=(FEED_MM_MIN, 0), pn="H")
    h.run(h.t + 0.2)
    assert h.fault_texts() == []
    assert h.engine.phase is Phase.JOGGING


def test_a_hold_input_pressed_mid_jog_names_the_input() -> None:
    h = _cruising()
    h.status("Jog", _estimate_mm(h, behind_mm=2.0), fs=(0, 0), pn="H")
    (fault,) = h.fault_texts()
    assert fault.endswith("stopped by the controller's feed-hold input")
    h2 = _cruising()
    h2.status("Jog", _estimate_mm(h2), fs=(FEED_MM_MIN, 0), pn="D")  # pressed, not yet slower
    assert h2.fault_texts() == [
        "the controller's door input was pressed: the controller is stopping"
    ]


def test_an_outside_stop_on_a_slide_along_a_keep_out_is_seen() -> None:
    # Along a zone's face the jog runs at the speed of the axis left (Y's 5000 mm/min here),
    # never at the diagonal's 7071: the speed it was seen at is that of the jog it is on.
    from smoothjog.core.machine import KeepOut

    h = EngineHarness(keepouts=(KeepOut("vise", (-100.0, -200.0, -100.0), (-20.0, -10.0, 0.0)),))
    h.rest_at(START_MPOS)
    h.intent(ContinuousIntent({"X": -1.0, "Y": -1.0}, 1.0))
    h.run(1.2)
    track = h.engine.track
    here = track.seg_at(track.x_est_mm)
    assert here is not None
    assert here.speed_mm_s < 0.8 * h.engine.stream.commanded.speed_mm_s  # on the slide
    # The path tracks the slide at the speed its lines ask for (Y alone at its $111).
    assert abs(here.speed_mm_s - V_MM_S) < 1e-6
    h.status("Jog", _estimate_mm(h), fs=(here.speed_mm_s * 60, 0))
    while h.engine.reports.asked_s is None:
        h.run(h.t + 0.002)
    h.advance(0.003)
    h.status("Jog", _estimate_mm(h, behind_mm=3.0), fs=(0, 0))
    assert _outside_faults(h), h.fault_texts()
    assert "stood still" in _outside_faults(h)[0]


def test_an_outside_stop_while_the_engine_waits_to_cancel_its_own_is_seen() -> None:
    # Let go (or turned) and the engine waits for the last oks before its 0x85: the queue
    # still runs as sent, so a rest far short of it is someone else's stop. It is said, and its
    # cancel is owed for the lines it left.
    h = _cruising()
    while not h.unanswered():
        h.advance(0.002)
        h.poll()
    h.intent(StopIntent())
    h.poll()
    assert h.engine.phase is Phase.STOPPING
    assert not h.engine.stopping.handshake.cancelled
    h.status("Jog", _estimate_mm(h), fs=(FEED_MM_MIN, 0))
    while h.engine.reports.asked_s is None:  # on to the next `?`
        h.advance(0.002)
        h.poll()
    h.advance(0.003)
    h.status("Jog", _estimate_mm(h, behind_mm=3.0), fs=(0, 0))
    assert _outside_faults(h), h.fault_texts()
    assert h.engine.stopping.handshake.owed
    # The stick was already let go: the next press is a press, not a held stick to ignore.
    h.ok_all()
    h.poll()
    h.ok()
    h.status("Idle", _estimate_mm(h, behind_mm=3.0))
    h.poll()
    h.intent(ContinuousIntent({"X": 1.0}, 1.0))
    h.status("Idle", _estimate_mm(h, behind_mm=3.0))
    assert "$J" in kinds(h.poll())


def test_a_stop_far_off_the_path_sent_is_said_and_not_judged_as_tracking() -> None:
    # An outside stop not seen while it happened: the lines it left ran from where it left the
    # machine, and the final rest lies off every jog sent. The engine says so at the stop.
    h = _cruising()
    h.intent(StopIntent())
    h.ok_all()
    h.poll()
    h.ok()  # the sync
    off = _estimate_mm(h)
    h.status("Idle", (off[0], off[1] + 2.0, off[2]))  # 2 mm beside the path
    h.poll()
    assert h.engine.phase is Phase.IDLE
    assert any("off the path smoothjog sent" in t for t in h.fault_texts()), h.fault_texts()
    assert h.engine.stats.stops[-1].after_outside_stop


def test_a_refused_step_does_not_hide_a_step_thrown_away_from_outside() -> None:
    # A 1 mm X- step is sent and answered, a Y+ step toward a keep-out is refused (nothing of
    # it is sent), and the machine comes to rest where it started: an outside 0x85 threw the X
    # step away (FluidNC answers a jog it throws away with `ok`). The refusal says nothing
    # about the path sent, so the rest 1 mm short of it is still someone else's doing.
    from smoothjog.core.machine import KeepOut

    zone = KeepOut("vise", (-100.0, -30.0, -100.0), (-20.0, -10.0, 0.0))
    h = EngineHarness(keepouts=(zone,))
    start = (-25.0, -30.01, -1.0)  # at the zone's Y- face: no room for Y+
    h.rest_at(start)
    h.intent(StepIntent("X", -1.0))
    for _ in range(20):
        if "$J" in kinds(h.poll()):
            break
        h.advance(0.005)
        h.status("Idle", start)
    assert h.unanswered() == ["$J=G21G91X-1F2500"], h.unanswered()
    h.ok()
    h.intent(StepIntent("Y", 1.0))
    h.poll()
    assert any("step refused" in t for t in h.fault_texts()), h.fault_texts()
    for _ in range(200):
        h.advance(0.01)
        if "?" in kinds(h.poll()):
            h.status("Idle", start)  # it never moved
        if h.engine.phase is Phase.IDLE:
            break
    assert h.engine.phase is Phase.IDLE
    assert any("off the path smoothjog sent" in t for t in h.fault_texts()), h.fault_texts()
    assert h.engine.stats.stops[-1].after_outside_stop


def test_a_stop_on_the_path_raises_nothing() -> None:
    h = _cruising()
    h.intent(StopIntent())
    h.ok_all()
    h.poll()
    h.ok()
    h.status("Idle", _estimate_mm(h))
    h.poll()
    assert h.engine.phase is Phase.IDLE
    assert h.fault_texts() == []
    assert not h.engine.stats.stops[-1].after_outside_stop


def test_a_turn_near_a_keep_out_waits_for_a_report_of_the_machine_at_the_corner() -> None:
    # Along the zone's face toward its corner, then a line past the corner and back across the
    # zone's extent: sent while the machine may still be short of the corner, an outside stop
    # would leave it running from there, into the zone (firmware-facts §3.1).
    from smoothjog.core.engine.tracker import PathSeg
    from smoothjog.core.machine import KeepOut

    zone = KeepOut("vise", (-100.0, -30.0, -100.0), (-20.0, -10.0, 0.0))
    h = EngineHarness(keepouts=(zone,))
    h.rest_at((-19.9, -25.0, -1.0))
    h.intent(ContinuousIntent({"Y": 1.0}, 0.1))
    h.poll()
    track = h.engine.track
    track.path.clear()
    track.end_mm = (-19.9, -25.0, -1.0)
    track.append(PathSeg((-19.9, -25.0, -1.0), (-19.9, -9.9, -1.0), 15.1, 8.3, 500.0, 0.0))
    across = (-1.0, 0.0, 0.0)  # from the corner, X- along the zone's edge (outside it)
    track.x_est_mm = 15.0  # the estimate: almost at the corner ...
    track.x_reported_mm = 14.0  # ... the last report: a millimetre short of it (Y -11)
    assert not _ghost_clear(h, across)
    track.x_est_mm = track.x_reported_mm = 15.1  # reported at the corner: the line may go
    assert _ghost_clear(h, across)
    track.x_reported_mm = None  # no report of this path yet: from its start
    assert not _ghost_clear(h, across)


def test_a_line_behind_unanswered_ones_is_checked_from_where_they_would_take_it() -> None:
    # X+Y+ begun and at once reversed toward a zone: a hold that cuts the X+ line short leaves
    # the X-Y- lines not yet parsed to run one after another from where it stopped, so the
    # next one ends that much further X- (2 mm into the vise in the fuzz, FluidNC over Wi-Fi).
    from smoothjog.core.engine.tracker import PathSeg
    from smoothjog.core.machine import KeepOut

    zone = KeepOut("vise", (-420.0, -420.0, -100.0), (-380.0, -380.0, 0.0))
    h = EngineHarness(keepouts=(zone,))
    start = (-377.0, -413.6, -32.0)
    h.rest_at(start)
    h.intent(ContinuousIntent({"X": -1.0, "Y": -1.0}, 1.0))
    h.poll()
    track = h.engine.track
    track.path.clear()
    track.end_mm = start
    turn = (-373.8, -410.4, -32.0)
    track.append(PathSeg(start, turn, 4.525, 50.0, 500.0, 0.0))
    track.path[0].acked = True
    back = (-0.9148, -0.9148, 0.0)
    here = turn
    for _ in range(5):  # sent, none answered yet
        end = tuple(p + d for p, d in zip(here, back, strict=True))
        track.append(PathSeg(here, end, 1.2937, 118.0, 500.0, track.length_mm()))
        here = end
    track.x_est_mm = track.x_reported_mm = 0.0
    step = (-0.7254, -0.7254, 0.0)  # ends at X -379.10: outside the zone, as planned
    assert here[0] + step[0] > -380.0
    assert not _ghost_clear(h, step)
    for seg in track.path:  # once they are answered they are planned: a hold throws them away
        seg.acked = True
    assert _ghost_clear(h, step)


def _suspended(
    h: EngineHarness,
    reports: int,
    *,
    reading: bool = False,
    braking: bool = True,
    from_feed_mm_min: float = FEED_MM_MIN,
) -> int:
    """Answer the engine's next `reports` queries with Jog at its estimate, as a controller in
    an outside hold's suspend loop does: it answers `?` and reads no line (with reading, it
    reads and answers each line as a running jog does). FS falls by a fifth of full speed per
    report from from_feed_mm_min (with braking; at full speed without). Returns the replies
    given."""
    replies = 0
    seen = 0
    feed = from_feed_mm_min
    while seen < reports:
        h.advance(0.002)
        h.poll()
        asked = h.engine.reports.asked_s
        if asked is not None and h.t - asked >= 0.005:
            if reading:
                replies += len(h.ok_all())
            if braking:
                feed = max(feed - FEED_MM_MIN / 5, 0.0)
            h.status("Jog", _estimate_mm(h), fs=(feed, 0))
            seen += 1
    return replies


def _start_unread_watch() -> EngineHarness:
    h = _cruising()
    h.status("Jog", _estimate_mm(h), fs=(FEED_MM_MIN, 0))  # the report of the `?` under way
    h.ok_all()
    return h


def test_a_jog_line_left_unread_across_two_reports_is_an_outside_stop() -> None:
    # A hold that strikes a jog braking anyway (a starved queue on a slow link) shows neither
    # a lag nor a rest short of the path; the controller answering `?` but leaving the lines it
    # holds unread does (firmware-facts §3.7).
    h = _start_unread_watch()
    _suspended(h, 1)
    assert _outside_faults(h) == []
    _suspended(h, 1, from_feed_mm_min=0.8 * FEED_MM_MIN)
    _assert_stopped_outside(h, "left a jog line unread")


def test_a_report_asked_before_the_line_can_have_arrived_is_not_counted() -> None:
    # Over a Wi-Fi-to-serial bridge a line takes 20-60 ms to reach the controller after it is
    # written: a `?` asked in that time comes back before the line is in, and proves nothing.
    # Only reports asked one usual round trip after the line was written are counted.
    h = _start_unread_watch()
    h.engine.clock.rtt_s = 0.060  # the usual round trip the engine measures on such a bridge
    _suspended(h, 2, from_feed_mm_min=0.8 * FEED_MM_MIN)
    assert _outside_faults(h) == []
    # A real hold still shows, once the reports are asked late enough.
    _suspended(h, 3, from_feed_mm_min=0.4 * FEED_MM_MIN)
    assert _outside_faults(h), h.fault_texts()


def test_a_controller_reading_its_lines_is_no_outside_stop() -> None:
    h = _start_unread_watch()
    assert _suspended(h, 6, reading=True) > 0
    assert h.fault_texts() == []
    assert h.engine.phase is Phase.JOGGING


def test_a_line_unread_while_the_jog_runs_at_its_speed_is_a_full_planner() -> None:
    # The estimate may count a turn's blocks out before the machine ran them, and the engine
    # then fills the planner: Grbl waits for a free block with the line read but unanswered,
    # and the machine runs on at its speed.
    h = _start_unread_watch()
    _suspended(h, 4, braking=False)
    assert h.fault_texts() == []
    assert h.engine.phase is Phase.JOGGING


def test_with_another_program_asking_too_one_more_report_is_needed() -> None:
    # Its `?` may be answered in reply to ours, before our line was in: one report more.
    h = _start_unread_watch()
    h.ledger.record_realtime("foreign:sender", b"?")
    _suspended(h, 2)
    assert _outside_faults(h) == []
    _suspended(h, 1, from_feed_mm_min=0.6 * FEED_MM_MIN)
    assert _outside_faults(h), h.fault_texts()


SLOW = ContinuousIntent({"X": -1.0}, 0.05)  # 250 mm/min on the hobby router's X


def _slow_run_dry(short_mm: float) -> EngineHarness:
    """A slow held jog seen at speed whose report shows FS:0 short_mm before the end of the
    acknowledged lines, the rest of them still unanswered (a Wi-Fi stall holds their oks)."""
    h = EngineHarness()
    h.rest_at(START_MPOS)
    h.intent(SLOW)
    h.run(1.0)
    h.status("Jog", _estimate_mm(h), fs=(SLOW.speed * FEED_MM_MIN, 0))
    while h.engine.reports.asked_s is None:
        h.run(h.t + 0.002, ack=False)
    h.advance(0.003)
    track = h.engine.track
    acked = [seg for seg in track.path if seg.acked]
    end_mm = acked[-1].x0_mm + acked[-1].length_mm
    h.status("Jog", track.point_at(end_mm - short_mm), fs=(0, 0))
    return h


def test_a_slow_jog_resting_short_of_the_end_is_an_outside_stop() -> None:
    # At 250 mm/min a queue that ran dry rests within a few steps of its end; an outside stop
    # rests short of it by the queue's lead (0.3 mm here, firmware-facts §3.1).
    h = _slow_run_dry(0.3)
    assert _outside_faults(h), h.fault_texts()


def _slow_run_out_at_the_soft_limit(short_mm: float) -> EngineHarness:
    """A held X+ jog at 350 mm/min seen at speed, run until everything sent ends at the soft
    limit, then reported at rest in Jog short_mm before that end."""
    h = EngineHarness(soft_limits=True)
    h.rest_at((-3.0, -1.0, -1.0))
    h.intent(ContinuousIntent({"X": 1.0}, 0.07))
    h.run(0.2)
    h.status("Jog", _estimate_mm(h), fs=(0.07 * FEED_MM_MIN, 0))
    track = h.engine.track
    while h.path_end()[0] < -0.02:  # until everything sent ends at X's soft limit (0)
        h.run(h.t + 0.002)
    while track.length_mm() - track.x_est_mm > max(short_mm, 0.3):
        h.run(h.t + 0.002)
    while h.engine.reports.asked_s is None:
        h.run(h.t + 0.002)
    h.advance(0.003)
    h.status("Jog", track.point_at(track.length_mm() - short_mm), fs=(0, 0))
    return h


def test_a_slow_jog_running_out_at_the_soft_limit_may_rest_its_committed_lead_short() -> None:
    # FluidNC at 9600 baud reported FS:0 0.20 mm before the Y soft limit at 350 mm/min with no
    # outside stop: the committed segments still ran at speed. Mid-path that rest would be
    # someone else's stop (test_a_slow_jog_resting_short_of_the_end_is_an_outside_stop).
    h = _slow_run_out_at_the_soft_limit(0.2)
    assert _outside_faults(h) == []
    # Further short than the committed segments at that speed can run: someone else's stop.
    h = _slow_run_out_at_the_soft_limit(1.2)
    assert _outside_faults(h), h.fault_texts()


def test_a_rest_braking_into_a_reversal_from_a_faster_block_is_near_the_junction() -> None:
    # A Y- step at 25 mm/s with a slow Y+ jog queued behind it: the machine brakes into the
    # reversal from the step's speed, and FluidNC was seen at FS:0 0.41 mm before it (its
    # last segments still running). That is within the step's reach, not the slow jog's.
    from smoothjog.core.engine.tracker import PathSeg

    h = EngineHarness()
    track = h.engine.track
    track.begin((0.0, 0.0, 0.0), 0.0)
    track.append(PathSeg((0.0, 0.0, 0.0), (0.0, -2.764, 0.0), 2.764, 25.0, 500.0, 0.0))
    back = PathSeg((0.0, -2.764, 0.0), (0.0, -2.624, 0.0), 0.14, 7.5, 500.0, 2.764)
    track.append(back)
    assert back.entry_cap_mm_s == 0.0  # a reversal: the planner passes it at rest
    track.x_est_mm = 2.764 - 0.41
    assert _near_a_junction_at_rest(h)
    track.x_est_mm = 2.764 - 1.4  # beyond the step's own reach (25²/500 = 1.25 mm)
    assert not _near_a_junction_at_rest(h)


def test_fs_0_ahead_of_a_slow_jog_cruising_into_a_reversal_is_near_the_junction() -> None:
    # A stick swept slowly through zero: an X- jog at 313 mm/min with an X+ jog queued behind
    # it. FS is the speed at the end of the prepared segments, so it reads 0 while the machine
    # still cruises the last committed time before the reversal (0.165 mm in the simulator).
    from smoothjog.core.engine.tracker import PathSeg

    h = EngineHarness()
    track = h.engine.track
    track.begin((0.0, 0.0, 0.0), 0.0)
    slow_mm_s = 313 / 60
    track.append(PathSeg((0.0, 0.0, 0.0), (-2.0, 0.0, 0.0), 2.0, slow_mm_s, 500.0, 0.0))
    back = PathSeg((-2.0, 0.0, 0.0), (-1.87, 0.0, 0.0), 0.13, 2.0, 500.0, 2.0)
    track.append(back)
    assert back.entry_cap_mm_s == 0.0
    track.x_est_mm = 2.0 - 0.165
    assert _near_a_junction_at_rest(h)
    # Beyond what the committed segments cover at that speed: a rest there is someone else's.
    track.x_est_mm = 2.0 - 0.5
    assert not _near_a_junction_at_rest(h)


def test_the_path_ends_where_the_firmware_sums_a_long_g91_stream() -> None:
    # Grbl adds each G91 value to its position in single precision: far from zero the sum of a
    # repeated increment drifts from the decimal one by half an ulp per line, the same way.
    # The engine's path must follow the firmware's sum, or after a few hundred lines a
    # faithful report lies more than two steps off it and is taken for an outside stop.
    from smoothjog.core.units import f32

    h = EngineHarness(limits={"envelope": None})
    start = (-600.0, -1.0, -1.0)
    h.rest_at(start)
    h.intent(ContinuousIntent({"X": -1.0}, 0.37))  # 0.31 mm increments, 2.9 steps in 4 s
    h.run(4.0)
    jogs = h.jog_lines()
    assert len(jogs) > 300
    firmware_x = f32(start[0])
    decimal_x = start[0]
    for line in jogs:
        value = float(line.split("X")[1].split("F")[0])
        firmware_x = f32(firmware_x + f32(value))
        decimal_x += value
    steps_per_mm = 250.0
    assert abs(decimal_x - firmware_x) * steps_per_mm > 2.0  # the drift the test is about
    assert h.engine.planned_end_mm is not None
    assert h.engine.planned_end_mm[0] == firmware_x


def test_a_slide_along_an_edge_keeps_blocks_of_the_engine_time() -> None:
    # At the Y+ soft limit, a stick pushed mostly into it with a little X slides along X at a
    # fraction of the stick's speed. Its increments must last about one block, as any other's:
    # cut to the stick's length they lasted seconds, and no later stick could undo them.
    h = EngineHarness(soft_limits=True)
    h.rest_at((-400.0, -0.004, -1.0))  # one step inside the edge at 0
    h.intent(ContinuousIntent({"X": 0.03, "Y": 0.3}, 1.0))  # the slide: 10 % of the speed
    h.run(0.5)
    jogs = h.jog_lines()
    assert jogs
    for line in jogs:
        assert "Y" not in line  # the blocked axis is dropped
        dist_mm = float(line.split("X")[1].split("F")[0])
        feed_mm_min = float(line.split("F")[1])
        assert dist_mm / (feed_mm_min / 60.0) < 0.1, line
    assert h.fault_texts() == []


def test_a_stick_nearly_square_to_an_edge_stops_there_rather_than_crawl_along_it() -> None:
    # 3 % of the stick's speed left along the edge is a wobble of the stick, not a request to
    # crawl: each such block would hold the planner for a second or more.
    h = EngineHarness(soft_limits=True)
    h.rest_at((-400.0, -0.004, -1.0))
    h.intent(ContinuousIntent({"X": 0.01, "Y": 0.3}, 1.0))
    h.run(0.5)
    assert h.jog_lines() == []
    assert any("the jog stops at the soft limit" in e.text for e in h.engine.events)
    assert h.fault_texts() == []


def test_the_start_of_a_fresh_jog_is_no_junction_at_rest() -> None:
    # A jog starts from rest at its first segment, but speeding up it reports a rising FS; a
    # braking report 14 mm in is someone else's stop, not the start's. Counted as a junction,
    # the start hid a feed hold there, and the lines in the buffer ran 37 mm (fuzz, FTDI).
    from smoothjog.core.engine.tracker import PathSeg

    h = EngineHarness()
    track = h.engine.track
    track.begin((0.0, 0.0, 0.0), 0.0)
    first = PathSeg((0.0, 0.0, 0.0), (-4.794, 0.0, 0.0), 4.794, 87.4, 500.0, 0.0)
    track.append(first)
    assert first.entry_cap_mm_s == 0.0
    x0 = 4.794
    for _ in range(8):
        track.append(PathSeg((-x0, 0.0, 0.0), (-x0 - 1.736, 0.0, 0.0), 1.736, 87.4, 500.0, x0))
        x0 += 1.736
    track.x_est_mm = 13.75
    assert not _near_a_junction_at_rest(h)


def test_a_rest_inside_a_block_holds_back_lines_that_would_enter_a_zone_from_there() -> None:
    """A hold 5 ms after a press, with a reversal behind it (fuzz, FluidNC over CH340): the
    report at rest inside the first block is not yet explained, and the lines behind that
    block may run from there. A slide along the vise sent on the engine's path, 1.5 mm off
    the machine's, took it into the vise before."""
    vise = KeepOut("vise", (-420.0, -420.0, -100.0), (-380.0, -380.0, 0.0))
    start = (-376.963, -400.950, -65.308)
    h = EngineHarness(keepouts=(vise,), limits={"firmware": "fluidnc"}, soft_limits=True)
    h.rest_at(start)
    h.intent(ContinuousIntent({"X": 0.7, "Y": 0.7}, 0.6))
    h.poll()
    h.advance(0.004)
    parsed = len(h.jog_lines())  # parsed before the hold struck: gone with the planner
    h.ok_all()
    h.intent(ContinuousIntent({"X": -1.0, "Y": -1.0, "Z": 0.3}, 1.0))
    h.advance(0.001)
    h.poll()
    h.advance(0.004)
    h.ok_all()
    rest = (-375.875, -399.863, -65.308)  # 1.1 mm into the first block, FS:0
    h.status("Jog", rest, fs=(0, 0))
    assert h.engine.signs.rest_inside is not None
    end = h.t + 0.12
    while h.t < end:
        h.advance(0.005)
        h.ok_all()
        h.poll()
    # Every line behind the first ones, run one after another from the rest, stays clear.
    lines = h.jog_lines()[parsed:]
    for k in range(len(lines) + 1):
        x, y, _z = jog_target(rest, lines[:k])
        assert not (x < -380.0 and y < -380.0), (k, lines)
