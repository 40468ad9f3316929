"""Every wait of the stop handshake ends: a reply lost on the link is presumed lost, in words.

Grbl answers every line, so a reply that never comes was garbled or dropped on the way back. The
stop used to wait for it for ever: the machine coasted to the end of its queue and every later
jog was ignored, with no fault shown.
"""

from __future__ import annotations

from smoothjog.core.engine import Phase
from smoothjog.core.engine.stopper import MAX_RECANCELS
from smoothjog.core.intents import ContinuousIntent, StepIntent, StopIntent
from tests.core.engine_harness import START_MPOS, EngineHarness, kinds

HELD = ContinuousIntent({"X": -1.0}, 1.0)


def _released_with_one_reply_lost() -> EngineHarness:
    """A held jog released; every jog line answered but the newest, whose `ok` is lost."""
    h = EngineHarness()
    h.rest_at(START_MPOS)
    h.intent(HELD)
    h.run(0.5)
    h.status("Jog", h.engine.track.point_at(h.engine.track.x_est_mm), fs=(5000, 0))
    h.ok_all()
    while not h.unanswered():  # on to the next top-up
        h.advance(0.002)
        h.poll()
    h.intent(StopIntent())
    assert kinds(h.poll()) in ([], ["?"])  # waiting for that jog's ok, which never comes
    h.advance(0.1)
    h.status("Idle", h.path_end())  # the machine ran its queue out and rests
    return h


def _idle_for(h: EngineHarness, seconds: float, *, answer: bool = True) -> list[list[str]]:
    """Run the engine for `seconds`, answering each of its `?` with an Idle report at the
    path's end (if `answer`); the outputs of each poll that gave any, `?` left out."""
    given: list[list[str]] = []
    end_s = h.t + seconds
    while h.t < end_s - 1e-9:
        h.advance(0.025)
        out = kinds(h.poll())
        if "?" in out and answer:
            h.advance(0.01)
            h.status("Idle", h.path_end())
        rest = [k for k in out if k != "?"]
        if rest:
            given.append(rest)
    return given


def test_a_stop_waiting_for_a_lost_jog_reply_cancels_and_syncs_after_the_timeout() -> None:
    h = _released_with_one_reply_lost()
    assert _idle_for(h, 0.4) == []  # a late reply is still possible
    # Reported Idle yet silent: first `~`, in case a late 0x85 left Grbl suspended
    # (firmware-facts §3.8); a suspended Grbl would answer then, so nothing is given up yet.
    assert _idle_for(h, 0.3) == [["~"]]
    assert h.engine.stats.suspend_releases == 1
    assert h.engine.stats.replies_presumed_lost == 0
    # Still silent after `~`: the reply was lost; the cancel and the sync, and no second `~`.
    assert _idle_for(h, 0.6) == [["0x85", "G4P0"]]
    assert h.engine.stats.suspend_releases == 1
    assert any("did not answer 1 line within" in t for t in h.fault_texts())
    assert h.engine.stats.replies_presumed_lost == 1
    assert h.ledger.stats.presumed_answered == 1
    h.ok()  # the sync's reply, now credited to the sync
    h.status("Idle", START_MPOS)
    h.poll()
    assert h.engine.phase is Phase.IDLE
    # Not wedged: the next jog runs.
    h.intent(StepIntent("X", -1.0))
    assert "$J" in kinds(h.poll())


def test_a_lost_sync_reply_syncs_again() -> None:
    h = _released_with_one_reply_lost()
    h.ok()  # the last jog's reply came after all
    assert [k for k in kinds(h.poll()) if k != "?"] == ["0x85", "G4P0"]
    # The G4P0's ok is lost: `~` first (nothing comes of it), then the cancel and sync again.
    assert _idle_for(h, 1.3) == [["~"], ["0x85", "G4P0"]]
    assert any("did not answer 1 line" in t for t in h.fault_texts())
    h.ok()
    h.status("Idle", START_MPOS)
    h.poll()
    assert h.engine.phase is Phase.IDLE


def test_a_suspended_grbl_answers_after_the_release_each_reply_to_its_own_line() -> None:
    # A late 0x85 left Grbl 1.1h suspended in Idle with the sync line unread (firmware-facts
    # §3.8). `~` releases it and it answers that G4P0 then: the stop ends on that reply, and
    # the next line's `ok` is its own. Given up at `~`, the sync's late `ok` went to a Z step
    # sent after the stop, which was taken for done before it began (fuzz: 4000 steps off).
    h = _released_with_one_reply_lost()
    h.ok()  # the last jog's reply came after all
    assert [k for k in kinds(h.poll()) if k != "?"] == ["0x85", "G4P0"]
    assert _idle_for(h, 0.7) == [["~"]]  # suspended: the G4P0 is not parsed
    h.advance(0.02)
    h.ok()  # the G4P0, parsed once `~` released the suspend
    h.status("Idle", h.path_end())
    h.poll()
    assert h.engine.phase is Phase.IDLE
    assert h.engine.stats.replies_presumed_lost == 0
    assert h.ledger.stats.presumed_answered == 0
    assert not any("did not answer" in t for t in h.fault_texts())
    h.intent(StepIntent("Z", -10.0))
    assert "$J" in kinds(h.poll())
    assert len(h.unanswered()) == 1  # the step waits for its own reply
    h.status("Idle", h.path_end())
    h.poll()
    assert h.engine.phase is not Phase.IDLE  # a report before its `ok` does not end the step


