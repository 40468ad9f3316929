"""The proxy: smoothjog between a desktop sender (UGS, CNCjs, bCNC, ...) and the machine.

smoothjog owns the controller's port; the sender opens a port of the proxy's instead (a raw
pseudo-terminal, `--link`, or a loopback TCP port, `--tcp`) and sees the machine through it:

- **On open** it gets the controller's banner again (the machine is not reset; the last banner
  the controller printed is replayed, or one made from what `$I` said), then whatever it asks.
- **Its bytes**: realtime bytes (`?`, `!`, `~`, Ctrl-X, every byte from 0x80 up, and 0x19 on
  grblHAL) go to the controller at once (`Host.send_realtime`); everything else is cut into
  lines at each `\\n` or `\\r` (an empty line is a line: Grbl answers it `ok`, so a sender that
  ends its lines with `\\r\\n` gets the two `ok`s it would get from the machine) and forwarded
  in order, one at a time, through `Host.write_line`, which waits for room in the controller's
  RX buffer beside smoothjog's own lines. The sender counts characters against the 128 bytes
  it believes it has; the ledger counts the real buffer, so it never overflows.
- **Bytes a line cannot carry** (`links.base.encode_line` refuses them): control bytes (0x00 to
  0x1F but the line ends and the realtime ones) are dropped, as Grbl's line reader drops them
  (firmware-facts §1.1); DEL (0x7F), which Grbl keeps in the line and then refuses, becomes `^`,
  a byte Grbl refuses in every place DEL would be refused (neither is a letter, a digit, a sign,
  a point or a `$` command), so the reply is the same. A line longer than the whole RX buffer
  (a long comment) goes as Grbl would store it (comments, spaces and case as the firmware's
  pre-parser leaves them, `core/gcode.preparse`); one that overflows Grbl's line buffer goes as
  a line that overflows it too, so it still gets `error:11` and does nothing.
- **Replies**: each `ok`/`error` of a sender line goes back to that sender (the ledger names
  the owner), and so does its query output (`[GC:]`, `$N=`, `[VER:]`, ...; `Host` routes query
  output to the owner of the oldest unanswered line). `ALARM`, `[MSG:]` and banners go to
  everyone. A status report goes to a sender only in answer to its own `?`: the
  next report after it (one per `?`, as Grbl folds a second `?` into the report pending), never
  the reports of smoothjog's own polls, which a sender that counts lines would take for
  replies.
- **Who may move the machine**: a sender line that may move it (anything but the queries `$`,
  `$$`, `$#`, `$G`, `$I`, `$N` and empty or comment-only lines) sets the jog lock, "the sender
  is running a job: jogging waits until it is idle", and the engine then refuses jogs with that
  sentence (and stops one under way with its full cancel handshake). When smoothjog's engine is
  moving the machine as such a line comes, the line (and every sender line behind it) waits
  until the engine's stop has ended; then it goes. The lock is lifted once no such line of the
  sender's is held or unanswered and the controller has reported Idle (or Alarm, Check, Sleep)
  for `quiet_s` (0.5 s). A stop (feed hold, jog cancel) and a reset from smoothjog's pendant or
  devices are realtime bytes and always pass; so do the sender's own.
- **Resets**: a sender's Ctrl-X drops its lines not yet forwarded (they were in the buffer the
  reset empties). After anybody's Ctrl-X no sender line goes until the banner (at most 2 s): a
  line reaching the controller while it restarts would run after the reset, its reply taken
  for another line's. Every banner resets the ledger; the sender gets the banner and no reply
  of the lines smoothjog reads the settings with again, and no stale `ok`: its lines lost to the
  reset are simply gone, as they are on the machine. A banner the sender's own Ctrl-X did not
  announce (smoothjog's reset, the controller's own) also drops the sender's lines still held.

The sender is owner `foreign:sender` of the ledger; several connections (the pty and TCP
clients) share that owner, and each line carries its connection, so replies and query output
go back to the one that sent it.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from smoothjog.authority.gate import MotionGate, engine_has_motion
from smoothjog.core.errors import LinkError, SmoothjogError
from smoothjog.core.firmware import GRBL, for_model
from smoothjog.core.gcode import preparse
from smoothjog.core.ledger import Entry, foreign, line_cost_bytes
from smoothjog.core.machine import MachineModel
from smoothjog.core.realtime import (
    EXTENDED_START,
    GRBLHAL_STATUS_QUERY,
    GRBLHAL_STOP,
    PRINTABLE_REALTIME,
    RESET,
    STATUS_QUERY,
)
from smoothjog.core.responses import Banner, ErrorReply, Ok, Response, StatusReport
from smoothjog.core.states import SETTLED_STATES
from smoothjog.host import Host
from smoothjog.pty_port import PtyPort

logger = logging.getLogger(__name__)

#: The ledger owner of every sender line.
SENDER = foreign("sender")
#: The source of the proxy's jog lock (Host.set_jog_lock).
LOCK_SOURCE = "sender"
#: Who stopped the machine when the sender went away mid-job (every page is told).
GONE = "the sender closing its port mid-job"
#: Why jogging waits while the sender has the machine.
JOB_LOCK = "the sender is running a job: jogging waits until it is idle"
#: Seconds of rest (nothing of the sender's in hand, the controller Idle) before jogs may go.
QUIET_S = 0.5
#: A pty opener may flush its input right after opening (node's serialport does): the banner
#: goes this long after the open was seen.
PTY_BANNER_DELAY_S = 0.1
#: Longest a waiting forwarder sleeps between looks (lines wake it sooner).
LOOK_S = 0.02
#: Most bytes of one unfinished sender line kept (no sender sends more without a line end).
MAX_LINE_BUFFER_BYTES = 65536
#: Sender lines that only ask (they never move the machine or change it), as Grbl stores them.
QUERY_LINES = frozenset({"", "$", "$$", "$#", "$G", "$I", "$N"})

#: The bytes that ask for a status report (grblHAL's 0x80 too; Grbl drops it unread).
STATUS_BYTES = frozenset({STATUS_QUERY, GRBLHAL_STATUS_QUERY})

_DEL = 0x7F
_SUBSTITUTE = b"^"  # refused wherever DEL is (see the module doc)
_LINE_ENDS = (0x0A, 0x0D)


# ------------------------------------------------------------------------ the sender's bytes
@dataclass(frozen=True, slots=True)
class SenderLine:
    """A line the sender ended (raw, without its end byte)."""

    raw: bytes


@dataclass(frozen=True, slots=True)
class SenderRealtime:
    """A realtime byte the sender sent (it acts at once, wherever it came)."""

    byte: bytes


def is_realtime(byte: int, firmware: str = "grbl") -> bool:
    """Whether the controller picks byte out of the stream as a realtime command (or drops it).

    Grbl, grblHAL and FluidNC: `?`, `!`, `~`, Ctrl-X and every byte from 0x80 up (those Grbl does
    not know it throws away unread); grblHAL also takes 0x19 (its stop). Grbl 1.1h reads 0x19
    into the line and drops it there, so it is a line byte (and dropped) on the others.
    """
    if byte >= EXTENDED_START or byte in PRINTABLE_REALTIME or byte == RESET[0]:
        return True
    return byte == GRBLHAL_STOP[0] and firmware == "grblhal"


class LineAssembler:
    """A sender's byte stream -> its lines and realtime bytes, in the order they came."""

    def __init__(self, firmware: Callable[[], str] = lambda: "grbl") -> None:
        """firmware() names the controller's family (it decides whether 0x19 is realtime)."""
        self.firmware = firmware
        self._buf = bytearray()
        #: Bytes of over-long lines thrown away (MAX_LINE_BUFFER_BYTES).
        self.overflow_bytes = 0

    @property
    def partial(self) -> bytes:
        """The bytes of the line not ended yet."""
        return bytes(self._buf)

    def feed(self, data: bytes) -> list[SenderLine | SenderRealtime]:
        """Take bytes from the sender; return what they complete, in order."""
        out: list[SenderLine | SenderRealtime] = []
        firmware = self.firmware()
        buf = self._buf
        for byte in data:
            if is_realtime(byte, firmware):
                out.append(SenderRealtime(bytes((byte,))))
                if byte == RESET[0]:
                    buf.clear()  # the controller drops the line it was reading, too
            elif byte in _LINE_ENDS:
                out.append(SenderLine(bytes(buf)))
                buf.clear()
            elif len(buf) < MAX_LINE_BUFFER_BYTES:
                buf.append(byte)
            else:
                self.overflow_bytes += 1
        return out

    def clear(self) -> None:
        """Forget the line not ended yet (the controller reset: it lost those bytes too)."""
        self._buf.clear()


