"""The device runner and the live readers, against stand-ins for the kernel's nodes.

No /dev/input, /dev/hidraw, uinput or uhid exists on these machines, so the real reading code
runs against faithful stand-ins: a SOCK_SEQPACKET socketpair for hidraw (one message per read,
EOF when the other end closes, as hidraw gives one report per read) and an object with
python-evdev's InputDevice methods yielding real `evdev.InputEvent`s, then ENODEV.
"""

from __future__ import annotations

import asyncio
import errno
import socket
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import evdev
import pytest

from smoothjog.authority.arbiter import Arbiter
from smoothjog.core.intents import ContinuousIntent, Intent, StopIntent
from smoothjog.core.options import Table
from smoothjog.inputs import hidraw_source
from smoothjog.inputs.device import (
    EV_ABS,
    EV_KEY,
    EV_SYN,
    SYN_DROPPED,
    SYN_REPORT,
    Action,
    Decoder,
    DeviceCommand,
    DeviceInfo,
    DeviceItem,
    DeviceNotice,
    EvdevFrame,
    HidReport,
)
from smoothjog.inputs.devinput import DeviceInput, DeviceLost, RecordedSource
from smoothjog.inputs.evdev_source import EvdevSource
from smoothjog.inputs.hidraw_source import HidrawSource

JOG = ContinuousIntent({"X": 1.0}, 0.5)
NEUTRAL = ContinuousIntent({"X": 0.0}, 0.5)


class ByteDecoder(Decoder):
    """A test decoder: 1 = hold +X, 0 = neutral, 9 = a command, 7 = a notice; a deadline."""

    name = "test"
    kind = "gamepad"
    transport = "hidraw"

    def __init__(self, deadline_after_s: float | None = None) -> None:
        super().__init__(DeviceInfo("test"), Table({}, "t", "<t>"), ("X", "Y", "Z"))
        self.holding = False
        self.items: list[DeviceItem] = []
        self.ticks: list[float] = []
        self.deadline_after_s = deadline_after_s
        self._deadline: float | None = None

    def feed(self, item: DeviceItem) -> list[Action]:
        self.items.append(item)
        if self.deadline_after_s is not None:
            self._deadline = item.t_s + self.deadline_after_s
        data = item.data if isinstance(item, HidReport) else b""
        if data[:1] == b"\x01":
            self.holding = True
            return [JOG]
        if data[:1] == b"\x00":
            self.holding = False
            return [NEUTRAL]
        if data[:1] == b"\x09":
            return [DeviceCommand("home")]
        if data[:1] == b"\x07":
            return [DeviceNotice("hello")]
        return []

    def deadline_s(self) -> float | None:
        return self._deadline

    def tick(self, now_s: float) -> list[Action]:
        self.ticks.append(now_s)
        self._deadline = None
        if self.holding:
            self.holding = False
            return [StopIntent()]
        return []

    @property
    def moving(self) -> bool:
        return self.holding

    def lost(self) -> list[Action]:
        self.holding = False
        return [DeviceNotice("gone")]


@dataclass
class Sink:
    intents: list[tuple[float, Intent]] = field(default_factory=list)

    def set_intent(self, intent: Intent) -> None:
        self.intents.append((asyncio.get_running_loop().time(), intent))

    def can_jog(self) -> tuple[bool, str | None]:
        return True, None


@pytest.fixture
def pair() -> Iterator[tuple[socket.socket, socket.socket]]:
    a, b = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    yield a, b
    for s in (a, b):
        s.close()


async def test_hidraw_reports_arrive_one_per_read_and_the_unplug_stops_the_jog(
    pair: tuple[socket.socket, socket.socket],
) -> None:
    ours, device = pair
    decoder = ByteDecoder()
    source = HidrawSource(ours.detach(), DeviceInfo("fake hidraw"), feature_ioctl=False)
    sink = Sink()
    arbiter = Arbiter(sink)
    told: list[str] = []
    dev = DeviceInput(decoder, source, notices=told.append)
    task = asyncio.create_task(arbiter.run_input(dev))
    device.send(b"\x01\xaa")  # two reports sent back to back stay two reports
    device.send(b"\x05\xbb\xcc")
    await asyncio.sleep(0.05)
    assert [i.data for i in decoder.items if isinstance(i, HidReport)] == [
        b"\x01\xaa",
        b"\x05\xbb\xcc",
    ]
    assert [i for _, i in sink.intents] == [JOG]
    unplugged_at = asyncio.get_running_loop().time()
    device.close()  # the node goes away: EOF on the stand-in, EIO on real hidraw
    await asyncio.wait_for(task, 1.0)
    assert [i for _, i in sink.intents] == [JOG, StopIntent()]
    assert sink.intents[-1][0] - unplugged_at < 0.05
    assert "closed" in (dev.ended or "")
    assert any("gone" in t for t in told)


