"""The Link contract every transport keeps: lines out, realtime bytes out, lines in.

A link knows nothing of jogging. It guarantees three things the layers above rely on:
- `send_line` puts exactly one `\\n` after the text and refuses text that would confuse Grbl's
  line reader (firmware-facts §1.1, §5.2);
- `send_realtime` never waits behind queued lines: the byte overtakes every line the link still
  holds, and goes out at a line boundary so grblHAL's jog cancel cannot cut a line in half
  (firmware-facts §7);
- `read_line` returns each received line once, in order, and raises `LinkError` (never hangs) once
  the peer has gone or the link was closed.
"""

from __future__ import annotations

import asyncio
import collections
import re
from abc import ABC, abstractmethod
from collections.abc import Callable
from types import TracebackType
from typing import Self

from smoothjog.core.errors import LinkError
from smoothjog.core.realtime import EXTENDED_START, LOW_REALTIME, PRINTABLE_REALTIME
from smoothjog.links.framing import DEFAULT_MAX_LINE_BYTES, LineFramer

#: Characters Grbl picks out of the stream wherever they appear (firmware-facts §5.2): inside a line
#: they would act at once (`!` holds, `~` resumes) instead of being part of the line.
REALTIME_CHARS = frozenset(chr(byte) for byte in PRINTABLE_REALTIME)
#: A line encode_line sends as it is: printable ASCII without those characters. Checked by
#: one regex match, since every jog line comes through here (~100 a second while a jog is held);
#: only a line it refuses is gone through character by character, to say what is wrong.
_SENDABLE = re.compile("[^" + "".join(re.escape(c) for c in sorted(REALTIME_CHARS)) + "]*")


class RefusedError(LinkError):
    """The caller asked a link to send something Grbl would misread; nothing was sent."""


def encode_line(text: str) -> bytes:
    """Check a line for sending and return its bytes with the single `\\n` appended."""
    if text.isascii() and text.isprintable() and _SENDABLE.fullmatch(text) is not None:
        return text.encode("ascii") + b"\n"
    for index, char in enumerate(text):
        if char in "\r\n":
            raise RefusedError(
                f"line {text!r} contains an end-of-line at position {index}: send one line"
                " per call, the link adds the `\\n` itself"
            )
        if char in REALTIME_CHARS:
            raise RefusedError(
                f"line {text!r} contains {char!r}, which Grbl treats as a realtime command"
                " wherever it appears: send it with send_realtime() instead"
            )
        # Bytes >= 0x80 are realtime commands or dropped, bytes < 0x20 are dropped or reset
        # the controller (Ctrl-X), so only printable ASCII can travel inside a line.
        if not " " <= char <= "~":
            raise RefusedError(
                f"line {text!r} contains the character {char!r} at position {index}:"
                " only printable ASCII can be sent to a Grbl controller"
            )
    return text.encode("ascii") + b"\n"


def check_realtime(byte: bytes) -> None:
    """Refuse anything that is not a single realtime command byte."""
    if len(byte) != 1:
        raise RefusedError(
            f"a realtime command is exactly one byte, not {len(byte)} ({byte!r}):"
            " send lines with send_line()"
        )
    # From 0x80 up every byte is realtime or ignored by the controller (firmware-facts §5.2, §7).
    if byte[0] < EXTENDED_START and byte[0] not in LOW_REALTIME:
        raise RefusedError(
            f"{byte!r} is not a realtime command (those are ?, !, ~, Ctrl-X and bytes"
            " 0x80-0xFF): send lines with send_line()"
        )


#: Bytes a link may hold before send_line waits; far above what character counting allows.
QUEUE_HIGH_WATER_BYTES = 64 * 1024
#: Most bytes a transport hands to the operating system in one write.
WRITE_CHUNK_BYTES = 4096
#: Most bytes a transport takes from the operating system in one read.
READ_CHUNK_BYTES = 65536