def wire_text(raw: bytes, *, capacity_bytes: int = 128, max_line_chars: int = 79) -> str:
    """The text to forward for one sender line, so that the controller does what it would do.

    Control bytes are dropped and DEL becomes `^` (module doc); a line that cannot fit in the
    RX buffer at all goes as the firmware's pre-parser would store it, and one that overflows
    the line buffer as a line that overflows it too (`error:11`, nothing runs).
    """
    # Bytes from 0x80 up never reach a line (LineAssembler takes them as realtime bytes).
    kept = bytes(b for b in raw if 0x20 <= b < EXTENDED_START).replace(bytes((_DEL,)), _SUBSTITUTE)
    text = kept.decode("ascii")
    if line_cost_bytes(text) <= capacity_bytes:
        return text
    stored = preparse(kept, max_line_chars=max_line_chars)
    return stored.text + "X" if stored.overflow else stored.text


def is_query(raw: bytes) -> bool:
    """Whether a sender line only asks (`$G`, `$#`, ...): it can neither move nor change a thing."""
    kept = bytes(b for b in raw if 0x20 <= b < _DEL)
    return preparse(kept, max_line_chars=MAX_LINE_BUFFER_BYTES).text in QUERY_LINES


def reply_bytes(resp: Ok | ErrorReply) -> bytes:
    """A reply as the controller printed it."""
    return b"ok\r\n" if isinstance(resp, Ok) else f"error:{resp.code}\r\n".encode("ascii")


