"""The engine's planned wake-ups: it asks to be polled only when something it can see is due.

A held jog is driven here the way the host drives it: a poll at each deadline the engine gives,
and after a reply or report only when the engine says it wants one. The queue must then stay as
full as the physics needs, while routine `ok`s and reports ask for no poll of their own.
"""

from __future__ import annotations

import pytest

from smoothjog.core.engine import Phase, SendLine, SendRealtime
from smoothjog.core.intents import ContinuousIntent, StopIntent
from smoothjog.core.ledger import ENGINE
from smoothjog.core.responses import ErrorReply, Ok
from tests.core.engine_harness import START_MPOS, EngineHarness, status_line

V_MM_S = 5000 / 60
A_MM_S2 = 500.0  # the harness machine's acceleration (mm/s²)
ROUND_TRIP_S = 0.003


def _drive(h: EngineHarness, until_s: float) -> dict[str, int]:
    """Run the host's rule to until_s: poll at deadlines, answer each line one round trip later."""
    counts = {"polls": 0, "reply_polls": 0, "quiet_replies": 0}
    h.poll()
    answer_at = [h.t + ROUND_TRIP_S] * len(h.ledger.outstanding(ENGINE))
    while h.t < until_s:
        deadline = h.engine.next_deadline_s(h.t)
        assert deadline > h.t  # never "poll again at once"
        nxt = min([deadline, *answer_at])
        h.t = nxt
        if answer_at and answer_at[0] <= nxt:
            answer_at.pop(0)
            entry = h.ledger.on_reply()
            assert entry is not None
            assert entry.owner == ENGINE
            if h.engine.on_reply(entry, Ok(), h.t):
                counts["reply_polls"] += 1
            else:
                counts["quiet_replies"] += 1
                continue
        before = len(h.ledger.outstanding(ENGINE))
        h.poll()
        counts["polls"] += 1
        answer_at += [h.t + ROUND_TRIP_S] * (len(h.ledger.outstanding(ENGINE)) - before)
    return counts


def test_a_held_jog_is_topped_up_at_its_planned_wake_ups_and_no_more() -> None:
    h = EngineHarness()
    h.status("Idle", START_MPOS)
    h.intent(ContinuousIntent({"X": -1.0}, 1.0))
    counts = _drive(h, 1.0)
    stop_mm = V_MM_S**2 / (2 * A_MM_S2)
    # Every poll the estimate is past its ramp finds at least the stopping distance queued.
    assert h.engine.view(h.t).queued_mm >= stop_mm
    jogs = h.jog_lines()
    # About one line per 10.5 ms block once at speed, each answered by a quiet `ok`.
    assert 70 <= len(jogs) <= 110
    assert counts["quiet_replies"] >= 0.85 * len(jogs)
    # No poll without a reason: about one per line sent plus the status polls (20 Hz).
    assert counts["polls"] <= len(jogs) + 2 * 20 + 10


def test_the_first_ok_and_every_ok_while_stopping_want_a_poll() -> None:
    h = EngineHarness()
    h.status("Idle", START_MPOS)
    h.intent(ContinuousIntent({"X": -1.0}, 1.0))
    h.poll()
    first = h.oldest_engine_line()
    assert h.engine.on_reply(h.ledger.on_reply() or first, Ok(), h.advance(0.003))
    h.intent(StopIntent())
    h.poll()
    assert h.engine.phase is Phase.STOPPING
    entry = h.ledger.on_reply()
    assert entry is not None
    assert h.engine.on_reply(entry, Ok(), h.advance(0.003))


def test_an_error_reply_always_wants_a_poll() -> None:
    h = EngineHarness()
    h.status("Idle", START_MPOS)
    h.intent(ContinuousIntent({"X": -1.0}, 1.0))
    h.poll()
    entry = h.ledger.on_reply()
    assert entry is not None
    assert h.engine.on_reply(entry, ErrorReply(15), h.advance(0.003))


@pytest.mark.parametrize(
    ("state", "lead_mm", "wants_poll"),
    [
        ("Jog", 0.0, False),  # where the estimate expected it
        ("Jog", -0.5, False),  # behind: the queue is longer than assumed, never shorter
        ("Jog", 0.2, True),  # ahead: the next top-up is due earlier than planned
        ("Idle", 0.0, True),  # any other state is news
        ("Hold", 0.0, True),
    ],
    ids=["on-the-estimate", "behind", "ahead", "idle", "hold"],
)
def test_a_status_report_wants_a_poll_only_when_it_changes_something(
    state: str, lead_mm: float, wants_poll: bool
) -> None:
    h = EngineHarness()
    h.status("Idle", START_MPOS)
    h.intent(ContinuousIntent({"X": -1.0}, 1.0))
    _drive(h, 0.5)
    assert h.engine.phase is Phase.JOGGING
    h.engine.track.update_estimate(h.t)
    x_now = h.engine.track.x_est_mm
    # The report's own wire time moves it forward; place it so the estimate lands lead_mm on.
    age_s = (len(status_line(state, START_MPOS)) + 2) * h.engine.clock.byte_s
    along_mm = x_now + lead_mm - h.engine.track.v_est_mm_s * age_s
    mpos = (START_MPOS[0] - along_mm, START_MPOS[1], START_MPOS[2])
    resp_line = status_line(state, mpos, (5000, 0))
    from smoothjog.core.responses import parse_response

    resp = parse_response(resp_line)
    h.model.apply(resp)
    assert h.engine.on_response(resp, h.t) is wants_poll


def test_a_routine_report_wants_a_poll_when_the_next_top_up_comes_after_the_next_query() -> None:
    # A long block (a slowdown, a slide along an edge) can put the next top-up 200 ms away:
    # the report's poll must re-arm the 50 ms status deadline, or the engine looks at the
    # machine four times less often (and sees an outside stop that much later).
    h = EngineHarness()
    h.status("Idle", START_MPOS)
    h.intent(ContinuousIntent({"X": -1.0}, 1.0))
    _drive(h, 0.5)
    h.poll()
    h.engine.track.update_estimate(h.t)
    age_s = (len(status_line("Jog", START_MPOS)) + 2) * h.engine.clock.byte_s
    along_mm = h.engine.track.x_est_mm - h.engine.track.v_est_mm_s * age_s
    from smoothjog.core.responses import parse_response

    resp = parse_response(
        status_line("Jog", (START_MPOS[0] - along_mm, *START_MPOS[1:]), (5000, 0))
    )
    h.model.apply(resp)
    h.engine.stream.wake_at_s = h.t + 0.2  # the top-up a 200 ms block plans
    assert h.engine.on_response(resp, h.t)
    assert h.engine.next_deadline_s(h.t) <= h.t + 0.06


def test_a_poll_between_top_ups_sends_only_the_status_query_when_it_is_due() -> None:
    h = EngineHarness()
    h.status("Idle", START_MPOS)
    h.intent(ContinuousIntent({"X": -1.0}, 1.0))
    _drive(h, 0.5)
    h.poll()  # a full poll: plans the next top-up
    mark = h.mark()
    wake = h.engine.next_deadline_s(h.t)
    # Just before the wake-up, with nothing heard since: no jog line, at most a status query.
    h.t = wake - 1e-4
    out = h.poll()
    assert not [o for o in out if isinstance(o, SendLine)]
    assert all(isinstance(o, SendRealtime) and o.byte == b"?" for o in out)
    # At the wake-up the queue has drained to its target: a line goes.
    h.t = wake
    assert [o for o in h.since(mark) + h.poll() if isinstance(o, SendLine)]
