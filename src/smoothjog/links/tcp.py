"""A Link over a raw TCP socket, as ESP32 Grbl, FluidNC and grblHAL offer (a telnet-like port).

Built on asyncio streams. Lines wait in the link's own queue and go to the transport in whole-line
chunks, one chunk at a time; a realtime byte is handed to the transport directly, so it overtakes
every queued line and can only follow the one chunk already in the transport. TCP keepalive is
turned on so a controller that vanishes without closing (power cut, Wi-Fi gone) is noticed.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import socket

from smoothjog.core.errors import LinkError
from smoothjog.links.base import READ_CHUNK_BYTES, WRITE_CHUNK_BYTES, LineInbox, Link, OutQueue

#: FluidNC's telnet port (firmware-facts §7); grblHAL's telnet plugin uses 23 as well.
DEFAULT_TCP_PORT = 23
DEFAULT_CONNECT_TIMEOUT_S = 5.0
# Keepalive: first probe after 5 s of silence, then every 2 s, give up after 3 (about 11 s).
_KEEPALIVE_IDLE_S = 5
_KEEPALIVE_INTERVAL_S = 2
_KEEPALIVE_PROBES = 3


class TcpLink(Link):
    """A TCP connection to a controller's raw serial-over-network port."""

    def __init__(
        self,
        host: str,
        port: int = DEFAULT_TCP_PORT,
        *,
        connect_timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S,
    ) -> None:
        """Describe the endpoint; nothing is connected until open()."""
        self.host = host
        self.port = port
        self.connect_timeout_s = connect_timeout_s
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._inbox = LineInbox()
        self._out = OutQueue()
        self._have_data = asyncio.Event()
        self._tasks: list[asyncio.Task[None]] = []
        self._error: LinkError | None = None

    def describe(self) -> str:
        """The endpoint as a URL."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"tcp://{host}:{self.port}"

    @property
    def queued_bytes(self) -> int:
        """Bytes accepted by the link but not yet handed to the transport."""
        return self._out.size

    async def open(self) -> None:
        """Connect, within connect_timeout_s."""
        if self._writer is not None:
            return
        if not 0 < self.port < 65536:
            raise LinkError(f"TCP port {self.port} is out of range: use 1-65535 (FluidNC: 23)")
        try:
            reader, writer = await asyncio.wait_for(
                asyncio.open_connection(self.host, self.port, limit=READ_CHUNK_BYTES),
                self.connect_timeout_s,
            )
        except TimeoutError:
            raise LinkError(
                f"no connection to {self.describe()} within {self.connect_timeout_s} s: check"
                " that the controller is on the network and the address is right"
            ) from None
        except OSError as exc:
            raise self._connect_error(exc) from None
        except (UnicodeError, ValueError) as exc:
            # The IDNA codec refuses some names (empty or over-long labels) before any lookup.
            raise LinkError(
                f"{self.host!r} is not a usable host name ({exc}): check the address"
            ) from None
        self._set_socket_options(writer)
        # A zero high-water mark makes drain() wait until the kernel has taken every byte, so
        # the transport never holds more than the one chunk a realtime byte may have to follow.
        writer.transport.set_write_buffer_limits(high=0)
        self._reader, self._writer = reader, writer
        self._inbox = LineInbox()
        self._error = None
        self._tasks = [
            asyncio.create_task(self._read_loop(reader), name=f"read {self.describe()}"),
            asyncio.create_task(self._write_loop(writer), name=f"write {self.describe()}"),
        ]

    async def read_line(self) -> bytes:
        """The next received line without its end-of-line."""
        return await self._inbox.get()

    async def close(self) -> None:
        """Stop the reader and writer and close the socket; harmless when already closed."""
        writer, self._writer = self._writer, None
        if writer is None:
            return
        closed = LinkError(f"the link to {self.describe()} was closed")
        if self._error is None:
            self._error = closed
        self._inbox.close(closed)
        self._out.clear()
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self._tasks = []
        writer.close()
        with contextlib.suppress(OSError):
            await writer.wait_closed()

    async def _write_line(self, data: bytes) -> None:
        """Queue a line for the writer task; wait while the queue is too long."""
        await self._out.put(data, self._check_usable)
        self._have_data.set()

    def _write_line_nowait(self, data: bytes) -> bool:
        """Queue a line for the writer task, unless the queue is too long."""
        if not self._out.put_nowait(data, self._check_usable):
            return False
        self._have_data.set()
        return True

    def _line_inbox(self) -> LineInbox:
        return self._inbox

    def _write_realtime(self, byte: bytes) -> None:
        """Hand the byte to the transport now, ahead of the queued lines."""
        self._check_usable()
        assert self._writer is not None  # _check_usable guarantees it
        self._writer.write(byte)

    def _check_usable(self) -> None:
        """Raise the link's error if it is closed or the peer has gone."""
        if self._error is not None:
            raise self._error
        if self._writer is None:
            raise LinkError(f"the link to {self.describe()} is not open: call open() first")

    async def _write_loop(self, writer: asyncio.StreamWriter) -> None:
        """Move whole lines from the queue to the transport, one chunk at a time."""
        try:
            while True:
                await self._have_data.wait()
                chunk = bytearray()
                items = self._out.items
                while items and (not chunk or len(chunk) + len(items[0]) <= WRITE_CHUNK_BYTES):
                    chunk += items.popleft()
                if not items:
                    self._have_data.clear()
                self._out.taken(len(chunk))
                writer.write(chunk)
                await writer.drain()
        except OSError as exc:
            self._lost(f"sending failed: {exc.strerror or exc}")

    async def _read_loop(self, reader: asyncio.StreamReader) -> None:
        """Frame received bytes into lines until the peer closes or fails."""
        try:
            while True:
                data = await reader.read(READ_CHUNK_BYTES)
                if not data:
                    self._lost("the controller closed the connection")
                    return
                self._inbox.feed(data)
        except OSError as exc:
            self._lost(f"receiving failed: {exc.strerror or exc}")

    def _lost(self, reason: str) -> None:
        """The peer went away: fail every reader and writer."""
        if self._error is not None:
            return
        error = LinkError(
            f"lost {self.describe()} ({reason}): the controller restarted, dropped off the"
            " network or accepted another client; connect again"
        )
        self._error = error
        self._out.clear()
        self._inbox.peer_gone(error)

    def _connect_error(self, exc: OSError) -> LinkError:
        """One actionable sentence for a failed connect."""
        where = self.describe()
        if isinstance(exc, ConnectionRefusedError) or exc.errno == errno.ECONNREFUSED:
            return LinkError(
                f"connection to {where} refused: nothing listens on port {self.port}; check"
                " the port number and that telnet/TCP is enabled on the controller"
            )
        if isinstance(exc, socket.gaierror):
            return LinkError(
                f"cannot resolve host {self.host!r} for {where}: check the name or use the"
                " controller's IP address"
            )
        if exc.errno in (errno.EHOSTUNREACH, errno.ENETUNREACH):
            return LinkError(
                f"{where} is unreachable: check that this computer and the controller are on"
                " the same network"
            )
        if exc.errno == errno.ETIMEDOUT:
            return LinkError(
                f"connection to {where} timed out: check that the controller is powered and"
                " on the network"
            )
        return LinkError(f"cannot connect to {where}: {exc.strerror or exc}")

    @staticmethod
    def _set_socket_options(writer: asyncio.StreamWriter) -> None:
        """Send small writes at once and detect a silently vanished peer."""
        sock = writer.get_extra_info("socket")
        if sock is None:
            return
        # setsockopt is allowed on asyncio's socket wrapper (unlike send/recv).
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
        for name, value in (
            ("TCP_KEEPIDLE", _KEEPALIVE_IDLE_S),
            ("TCP_KEEPINTVL", _KEEPALIVE_INTERVAL_S),
            ("TCP_KEEPCNT", _KEEPALIVE_PROBES),
        ):
            option = getattr(socket, name, None)
            if option is not None:
                sock.setsockopt(socket.IPPROTO_TCP, option, value)


