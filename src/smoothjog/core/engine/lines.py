"""The engine's own lines in the host's ledger: what each one is, and which still wait for a reply.

The ledger counts every owner's bytes against the controller's RX buffer; the engine keeps its
own entries, oldest first, to match each reply to the kind of line it answers.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from smoothjog.core.engine.clock import LinkClock
from smoothjog.core.engine.records import EngineStats, Output, SendLine
from smoothjog.core.engine.tracker import PathSeg
from smoothjog.core.ledger import ENGINE, Entry, Ledger, line_cost_bytes


@dataclass(frozen=True)
class LineTag:
    """What the engine keeps with each of its lines in the ledger."""

    kind: str  # "jog", "sync"
    seg: PathSeg | None = None
    #: By when its last byte has surely left the host: every byte counted in flight before it
    #: (its own included) at the controller's baud rate (the link's queue drains no slower).
    written_by_s: float = 0.0


def kind(entry: Entry) -> str:
    """The kind of one of the engine's ledger entries."""
    tag = entry.tag
    return tag.kind if isinstance(tag, LineTag) else ""


class EngineLines:
    """The engine's lines sent and not yet answered, oldest first."""

    def __init__(self, ledger: Ledger, clock: LinkClock, stats: EngineStats) -> None:
        """No line pending."""
        self.ledger = ledger
        self.clock = clock
        self.stats = stats
        self.pending: deque[Entry] = deque()
        #: The last poll held a line back for want of room in the controller's RX buffer.
        self.rx_blocked = False

    def send(
        self, line: str, kind: str, now_s: float, out: list[Output], seg: PathSeg | None = None
    ) -> None:
        """Send a line and remember it until its ok/error."""
        clock = self.clock
        in_flight_bytes = self.ledger.in_flight_bytes + line_cost_bytes(line)
        tag = LineTag(kind, seg, now_s + in_flight_bytes * clock.byte_s)
        clock.wire_free_s = max(clock.wire_free_s, now_s) + line_cost_bytes(line) * clock.byte_s
        self.pending.append(self.ledger.record_line(ENGINE, line, now_s, tag))
        self.stats.lines_sent += 1
        if kind == "jog":
            self.stats.jogs_sent += 1
        out.append(SendLine(line))

    def fits(self, line: str) -> bool:
        """True when the line fits in the controller's RX buffer beside every owner's lines."""
        return self.ledger.fits(line)

    def unanswered(self) -> bool:
        """True while any line sent awaits its ok/error."""
        return bool(self.pending)

    def jogs_unanswered(self) -> bool:
        """True while any jog line sent awaits its ok/error."""
        return any(kind(e) == "jog" for e in self.pending)

    def jogs_pending(self) -> int:
        """How many jog lines await their reply."""
        return sum(1 for e in self.pending if kind(e) == "jog")

    def forget(self) -> None:
        """Forget every line unanswered (the controller was reset and dropped them)."""
        self.pending.clear()

    def answered(self, entry: Entry) -> bool:
        """Take entry's reply: True when it is the oldest line (Grbl answers in order); else
        drop it from the pending lines if it is there, and False."""
        if not self.pending or self.pending[0] is not entry:
            if entry in self.pending:
                self.pending.remove(entry)
            return False
        self.pending.popleft()
        return True

    def presume_answered(self, kinds: tuple[str, ...]) -> int:
        """Release the unanswered lines of these kinds as answered; how many."""
        lost = [e for e in self.pending if kind(e) in kinds]
        for entry in lost:
            self.pending.remove(entry)
        self.ledger.presume_answered(lost)
        self.stats.replies_presumed_lost += len(lost)
        return len(lost)


def others_poll(ledger: Ledger) -> bool:
    """True when another program also asks `?` (or relays its lines): a report may then
    answer its `?` rather than smoothjog's."""
    return ledger.relayed or ledger.stats.queries_by_others > 0
