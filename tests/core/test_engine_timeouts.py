"""Every wait of the stop handshake ends: a reply lost on the link is presumed lost, in words.

Grbl answers every line, so a reply that never comes was garbled or dropped on the way back. The
stop used to wait for it for ever: the machine coasted to the end of its queue and every later
jog was ignored, with no fault shown.
"""

from __future__ import annotations

from smoothjog.core.intents import ContinuousIntent, StepIntent, StopIntent
from smoothjog.core.jogger import Phase
from tests.core.engine_harness import START_MPOS, EngineHarness, kinds

HELD = ContinuousIntent({"X": -1.0}, 1.0)


def _released_with_one_reply_lost() -> EngineHarness:
    """A held jog released; every jog line answered but the newest, whose `ok` is lost."""
    h = EngineHarness()
    h.rest_at(START_MPOS)
    h.intent(HELD)
    h.run(0.5)
    h.status("Jog", h.engine._track.point_at(h.engine._track.x_est_mm), fs=(5000, 0))
    h.ok_all()
    while not h.unanswered():  # on to the next top-up
        h.advance(0.002)
        h.poll()
    h.intent(StopIntent())
    assert kinds(h.poll()) in ([], ["?"])  # waiting for that jog's ok, which never comes
    h.advance(0.1)
    h.status("Idle", h.path_end())  # the machine ran its queue out and rests
    return h


def test_a_stop_waiting_for_a_lost_jog_reply_cancels_and_syncs_after_the_timeout() -> None:
    h = _released_with_one_reply_lost()
    h.advance(0.3)
    assert [k for k in kinds(h.poll()) if k != "?"] == []  # a late reply is still possible
    h.advance(0.3)
    # Reported Idle yet silent: first `~`, in case a late 0x85 left Grbl suspended
    # (firmware-facts §3.8), then the cancel and the sync.
    assert [k for k in kinds(h.poll()) if k != "?"] == ["~", "0x85", "G4P0"]
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
    h.advance(0.1)
    h.status("Idle", h.path_end())
    h.advance(0.5)  # the G4P0's ok is lost
    assert [k for k in kinds(h.poll()) if k != "?"] == ["~", "0x85", "G4P0"]
    assert any("did not answer 1 line" in t for t in h.fault_texts())
    h.ok()
    h.status("Idle", START_MPOS)
    h.poll()
    assert h.engine.phase is Phase.IDLE


def test_a_sync_reply_lost_every_time_ends_the_stop_on_a_status_report() -> None:
    h = _released_with_one_reply_lost()
    h.ok()
    h.poll()
    for _ in range(10):
        h.advance(0.1)
        h.status("Idle", h.path_end())
        h.advance(0.5)
        h.poll()
        if h.engine._stop.phase.value == "wait-status":
            break
    else:
        raise AssertionError("the stop never gave up on the sync line")
    h.status("Idle", START_MPOS)
    h.poll()
    assert h.engine.phase is Phase.IDLE


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
    h.advance(0.1)
    h.status("Idle", h.path_end())
    h.advance(0.6)
    assert "~" not in kinds(h.poll())
    assert h.engine.stats.replies_presumed_lost == 1
