"""The stop handshake (firmware-facts §3.1, §3.6): its steps, and the driver that takes them.

The handshake: wait until every `$J` has its `ok`, send 0x85 if anything may be moving, send
`G4P0`; its `ok` means stopped and synced, then an Idle status report gives the position. An
`error:9` on the `G4P0` means a jog restarted: cancel again. StopHandshake only records the
steps; StopDriver decides when each one happens, and bounds every wait.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from smoothjog.core.codes import ERR_SYSTEM_GC_LOCK, error_info
from smoothjog.core.engine.clock import LinkClock
from smoothjog.core.engine.limits import EngineLimits, JogTuning
from smoothjog.core.engine.lines import EngineLines, others_poll
from smoothjog.core.engine.records import EngineStats, Notices, Output, SendRealtime
from smoothjog.core.engine.reports import ReportReader
from smoothjog.core.engine.tracker import PathTracker
from smoothjog.core.firmware import firmware_facts
from smoothjog.core.machine import MachineModel
from smoothjog.core.realtime import CYCLE_START, JOG_CANCEL
from smoothjog.core.responses import ErrorReply, Ok

#: The line whose `ok` means stopped, planner empty and positions synced.
SYNC_LINE = "G4P0"

#: Re-cancels after an `error:9` on the sync line before the stop is given up as failed.
MAX_RECANCELS = 5


class StopPhase(Enum):
    """Where the stop handshake is."""

    IDLE = "idle"  # no handshake under way
    WAIT_ACKS = "wait-acks"  # waiting for every jog line's ok before cancelling
    WAIT_SYNC = "wait-sync"  # cancel (if needed) and the sync line sent; waiting for its reply
    WAIT_STATUS = "wait-status"  # synced (or given up); waiting for an Idle status report


@dataclass
class StopHandshake:
    """The handshake's phase, whether it sent a jog cancel, and how often it re-cancelled."""

    phase: StopPhase = StopPhase.IDLE
    cancelled: bool = False
    recancels: int = 0
    #: The stop was not smoothjog's idea (an outside stop, a door, hold or reset): lines may
    #: restart the machine on their own, so every report of a jog moving is cancelled.
    owed: bool = False

    def begin(self) -> None:
        """A new stop: wait for the jog lines' oks."""
        self.phase = StopPhase.WAIT_ACKS
        self.cancelled = False
        self.recancels = 0
        self.owed = False

    def owe_cancel(self) -> None:
        """Send 0x85 even with no path: lines left in the controller must not run."""
        self.cancelled = True
        self.owed = True

    def sync_sent(self, *, cancel_sent: bool) -> None:
        """Every jog was answered; the sync line (after 0x85 if cancel_sent) is on its way."""
        self.cancelled = self.cancelled or cancel_sent
        self.phase = StopPhase.WAIT_SYNC

    def sync_ok(self) -> None:
        """The sync line's ok: stopped, planner empty, positions synced."""
        self.phase = StopPhase.WAIT_STATUS

    def may_recancel(self) -> bool:
        """True while another re-cancel is allowed."""
        return self.recancels < MAX_RECANCELS

    def recancel(self) -> None:
        """error:9 on the sync line: a jog restarted, so wait for oks and cancel again."""
        self.recancels += 1
        self.phase = StopPhase.WAIT_ACKS

    def sync_failed(self) -> None:
        """The sync line failed otherwise: read the position anyway."""
        self.phase = StopPhase.WAIT_STATUS

    def end(self) -> None:
        """The handshake is over (finished or given up); cancelled and recancels keep its record."""
        self.phase = StopPhase.IDLE


@dataclass
class StopParts:
    """What the stop driver reads and writes beside its own handshake."""

    model: MachineModel
    tuning: JogTuning
    track: PathTracker
    lines: EngineLines
    clock: LinkClock
    reports: ReportReader
    notices: Notices
    stats: EngineStats


