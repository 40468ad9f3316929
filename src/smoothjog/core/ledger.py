"""The line ledger: every line and realtime byte sent to one controller, with who sent it.

Grbl answers every line it reads with exactly one `ok` or `error:N`, in the order the lines
arrived, and drops bytes that reach a full RX ring (firmware-facts §5.1). So one place must count
the bytes of every unanswered line against the controller's RX buffer, whoever wrote the line,
and hand each reply to the owner of the oldest unanswered line. That place is this ledger.

Owners are short names: `handshake`, `engine`, `console`, or `foreign:NAME` for a sender whose
lines smoothjog forwards without having written them (a second program on the same controller).
Status reports, alarms, `[MSG:]` and banners belong to nobody; the host fans them out to all.

Over a relay that several clients write through (CNCjs), the order in which lines reach the
controller is the relay's, not smoothjog's: the relay echoes every client's line, in wire order,
before it writes it. A relayed ledger (`relayed=True`) therefore keeps smoothjog's own lines
"not yet on the wire" until their echo comes (`on_echo`), and puts a line echoed for somebody else
(a foreign writer) just before the first of its own lines still waiting for theirs: that is where
it went on the wire. Replies then pop the oldest line as everywhere else.

Pure bookkeeping: no I/O, no clock (the caller passes `now_s`).
"""

from __future__ import annotations

import collections
from collections.abc import Iterable
from dataclasses import dataclass, field

from smoothjog.core.errors import CoreError
from smoothjog.core.firmware import GRBL

#: Grbl 1.1h's RX ring, assumed until the handshake's `$I` says otherwise.
DEFAULT_RX_BYTES = GRBL.rx_buffer_bytes

HANDSHAKE = "handshake"
ENGINE = "engine"
CONSOLE = "console"
FOREIGN_PREFIX = "foreign:"


class LedgerError(CoreError):
    """A line was recorded that does not fit in the controller's RX buffer."""


def line_cost_bytes(text: str) -> int:
    """RX-buffer bytes a line takes: its ASCII bytes plus the single `\\n` the link appends."""
    # Encoded as ASCII with errors="replace", every character is one byte (a `?` for those
    # outside ASCII), so the length is the text's own: no need to encode it at every check.
    return len(text) + 1


def foreign(name: str) -> str:
    """The owner name of a sender whose lines are forwarded, not written, by smoothjog."""
    return FOREIGN_PREFIX + name


@dataclass(eq=False, slots=True)
class Entry:
    """One line on its way to the controller or waiting for its reply."""

    owner: str
    text: str
    cost: int
    sent_s: float
    #: Whatever the owner wants back with the reply (the engine keeps its line's kind here).
    tag: object = None
    #: False while a relayed line waits for the relay's echo (it may not be on the wire yet).
    on_wire: bool = True
    #: When the relay echoed it (relayed lines only): it went on the wire then.
    echo_s: float | None = None


@dataclass
class LedgerStats:
    """Counters for tests, logs and the benchmark."""

    lines: collections.Counter[str] = field(default_factory=collections.Counter)
    realtime: collections.Counter[str] = field(default_factory=collections.Counter)
    replies: collections.Counter[str] = field(default_factory=collections.Counter)
    #: `?` bytes sent by owners other than the engine and the handshake (a proxied sender, a
    #: user's console): their reports reach every owner, so the engine may take one for its own.
    queries_by_others: int = 0
    #: Replies that arrived with no line waiting: another writer bypassing the ledger, or a
    #: reply to a line sent before the controller reset.
    unowned_replies: int = 0
    #: Lines dropped unanswered because the controller reset.
    lost_to_reset: int = 0
    #: Lines whose reply never came and was presumed lost (a garbled or dropped `ok`).
    presumed_answered: int = 0
    #: Relayed: own lines the relay never echoed (a later own line's echo came first).
    unechoed_dropped: int = 0
    #: Relayed: replies that arrived while the oldest line still waited for its echo.
    replies_before_echo: int = 0


