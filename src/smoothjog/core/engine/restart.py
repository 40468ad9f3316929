"""The restart watch: after a banner with jog lines on the wire, cancel each one that starts.

Lines still on the wire when the controller restarted reach it as new jogs. One 0x85 goes out
with the banner (reset_outputs); then, until the settings are read again, the engine asks `?`
every OWED_POLL_S and cancels each jog a report shows running, once the replies of those lines
have come or gone quiet (one 0x85 after the last of them throws them away together; where 0x85
empties the RX buffer, at once). Measured: docs/jogging.md, "Resets"; bench/results (reset).
"""

from __future__ import annotations

import math

from smoothjog.core.engine.clock import LinkClock
from smoothjog.core.engine.limits import JOG_STATES
from smoothjog.core.engine.lines import others_poll
from smoothjog.core.engine.reports import OWED_POLL_S, ReportReader
from smoothjog.core.ledger import Ledger


class RestartWatch:
    """Whether lines sent before a reset may still start the restarted controller."""

    def __init__(self, ledger: Ledger, clock: LinkClock, reports: ReportReader) -> None:
        """No reset watched."""
        self.ledger = ledger
        self.clock = clock
        self.reports = reports
        #: A banner came with jog lines unanswered: one 0x85 goes out at once (reset_outputs).
        self.reset_cancel = False
        #: When that banner came (None: no watch); the host reads no settings until settled.
        self.since_s: float | None = None
        #: Replies still due to lines the ledger dropped at that banner (any owner's), the
        #: ledger's counts of lines dropped at resets and of replies to nobody's line when last
        #: looked at, and when the last such reply came.
        self.replies_due = 0
        self._lost = ledger.stats.lost_to_reset
        self._unowned = 0
        self.reply_s = -math.inf

    @property
    def watching(self) -> bool:
        """True while lines from before a reset are watched."""
        return self.since_s is not None

    def banner(self, now_s: float, *, jogs: int, watching: bool) -> bool:
        """A banner came (jogs: the engine's jog lines unanswered then, watching: a watch was
        under way); True when the watch (re)starts."""
        lost_total = self.ledger.stats.lost_to_reset
        dropped, self._lost = lost_total - self._lost, lost_total
        if not (jogs or watching):
            return False
        self.since_s = now_s
        # Each line the ledger dropped may still be answered, whoever wrote it: its reply then
        # goes to nobody's line.
        self.replies_due = (self.replies_due if watching else 0) + dropped
        self._unowned = self.ledger.stats.unowned_replies
        self.reply_s = now_s
        return True

    def quiet_s(self) -> float:
        """How long no reply of a line from before the reset must come before the rest count as
        thrown away by it: a poll and the spread of the round trips (an FTDI adapter's timer
        holds replies back in batches)."""
        return OWED_POLL_S + max(self.clock.rtt_hi_s - self.clock.rtt_s, 0.0)

    def cancel_due(self, now_s: float, *, flushes_rx: bool) -> bool:
        """True when a jog seen running may be cancelled now: no reply of the old lines is
        still due, they went quiet, or 0x85 empties the RX buffer anyway."""
        unowned = self.ledger.stats.unowned_replies
        if unowned != self._unowned:
            self.replies_due -= unowned - self._unowned
            self._unowned = unowned
            self.reply_s = now_s
        return self.replies_due <= 0 or now_s - self.reply_s >= self.quiet_s() or flushes_rx

    def wire_clear(self, now_s: float) -> None:
        """Every line written before the reset has left the host now: only a `?` asked from
        now on comes behind them all."""
        if self.since_s is not None:
            self.since_s = max(self.since_s, now_s)

    def settled(self, state: str | None) -> bool:
        """True once no line sent before the restart can still start the machine.

        That is when the controller answered Idle to two `?`s in a row written after the
        banner (or wire_clear), the second after the first report came back: each `?` went
        behind every earlier line, and Grbl parses a jog line within milliseconds once no
        cancel holds it (firmware-facts §3.7). Also in a state that starts no jog.
        """
        since_s = self.since_s
        if since_s is None:
            return True
        if state is not None and state not in JOG_STATES:
            return True
        return self.reports.idle_answers_since(since_s) >= 2 + others_poll(self.ledger)