class OutQueue:
    """What a transport has accepted but not yet written: encoded lines and realtime bytes.

    `items` holds them oldest first (a transport may put a realtime byte ahead of lines);
    `size` counts their bytes. put() makes send_line wait while the queue is past its high-water
    mark, and taken() / clear() let it go on.
    """

    def __init__(self) -> None:
        """An empty queue."""
        self.items: collections.deque[bytes] = collections.deque()
        self.size = 0
        self._room = asyncio.Event()
        self._room.set()

    async def put(self, data: bytes, check_usable: Callable[[], None]) -> None:
        """Append data once the queue is under its high-water mark.

        check_usable raises the link's error; it runs before every wait and after it, so a
        link that fails or closes meanwhile never queues the data.
        """
        while not self.put_nowait(data, check_usable):
            self._room.clear()
            await self._room.wait()

    def put_nowait(self, data: bytes, check_usable: Callable[[], None]) -> bool:
        """Append data if the queue is under its high-water mark; False (nothing queued) if not."""
        check_usable()
        if self.size >= QUEUE_HIGH_WATER_BYTES:
            return False
        self.items.append(data)
        self.size += len(data)
        return True

    def insert(self, index: int, data: bytes) -> None:
        """Put data at index, ahead of what follows (a realtime byte overtaking lines)."""
        self.items.insert(index, data)
        self.size += len(data)

    def taken(self, nbytes: int) -> None:
        """nbytes left the queue (written); wake a waiting put() if there is room again."""
        self.size -= nbytes
        if self.size < QUEUE_HIGH_WATER_BYTES:
            self._room.set()

    def clear(self) -> None:
        """Drop everything (closed or lost); waiting put() calls wake up and find the error."""
        self.items.clear()
        self.size = 0
        self._room.set()


class LineInbox:
    """Received bytes in, whole lines out, in order; ends with a LinkError, never a hang."""

    def __init__(self, max_line_bytes: int = DEFAULT_MAX_LINE_BYTES) -> None:
        """Create an empty inbox."""
        self.framer = LineFramer(max_line_bytes)
        self._lines: collections.deque[bytes] = collections.deque()
        self._waiters: list[asyncio.Future[None]] = []
        self._gone: LinkError | None = None
        self._closed: LinkError | None = None
        self.lines_received = 0
        # Set by subscribe(): lines go straight to on_line from the transport's callback.
        self._on_line: Callable[[bytes], None] | None = None
        self._on_end: Callable[[LinkError], None] | None = None

    @property
    def ended(self) -> bool:
        """True once the peer has gone or the link was closed."""
        return self._gone is not None or self._closed is not None

    def feed(self, data: bytes) -> None:
        """Frame received bytes and queue (or, when subscribed, deliver) the completed lines."""
        lines = self.framer.feed(data)
        if not lines:
            return
        self.lines_received += len(lines)
        on_line = self._on_line
        if on_line is None:
            self._lines.extend(lines)
            self._wake()
            return
        for line in lines:
            if self._on_line is None:  # the subscriber left while handling an earlier line
                self._lines.append(line)
            else:
                on_line(line)

    def subscribe(
        self, on_line: Callable[[bytes], None], on_end: Callable[[LinkError], None]
    ) -> None:
        """Deliver every line to on_line as it is framed, and the end of the link to on_end.

        This saves the reader a task switch per line (about two hundred a second while a jog is
        held). Lines already queued are delivered first; read_line() is not to be used meanwhile.
        """
        self._on_line, self._on_end = on_line, on_end
        while self._lines and self._on_line is not None:
            on_line(self._lines.popleft())
        end = self._closed or self._gone
        if end is not None and self._on_end is not None:
            on_end(end)

    def unsubscribe(self) -> None:
        """Stop delivering; later lines queue for read_line() again."""
        self._on_line = self._on_end = None

    def peer_gone(self, error: LinkError) -> None:
        """The peer went away: lines already received are still delivered, then error."""
        if self._gone is None:
            self._gone = error
        self._wake()
        if self._on_end is not None:
            self._on_end(error)

    def close(self, error: LinkError) -> None:
        """The link was closed here: readers get the error at once, queued lines are dropped."""
        if self._closed is None:
            self._closed = error
        self._lines.clear()
        self._wake()
        if self._on_end is not None:
            self._on_end(error)

    def peek(self) -> tuple[bytes, ...]:
        """The lines waiting to be read, oldest first, without taking them."""
        return tuple(self._lines)

    async def get(self) -> bytes:
        """The oldest unread line; raises the LinkError once there is none and never will be."""
        while True:
            if self._closed is not None:
                raise self._closed
            if self._lines:
                return self._lines.popleft()
            if self._gone is not None:
                raise self._gone
            await self._changed()

    async def wait_for(self, predicate: Callable[[bytes], bool], timeout_s: float) -> bool:
        """Wait until a queued (unread) line satisfies predicate; False on timeout or end."""
        loop = asyncio.get_running_loop()
        deadline_s = loop.time() + timeout_s
        while not any(predicate(line) for line in self._lines):
            remaining_s = deadline_s - loop.time()
            if self.ended or remaining_s <= 0:
                return False
            try:
                await asyncio.wait_for(self._changed(), remaining_s)
            except TimeoutError:
                return False
        return True

    def _changed(self) -> asyncio.Future[None]:
        """A future resolved at the next change (new lines, peer gone, closed)."""
        waiter: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._waiters.append(waiter)
        return waiter

    def _wake(self) -> None:
        """Resolve every pending waiter."""
        waiters, self._waiters = self._waiters, []
        for waiter in waiters:
            if not waiter.done():
                waiter.set_result(None)