async def test_hidraw_eio_is_a_loss_and_the_fd_leaves_the_loop(
    monkeypatch: pytest.MonkeyPatch, pair: tuple[socket.socket, socket.socket]
) -> None:
    ours, device = pair
    fd = ours.detach()
    real_read = hidraw_source.os.read
    calls = {"n": 0}

    def read(f: int, n: int) -> bytes:
        if f == fd:
            calls["n"] += 1
            if calls["n"] > 1:
                raise OSError(errno.EIO, "Input/output error")
        return real_read(f, n)

    monkeypatch.setattr(hidraw_source.os, "read", read)
    source = HidrawSource(fd, DeviceInfo("fake"), feature_ioctl=False)
    loop = asyncio.get_running_loop()
    removed: list[int] = []
    original_remove = loop.remove_reader

    def remove_reader(f: Any) -> bool:
        removed.append(f)
        return original_remove(f)

    monkeypatch.setattr(loop, "remove_reader", remove_reader)
    sink = Sink()
    dev = DeviceInput(ByteDecoder(), source)
    task = asyncio.create_task(Arbiter(sink).run_input(dev))
    device.send(b"\x01")
    device.send(b"\x01")
    await asyncio.wait_for(task, 1.0)
    assert "unplugged" in (dev.ended or "")
    assert [i for _, i in sink.intents] == [JOG, StopIntent()]
    assert fd in removed  # a dead fd left registered would spin the loop


def test_the_hidraw_ioctl_numbers_are_the_kernels() -> None:
    assert hidraw_source.HIDIOCGRAWINFO == 0x80084803
    assert hidraw_source.hidiocsfeature(8) == 0xC0084806
    assert hidraw_source.hidiocgrawname(256) == 0x81004804


async def test_a_decoder_deadline_fires_while_the_device_is_silent() -> None:
    # A watchdog must fire even when nothing more is ever read.
    decoder = ByteDecoder(deadline_after_s=0.05)
    sink = Sink()
    never = asyncio.Event()

    class Silent:
        info = DeviceInfo("silent")

        async def items(self) -> Any:
            yield HidReport(asyncio.get_running_loop().time(), b"\x01")
            await never.wait()

        def write(self, data: bytes) -> None:
            raise OSError

        def close(self) -> None:
            pass

    dev = DeviceInput(decoder, Silent())
    task = asyncio.create_task(Arbiter(sink).run_input(dev))
    await asyncio.sleep(0.2)
    assert [i for _, i in sink.intents] == [JOG, StopIntent()]
    assert len(decoder.ticks) == 1
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task


async def test_a_recording_plays_on_time_and_commands_run_beside_the_jog() -> None:
    decoder = ByteDecoder()
    sink = Sink()
    ran: list[str] = []

    async def commands(command: DeviceCommand, submit: Any) -> str:
        ran.append(command.name)
        return "homed"

    told: list[str] = []
    items = [HidReport(0.0, b"\x09"), HidReport(0.1, b"\x01"), HidReport(0.3, b"\x00")]
    dev = DeviceInput(
        decoder, RecordedSource(DeviceInfo("rec"), items), commands=commands, notices=told.append
    )
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    await Arbiter(sink).run_input(dev)
    assert ran == ["home"]
    assert [i for _, i in sink.intents] == [JOG, NEUTRAL]
    assert sink.intents[0][0] - t0 == pytest.approx(0.1, abs=0.05)
    assert any("homed" in t for t in told)
    assert dev.ended == "the device's stream ended"