def banner_for(model: MachineModel) -> bytes:
    """A welcome line for a controller whose banner was not seen (no reset since connecting)."""
    version = model.version or "1.1h"
    if model.firmware == "grblhal":
        return f"GrblHAL {version} ['$' or '$HELP' for help]".encode("ascii", "replace")
    return f"Grbl {version} ['$' for help]".encode("ascii", "replace")


# ------------------------------------------------------------------------ the forwarder
@dataclass(eq=False)
class _Line:
    """One sender line on its way: where it came from, what goes on the wire."""

    conn: SenderConnection
    text: str
    moves: bool
    generation: int


@dataclass
class ProxyStats:
    """Counters for tests, logs and the benchmark."""

    lines_forwarded: int = 0
    replies_sent: int = 0
    realtime_sent: int = 0
    #: Sender lines dropped unsent because the controller reset (or the link was lost).
    lines_dropped: int = 0
    #: Times a sender line waited for smoothjog's own jog to stop.
    held_for_jog: int = 0
    banners_sent: int = 0
    #: Lines forwarded changed to what the firmware would store (control bytes, DEL, overlong).
    lines_rewritten: int = 0
    #: Every line the sender got, by kind, for tests: reply, owned (query output), broadcast.
    sent: collections.Counter[str] = field(default_factory=collections.Counter)