class Link(ABC):
    """An open-able, close-able line transport to one controller (asyncio)."""

    async def __aenter__(self) -> Self:
        """Open the link."""
        await self.open()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        """Close the link."""
        await self.close()

    @abstractmethod
    async def open(self) -> None:
        """Open the transport; raises LinkError with a sentence a user can act on."""

    async def send_line(self, text: str) -> None:
        """Send one line followed by exactly one `\\n`; waits only if the link's queue is full."""
        await self._write_line(encode_line(text))

    def send_line_nowait(self, text: str) -> bool:
        """Send one line now if the link's queue has room; False (nothing sent) if it must wait."""
        return self._write_line_nowait(encode_line(text))

    def subscribe(
        self, on_line: Callable[[bytes], None], on_end: Callable[[LinkError], None]
    ) -> bool:
        """Deliver received lines by callback instead of read_line(); False if unsupported."""
        inbox = self._line_inbox()
        if inbox is None:
            return False
        inbox.subscribe(on_line, on_end)
        return True

    def unsubscribe(self) -> None:
        """Go back to read_line() (harmless when not subscribed)."""
        inbox = self._line_inbox()
        if inbox is not None:
            inbox.unsubscribe()

    def byte_time_s(self) -> float | None:
        """Wire time of one byte from the controller, when the link knows it (None if not)."""
        return None

    def attach_relay(
        self,
        on_wire_line: Callable[[str, str], None],
        on_jog_lock: Callable[[str | None], None],
        on_moved: Callable[[], None],
    ) -> bool:
        """For a relay other clients write through too (CNCjs); False for a link of one writer.

        A relay calls on_wire_line(text, writer) for every line it puts on the controller's
        wire, its own and other clients', in wire order (the ledger places foreign lines by it);
        on_jog_lock(reason) when jogging must wait for another program, None when it may go on;
        and on_moved() when the relay's own view of the controller changed (so a fresh status
        report is worth asking for: see idle_poll_s).
        """
        return False

    def idle_poll_s(self) -> float | None:
        """How seldom the host may ask for status while nothing moves (None: its own rate).

        Every `?` through a relay is shown to the relay's other clients (CNCjs's console), and
        the relay tells of changes itself (on_moved), so it asks for less.
        """
        return None

    def rx_reserve_bytes(self) -> int:
        """RX-buffer bytes kept for lines the far side writes without telling (0: none)."""
        return 0

    def cork(self) -> None:  # noqa: B027 - optional: most links write at once
        """Hold what is sent from now on until uncork(), to write it in one go."""

    @property
    def queued_bytes(self) -> int:
        """Bytes accepted by the link but not yet handed on to the wire (none by default)."""
        return 0

    def uncork(self) -> None:  # noqa: B027 - optional, as cork()
        """Write what cork() held back (a no-op for links that never hold anything)."""

    def _line_inbox(self) -> LineInbox | None:
        """The inbox received lines are framed into, for subscribe(); None if the link has none."""
        return None

    def _write_line_nowait(self, data: bytes) -> bool:
        """Queue one encoded line without waiting; False if the link cannot take it now."""
        return False

    def send_realtime(self, byte: bytes) -> None:
        """Send one realtime byte now, ahead of every line still queued in the link."""
        check_realtime(byte)
        self._write_realtime(byte)

    @abstractmethod
    async def read_line(self) -> bytes:
        """The next received line without its end-of-line; LinkError once the peer is gone.

        Cancelling a waiting read_line (e.g. with asyncio.wait_for) loses no line.
        """

    @abstractmethod
    async def close(self) -> None:
        """Close the transport; closing twice is harmless."""

    @abstractmethod
    def describe(self) -> str:
        """Where this link goes, for messages (e.g. "/dev/ttyUSB0 at 115200 baud")."""

    @abstractmethod
    async def _write_line(self, data: bytes) -> None:
        """Queue one checked, encoded line (ending in `\\n`) for sending."""

    @abstractmethod
    def _write_realtime(self, byte: bytes) -> None:
        """Write one checked realtime byte ahead of the queued lines."""
