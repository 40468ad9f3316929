"""SerialLink against real bytes on a pseudo-terminal: framing, ordering, banner, failures."""

from __future__ import annotations

import asyncio
import os
import time
from pathlib import Path

import pytest

from smoothjog.core.errors import LinkError
from smoothjog.core.responses import StatusReport, parse_response
from smoothjog.links.base import RefusedError
from smoothjog.links.serial import SerialLink
from tests.links.conftest import RawPty
from tests.peers import PtyPeer, ScriptedGrbl


async def test_open_waits_for_the_banner_and_keeps_it() -> None:
    """open() returns once the reset banner is in, and the banner is the first line read."""
    with PtyPeer(boot_s=0.1) as peer:
        async with SerialLink(peer.path, wait_banner_s=30) as link:
            assert link.banner_seen
            assert await link.read_line() == b""
            assert await link.read_line() == b"Grbl 1.1h ['$' for help]"
            await link.send_line("$I")
            assert [await link.read_line() for _ in range(3)] == [
                b"[VER:1.1h.20190830:]",
                b"[OPT:V,15,128]",
                b"ok",
            ]
        assert peer.grbl.received_lines == [b"$I"]


async def test_open_without_banner_returns_after_the_wait() -> None:
    """A controller that prints no banner and answers no `?` still opens after the wait; the
    handshake decides later."""
    with PtyPeer(ScriptedGrbl(answer_status=False), banner_on_open=False) as peer:
        async with SerialLink(peer.path, wait_banner_s=0.2) as link:
            assert not link.banner_seen
            await link.send_line("")
            assert await link.read_line() == b"ok"


async def test_open_without_reset_asks_status_and_returns_at_once() -> None:
    """A controller that does not reset on open (grblHAL, a board without the DTR reset) prints
    no banner: open() asks `?` and returns on its report instead of waiting for a banner."""
    with PtyPeer(banner_on_open=False) as peer:
        start_s = time.monotonic()
        async with SerialLink(peer.path, wait_banner_s=5) as link:
            opened_s = time.monotonic() - start_s
            assert not link.banner_seen
            assert isinstance(parse_response(await link.read_line()), StatusReport)
        assert opened_s < 1.0
        assert peer.grbl.received_realtime == [ord("?")]
        assert peer.grbl.received_lines == []


async def test_open_waits_for_a_slow_boot_sending_only_status_queries() -> None:
    """An Arduino's bootloader holds the banner back after the DTR reset: open() waits for it
    and keeps it, and all it sent meanwhile is `?` (nothing a restarting controller would run)."""
    with PtyPeer(boot_s=0.8) as peer:
        async with SerialLink(peer.path, wait_banner_s=5) as link:
            assert link.banner_seen
            assert await link.read_line() == b""
            assert await link.read_line() == b"Grbl 1.1h ['$' for help]"
        assert len(peer.swallowed) >= 2
        assert set(peer.swallowed) == {ord("?")}
        assert peer.grbl.received_lines == []


async def test_line_goes_out_with_exactly_one_newline(raw_pty: RawPty) -> None:
    """send_line appends one `\\n`, nothing else, in order."""
    async with SerialLink(raw_pty.path, wait_banner_s=0) as link:
        await link.send_line("$J=G91X1F100")
        await link.send_line("")
        await link.send_line("G4P0")
        expected = b"$J=G91X1F100\n\nG4P0\n"
        assert await raw_pty.read_at_least(len(expected)) == expected


@pytest.mark.parametrize(
    ("chunks", "expected"),
    [
        ([b"o", b"k\r", b"\nerror:9\r\n"], [b"ok", b"error:9"]),
        ([b"<Idle|MPos:0.000,0.000", b",0.000|FS:0,0>\r\n"],
         [b"<Idle|MPos:0.000,0.000,0.000|FS:0,0>"]),
        ([b"ok\nok\rok\r\n"], [b"ok", b"ok", b"ok"]),
        ([b"".join(b"$%d=1\r\n" % n for n in range(300))], [b"$%d=1" % n for n in range(300)]),
    ],
)  # fmt: skip
async def test_lines_arrive_whole_however_the_bytes_come(
    raw_pty: RawPty, chunks: list[bytes], expected: list[bytes]
) -> None:
    """Split lines, mixed EOLs and bursts all come out as whole lines, in order."""
    async with SerialLink(raw_pty.path, wait_banner_s=0) as link:
        for chunk in chunks:
            raw_pty.write(chunk)
            await asyncio.sleep(0.01)
        assert [await link.read_line() for _ in expected] == expected