class Ledger:
    """Unanswered lines of every owner, oldest first, counted against the RX buffer."""

    def __init__(self, capacity_bytes: int = DEFAULT_RX_BYTES, *, relayed: bool = False) -> None:
        """An empty ledger for a controller whose RX buffer holds capacity_bytes.

        relayed=True: the link is a relay that echoes every client's line in wire order, and
        own lines count as on the wire only once on_echo() has seen them.
        """
        self._capacity_bytes = DEFAULT_RX_BYTES
        self.capacity_bytes = capacity_bytes
        self.relayed = relayed
        self._entries: collections.deque[Entry] = collections.deque()
        self._in_flight_bytes = 0
        # The entries still waiting for their echo: always the newest ones (echoes come in
        # order, and a foreign line goes in front of them).
        self._unechoed = 0
        self.stats = LedgerStats()

    @property
    def capacity_bytes(self) -> int:
        """The controller's RX buffer size in bytes."""
        return self._capacity_bytes

    @capacity_bytes.setter
    def capacity_bytes(self, value: int) -> None:
        if value < 2:
            raise LedgerError(
                f"an RX buffer of {value} bytes cannot hold any line: the controller reported"
                " an impossible size"
            )
        self._capacity_bytes = value

    @property
    def in_flight_bytes(self) -> int:
        """Bytes sent and not yet answered, all owners together."""
        return self._in_flight_bytes

    @property
    def free_bytes(self) -> int:
        """Bytes that may still be sent before a reply is needed."""
        return self._capacity_bytes - self._in_flight_bytes

    def fits(self, text: str) -> bool:
        """True when text can be sent now without overrunning the RX buffer."""
        return line_cost_bytes(text) <= self.free_bytes

    def record_line(self, owner: str, text: str, now_s: float, tag: object = None) -> Entry:
        """Count a line as sent by owner; LedgerError (nothing counted) if it does not fit."""
        cost = line_cost_bytes(text)
        if cost > self.free_bytes:
            raise LedgerError(
                f"{owner}'s line {text!r} needs {cost} bytes but only {self.free_bytes} of the"
                f" controller's {self._capacity_bytes}-byte RX buffer are free"
            )
        entry = Entry(owner, text, cost, now_s, tag, on_wire=not self.relayed)
        self._entries.append(entry)
        self._in_flight_bytes += cost
        self._unechoed += self.relayed
        self.stats.lines[owner] += 1
        return entry

    def on_echo(self, text: str, foreign_owner: str, now_s: float) -> Entry:
        """The relay echoed a line (it goes on the wire now); return its entry.

        The oldest own line still waiting for its echo is the one echoed when the text is the
        same; any other line is a foreign writer's, counted in the RX buffer from now on (even
        past its size: the bytes are there whether they fit or not) and answered before the own
        lines not echoed yet. An own line further back with this text means the lines before it
        were never relayed: they are dropped, since no reply will come for them.
        """
        first = len(self._entries) - self._unechoed
        for index in range(first, len(self._entries)):
            entry = self._entries[index]
            if entry.text != text:
                continue
            skipped = index - first
            for _ in range(skipped):
                gone = self._entries[first]
                del self._entries[first]
                self._in_flight_bytes -= gone.cost
            self._unechoed -= skipped + 1
            self.stats.unechoed_dropped += skipped
            entry.on_wire = True
            entry.echo_s = now_s
            return entry
        entry = Entry(foreign_owner, text, line_cost_bytes(text), now_s)
        self._entries.insert(first, entry)
        self._in_flight_bytes += entry.cost
        self.stats.lines[foreign_owner] += 1
        return entry

    def record_realtime(self, owner: str, byte: bytes) -> None:
        """Note a realtime byte sent by owner: it takes no room in the RX buffer."""
        self.stats.realtime[owner] += 1
        if byte == b"?" and owner not in (ENGINE, HANDSHAKE):
            self.stats.queries_by_others += 1

    def on_reply(self) -> Entry | None:
        """An `ok`/`error` arrived: release and return the oldest unanswered line, if any."""
        if not self._entries:
            self.stats.unowned_replies += 1
            return None
        entry = self._entries.popleft()
        self._in_flight_bytes -= entry.cost
        if not entry.on_wire:
            # The relay's echo order broke its promise (or a writer bypassed it): go on.
            self._unechoed -= 1
            self.stats.replies_before_echo += 1
        self.stats.replies[entry.owner] += 1
        return entry

    def presume_answered(self, entries: Iterable[Entry]) -> int:
        """Release lines whose reply was lost on the way (never arrives); return how many.

        Grbl answers every line, so a reply that never comes was garbled or dropped on the
        link; keeping its entry would credit every later reply to the wrong line.
        """
        gone = {id(e) for e in entries}
        kept = collections.deque(e for e in self._entries if id(e) not in gone)
        dropped = len(self._entries) - len(kept)
        self._entries = kept
        self._in_flight_bytes = sum(e.cost for e in kept)
        self._unechoed = sum(1 for e in kept if not e.on_wire)
        self.stats.presumed_answered += dropped
        return dropped

    def outstanding(self, owner: str | None = None) -> tuple[Entry, ...]:
        """The unanswered lines (of one owner, or of all), oldest first."""
        if owner is None:
            return tuple(self._entries)
        return tuple(e for e in self._entries if e.owner == owner)

    def oldest(self) -> Entry | None:
        """The oldest unanswered line on the wire: the one the controller is answering now.

        Whatever a query prints before its `ok` ([GC:...] for `$G`, the `$$` listing) belongs to
        this line, since Grbl handles lines one at a time, in order (firmware-facts §5.1). None
        when nothing waits, or (relayed) when the oldest line has not reached the wire yet.
        """
        if not self._entries or not self._entries[0].on_wire:
            return None
        return self._entries[0]

    def waiting(self, owner: str) -> int:
        """How many of owner's lines wait for a reply."""
        return sum(1 for e in self._entries if e.owner == owner)

    def reset(self) -> list[Entry]:
        """The controller reset (its RX buffer is empty): drop and return every entry."""
        dropped = list(self._entries)
        self._entries.clear()
        self._in_flight_bytes = 0
        self._unechoed = 0
        self.stats.lost_to_reset += len(dropped)
        return dropped