class SenderConnection:
    """One sender's open port (the pty while a program has it open, or one TCP client)."""

    def __init__(self, proxy: SenderProxy, write: Callable[[bytes], object], name: str) -> None:
        """A connection whose output goes to write; feed() takes its bytes."""
        self.proxy = proxy
        self.name = name
        self._write = write
        self.open = True
        #: The banner went out: lines for everyone reach it from now on (not before it).
        self.greeted = False
        self.assembler = LineAssembler(proxy.firmware)
        #: Every chunk written to this sender, in order (tests read it; bounded).
        self.sent: collections.deque[bytes] = collections.deque(maxlen=10000)
        #: It sent `?` and has had no status report since: the next one is its answer.
        self.status_asked = False

    def feed(self, data: bytes) -> None:
        """Bytes from the sender."""
        for item in self.assembler.feed(data):
            if isinstance(item, SenderRealtime):
                self.proxy.realtime_from(self, item.byte)
            else:
                self.proxy.line_from(self, item.raw)

    def send(self, data: bytes) -> None:
        """Bytes to the sender (dropped once it has closed the port)."""
        if not self.open:
            return
        self.sent.append(data)
        try:
            self._write(data)
        except (OSError, RuntimeError):  # a TCP client gone between two lines
            self.close()

    def close(self) -> None:
        """The sender closed the port (the proxy drops its queued lines once none is open)."""
        if self.open:
            self.open = False
            self.proxy.disconnected(self)