def parse_tcp_url(url: str) -> tuple[str, int]:
    """Split `tcp://HOST:PORT` (or `tcp://HOST`, port 23; `[v6]` for IPv6) into host and port."""
    scheme, sep, rest = url.partition("://")
    if not sep or scheme.lower() != "tcp":
        raise LinkError(
            f"{url!r} is not a tcp:// address: write it as tcp://HOST:PORT, e.g."
            " tcp://192.168.1.50:23"
        )
    rest = rest.rstrip("/")
    if rest.startswith("["):
        host, bracket, tail = rest[1:].partition("]")
        if not bracket or (tail and not tail.startswith(":")):
            raise LinkError(f"{url!r} has a broken [IPv6] host: write tcp://[fe80::1]:23")
        port_text = tail[1:] if tail else ""
    elif rest.count(":") > 1:
        raise LinkError(f"{url!r}: put an IPv6 address in brackets, e.g. tcp://[fe80::1]:23")
    else:
        host, _, port_text = rest.partition(":")
    if not host or "/" in host or "@" in host:
        raise LinkError(
            f"{url!r} has no usable host: write tcp://HOST:PORT, e.g. tcp://cnc.local:23"
        )
    if not port_text:
        return host, DEFAULT_TCP_PORT
    if not port_text.isdigit() or not 0 < int(port_text) < 65536:
        raise LinkError(f"{url!r} has port {port_text!r}: give a number from 1 to 65535")
    return host, int(port_text)
