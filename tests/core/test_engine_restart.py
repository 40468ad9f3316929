"""A controller reset by someone else while jog lines of ours were on the wire.

Lines that reach the restarted controller start it as fresh jogs (firmware-facts §3.4). Before
the host reads the settings again, the engine watches with `?` and cancels each such jog it sees
running (restart_outputs), and says when none can start any more (restart_settled). Only
realtime bytes go out meanwhile: the settings' replies must not mix with a sync line's.
"""

from __future__ import annotations

import dataclasses

from smoothjog.core.engine import JogTuning
from smoothjog.core.engine.reports import OWED_POLL_S
from smoothjog.core.intents import ContinuousIntent
from tests.core.engine_harness import BANNER, START_MPOS, EngineHarness, kinds

HELD = ContinuousIntent({"X": -1.0}, 1.0)
RUNNING = (-1.2, -1.0, -1.0)
GRBLHAL_BANNER = "GrblHAL 1.1f ['$' or '$HELP' for help]"


def _reset_with_jogs_on_the_wire(
    firmware: str = "grbl", tuning: JogTuning | None = None
) -> tuple[EngineHarness, int]:
    """A press whose first jog lines are unanswered when the banner comes; how many."""
    h = EngineHarness(limits={"firmware": firmware}, tuning=tuning)
    h.rest_at(START_MPOS)
    h.intent(HELD)
    h.poll()
    jogs = len(h.unanswered())
    assert jogs >= 2
    h.advance(0.02)
    h.feed(BANNER if firmware == "grbl" else GRBLHAL_BANNER)
    assert kinds(h.engine.reset_outputs()) == ["0x85"]
    return h, jogs


def _watch(h: EngineHarness, dt_s: float = OWED_POLL_S) -> list[str]:
    """The host's wait: some time passes, then the engine says what to send."""
    h.advance(dt_s)
    return kinds(h.engine.restart_outputs(h.t))


def test_after_a_reset_the_engine_asks_until_two_idle_reports_show_nothing_started() -> None:
    h, _jogs = _reset_with_jogs_on_the_wire()
    assert not h.engine.restart_settled()
    assert h.engine.busy()  # the host is not at rest while such a line may still start it
    assert _watch(h, 0.0) == ["?"]
    h.status("Idle", START_MPOS)
    assert not h.engine.restart_settled()  # that `?` may have passed a line still unparsed
    assert _watch(h) == ["?"]
    h.status("Idle", START_MPOS)
    assert h.engine.restart_settled()
    assert not h.engine.busy()


def test_a_jog_started_by_lines_from_before_the_reset_is_cancelled_after_their_replies() -> None:
    h, jogs = _reset_with_jogs_on_the_wire()
    assert _watch(h, 0.0) == ["?"]
    h.status("Idle", START_MPOS)
    for _ in range(jogs - 1):
        h.feed("ok")  # replies to lines the ledger forgot at the banner
    assert _watch(h) == ["?"]
    h.status("Jog", RUNNING, fs=(1500, 0))
    # One reply may still come: its line would start on its own after a cancel now.
    assert "0x85" not in _watch(h, 0.002)
    h.feed("ok")
    assert _watch(h, 0.001) == ["0x85"]
    assert not h.engine.restart_settled()
    # The jog brakes under that cancel: no second 0x85 into its end (firmware-facts §3.8).
    assert _watch(h) == ["?"]
    h.status("Jog", (-1.3, -1.0, -1.0), fs=(600, 0))
    assert "0x85" not in _watch(h)
    h.status("Idle", (-1.35, -1.0, -1.0))
    assert _watch(h) == ["?"]
    h.status("Idle", (-1.35, -1.0, -1.0))
    assert h.engine.restart_settled()


def test_replies_the_reset_threw_away_are_waited_for_only_a_quiet_spell() -> None:
    h, _jogs = _reset_with_jogs_on_the_wire()
    assert _watch(h, 0.0) == ["?"]
    h.status("Idle", START_MPOS)
    h.feed("ok")  # the others were lost with the reset's RX buffer
    assert _watch(h) == ["?"]
    h.status("Jog", RUNNING, fs=(1500, 0))
    assert "0x85" not in _watch(h, 0.001)
    quiet_s = OWED_POLL_S + h.engine.clock.rtt_hi_s - h.engine.clock.rtt_s
    assert kinds(h.engine.restart_outputs(h.t + quiet_s))[:1] == ["0x85"]


def test_the_first_jog_report_after_the_banner_may_be_braking_and_is_not_cancelled() -> None:
    h, jogs = _reset_with_jogs_on_the_wire()
    for _ in range(jogs):
        h.feed("ok")
    assert _watch(h, 0.0) == ["?"]
    h.status("Jog", RUNNING, fs=(900, 0))  # under reset_outputs' 0x85, or just started
    assert "0x85" not in _watch(h)
    h.status("Jog", (-1.3, -1.0, -1.0), fs=(1500, 0))  # faster: running, not braking
    assert _watch(h, 0.0)[:1] == ["0x85"]