def test_a_stall_that_holds_every_report_back_gives_no_reply_up() -> None:
    # A stall holds the sync's reply back, and every report with it: the Idle report from
    # before the wait proves nothing. Given up after 0.5 s, the late `ok` went to the step
    # sent next (FluidNC at 9600 baud in the fuzz: the engine 8.8 mm off, then a keep-out).
    h = _released_with_one_reply_lost()
    h.ok()  # the last jog's reply
    assert [k for k in kinds(h.poll()) if k != "?"] == ["0x85", "G4P0"]
    assert _idle_for(h, 1.0, answer=False) == []  # no report since: no `~`, nothing given up
    assert h.engine.stats.replies_presumed_lost == 0
    h.ok()  # the sync's reply, once the stall ends
    h.status("Idle", h.path_end())
    h.poll()
    assert h.engine.phase is Phase.IDLE
    assert not any("did not answer" in t for t in h.fault_texts())


def test_with_another_poller_one_idle_report_is_not_enough_to_give_a_reply_up() -> None:
    # Another program's `?` may have been answered by the report that looks like ours, so it
    # takes two Idle reports asked after the wait began before the reply is given up.
    h = _released_with_one_reply_lost()
    h.ledger.record_realtime("foreign:sender", b"?")
    h.ok()
    assert [k for k in kinds(h.poll()) if k != "?"] == ["0x85", "G4P0"]
    while "?" not in kinds(h.poll()):  # the engine's next `?`, asked after the wait began
        h.advance(0.01)
    h.advance(0.01)
    h.status("Idle", h.path_end())  # answered: one Idle report
    assert _idle_for(h, 1.2, answer=False) == []  # not yet
    assert _idle_for(h, 0.7) == [["~"]]  # further reports: given up (after `~` on Grbl 1.1h)


def test_a_sync_reply_lost_every_time_ends_the_stop_on_a_status_report() -> None:
    h = _released_with_one_reply_lost()
    h.ok()
    h.poll()
    for _ in range(30):
        _idle_for(h, 0.6)  # every `?` answered Idle, no `ok` ever
        if h.engine.phase is Phase.IDLE:
            break
    else:
        raise AssertionError("the stop never gave up on the sync line")
    # It gave up after its bounded re-syncs and ended on a status report.
    assert h.engine.stats.recancels == MAX_RECANCELS


def test_while_the_machine_still_moves_a_reply_may_wait_for_planner_room() -> None:
    # Grbl holds a line's ok until its planner has room: on a slow machine with long blocks
    # that is a long wait, and no sign of a lost reply while reports still show Jog.
    h = _released_with_one_reply_lost()
    h.status("Jog", h.path_end())
    h.advance(2.0)
    h.status("Jog", h.path_end())
    assert [k for k in kinds(h.poll()) if k != "?"] == []
    h.advance(2.5)  # far longer than any planner wait: presumed lost after all
    # Still reported Jog: no `~` (it would resume a hold), only the cancel and the sync.
    assert [k for k in kinds(h.poll()) if k != "?"] == ["0x85", "G4P0"]


def test_replies_that_keep_coming_are_never_presumed_lost() -> None:
    # A slow link: the replies come, late but steadily; the wait restarts at each of them.
    h = EngineHarness()
    h.rest_at(START_MPOS)
    h.intent(HELD)
    h.run(0.5)
    h.intent(StopIntent())
    while h.unanswered():
        h.advance(0.4)
        h.ok()
        h.poll()
    assert h.engine.stats.replies_presumed_lost == 0
    assert not any("did not answer" in t for t in h.fault_texts())


def test_a_silent_idle_grblhal_gets_no_cycle_start() -> None:
    # Only Grbl 1.1h is known to suspend in Idle on a late 0x85; elsewhere `~` is not sent.
    h = EngineHarness(limits={"firmware": "grblhal"})
    h.rest_at(START_MPOS)
    h.intent(HELD)
    h.run(0.5)
    h.ok_all()
    while not h.unanswered():
        h.advance(0.002)
        h.poll()
    h.intent(StopIntent())
    h.poll()
    assert ["~"] not in _idle_for(h, 0.7)
    assert h.engine.stats.replies_presumed_lost == 1
