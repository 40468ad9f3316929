"""The sender's ports in real time: the pty (open and close seen, nothing stale) and TCP."""

from __future__ import annotations

import asyncio
import os
from pathlib import Path

import pytest

from smoothjog.core.errors import LinkError
from smoothjog.host import Host
from smoothjog.links.sim import SimLink
from smoothjog.proxy import PtySender, SenderProxy, TcpSender
from smoothjog.pty_port import PtyPort
from smoothjog.sim.firmware import GrblFirmware


async def _until(predicate: object, timeout_s: float = 3.0) -> None:
    assert callable(predicate)
    async with asyncio.timeout(timeout_s):
        while not predicate():  # noqa: ASYNC110 - the state changes in callbacks, no event
            await asyncio.sleep(0.01)


def _read_all(fd: int) -> bytes:
    out = b""
    while True:
        try:
            chunk = os.read(fd, 4096)
        except BlockingIOError:
            return out
        if not chunk:
            return out
        out += chunk


async def test_a_port_nobody_holds_sees_each_open_and_close(tmp_path: Path) -> None:
    events: list[str] = []
    data: list[bytes] = []
    link = tmp_path / "ttyX"
    port = PtyPort(
        data.append,
        link_path=link,
        hold_slave=False,
        on_open=lambda: events.append("open"),
        on_close=lambda: events.append("close"),
        poll_s=0.01,
    )
    port.open()
    try:
        assert link.is_symlink()
        assert not port.peer_open
        assert not port.write(b"nobody hears this\r\n")
        for round_ in range(2):
            fd = os.open(link, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            await _until(lambda: port.peer_open)
            assert port.write(b"hello\r\n")
            await asyncio.sleep(0.02)
            assert _read_all(fd) == b"hello\r\n"  # and nothing stale from before the open
            os.write(fd, b"$G\n")
            await _until(lambda: data)
            assert data.pop() == b"$G\n"
            os.close(fd)
            await _until(lambda: not port.peer_open)
            assert events == ["open", "close"] * (round_ + 1)
    finally:
        port.close()
    assert not link.exists()
    assert not link.is_symlink()


async def test_a_link_path_that_is_a_file_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "taken"
    path.write_text("mine")
    port = PtyPort(lambda data: None, link_path=path)
    with pytest.raises(LinkError, match="exists and is not a symlink"):
        port.open()
    assert path.read_text() == "mine"


async def _started_proxy() -> tuple[Host, SenderProxy, asyncio.Task[None]]:
    link = SimLink(GrblFirmware(machine="hobby-router"))
    await link.open()
    host = Host(link)
    proxy = SenderProxy()
    proxy.attach(host)
    await host.start()
    proxy.started(host)
    return host, proxy, asyncio.create_task(proxy.run())


async def _read_until(fd: int, marker: bytes, timeout_s: float = 3.0) -> bytes:
    got = b""
    async with asyncio.timeout(timeout_s):
        while marker not in got:
            got += _read_all(fd)
            await asyncio.sleep(0.01)
    return got


async def test_a_sender_on_the_pty_gets_the_banner_and_its_answers(tmp_path: Path) -> None:
    host, proxy, task = await _started_proxy()
    pty = PtySender(proxy, tmp_path / "ttyPROXY")
    pty.open()
    try:
        for _ in range(2):  # a second open gets the banner again
            fd = os.open(tmp_path / "ttyPROXY", os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            got = await _read_until(fd, b"['$' for help]\r\n")
            assert got.startswith(b"Grbl 1.1h ['$' for help]\r\n")  # the first thing it hears
            os.write(fd, b"$G\n")
            got = await _read_until(fd, b"ok\r\n")
            assert b"[GC:G0 G54 G17 G21 G90 G94" in got
            os.close(fd)
            await _until(lambda: pty.conn is None)
        assert host.model.reset_count == 0
    finally:
        pty.close()
        task.cancel()
        await host.close()


async def test_a_sender_on_tcp_gets_the_same() -> None:
    host, proxy, task = await _started_proxy()
    server = TcpSender(proxy)
    port = await server.start(0)
    try:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        banner = await asyncio.wait_for(reader.readline(), 3.0)
        assert banner == b"Grbl 1.1h ['$' for help]\r\n"
        writer.write(b"$G\n")
        lines = []
        while not lines or lines[-1] != b"ok\r\n":
            lines.append(await asyncio.wait_for(reader.readline(), 3.0))
        assert any(x.startswith(b"[GC:") for x in lines)
        writer.close()
        await _until(lambda: not proxy.connections)
    finally:
        await server.close()
        task.cancel()
        await host.close()
