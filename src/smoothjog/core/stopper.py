"""Holds which step of the stop handshake (firmware-facts §3.1, §3.6) is under way; the engine
drives it.

The handshake: wait until every `$J` has its `ok`, send 0x85 if anything may be moving, send
`G4P0`; its `ok` means stopped and synced, then an Idle status report gives the position. An
`error:9` on the `G4P0` means a jog restarted: cancel again. This object only records the
steps; the engine decides when each one happens.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

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
