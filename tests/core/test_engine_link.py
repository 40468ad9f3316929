"""The engine sizes itself from the link it measures: round trips, stalls, baud and RX room."""

from __future__ import annotations

import re

from smoothjog.core import increments as inc
from smoothjog.core.engine import JogTuning, SendRealtime
from smoothjog.core.engine.stream import LINE_SHARE, RELEASE_WAIT_S
from smoothjog.core.intents import ContinuousIntent
from smoothjog.core.realtime import STATUS_QUERY
from tests.core.engine_harness import START_MPOS, EngineHarness

HELD = ContinuousIntent({"X": -1.0}, 1.0)
V_MM_S = 5000 / 60
A_MM_S2 = 500.0


def _increment_mm(line: str) -> float:
    match = re.search(r"X(-?[\d.]+)", line)
    assert match, line
    return abs(float(match.group(1)))


def _held(h: EngineHarness, seconds: float, *, reply_s: float = 0.002) -> None:
    """Hold the stick; every line answered reply_s after it was sent, a report at each `?`."""
    h.rest_at(START_MPOS)
    h.intent(HELD)
    answers: list[float] = []
    end_s = h.t + seconds
    while h.t < end_s:
        h.advance(0.002)
        while answers and answers[0] <= h.t:
            answers.pop(0)
            h.ok()
        out = h.poll()
        answers += [h.t + reply_s] * sum(1 for o in out if not isinstance(o, SendRealtime))


def test_at_9600_baud_blocks_are_long_enough_for_the_wire_and_polls_leave_it_room() -> None:
    fast = EngineHarness()
    _held(fast, 1.0)
    slow = EngineHarness(tuning=JogTuning(byte_s=10 / 9600))
    _held(slow, 1.0)
    fast_mm = _increment_mm(fast.jog_lines()[-2])
    slow_mm = _increment_mm(slow.jog_lines()[-2])
    line_s = (len(slow.jog_lines()[-2]) + 1) * 10 / 9600
    # A line takes line_s on the wire: a block must last well over that at full speed, and so
    # long that a release expects to wait at most RELEASE_WAIT_S for a line still crossing.
    assert slow_mm / V_MM_S >= line_s / LINE_SHARE - 1e-9
    assert slow_mm / V_MM_S >= line_s * line_s / (2 * RELEASE_WAIT_S) - 1e-9
    assert slow_mm / V_MM_S > 0.075  # 25 ms lines: blocks of 78 ms
    assert slow_mm > 2 * fast_mm
    queries = [i for i, o in enumerate(slow.sent) if getattr(o, "byte", None) == STATUS_QUERY]
    assert len(queries) <= 1.0 / 0.15 + 1  # 50-byte reports at 9600 baud: not 20 a second


def test_slow_round_trips_lengthen_the_queue_and_the_blocks() -> None:
    h = EngineHarness()
    _held(h, 2.0, reply_s=0.100)
    engine = h.engine
    assert engine.clock.rtt_hi_s >= 0.099
    # The lines the 128-byte RX buffer holds must span the round trip.
    line_bytes = len(h.jog_lines()[-2]) + 1
    rx_lines = 128 // line_bytes - 1
    assert _increment_mm(h.jog_lines()[-2]) / V_MM_S >= 0.1 / rx_lines - 1e-5  # 4 decimals
    # And the queue bridges that round trip beyond the stopping distance.
    target_mm = inc.queue_target_mm(V_MM_S, A_MM_S2, engine.stream.ahead_s(0.0105, h.t))
    assert target_mm >= V_MM_S**2 / (2 * A_MM_S2) + V_MM_S * 0.1


def test_a_stall_is_remembered_for_thirty_seconds_then_forgotten() -> None:
    h = EngineHarness()
    _held(h, 0.5)
    typical_s = h.engine.clock.rtt_hi_s
    # One reply held up 0.3 s, then the link is quick again for 20 s of replies.
    engine = h.engine
    h.ok_all()
    while not h.unanswered():
        h.advance(0.002)
        h.poll()
    h.oldest_engine_line().sent_s = h.t - 0.3
    h.ok()
    assert engine.clock.rtt_hi_s >= 0.299
    _answers_for(h, 20.0)
    assert engine.clock.rtt_hi_s >= 0.299  # still sized for the stall
    _answers_for(h, 11.0)
    assert engine.clock.rtt_hi_s <= typical_s + 0.005


def _answers_for(h: EngineHarness, seconds: float) -> None:
    end_s = h.t + seconds
    while h.t < end_s:
        h.advance(0.002)
        h.ok_all()
        h.poll()


def test_a_host_that_wakes_late_gets_a_longer_queue() -> None:
    """Woken 4 ms after each planned top-up (a busy computer): the queue grows by that much."""
    on_time = EngineHarness()
    _held(on_time, 1.0)
    late = EngineHarness()
    late.rest_at(START_MPOS)
    late.intent(HELD)
    end_s = late.t + 1.0
    while late.t < end_s:
        deadline_s = late.engine.next_deadline_s(late.t)
        late.t = max(deadline_s + 0.004, late.t + 0.002)
        late.ok_all()
        late.poll()
    assert late.engine.clock.lateness_s >= 0.0039
    assert on_time.engine.clock.lateness_s <= 0.002
    grown_s = late.engine.stream.ahead_s(0.0105, late.t) - on_time.engine.stream.ahead_s(
        0.0105, on_time.t
    )
    assert grown_s >= 0.0035


def test_lines_slower_to_be_answered_than_reports_keep_the_queue_for_their_round_trip() -> None:
    # Every `?` answered at once with the machine where the engine expects it (a cruise the link
    # split reads as an instant way out), every line 30 ms after it was sent: the controller is
    # slow to take lines (a slow parser, or lines queued behind someone else's in its RX
    # buffer). The queue must still span those 30 ms, whatever the reports say of the wire.
    h = EngineHarness()
    h.rest_at(START_MPOS)
    h.intent(HELD)
    answers: list[float] = []
    report_due_s: float | None = None
    moving_from_s: float | None = None  # the first line planned: the machine starts
    end_s = h.t + 3.0
    while h.t < end_s:
        h.advance(0.002)
        while answers and answers[0] <= h.t:
            answers.pop(0)
            h.ok()
            if moving_from_s is None:
                moving_from_s = h.t
        if report_due_s is not None and report_due_s <= h.t:
            # Built as the `?` arrives, where the machine is: at rest, speeding up, cruising.
            report_due_s = None
            run_s = h.t - moving_from_s if moving_from_s is not None else 0.0
            if run_s <= 0.0:
                h.status("Idle", START_MPOS)
            elif run_s < V_MM_S / A_MM_S2:
                x_mm = START_MPOS[0] - 0.5 * A_MM_S2 * run_s**2
                h.status("Jog", (x_mm, *START_MPOS[1:]), fs=(round(A_MM_S2 * run_s * 60), 0))
            else:
                x_mm = START_MPOS[0] - V_MM_S * (run_s - V_MM_S / (2 * A_MM_S2))
                h.status("Jog", (x_mm, *START_MPOS[1:]), fs=(5000, 0))
        out = h.poll()
        answers += [h.t + 0.030] * sum(1 for o in out if not isinstance(o, SendRealtime))
        if any(getattr(o, "byte", None) == STATUS_QUERY for o in out):
            report_due_s = h.t + 0.004
    split = h.engine.clock.split
    assert split.ready
    spread_s = split.spread_s()
    assert spread_s is not None
    assert spread_s < 0.003  # the reports show a quick, steady way out
    assert h.engine.clock.queue_rtt_s(h.t) >= 0.029