class SenderProxy:
    """The forwarder between sender connections and one Host (attach() a new one on reconnect).

    run() is its one task: it forwards the queued sender lines in order.
    """

    def __init__(
        self,
        *,
        quiet_s: float = QUIET_S,
        lock_reason: str = JOB_LOCK,
    ) -> None:
        """A proxy with no host yet; attach() one before its start()."""
        self.quiet_s = quiet_s
        self.lock_reason = lock_reason
        self.host: Host | None = None
        #: The session's motion gate (gated()); None before the session has one.
        self.gate: MotionGate | None = None
        self.stats = ProxyStats()
        self.connections: list[SenderConnection] = []
        self._queue: collections.deque[_Line] = collections.deque()
        self._current: _Line | None = None
        self._changed: asyncio.Event | None = None
        self._generation = 0
        self._banner: bytes | None = None
        self._banner_since_attach = False
        #: The sender has sent a line that may move the machine since the lock was last lifted.
        self._active = False
        self._locked = False
        self._quiet_since: float | None = None
        self._quiet_timer: asyncio.TimerHandle | None = None
        self._sessions = 0

    # ----------------------------------------------------------------- the session
    def firmware(self) -> str:
        """The controller's family, as the model knows it."""
        return self.host.model.firmware if self.host is not None else "grbl"

    def attach(self, host: Host) -> None:
        """Forward to host from now on; call before host.start() (it may print a banner)."""
        if self.host is not None:
            # A new session (the link was lost): the old one's lines are gone with it, and
            # the lock, if the sender goes on, is taken again on the new host.
            self._drop_queued()
            self._active = self._locked = False
            self._quiet_since = None
        self.host = host
        self._banner_since_attach = False
        host.add_reply_handler(SENDER, self._on_reply)
        host.add_routed_listener(self._on_line)
        self._wake()

    def started(self, host: Host) -> None:
        """host finished its handshake: a sender already connected hears of a new session."""
        self._sessions += 1
        if self._sessions > 1 and not self._banner_since_attach:
            # The controller did not reset on connecting again, yet every sender line in flight
            # was lost with the old link: a banner tells the sender to start over.
            self._broadcast(self.banner())
        self._update_lock()
        self._wake()

    def banner(self) -> bytes:
        """The welcome line a sender gets on opening the port (with its CR LF)."""
        if self._banner is not None:
            return self._banner + b"\r\n"
        model = self.host.model if self.host is not None else MachineModel()
        return banner_for(model) + b"\r\n"

    def connect(
        self, write: Callable[[bytes], object], name: str, *, banner_delay_s: float = 0.0
    ) -> SenderConnection:
        """A sender opened a port: its connection (the banner follows after banner_delay_s)."""
        conn = SenderConnection(self, write, name)
        self.connections.append(conn)
        logger.info("a sender opened %s", name)

        def greet() -> None:
            if conn.open and self.host is not None:
                self.stats.banners_sent += 1
                self.stats.sent["broadcast"] += 1
                conn.send(self.banner())
            conn.greeted = True

        loop = asyncio.get_running_loop()
        if banner_delay_s > 0:
            loop.call_later(banner_delay_s, greet)
        else:
            loop.call_soon(greet)
        return conn

    def gated(self, gate: MotionGate) -> None:
        """The session's motion gate: it stops what a sender that went away left running."""
        self.gate = gate

    def disconnected(self, conn: SenderConnection) -> None:
        """A connection closed (SenderConnection.close calls this). A sender that went away
        takes its lines with it: those not yet forwarded are dropped, and motion its lines
        already in the controller drive is stopped (the gate's feed hold), so the next sender
        to open the port starts clean and nothing runs for a program that is gone."""
        with contextlib.suppress(ValueError):
            self.connections.remove(conn)
        logger.info("the sender closed %s", conn.name)
        if self.connections:
            return
        moving = self._motion_in_hand() or (
            self._locked and self.host is not None and self.host.model.state not in SETTLED_STATES
        )
        self._drop_queued()
        if moving and self.gate is not None:
            self.gate.stop(GONE)

    # ----------------------------------------------------------------- from the sender
    def realtime_from(self, conn: SenderConnection, byte: bytes) -> None:
        """A realtime byte from the sender: to the controller at once."""
        host = self.host
        if host is None or host.link_error is not None:
            return
        if byte in STATUS_BYTES:
            conn.status_asked = True
        if byte == RESET:
            # The reset empties the controller's buffers: the sender's lines not yet forwarded
            # were in them as far as the sender knows. Lines it sends from now on wait for the
            # banner (Host.reset_pending), so none lands in the controller while it restarts.
            self._drop_queued()
            for other in self.connections:
                if other is not conn:  # conn's own line was cut where the byte came
                    other.assembler.clear()
        with contextlib.suppress(LinkError):
            host.send_realtime(SENDER, byte)
            self.stats.realtime_sent += 1
        self._wake()

    def line_from(self, conn: SenderConnection, raw: bytes) -> None:
        """A line the sender ended: queued to go in order."""
        host = self.host
        facts = for_model(host.model) if host is not None else GRBL
        capacity = host.ledger.capacity_bytes if host is not None else facts.rx_buffer_bytes
        # A stored line (at most max_line_chars + 2 bytes) fits in every family's RX buffer.
        text = wire_text(raw, capacity_bytes=capacity, max_line_chars=facts.max_line_chars)
        if text.encode("ascii") != raw:
            self.stats.lines_rewritten += 1
        moves = not is_query(raw)
        self._queue.append(_Line(conn, text, moves, self._generation))
        if moves and not self._active:
            self._active = True
            self._update_lock()
        self._wake()

    # ----------------------------------------------------------------- the task
    async def run(self) -> None:
        """Forward queued sender lines, in order, until cancelled."""
        self._changed = asyncio.Event()
        while True:
            item = await self._next_line()
            host = self.host
            assert host is not None
            self._current = item
            try:
                await host.write_line(SENDER, item.text, tag=item)
            except LinkError as exc:
                # The link is gone: this line and those behind it have nowhere to go; the
                # session that replaces it starts afresh (started() tells the sender).
                logger.warning("a sender line was dropped: %s", exc)
                self.stats.lines_dropped += 1
                self._drop_queued()
            else:
                self.stats.lines_forwarded += 1
            finally:
                self._current = None

    async def _next_line(self) -> _Line:
        """The next line that may go now: in order, after holds for a reset or a jog."""
        held = False
        while True:
            look: float | None = None  # wait for a change (a line, a sender byte) only
            item = self._queue[0] if self._queue else None
            if item is not None and item.generation != self._generation:
                self._queue.popleft()  # lost to a reset (the queue was cleared meanwhile)
                continue
            host = self.host
            # After anybody's Ctrl-X nothing goes until the banner: a line reaching the
            # controller while it restarts would run after the reset, answered to nobody.
            resetting = host is not None and host.reset_pending
            ready = item is not None and host is not None and host.link_error is None
            ready = ready and not resetting
            if item is not None and resetting:
                look = LOOK_S  # the banner's wait ends by time, too
            if ready and host is not None and item is not None:
                if item.moves and engine_has_motion(host):
                    # smoothjog's own jog is under way: the lock (set when the line came)
                    # stops it with the full handshake; the sender's line goes after.
                    if not held:
                        held = True
                        self.stats.held_for_jog += 1
                        logger.info("a sender line waits for smoothjog's jog to stop")
                    self._update_lock()
                    look = LOOK_S  # the engine's stop ends on a line, but also by its timers
                elif host.ledger.fits(item.text):
                    return self._queue.popleft()
            await self._wait_change(look)

    async def _wait_change(self, timeout_s: float | None) -> None:
        changed = self._changed
        assert changed is not None
        changed.clear()
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout_s):
                await changed.wait()

    def _wake(self) -> None:
        if self._changed is not None:
            self._changed.set()

    def _drop_queued(self) -> None:
        """Lines not yet forwarded are gone (a reset emptied the buffer they were in)."""
        self._generation += 1
        dropped = len(self._queue)
        self._queue.clear()
        if dropped:
            self.stats.lines_dropped += dropped
            logger.info("%d sender lines not yet forwarded were dropped", dropped)
        self._update_lock()

    # ----------------------------------------------------------------- from the controller
    def _on_reply(self, entry: Entry, resp: Ok | ErrorReply, now_s: float) -> None:
        """A sender line was answered: the reply goes to the connection that sent it."""
        item = entry.tag
        if isinstance(item, _Line):
            self.stats.replies_sent += 1
            self.stats.sent["reply"] += 1
            item.conn.send(reply_bytes(resp))
        self._update_lock()
        self._wake()

    def _on_line(self, raw: bytes, resp: Response, route: Entry | None) -> None:
        """Every line from the controller, with its route (Host.add_routed_listener)."""
        if isinstance(resp, Ok | ErrorReply):
            return  # a sender's own reply came through _on_reply
        if route is None:
            if isinstance(resp, Banner):
                self._on_banner(raw)
            if isinstance(resp, StatusReport):
                self._answer_status(raw + b"\r\n")
            else:
                self._broadcast(raw + b"\r\n")
        elif route.owner == SENDER and isinstance(route.tag, _Line):
            self.stats.sent["owned"] += 1
            route.tag.conn.send(raw + b"\r\n")
        self._update_lock()
        self._wake()

    def _on_banner(self, raw: bytes) -> None:
        """The controller reset: the host's ledger forgot every line; so do we, unless the
        sender's own Ctrl-X announced it (its lines since then were written for the new
        session)."""
        self._banner = raw
        self._banner_since_attach = True
        if self.host is None or self.host.last_reset_by != SENDER:
            self._drop_queued()
            for conn in self.connections:
                conn.assembler.clear()

    def _answer_status(self, data: bytes) -> None:
        """A status report goes only to the connections that asked `?` since their last one:
        one report per `?`, as the bare controller gives (smoothjog's own polls are not theirs;
        a sender that counts lines took them for replies)."""
        for conn in list(self.connections):
            if conn.greeted and conn.status_asked:
                conn.status_asked = False
                self.stats.sent["broadcast"] += 1
                conn.send(data)

    def _broadcast(self, data: bytes) -> None:
        for conn in list(self.connections):
            if conn.greeted:  # a port just opened hears the banner first, as after a reset
                self.stats.sent["broadcast"] += 1
                conn.send(data)

    # ----------------------------------------------------------------- the jog lock
    def _motion_in_hand(self) -> bool:
        """A sender line that may move the machine is queued, being written or unanswered."""
        if any(item.moves for item in self._queue):
            return True
        if self._current is not None and self._current.moves:
            return True
        host = self.host
        if host is None:
            return False
        return any(
            isinstance(e.tag, _Line) and e.tag.moves for e in host.ledger.outstanding(SENDER)
        )

    def _update_lock(self) -> None:
        """Lock jogging while the sender has the machine; lift it after quiet_s at rest."""
        host = self.host
        if host is None:
            return
        if self._active and not self._locked:
            self._locked = True
            host.set_jog_lock(LOCK_SOURCE, self.lock_reason)
        if not self._locked:
            return
        now = self._now()
        settled = (
            not self._motion_in_hand()
            and host.model.state in SETTLED_STATES
            and not host.reset_pending
        )
        if not settled:
            self._quiet_since = None
            return
        if self._quiet_since is None:
            self._quiet_since = now
        if now - self._quiet_since >= self.quiet_s:
            self._active = False
            self._locked = False
            self._quiet_since = None
            host.set_jog_lock(LOCK_SOURCE, None)
            return
        if self._quiet_timer is None:
            loop = asyncio.get_running_loop()
            self._quiet_timer = loop.call_at(self._quiet_since + self.quiet_s, self._quiet_due)

    def _quiet_due(self) -> None:
        self._quiet_timer = None
        self._update_lock()

    @property
    def locked(self) -> bool:
        """True while the proxy holds the jog lock."""
        return self._locked

    def _now(self) -> float:
        return asyncio.get_running_loop().time()


