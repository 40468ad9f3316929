"""TcpLink against a real loopback server: framing, ordering, vanishing peers, refusals."""

from __future__ import annotations

import asyncio
import errno
import re
import socket
import struct
from collections.abc import AsyncIterator, Awaitable, Callable

import pytest

from smoothjog.core.errors import LinkError
from smoothjog.links.tcp import TcpLink, parse_tcp_url
from tests.peers import ScriptedGrbl, TcpPeer


class LoopbackServer:
    """One-client asyncio server whose side of the connection the test drives."""

    def __init__(self) -> None:
        """Not listening until start()."""
        self.port = 0
        self.connected: asyncio.Future[tuple[asyncio.StreamReader, asyncio.StreamWriter]]
        self._server: asyncio.Server | None = None

    async def start(self, rcvbuf_bytes: int | None = None) -> None:
        """Listen on a free loopback port."""
        self.connected = asyncio.get_running_loop().create_future()
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        if rcvbuf_bytes is not None:
            # Set before listen() so the accepted socket inherits the small receive window.
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf_bytes)
        sock.bind(("127.0.0.1", 0))
        self.port = sock.getsockname()[1]
        self._server = await asyncio.start_server(self._accept, sock=sock)

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        """Hand the connection to the test."""
        if not self.connected.done():
            self.connected.set_result((reader, writer))

    async def stop(self) -> None:
        """Stop listening and drop the client."""
        if self.connected.done():
            self.connected.result()[1].close()
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()


@pytest.fixture
async def server() -> AsyncIterator[LoopbackServer]:
    """A started loopback server."""
    srv = LoopbackServer()
    await srv.start()
    yield srv
    await srv.stop()


async def test_line_goes_out_with_exactly_one_newline(server: LoopbackServer) -> None:
    """send_line puts one `\\n` after the text; lines arrive in order."""
    async with TcpLink("127.0.0.1", server.port) as link:
        reader, _ = await server.connected
        await link.send_line("$J=G91X1F100")
        await link.send_line("")
        expected = b"$J=G91X1F100\n\n"
        assert await reader.readexactly(len(expected)) == expected


@pytest.mark.parametrize(
    ("chunks", "expected"),
    [
        ([b"o", b"k\r", b"\nerror:9\r\n"], [b"ok", b"error:9"]),
        ([b"<Jog|MPos:1.000,2", b".000,3.000|FS:500,0>\r\n"],
         [b"<Jog|MPos:1.000,2.000,3.000|FS:500,0>"]),
        ([b"ok\nok\rok\r\n"], [b"ok", b"ok", b"ok"]),
        ([b"".join(b"$%d=1\r\n" % n for n in range(300))], [b"$%d=1" % n for n in range(300)]),
    ],
)  # fmt: skip
async def test_lines_arrive_whole_however_the_bytes_come(
    server: LoopbackServer, chunks: list[bytes], expected: list[bytes]
) -> None:
    """Split lines, mixed EOLs and bursts come out as whole lines, in order."""
    async with TcpLink("127.0.0.1", server.port) as link:
        _, writer = await server.connected
        for chunk in chunks:
            writer.write(chunk)
            await writer.drain()
            await asyncio.sleep(0.01)
        assert [await link.read_line() for _ in expected] == expected


async def test_realtime_byte_overtakes_queued_lines() -> None:
    """With the peer not reading and lines queued, a realtime byte goes out ahead of them."""
    srv = LoopbackServer()
    await srv.start(rcvbuf_bytes=4096)
    lines = [f"G1X{n:06d}" + "Y1" * 40 for n in range(40000)]
    try:
        async with TcpLink("127.0.0.1", srv.port) as link:
            reader, _ = await srv.connected

            async def send_all() -> None:
                for line in lines:
                    await link.send_line(line)

            sender = asyncio.create_task(send_all())
            while link.queued_bytes < 32 * 1024:  # noqa: ASYNC110 (no event exposes the queue level)
                await asyncio.sleep(0.005)
            held_back = link.queued_bytes
            link.send_realtime(b"\x85")
            stream = b"".join(line.encode() + b"\n" for line in lines)
            received = await reader.readexactly(len(stream) + 1)
            await sender
    finally:
        await srv.stop()
    position = received.index(b"\x85")
    assert position < len(stream) - held_back + 4096
    assert received[position - 1 : position] == b"\n"
    assert received[:position] + received[position + 1 :] == stream


async def test_realtime_byte_goes_out_at_once_when_idle(server: LoopbackServer) -> None:
    """With nothing queued, a realtime byte is sent immediately."""
    async with TcpLink("127.0.0.1", server.port) as link:
        reader, _ = await server.connected
        link.send_realtime(b"?")
        assert await reader.readexactly(1) == b"?"


async def _close_gracefully(writer: asyncio.StreamWriter) -> None:
    """FIN: the controller closed the connection."""
    writer.close()


async def _reset(writer: asyncio.StreamWriter) -> None:
    """RST: the controller dropped the connection abruptly."""
    sock = writer.get_extra_info("socket")
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    writer.close()


@pytest.mark.parametrize("vanish", [_close_gracefully, _reset])
async def test_peer_vanishing_mid_read_raises_promptly(
    server: LoopbackServer, vanish: Callable[[asyncio.StreamWriter], Awaitable[None]]
) -> None:
    """A reader waiting when the peer goes away gets a LinkError, and so do later calls."""
    async with TcpLink("127.0.0.1", server.port) as link:
        _, writer = await server.connected
        reader_task = asyncio.create_task(link.read_line())
        await asyncio.sleep(0.05)
        assert not reader_task.done()
        await vanish(writer)
        with pytest.raises(LinkError, match=r"lost tcp://127\.0\.0\.1"):
            await reader_task
        with pytest.raises(LinkError, match="lost"):
            await link.send_line("G4P0")
        with pytest.raises(LinkError, match="lost"):
            link.send_realtime(b"?")