async def test_realtime_byte_overtakes_queued_lines(raw_pty: RawPty) -> None:
    """With the port stalled and lines queued, a realtime byte goes out ahead of them."""
    lines = [f"G1X{n:05d}" + "Y1" * 40 for n in range(2000)]
    async with SerialLink(raw_pty.path, wait_banner_s=0) as link:

        async def send_all() -> None:
            for line in lines:
                await link.send_line(line)

        sender = asyncio.create_task(send_all())
        # Nobody reads the master yet, so the pty fills and the link has to hold lines back.
        while link.queued_bytes < 16 * 1024:  # noqa: ASYNC110 (no event exposes the queue level)
            await asyncio.sleep(0.005)
        held_back = link.queued_bytes
        link.send_realtime(b"\x85")
        stream = b"".join(line.encode() + b"\n" for line in lines)
        received = await raw_pty.read_at_least(len(stream) + 1)
        await sender
    position = received.index(b"\x85")
    assert position < len(stream) - held_back + len(lines[0]) + 1
    # It lands between two lines, and nothing was lost or reordered.
    assert received[position - 1 : position] == b"\n"
    assert received[:position] + received[position + 1 :] == stream


async def test_corked_lines_and_bytes_go_out_together_at_uncork(raw_pty: RawPty) -> None:
    """cork(): nothing is written until uncork(), then all at once, the realtime byte first."""
    async with SerialLink(raw_pty.path, wait_banner_s=0) as link:
        link.cork()
        assert link.send_line_nowait("$J=G91X0.875F5000")
        link.send_realtime(b"?")
        await asyncio.sleep(0.05)
        with pytest.raises(BlockingIOError):
            os.read(raw_pty.master, 100)
        link.uncork()
        expected = b"?$J=G91X0.875F5000\n"
        assert await raw_pty.read_at_least(len(expected)) == expected


async def test_realtime_byte_goes_out_at_once_when_idle(raw_pty: RawPty) -> None:
    """With nothing queued, a realtime byte is written immediately."""
    async with SerialLink(raw_pty.path, wait_banner_s=0) as link:
        link.send_realtime(b"?")
        assert link.queued_bytes == 0
        assert await raw_pty.read_at_least(1) == b"?"


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("G0X1\nG0X2", "end-of-line"),
        ("G0X1\r", "end-of-line"),
        ("$J=G91X1F100!", "realtime"),
        ("(why?)", "realtime"),
        ("G0X1\x18", "printable ASCII"),
        ("G0X1°", "printable ASCII"),
    ],
)
async def test_bad_lines_are_refused_and_nothing_is_sent(
    raw_pty: RawPty, text: str, match: str
) -> None:
    """A line Grbl would misread raises RefusedError before any byte leaves."""
    async with SerialLink(raw_pty.path, wait_banner_s=0) as link:
        with pytest.raises(RefusedError, match=match):
            await link.send_line(text)
        await link.send_line("ok-marker")
        assert await raw_pty.read_at_least(10) == b"ok-marker\n"


@pytest.mark.parametrize("byte", [b"", b"??", b"a", b"\n", b"$"])
async def test_bad_realtime_bytes_are_refused(raw_pty: RawPty, byte: bytes) -> None:
    """Only one realtime command byte at a time is accepted."""
    async with SerialLink(raw_pty.path, wait_banner_s=0) as link:
        with pytest.raises(RefusedError):
            link.send_realtime(byte)


async def test_peer_vanishing_mid_read_raises_promptly(raw_pty: RawPty) -> None:
    """A reader waiting when the device goes away gets a LinkError, not a hang."""
    async with SerialLink(raw_pty.path, wait_banner_s=0) as link:
        reader = asyncio.create_task(link.read_line())
        await asyncio.sleep(0.05)
        assert not reader.done()
        raw_pty.vanish()
        with pytest.raises(LinkError, match="lost"):
            await reader
        with pytest.raises(LinkError, match="lost"):
            await link.send_line("G4P0")
        with pytest.raises(LinkError, match="lost"):
            await link.read_line()