def test_where_0x85_empties_the_rx_buffer_a_running_jog_is_cancelled_at_once() -> None:
    h, _jogs = _reset_with_jogs_on_the_wire("grblhal")
    assert _watch(h, 0.0) == ["?"]
    h.status("Idle", START_MPOS)
    assert _watch(h) == ["?"]
    h.status("Jog", RUNNING, fs=(1500, 0))
    # No reply came yet, but grblHAL's 0x85 throws the lines not yet read away as well.
    assert _watch(h, 0.0)[:1] == ["0x85"]


def test_a_restart_into_alarm_starts_no_jog_and_needs_no_watch() -> None:
    h, _jogs = _reset_with_jogs_on_the_wire()
    h.feed("ALARM:3")
    h.status("Alarm", START_MPOS)
    assert h.engine.restart_settled()


def test_a_reset_with_every_jog_answered_needs_no_watch() -> None:
    h = EngineHarness()
    h.rest_at(START_MPOS)
    h.intent(HELD)
    h.poll()
    h.ok_all()
    h.feed(BANNER)
    assert h.engine.restart_settled()
    assert h.engine.restart_outputs(h.t) == []


def test_reading_the_settings_again_ends_the_watch_and_keeps_the_cancel_owed() -> None:
    h, _jogs = _reset_with_jogs_on_the_wire()
    h.engine.reset_machine(dataclasses.replace(h.engine.limits))
    assert h.engine.restart_settled()
    assert h.engine.restart_outputs(h.t) == []
    h.status("Idle", START_MPOS)
    assert kinds(h.poll())[:2] == ["0x85", "G4P0"]


def test_reports_are_asked_often_while_watching_even_on_a_slow_wire() -> None:
    """At 9600 baud the usual share of the return wire spaces reports 150 ms apart."""
    h, _jogs = _reset_with_jogs_on_the_wire(tuning=JogTuning(byte_s=10 / 9600))
    assert _watch(h, 0.0) == ["?"]
    h.status("Idle", START_MPOS)
    assert _watch(h) == ["?"]


def test_a_second_reset_during_the_watch_starts_it_again_and_keeps_the_cancel_owed() -> None:
    h, _jogs = _reset_with_jogs_on_the_wire()
    assert _watch(h, 0.0) == ["?"]
    h.status("Idle", START_MPOS)
    assert _watch(h) == ["?"]  # this `?` dies with the second reset
    h.feed(BANNER)
    assert kinds(h.engine.reset_outputs()) == ["0x85"]  # the old lines may still start it
    # The report from before it does not count, and the lost `?` is not waited for.
    assert not h.engine.restart_settled()
    assert _watch(h, 0.001) == ["?"]
    h.status("Idle", START_MPOS)
    assert not h.engine.restart_settled()
    assert _watch(h) == ["?"]
    h.status("Idle", START_MPOS)
    assert h.engine.restart_settled()
    h.engine.reset_machine(dataclasses.replace(h.engine.limits))
    assert kinds(h.poll())[:2] == ["0x85", "G4P0"]


def test_reports_asked_before_the_old_lines_left_the_host_do_not_count() -> None:
    h, _jogs = _reset_with_jogs_on_the_wire()
    assert _watch(h, 0.0) == ["?"]
    h.status("Idle", START_MPOS)
    h.engine.restart_wire_clear(h.advance(0.002))  # the link's queue held lines until now
    assert _watch(h) == ["?"]
    h.status("Idle", START_MPOS)
    assert not h.engine.restart_settled()
    assert _watch(h) == ["?"]
    h.status("Idle", START_MPOS)
    assert h.engine.restart_settled()


def test_a_jog_waiting_on_old_replies_is_woken_when_they_go_quiet() -> None:
    h, _jogs = _reset_with_jogs_on_the_wire()
    assert _watch(h, 0.0) == ["?"]
    h.status("Idle", START_MPOS)
    assert _watch(h) == ["?"]
    h.advance(0.005)
    h.feed("ok")  # one old line answered; the others may follow
    h.status("Jog", RUNNING, fs=(1500, 0))
    assert _watch(h, 0.0) == []
    assert _watch(h, 0.006) == ["?"]  # no 0x85 yet: the last reply came 6 ms ago
    # That `?`'s report may be slow (up to status_timeout_s): the engine's deadline is the end
    # of the quiet spell, when the jog is cancelled.
    quiet_s = OWED_POLL_S + h.engine.clock.rtt_hi_s - h.engine.clock.rtt_s
    deadline_s = h.engine.next_deadline_s(h.t)
    assert deadline_s <= h.engine.restart.reply_s + quiet_s + 1e-9
    assert kinds(h.engine.restart_outputs(deadline_s)) == ["0x85"]


def test_a_jog_at_rest_right_after_idle_is_ending_and_gets_no_cancel() -> None:
    """A step of 0.01 mm sent as someone reset the controller starts it and ends at once: its
    first report is Jog with FS:0. A 0x85 then would land in its last moments and leave Grbl
    1.1h suspended, answering no line, so the settings could never be read again (fuzz)."""
    h, jogs = _reset_with_jogs_on_the_wire()
    for _ in range(jogs):
        h.feed("ok")
    assert _watch(h, 0.0) == ["?"]
    h.status("Idle", START_MPOS)
    assert _watch(h) == ["?"]
    h.status("Jog", (-1.0, -1.0, -1.01), fs=(0, 0))
    assert "0x85" not in _watch(h)