async def test_a_device_that_only_watches_takes_control_when_touched() -> None:
    sink = Sink()
    arbiter = Arbiter(sink)

    class Page:
        name = "page"
        kind = "web"
        lease_s = None

        async def run(self, handle: Any) -> None:
            await asyncio.Event().wait()

        def notice(self, notice: Any) -> None:
            pass

    page_task = asyncio.create_task(arbiter.run_input(Page()))  # type: ignore[arg-type]
    await asyncio.sleep(0)
    items = [HidReport(0.0, b"\x01"), HidReport(0.05, b"\x00")]
    dev = DeviceInput(ByteDecoder(), RecordedSource(DeviceInfo("rec"), items))
    await arbiter.run_input(dev)
    assert [i for _, i in sink.intents] == [JOG, NEUTRAL]
    page_task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await page_task


class FakeEvdevDevice:
    """python-evdev's InputDevice surface, yielding real InputEvents, then ENODEV."""

    def __init__(self, batches: list[list[evdev.InputEvent]]) -> None:
        self.rfd, self.wfd = socket.socketpair()
        self.batches = batches
        self.name = "Fake Pad"
        self.path = "/dev/input/event9"
        self.info = evdev.DeviceInfo(bustype=3, vendor=0x045E, product=0x028E, version=1)
        self.grabbed = False
        self.closed = False
        self.abs_values = {0: 0, 1: 0}
        # One byte per read keeps the fd readable exactly as long as there is something to read.
        self.wfd.send(b"x" * (len(batches) + 1))

    def fileno(self) -> int:
        return self.rfd.fileno()

    def read(self) -> Iterator[evdev.InputEvent]:
        self.rfd.recv(1)
        if not self.batches:
            raise OSError(errno.ENODEV, "No such device")
        return iter(self.batches.pop(0))

    def capabilities(self, absinfo: bool = True) -> dict[int, Any]:
        info = evdev.AbsInfo(0, -32768, 32767, 16, 128, 0)
        return {EV_ABS: [(0, info), (1, info)], EV_KEY: [304]}

    def absinfo(self, code: int) -> evdev.AbsInfo:
        return evdev.AbsInfo(self.abs_values[code], -32768, 32767, 16, 128, 0)

    def active_keys(self) -> list[int]:
        return [304]

    def grab(self) -> None:
        self.grabbed = True

    def ungrab(self) -> None:
        self.grabbed = False

    def close(self) -> None:
        self.closed = True
        self.rfd.close()
        self.wfd.close()


def _ev(t: float, type_: int, code: int, value: int) -> evdev.InputEvent:
    return evdev.InputEvent(int(t), round((t % 1) * 1e6), type_, code, value)


async def test_evdev_frames_resync_after_syn_dropped_and_enodev_ends_it() -> None:
    fake = FakeEvdevDevice(
        [
            [_ev(1.0, EV_ABS, 0, 20000), _ev(1.0, EV_SYN, SYN_REPORT, 0)],
            # A frame split over two reads stays one frame (same kernel time).
            [_ev(1.1, EV_ABS, 0, 30000)],
            [_ev(1.1, EV_ABS, 1, -5), _ev(1.1, EV_SYN, SYN_REPORT, 0)],
            [
                _ev(1.2, EV_SYN, SYN_DROPPED, 0),
                _ev(1.2, EV_ABS, 0, 1),
                _ev(1.2, EV_SYN, SYN_REPORT, 0),
            ],
        ]
    )
    fake.abs_values = {0: 123, 1: 456}
    source = EvdevSource(fake)
    assert fake.grabbed
    assert source.info.absinfo[0].min == -32768
    frames: list[EvdevFrame] = []

    async def collect() -> None:
        async for frame in source.items():
            frames.append(frame)

    with pytest.raises(DeviceLost, match="unplugged"):
        await asyncio.wait_for(collect(), 1.0)
    assert [f.events for f in frames] == [
        ((EV_ABS, 0, 20000),),
        ((EV_ABS, 0, 30000), (EV_ABS, 1, -5)),
        ((EV_ABS, 0, 123), (EV_ABS, 1, 456), (EV_KEY, 304, 1)),
    ]
    assert frames[2].resync
    source.close()
    assert fake.closed
    assert not fake.grabbed