async def test_lines_received_before_the_peer_vanished_are_still_read(raw_pty: RawPty) -> None:
    """Lines already in are delivered first, then the LinkError."""
    async with SerialLink(raw_pty.path, wait_banner_s=0) as link:
        raw_pty.write(b"ok\r\nALARM:1\r\n")
        await asyncio.sleep(0.05)
        raw_pty.vanish()
        assert await link.read_line() == b"ok"
        assert await link.read_line() == b"ALARM:1"
        with pytest.raises(LinkError):
            await link.read_line()


async def test_close_is_idempotent_and_wakes_a_reader(raw_pty: RawPty) -> None:
    """close() twice is fine, a waiting reader gets LinkError, later calls too."""
    link = SerialLink(raw_pty.path, wait_banner_s=0)
    await link.open()
    reader = asyncio.create_task(link.read_line())
    await asyncio.sleep(0.01)
    await link.close()
    await link.close()
    with pytest.raises(LinkError, match="closed"):
        await reader
    with pytest.raises(LinkError, match="closed"):
        await link.send_line("G4P0")
    with pytest.raises(LinkError, match="closed"):
        link.send_realtime(b"?")


async def test_unopened_link_refuses_to_send() -> None:
    """Sending before open() is a LinkError saying so."""
    link = SerialLink("/dev/ttyUSB9")
    with pytest.raises(LinkError, match="not open"):
        await link.send_line("G4P0")


def test_describe() -> None:
    """describe() names the port and the speed."""
    assert SerialLink("/dev/ttyUSB0", 250000).describe() == "/dev/ttyUSB0 at 250000 baud"


async def test_missing_device(tmp_path: Path) -> None:
    """A path that does not exist: one sentence saying so and what to check."""
    with pytest.raises(LinkError, match=r"no serial port at .*ttyNOPE.*plugged in"):
        await SerialLink(str(tmp_path / "ttyNOPE")).open()


async def test_regular_file_is_not_a_port(tmp_path: Path) -> None:
    """A regular file is refused as not a serial port."""
    path = tmp_path / "notes.txt"
    path.write_text("hello")
    with pytest.raises(LinkError, match="is not a serial port"):
        await SerialLink(str(path)).open()


async def test_device_that_is_not_a_tty() -> None:
    """A character device that is not a terminal (/dev/null) is refused clearly."""
    with pytest.raises(LinkError, match="/dev/null is not a serial port"):
        await SerialLink("/dev/null").open()


async def test_port_in_use(raw_pty: RawPty) -> None:
    """A second opener of the same port is told another program has it."""
    async with SerialLink(raw_pty.path, wait_banner_s=0):
        with pytest.raises(LinkError, match="in use by another program"):
            await SerialLink(raw_pty.path, wait_banner_s=0).open()


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores file permissions")
async def test_permission_denied(raw_pty: RawPty) -> None:
    """A port the user may not open names the group fix."""
    os.chmod(raw_pty.path, 0)
    with pytest.raises(LinkError, match=r"permission denied.*dialout"):
        await SerialLink(raw_pty.path).open()


@pytest.mark.parametrize("baud", [0, -9600])
async def test_bad_baud(raw_pty: RawPty, baud: int) -> None:
    """A baud rate that is not positive is refused before opening."""
    with pytest.raises(LinkError, match="not positive"):
        await SerialLink(raw_pty.path, baud).open()


async def test_status_report_answer_from_scripted_peer() -> None:
    """The realtime `?` reaches the peer and its report comes back as one line."""
    with PtyPeer(ScriptedGrbl(state="Alarm"), banner_on_open=False) as peer:
        async with SerialLink(peer.path, wait_banner_s=0) as link:
            link.send_realtime(b"?")
            assert (
                await link.read_line()
                == b"<Alarm|MPos:0.000,0.000,0.000|FS:0,0|WCO:0.000,0.000,0.000>"
            )