async def test_lines_before_the_close_are_still_read(server: LoopbackServer) -> None:
    """Lines already received are delivered first, then the LinkError."""
    async with TcpLink("127.0.0.1", server.port) as link:
        _, writer = await server.connected
        writer.write(b"ok\r\n[MSG:Reset to continue]\r\n")
        await writer.drain()
        writer.close()
        assert await link.read_line() == b"ok"
        assert await link.read_line() == b"[MSG:Reset to continue]"
        with pytest.raises(LinkError):
            await link.read_line()


async def test_close_is_idempotent_and_wakes_a_reader(server: LoopbackServer) -> None:
    """close() twice is harmless; a waiting reader and later sends get LinkError."""
    link = TcpLink("127.0.0.1", server.port)
    await link.open()
    reader_task = asyncio.create_task(link.read_line())
    await asyncio.sleep(0.01)
    await link.close()
    await link.close()
    with pytest.raises(LinkError, match="closed"):
        await reader_task
    with pytest.raises(LinkError, match="closed"):
        await link.send_line("G4P0")


async def test_refused_connection() -> None:
    """Nothing listening: one sentence naming the port and what to check."""
    probe = socket.socket()
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    with pytest.raises(LinkError, match=rf"tcp://127.0.0.1:{port} refused.*telnet"):
        await TcpLink("127.0.0.1", port).open()


@pytest.mark.parametrize("port", [0, 70000, -1])
async def test_port_out_of_range(port: int) -> None:
    """A port outside 1-65535 is refused before connecting."""
    with pytest.raises(LinkError, match="out of range"):
        await TcpLink("127.0.0.1", port).open()


@pytest.mark.parametrize(
    ("error", "match"),
    [
        (ConnectionRefusedError(errno.ECONNREFUSED, "refused"), "refused: nothing listens"),
        (OSError(errno.EHOSTUNREACH, "No route to host"), "unreachable"),
        (OSError(errno.ENETUNREACH, "Network is unreachable"), "unreachable"),
        (OSError(errno.ETIMEDOUT, "timed out"), "timed out"),
        (socket.gaierror(socket.EAI_NONAME, "Name or service not known"), "cannot resolve host"),
        (OSError(errno.EPERM, "Operation not permitted"), "cannot connect to .*not permitted"),
    ],
)
def test_connect_errors_become_one_sentence(error: OSError, match: str) -> None:
    """Each way a connect can fail maps to a sentence naming the endpoint."""
    message = str(TcpLink("cnc.local", 23)._connect_error(error))
    assert "tcp://cnc.local:23" in message
    assert re.search(match, message)


def test_describe() -> None:
    """describe() is the URL, with brackets around an IPv6 address."""
    assert TcpLink("192.168.1.50", 23).describe() == "tcp://192.168.1.50:23"
    assert TcpLink("::1", 8080).describe() == "tcp://[::1]:8080"


async def test_scripted_peer_answers_over_tcp() -> None:
    """The reusable peer answers queries and `?` over a real socket."""
    with TcpPeer(ScriptedGrbl(), banner_on_connect=True) as peer:
        async with TcpLink(peer.host, peer.port) as link:
            assert await link.read_line() == b""
            assert await link.read_line() == b"Grbl 1.1h ['$' for help]"
            await link.send_line("$G")
            assert await link.read_line() == b"[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]"
            assert await link.read_line() == b"ok"
            link.send_realtime(b"?")
            assert (await link.read_line()).startswith(b"<Idle|MPos:")


@pytest.mark.parametrize(
    ("url", "expected"),
    [
        ("tcp://192.168.1.50:23", ("192.168.1.50", 23)),
        ("tcp://cnc.local:8080/", ("cnc.local", 8080)),
        ("TCP://cnc.local", ("cnc.local", 23)),
        ("tcp://[fe80::1]:2323", ("fe80::1", 2323)),
        ("tcp://[::1]", ("::1", 23)),
    ],
)
def test_parse_tcp_url(url: str, expected: tuple[str, int]) -> None:
    """Well-formed addresses split into host and port (23 when left out)."""
    assert parse_tcp_url(url) == expected


@pytest.mark.parametrize(
    ("url", "match"),
    [
        ("192.168.1.50:23", "not a tcp:// address"),
        ("telnet://cnc:23", "not a tcp:// address"),
        ("tcp://", "no usable host"),
        ("tcp://:23", "no usable host"),
        ("tcp://user@cnc:23", "no usable host"),
        ("tcp://cnc:0", "from 1 to 65535"),
        ("tcp://cnc:65536", "from 1 to 65535"),
        ("tcp://cnc:telnet", "from 1 to 65535"),
        ("tcp://cnc:-1", "from 1 to 65535"),
        ("tcp://fe80::1:23", "brackets"),
        ("tcp://[fe80::1:23", "broken"),
        ("tcp://[fe80::1]x", "broken"),
    ],
)
def test_parse_tcp_url_errors(url: str, match: str) -> None:
    """Malformed addresses are a LinkError saying how to write them."""
    with pytest.raises(LinkError, match=match):
        parse_tcp_url(url)


async def test_unusable_host_name_is_one_sentence() -> None:
    """A host name the resolver cannot even encode is a LinkError, not a traceback."""
    with pytest.raises(LinkError, match="not a usable host name"):
        await TcpLink("a" * 300, 23).open()
