"""A scripted Grbl 1.1h for tests, served on a pseudo-terminal or a loopback TCP port.

`ScriptedGrbl` is the protocol side only: bytes in, bytes out, no I/O. It answers `$I`, `$$`,
`$G`, `$#`, `$X`, empty lines, G-code and `$J=` lines, and the `?` and Ctrl-X realtime bytes with
the exact forms of firmware-facts §5.3/§5.4, and records everything it received. `PtyPeer` and
`TcpPeer` run one in a thread behind real bytes, so both asyncio tests and subprocess tests can talk
to it. Knobs make it misbehave on purpose: silent, not Grbl at all, a reset in mid-handshake, in
Alarm.
"""

from __future__ import annotations

import contextlib
import os
import select
import socket
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

BANNER = b"\r\nGrbl 1.1h ['$' for help]\r\n"

#: Grbl 1.1h default settings in `$$` order and print format (firmware-facts §0, §5.3).
DEFAULT_SETTINGS: dict[int, str] = {
    0: "10", 1: "25", 2: "0", 3: "0", 4: "0", 5: "0", 6: "0",
    10: "1", 11: "0.010", 12: "0.002", 13: "0",
    20: "0", 21: "0", 22: "0", 23: "0", 24: "25.000", 25: "500.000", 26: "250", 27: "1.000",
    30: "1000", 31: "0", 32: "0",
    100: "250.000", 101: "250.000", 102: "250.000",
    110: "500.000", 111: "500.000", 112: "500.000",
    120: "10.000", 121: "10.000", 122: "10.000",
    130: "200.000", 131: "200.000", 132: "200.000",
}  # fmt: skip

_REALTIME = frozenset(b"?!~\x18") | frozenset(range(0x80, 0x100))


@dataclass
class ScriptedGrbl:
    """Grbl 1.1h's replies to a host, with switches for the failures tests need."""

    settings: dict[int, str] = field(default_factory=lambda: dict(DEFAULT_SETTINGS))
    state: str = "Idle"
    mpos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    wco: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: Never answer anything (a device that is not a controller, or a wrong baud rate).
    silent: bool = False
    #: Answer every line with this text instead (a modem, a 3D printer, a shell...).
    foreign_reply: bytes | None = None
    #: Print the banner instead of answering a line that starts with this (a reset)...
    reset_on: str | None = None
    #: ... this many times.
    reset_times: int = 1
    #: Answer `?` (Grbl makes no report while homing or after a limit alarm).
    answer_status: bool = True
    #: Exact replies for given lines, overriding the built-in ones (without the final CRLF).
    replies: Mapping[str, list[str]] = field(default_factory=dict)
    received_lines: list[bytes] = field(default_factory=list)
    received_realtime: list[int] = field(default_factory=list)
    _partial: bytearray = field(default_factory=bytearray)

    def banner(self) -> bytes:
        """What the controller prints after a reset."""
        return BANNER

    def receive(self, data: bytes) -> bytes:
        """Take bytes from the host; return the bytes the controller sends back."""
        out = bytearray()
        for value in data:
            if value in _REALTIME:
                self.received_realtime.append(value)
                out += self._realtime(value)
            elif value in b"\r\n":
                line = bytes(self._partial)
                self._partial.clear()
                self.received_lines.append(line)
                out += self._line(line.decode("ascii", "replace"))
            else:
                self._partial.append(value)
        return bytes(out)

    def _realtime(self, value: int) -> bytes:
        """The answer to one realtime byte."""
        if self.silent or self.foreign_reply is not None:
            return b""
        if value == ord("?") and self.answer_status:
            return self.status_report().encode() + b"\r\n"
        if value == 0x18:
            self._partial.clear()
            return BANNER
        return b""

    def status_report(self) -> str:
        """A status report in the default `$10=1` form (MPos)."""
        mpos = ",".join(f"{v:.3f}" for v in self.mpos)
        wco = ",".join(f"{v:.3f}" for v in self.wco)
        return f"<{self.state}|MPos:{mpos}|FS:0,0|WCO:{wco}>"

    def _line(self, line: str) -> bytes:
        """The reply to one complete line."""
        if self.silent or self.state.startswith(("Hold", "Door", "Sleep")):
            return b""  # Grbl's main loop reads no line while suspended (firmware-facts §3.2)
        if self.foreign_reply is not None:
            return self.foreign_reply
        command = line.strip().upper()
        if self.reset_on is not None and self.reset_times > 0 and command.startswith(self.reset_on):
            self.reset_times -= 1
            return BANNER
        if command in self.replies:
            return b"".join(text.encode() + b"\r\n" for text in self.replies[command])
        return b"".join(text.encode() + b"\r\n" for text in self._builtin(command))

    def _builtin(self, command: str) -> list[str]:
        """Grbl 1.1h's own reply lines to a command (firmware-facts §5.3)."""
        alarm = self.state == "Alarm"
        if command == "":
            return ["ok"]
        if command == "$I":
            return ["[VER:1.1h.20190830:]", "[OPT:V,15,128]", "ok"]
        if command == "$$":
            return [*(f"${n}={v}" for n, v in self.settings.items()), "ok"]
        if command == "$G":
            return ["[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]", "ok"]
        if command == "$#":
            zeros = "0.000,0.000,0.000"
            names = ["G54", "G55", "G56", "G57", "G58", "G59", "G28", "G30", "G92"]
            return [
                *(f"[{name}:{zeros}]" for name in names),
                "[TLO:0.000]",
                f"[PRB:{zeros}:0]",
                "ok",
            ]
        if command == "$X":
            self.state = "Idle"
            return ["[MSG:Caution: Unlocked]", "ok"]
        if command.startswith("$J="):
            return ["error:8"] if alarm else ["ok"]
        if command.startswith("$"):
            return ["error:3"]
        return ["error:9"] if alarm else ["ok"]


