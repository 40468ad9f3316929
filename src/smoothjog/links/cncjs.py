"""A Link through a running CNCjs server: smoothjog as a pendant, CNCjs keeps the serial port.

CNCjs (1.x) owns the controller's port and serves socket.io 2 (Engine.IO 3); a pendant joins a
port with `open`, writes raw text with `write` and hears every line the controller prints as a
`serialport:read` event. Three things make this a relay rather than a wire (docs/cncjs.md):

- other clients write to the same controller (the CNCjs console, another pendant, CNCjs's own
  `$$` on first open) and their `ok`s come to everybody, untagged. CNCjs echoes every client's
  line to everybody as `serialport:write`, in the order it writes them, before writing: the link
  hands those echoes to the host (attach_relay), whose ledger puts each foreign line where it went
  on the wire, so every reply still reaches the owner of its line;
- CNCjs polls `$G` twice a second by itself, unechoed, with its `ok` swallowed: those 3 bytes
  are held back from smoothjog's RX budget (rx_reserve_bytes), with room for one short line a
  client may write between two of smoothjog's;
- while a CNCjs job runs or is paused (`workflow:state`), CNCjs's sender takes every `ok`: the
  link tells the host that jogging must wait (a jog lock with the reason).

CNCjs rewrites some lines for its users (`error:9 (G-code lock)`, `ALARM:1 (Hard limit)`, `$110=500
(X-axis maximum rate, mm/min)`): the link gives the controller's own line back. A realtime byte is
written as a one-character string; CNCjs sends it UTF-8 encoded, so a byte from 0x80 up reaches
the controller as 0xC2 and the byte, and Grbl 1.1 drops the 0xC2 (measured with CNCjs 1.11.5;
assumed for grblHAL and FluidNC, which CNCjs also drives as "Grbl"). `close` is never sent: it
would close the port for every client; the link just disconnects.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import re
import urllib.parse
from collections.abc import Callable
from typing import Any

from smoothjog.core.errors import LinkError
from smoothjog.core.realtime import EXTENDED_START, LOW_REALTIME, PRINTABLE_REALTIME
from smoothjog.links.base import LineInbox, Link
from smoothjog.links.cncjs_auth import refusal_sentence

logger = logging.getLogger(__name__)

#: CNCjs's own port unless started with `-p`.
DEFAULT_CNCJS_PORT = 8000
#: CNCjs's `$G\\n` poll, which it writes every 500 ms without echo (its `ok` it keeps).
CNCJS_POLL_BYTES = 3
#: Room for one line another client may write before its echo reaches smoothjog (a console
#: command, another pendant's jog line). An assumption: longer foreign lines written in that
#: instant could still overrun the controller, which no pendant can prevent.
FOREIGN_ALLOWANCE_BYTES = 32
#: How seldom smoothjog asks for status through CNCjs while nothing moves (see idle_poll_s).
IDLE_POLL_S = 2.0
#: Writers as CNCjs names them in an echo's context (`source`).
_DEFAULT_WRITER = "cncjs"
#: A line CNCjs decorated with a description in brackets: the controller's own text is group 1.
_DECORATED = re.compile(r"^((?:error|ALARM):\d+|\$\d+=[^ ]*) \(.*\)$")
#: Characters the controller takes out of the stream wherever they appear (never in its buffer).
_REALTIME = frozenset(chr(b) for b in (*PRINTABLE_REALTIME, *LOW_REALTIME))

_WORKFLOW_LOCKS = {
    "running": "CNCjs is running a job: jogging waits until it ends",
    "paused": "a CNCjs job is paused: stop or finish it in CNCjs before jogging",
}


def undecorate(line: str) -> str:
    """The controller's own line from CNCjs's rewritten one (`error:9 (G-code lock)`)."""
    match = _DECORATED.match(line)
    return match.group(1) if match else line


def wire_lines(data: str, partial: str) -> tuple[list[str], str]:
    """Split an echoed write into the lines the controller's buffer takes, and the rest.

    Realtime characters never enter the buffer and are left out; `\\r` and `\\n` each end a line
    (Grbl answers an empty line with `ok`, so `\\r\\n` is two lines). Text after the last end is
    kept as partial for the next write.
    """
    lines: list[str] = []
    current = [partial]
    for char in data:
        if char in "\r\n":
            lines.append("".join(current))
            current = []
        elif char in _REALTIME or ord(char) >= EXTENDED_START:
            continue
        else:
            current.append(char)
    return lines, "".join(current)


def parse_cncjs_url(url: str) -> str:
    """Check `http://HOST[:PORT]` and return it without a trailing slash; LinkError in words."""
    parsed = urllib.parse.urlsplit(url)
    if parsed.scheme not in ("http", "https") or not parsed.hostname:
        raise LinkError(
            f"{url!r} is not a CNCjs address: write it as http://HOST:PORT, e.g."
            f" http://127.0.0.1:{DEFAULT_CNCJS_PORT}"
        )
    try:
        port = parsed.port
    except ValueError:
        raise LinkError(f"{url!r} has a port that is not a number from 1 to 65535") from None
    netloc = parsed.hostname if ":" not in parsed.hostname else f"[{parsed.hostname}]"
    return f"{parsed.scheme}://{netloc}:{port or DEFAULT_CNCJS_PORT}"


class CncjsLink(Link):
    """The controller on one port of a CNCjs server, reached as a socket.io pendant."""

    def __init__(
        self,
        url: str,
        port: str,
        token: str,
        *,
        baud: int = 115200,
        timeout_s: float = 5.0,
    ) -> None:
        """Describe the server and port; nothing is connected until open()."""
        self.url = parse_cncjs_url(url)
        if not port:
            raise LinkError(
                "--cncjs needs --cncjs-port: the controller's port as CNCjs knows it, e.g."
                " /dev/ttyUSB0"
            )
        self.port = port
        self.baud = baud
        self.timeout_s = timeout_s
        self._token = token
        self._sio: Any = None
        self._inbox = LineInbox()
        self._out: collections.deque[str] = collections.deque()
        self._have_data = asyncio.Event()
        self._writer_task: asyncio.Task[None] | None = None
        self._error: LinkError | None = None
        self._partial = ""
        self._on_wire_line: Callable[[str, str], None] | None = None
        self._early_echoes: list[tuple[str, str]] = []
        self._on_jog_lock: Callable[[str | None], None] | None = None
        self._on_moved: Callable[[], None] | None = None
        self._last_state: object = None
        #: The newest workflow state CNCjs reported ("idle", "running", "paused").
        self.workflow = "idle"
        self._connected: asyncio.Future[str | None] | None = None
        self._settings_seen: asyncio.Event | None = None
        #: Lines other clients wrote, as echoed (for tests and logs).
        self.foreign_lines = 0

    def describe(self) -> str:
        """Where the controller is, for messages."""
        return f"{self.port} through CNCjs at {self.url}"

    def attach_relay(
        self,
        on_wire_line: Callable[[str, str], None],
        on_jog_lock: Callable[[str | None], None],
        on_moved: Callable[[], None],
    ) -> bool:
        """Hand every echoed line, every change of CNCjs's workflow and of its view of the
        controller to the host."""
        self._on_wire_line, self._on_jog_lock = on_wire_line, on_jog_lock
        self._on_moved = on_moved
        # Lines echoed while opening (CNCjs's own `$$`) come first: their replies may still be
        # on their way, queued in the inbox behind them.
        early, self._early_echoes = self._early_echoes, []
        for line, writer in early:
            on_wire_line(line, writer)
        on_jog_lock(_WORKFLOW_LOCKS.get(self.workflow))
        return True

    def idle_poll_s(self) -> float:
        """CNCjs's console shows every client's `?`: while idle, ask seldom and rely on CNCjs's
        own state reports (Grbl:state, sent when something changed) to ask at once."""
        return IDLE_POLL_S

    def rx_reserve_bytes(self) -> int:
        """CNCjs's unseen `$G` poll and room for one line of another client in flight."""
        return CNCJS_POLL_BYTES + FOREIGN_ALLOWANCE_BYTES

    # ----------------------------------------------------------------- open and close
    async def open(self) -> None:
        """Connect to CNCjs, join the port, and wait until CNCjs has seen the controller."""
        if self._sio is not None:
            return
        import socketio  # type: ignore[import-untyped]  # noqa: PLC0415 - CNCjs users only

        loop = asyncio.get_running_loop()
        self._connected = loop.create_future()
        self._settings_seen = asyncio.Event()
        self._inbox = LineInbox()
        self._early_echoes = []
        self._error = None
        sio = socketio.AsyncClient(reconnection=False)
        self._register(sio)
        self._sio = sio
        query = urllib.parse.urlencode({"token": self._token})
        try:
            try:
                await asyncio.wait_for(
                    sio.connect(f"{self.url}?{query}", transports=["websocket"]), self.timeout_s
                )
            except TimeoutError:
                raise LinkError(
                    f"CNCjs at {self.url} did not accept a connection within {self.timeout_s} s:"
                    " is it running and is this its address?"
                ) from None
            except socketio.exceptions.ConnectionError as exc:
                raise LinkError(
                    f"no CNCjs server answers at {self.url} ({exc}): start CNCjs, or give the"
                    f" address and port it listens on (its -p option, {DEFAULT_CNCJS_PORT} by"
                    " default)"
                ) from None
            refused = await self._wait(self._connected, "accept the token")
            if refused is not None:
                raise LinkError(refused)
            ack: asyncio.Future[tuple[object, ...]] = loop.create_future()

            def on_ack(*args: object) -> None:
                if not ack.done():
                    ack.set_result(args)

            await sio.emit(
                "open",
                (self.port, {"baudrate": self.baud, "controllerType": "Grbl"}),
                callback=on_ack,
            )
            result = await self._wait(ack, f"open {self.port}")
            if result and result[0]:
                raise LinkError(
                    f"CNCjs could not open {self.port} ({result[0]}): check the port's name"
                    " (CNCjs's port list shows it) and that no other program holds it"
                )
            if self._error is not None:
                raise self._error
            # CNCjs takes a freshly opened port as ready only after a banner or a status report
            # (it asks with `?` 2 s later by itself): ask now. Then it reads `$$`: wait for that
            # so its lines are not mistaken for answers to the handshake. A port CNCjs already
            # had open replays its settings at once.
            await sio.emit("write", (self.port, "?"))
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._settings_seen.wait(), self.timeout_s)
        except BaseException:
            await self._disconnect()
            raise
        self._writer_task = loop.create_task(self._write_loop(), name=f"write {self.describe()}")

    async def _wait(self, future: asyncio.Future[Any], what: str) -> Any:
        try:
            return await asyncio.wait_for(asyncio.shield(future), self.timeout_s)
        except TimeoutError:
            raise LinkError(
                f"CNCjs at {self.url} did not {what} within {self.timeout_s} s"
            ) from None

    async def close(self) -> None:
        """Leave CNCjs (the port stays open for its other clients); harmless twice."""
        if self._sio is None:
            return
        closed = LinkError(f"the link to {self.describe()} was closed")
        if self._error is None:
            self._error = closed
        self._inbox.close(closed)
        self._out.clear()
        await self._disconnect()

    async def _disconnect(self) -> None:
        sio, self._sio = self._sio, None
        task, self._writer_task = self._writer_task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        if sio is not None:
            with contextlib.suppress(Exception):  # a half-open socket.io client may fail here
                await sio.disconnect()

    # ----------------------------------------------------------------- events from CNCjs
    def _register(self, sio: Any) -> None:
        sio.on("connect", self._on_connect)
        sio.on("connect_error", self._on_connect_error)
        sio.on("disconnect", self._on_disconnect)
        sio.on("serialport:read", self._on_read)
        sio.on("serialport:write", self._on_write)
        sio.on("serialport:open", self._on_open)
        sio.on("serialport:close", self._on_close)
        sio.on("serialport:error", self._on_error)
        sio.on("workflow:state", self._on_workflow)
        sio.on("Grbl:settings", self._on_settings)
        sio.on("Grbl:state", self._on_state)

    def _on_connect(self) -> None:
        if self._connected is not None and not self._connected.done():
            self._connected.set_result(None)

    def _on_connect_error(self, data: object = None) -> None:
        if self._connected is not None and not self._connected.done():
            self._connected.set_result(refusal_sentence(data, self.url))

    def _on_disconnect(self) -> None:
        self._lost(f"the connection to CNCjs at {self.url} was lost (CNCjs stopped or restarted)")

    def _on_read(self, data: object) -> None:
        if isinstance(data, str):
            self._inbox.feed(undecorate(data).encode("utf-8", "replace") + b"\n")

    def _on_write(self, data: object, context: object = None) -> None:
        if not isinstance(data, str):
            return
        lines, self._partial = wire_lines(data, self._partial)
        writer = _DEFAULT_WRITER
        if isinstance(context, dict) and isinstance(context.get("source"), str):
            writer = f"{_DEFAULT_WRITER}-{context['source']}"
        for line in lines:
            if self._on_wire_line is None:
                self._early_echoes.append((line, writer))
            else:
                self._on_wire_line(line, writer)

    def _on_open(self, data: object = None) -> None:
        if not isinstance(data, dict) or data.get("port") != self.port:
            return
        kind = data.get("controllerType")
        if kind not in (None, "Grbl"):
            self._lost(
                f"CNCjs has {self.port} open as a {kind} controller: smoothjog drives Grbl,"
                " grblHAL and FluidNC; reopen the port in CNCjs as Grbl"
            )

    def _on_close(self, data: object = None) -> None:
        if isinstance(data, dict) and data.get("port") not in (None, self.port):
            return
        self._lost(f"CNCjs closed {self.port} (another client closed it, or the device went away)")

    def _on_error(self, data: object = None) -> None:
        if isinstance(data, dict) and data.get("port") not in (None, self.port):
            return
        detail = data.get("err") if isinstance(data, dict) else data
        if self._writer_task is None:  # still opening: CNCjs could not open the port
            self._lost(
                f"CNCjs could not open {self.port}{f' ({detail})' if detail else ''}: check the"
                " port's name (CNCjs's port list shows it) and that no other program holds it"
            )
        else:
            self._lost(f"CNCjs reports an error on {self.port}: {detail or 'no detail given'}")

    def _on_workflow(self, state: object = None) -> None:
        if not isinstance(state, str):
            return
        self.workflow = state
        if self._on_jog_lock is not None:
            self._on_jog_lock(_WORKFLOW_LOCKS.get(state))

    def _on_state(self, data: object = None) -> None:
        # CNCjs sends its view of the controller (from its own 4 Hz `?`) when it changed; only
        # the state and position matter here, not its modal-state echo of every `$G`.
        status = data.get("status") if isinstance(data, dict) else None
        if not isinstance(status, dict):
            return
        key = (status.get("activeState"), str(status.get("mpos")), str(status.get("wpos")))
        if key != self._last_state:
            self._last_state = key
            if self._on_moved is not None:
                self._on_moved()

    def _on_settings(self, data: object = None) -> None:
        settings = data.get("settings") if isinstance(data, dict) else None
        if settings and self._settings_seen is not None:
            self._settings_seen.set()

    def _lost(self, reason: str) -> None:
        if self._error is not None:
            return
        error = LinkError(reason)
        self._error = error
        self._out.clear()
        self._have_data.set()
        if self._connected is not None and not self._connected.done():
            self._connected.set_result(reason)
        self._inbox.peer_gone(error)

    # ----------------------------------------------------------------- writing
    def _check_usable(self) -> None:
        if self._error is not None:
            raise self._error
        if self._sio is None:
            raise LinkError(f"the link to {self.describe()} is not open: call open() first")

    async def _write_line(self, data: bytes) -> None:
        self._write_line_nowait(data)

    def _write_line_nowait(self, data: bytes) -> bool:
        self._check_usable()
        self._out.append(data.decode("ascii"))
        self._have_data.set()
        return True

    def _write_realtime(self, byte: bytes) -> None:
        self._check_usable()
        self._out.appendleft(chr(byte[0]))  # ahead of every line not yet handed to CNCjs
        self._have_data.set()

    def _line_inbox(self) -> LineInbox:
        return self._inbox

    async def read_line(self) -> bytes:
        """The next line the controller printed (as CNCjs relays it)."""
        return await self._inbox.get()

    async def _write_loop(self) -> None:
        """Emit queued text in order, one `write` per line or realtime byte."""
        sio = self._sio
        while True:
            await self._have_data.wait()
            if self._error is not None:
                return
            while self._out:
                text = self._out.popleft()
                try:
                    await sio.emit("write", (self.port, text))
                except Exception as exc:  # the socket.io client fails in its own ways
                    self._lost(f"writing to CNCjs at {self.url} failed: {exc}")
                    return
            self._have_data.clear()