class StopDriver:
    """Takes the handshake's steps; every method that ends a wait says whether the stop now
    waits for a fresh Idle report (the caller then asks one)."""

    def __init__(self, parts: StopParts, limits: EngineLimits) -> None:
        """No stop under way."""
        self.parts = parts
        self.limits = limits
        self.handshake = StopHandshake()
        #: When the stop began its current wait, and when the last reply to the engine came.
        self.wait_s = -math.inf
        self.last_reply_s = -math.inf
        #: `~` was sent for a silent Idle since the last reply (see release_suspend).
        self.suspend_released = False

    def begin(self, now_s: float) -> None:
        """A new stop: wait for the jog lines' oks."""
        self.handshake.begin()
        self.wait_s = now_s
        self.suspend_released = False

    def replied(self, now_s: float) -> None:
        """A reply to one of the engine's lines came."""
        self.last_reply_s = now_s
        self.suspend_released = False

    def send_cancel(self, out: list[Output]) -> None:
        """0x85 for a jog a report showed running; the next one needs a new such report."""
        self.parts.reports.cancel_sent()
        out.append(SendRealtime(JOG_CANCEL))
        self.parts.stats.cancels += 1

    def _flushes_rx(self) -> bool:
        return firmware_facts(self.limits.firmware).jog_cancel.flushes_rx

    def advance(self, now_s: float, out: list[Output]) -> bool:
        """Take the next step the replies and reports allow; True when it gave the sync up."""
        p = self.parts
        stop = self.handshake
        if stop.phase is StopPhase.WAIT_ACKS:
            if p.lines.jogs_unanswered():
                # Lines left by someone else's stop start once it ends, each answered as Grbl
                # parses it: one 0x85 after the last of those oks throws them all away together
                # (one sent at the first would hold the others back, firmware-facts §3.1, §3.7).
                if not self.reply_overdue(now_s):
                    if stop.owed and p.reports.jog_unbraked and self._flushes_rx():
                        # Where 0x85 empties the RX buffer (grblHAL, firmware-facts §7) the
                        # outside cancel threw some of these lines away and their oks never
                        # come: cancel the jog that runs now (no sync is out yet to lose).
                        self.send_cancel(out)
                    return False
                if self.release_suspend(now_s, out):
                    return False  # their replies come once `~` acts
                # Their replies were lost: the lines ran (or run); cancel whatever moves.
                self.presume_lost(now_s, ("jog",))
                stop.owe_cancel()
            if p.reports.cancel_ending and p.model.state == "Jog":
                # A cancel not yet seen to end: a 0x85 in its last moments would leave Grbl
                # suspended (firmware-facts §3.8); a line that starts after it is cancelled then.
                cancel = False
            else:
                cancel = bool(p.track.path) or stop.cancelled or p.model.state == "Jog"
            if cancel:
                p.reports.cancel_sent()
                out.append(SendRealtime(JOG_CANCEL))
                p.stats.cancels += 1
            p.lines.send(SYNC_LINE, "sync", now_s, out)
            stop.sync_sent(cancel_sent=cancel)
            self.wait_s = now_s
        elif (
            stop.phase is StopPhase.WAIT_SYNC
            and stop.owed
            and p.reports.jog_unbraked
            and not self._flushes_rx()
        ):
            # The lines left behind an outside stop start as fresh jogs the moment it ends
            # (firmware-facts §3.7): cancel each one seen running until the sync is answered
            # (not where 0x85 empties the RX buffer: it would throw the sync away).
            self.send_cancel(out)
        elif stop.phase is StopPhase.WAIT_SYNC and self.reply_overdue(now_s):
            # The sync line's reply was lost: sync again, a bounded number of times.
            if self.release_suspend(now_s, out):
                return False  # its reply comes once `~` acts
            self.presume_lost(now_s, ("sync",))
            if stop.may_recancel():
                stop.recancel()  # back to waiting for acks, then 0x85 and G4P0 again
                p.stats.recancels += 1
                return self.advance(now_s, out)
            stop.sync_failed()
            return True
        return False

    def reply_overdue(self, now_s: float) -> bool:
        """True when the stop has waited for a reply longer than any link delays one.

        While the machine may still move, Grbl may rightly hold a reply until its planner has
        room, so the wait is eight times as long; the short wait needs an Idle report that
        answers a `?` written a usual round trip after the wait began (two when another program
        polls too): only then is the reply truly missing (see docs/jogging.md, "Stopping").
        """
        p = self.parts
        since_s = max(self.wait_s, self.last_reply_s)
        limit_s = max(p.tuning.reply_timeout_s, 10.0 * p.clock.rtt_s)
        idle_s = p.reports.idle_since_s
        others = others_poll(p.lines.ledger)
        answered_after = p.reports.idle_answers_since(since_s + p.clock.rtt_s)
        if idle_s is not None and answered_after >= 1 + others:
            # Reported at rest for limit_s of the wait: nothing runs that the reply waits for.
            return now_s - max(idle_s, since_s) > limit_s
        return now_s - since_s > 8.0 * limit_s

    def release_suspend(self, now_s: float, out: list[Output]) -> bool:
        """Send `~` to a Grbl 1.1h that reports Idle yet answers no line; True when sent.

        A 0x85 that reached it as a cancel ended suspends it (firmware-facts §3.8); `~`
        releases it, and the lines in its buffer are then parsed and answered, so the wait
        starts again rather than giving them up (a late `ok` would go to the next line).
        """
        facts = firmware_facts(self.limits.firmware).jog_cancel
        if self.suspend_released or not (
            facts.late_cancel_suspends and self.parts.model.state == "Idle"
        ):
            return False
        out.append(SendRealtime(CYCLE_START))
        self.parts.stats.suspend_releases += 1
        self.suspend_released = True
        self.wait_s = now_s
        return True

    def presume_lost(self, now_s: float, kinds: tuple[str, ...]) -> int:
        """Release the engine's unanswered lines of these kinds as answered; say so."""
        lost = self.parts.lines.presume_answered(kinds)
        waited_s = now_s - max(self.wait_s, self.last_reply_s)
        self.parts.notices.fault_now(
            now_s,
            f"the controller did not answer {lost} line{'s' if lost != 1 else ''}"
            f" within {waited_s:.1f} s: the reply was lost on the link",
            "smoothjog cancelled and re-synced; check the cable or connection if this repeats",
        )
        self.wait_s = now_s
        return lost

    def sync_reply(self, resp: Ok | ErrorReply, now_s: float) -> bool:
        """The sync line's reply; True when the stop now waits for a fresh Idle report."""
        p = self.parts
        stop = self.handshake
        if isinstance(resp, Ok):
            stop.sync_ok()
            return True
        if resp.code == ERR_SYSTEM_GC_LOCK and p.model.state != "Alarm" and stop.may_recancel():
            # firmware-facts §3.6: the sync line met a jog that restarted: cancel again (it
            # runs, so no cancel is ending).
            p.reports.cancel_ending = False
            stop.recancel()
            p.stats.recancels += 1
            self.wait_s = now_s
            return False
        p.notices.fault_now(
            now_s, f"stop sync failed: error:{resp.code}", error_info(resp.code).hint
        )
        stop.sync_failed()
        return True