class PtyPeer:
    """A ScriptedGrbl behind a pseudo-terminal; connect a SerialLink to `.path`.

    Like an Arduino, it prints the banner each time the port is opened (DTR reset), after a short
    pause standing in for the bootloader; `banner_on_open=False` skips it. What the client sends
    during that pause is lost, as in a bootloader: it is kept in `swallowed`, never answered.
    """

    def __init__(
        self,
        grbl: ScriptedGrbl | None = None,
        *,
        banner_on_open: bool = True,
        boot_s: float = 0.15,
    ) -> None:
        """Create the pseudo-terminal and start answering in a thread."""
        self.grbl = grbl if grbl is not None else ScriptedGrbl()
        self.banner_on_open = banner_on_open
        self.boot_s = boot_s
        #: Bytes the client sent while the peer was booting (the bootloader took them).
        self.swallowed = bytearray()
        self._master, slave = os.openpty()
        self.path = os.ttyname(slave)
        # With no slave fd open here, the master reports a hang-up until a client opens the
        # port: that is how the peer sees an "open" and knows when to print its banner.
        os.close(slave)
        self._stop_r, self._stop_w = os.pipe()
        self._thread = threading.Thread(target=self._run, name=f"pty peer {self.path}")
        self._thread.daemon = True
        self._thread.start()

    def __enter__(self) -> PtyPeer:
        """Use in a with block."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Stop the peer."""
        self.close()

    def write(self, data: bytes) -> None:
        """Send raw bytes to whoever has the port open."""
        os.write(self._master, data)

    def close(self) -> None:
        """Stop the thread and destroy the pseudo-terminal (the client then sees it vanish)."""
        if self._thread.is_alive():
            os.write(self._stop_w, b"x")
            self._thread.join(timeout=10)
        for fd in (self._master, self._stop_r, self._stop_w):
            with contextlib.suppress(OSError):
                os.close(fd)

    def _run(self) -> None:
        """Serve until stopped."""
        poller = select.poll()
        poller.register(self._master, select.POLLIN)
        poller.register(self._stop_r, select.POLLIN)
        client_open = False
        while True:
            events = dict(poller.poll(50 if not client_open else None))
            if self._stop_r in events:
                return
            master_events = events.get(self._master, 0)
            if master_events & select.POLLHUP:
                client_open = False
                # POLLHUP is level-triggered while no client is there; poll slowly meanwhile.
                time.sleep(0.01)
                continue
            if not client_open:
                client_open = True
                if self.banner_on_open:
                    time.sleep(self.boot_s)
                    self._swallow()
                    self._send(self.grbl.banner())
            if master_events & select.POLLIN:
                try:
                    data = os.read(self._master, 65536)
                except OSError:
                    continue
                self._send(self.grbl.receive(data))

    def _swallow(self) -> None:
        """Take in, unanswered, whatever the client sent while booting."""
        while select.select([self._master], [], [], 0)[0]:
            try:
                data = os.read(self._master, 65536)
            except OSError:
                return
            if not data:
                return
            self.swallowed += data

    def _send(self, data: bytes) -> None:
        """Write a reply, ignoring a client that just went away."""
        if data:
            with contextlib.suppress(OSError):
                os.write(self._master, data)


class TcpPeer:
    """A ScriptedGrbl behind a loopback TCP server; connect a TcpLink to `.host`, `.port`."""

    def __init__(
        self,
        grbl: ScriptedGrbl | None = None,
        *,
        banner_on_connect: bool = False,
    ) -> None:
        """Listen on a free loopback port and serve clients one after another in a thread."""
        self.grbl = grbl if grbl is not None else ScriptedGrbl()
        self.banner_on_connect = banner_on_connect
        self._server = socket.create_server(("127.0.0.1", 0))
        self._server.settimeout(0.05)
        self.host = "127.0.0.1"
        self.port: int = self._server.getsockname()[1]
        self.url = f"tcp://{self.host}:{self.port}"
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"tcp peer {self.port}")
        self._thread.daemon = True
        self._thread.start()

    def __enter__(self) -> TcpPeer:
        """Use in a with block."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Stop the peer."""
        self.close()

    def close(self) -> None:
        """Stop serving and close every socket."""
        self._stopping.set()
        self._thread.join(timeout=10)
        self._server.close()

    def _run(self) -> None:
        """Accept clients and answer them until stopped."""
        while not self._stopping.is_set():
            try:
                conn, _ = self._server.accept()
            except TimeoutError:
                continue
            with conn:
                conn.settimeout(0.05)
                if self.banner_on_connect:
                    conn.sendall(self.grbl.banner())
                self._serve(conn)

    def _serve(self, conn: socket.socket) -> None:
        """Answer one client until it leaves or the peer stops."""
        while not self._stopping.is_set():
            try:
                data = conn.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            if not data:
                return
            reply = self.grbl.receive(data)
            if reply:
                try:
                    conn.sendall(reply)
                except OSError:
                    return