# ------------------------------------------------------------------------ the sender's ports
class PtySender:
    """The sender's pseudo-terminal: a connection while a program has it open."""

    def __init__(self, proxy: SenderProxy, link_path: Path | None) -> None:
        """Prepare; open() makes the pty (and its --link symlink)."""
        self.proxy = proxy
        self.link_path = link_path
        self.port = PtyPort(
            self._on_data,
            link_path=link_path,
            hold_slave=False,
            on_open=self._on_open,
            on_close=self._on_close,
        )
        self.conn: SenderConnection | None = None

    def open(self) -> str:
        """Make the pty; returns its path (/dev/pts/N)."""
        return self.port.open()

    def close(self) -> None:
        """Close the pty and remove the symlink."""
        if self.conn is not None:
            self.conn.close()
            self.conn = None
        self.port.close()

    def _on_open(self) -> None:
        self.conn = self.proxy.connect(
            self.port.write, f"pty {self.port.path}", banner_delay_s=PTY_BANNER_DELAY_S
        )

    def _on_close(self) -> None:
        if self.conn is not None:
            self.conn.close()
            self.conn = None

    def _on_data(self, data: bytes) -> None:
        if self.conn is not None:
            self.conn.feed(data)


class TcpSender:
    """A loopback TCP port for senders that open network controllers; each client a connection."""

    def __init__(self, proxy: SenderProxy) -> None:
        """Prepare; start() listens."""
        self.proxy = proxy
        self._server: asyncio.Server | None = None
        self._writers: set[asyncio.StreamWriter] = set()
        #: The port listened on, once started.
        self.port: int | None = None

    async def start(self, port: int) -> int:
        """Listen on 127.0.0.1:port (0: any free port); returns the port."""
        try:
            self._server = await asyncio.start_server(self._on_client, "127.0.0.1", port)
        except OSError as exc:
            raise LinkError(f"cannot listen on 127.0.0.1:{port}: {exc.strerror}") from None
        self.port = int(self._server.sockets[0].getsockname()[1])
        return self.port

    async def close(self) -> None:
        """Stop listening and close every client."""
        if self._server is not None:
            self._server.close()
            for writer in list(self._writers):
                writer.close()
            await self._server.wait_closed()
            self._server = None

    async def _on_client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername")
        conn = self.proxy.connect(writer.write, f"tcp client {peer}")
        self._writers.add(writer)
        try:
            while data := await reader.read(4096):
                conn.feed(data)
        except (ConnectionError, SmoothjogError):
            pass
        finally:
            conn.close()
            self._writers.discard(writer)
            writer.close()
