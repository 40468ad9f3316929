"""Reading a /dev/input/eventN node with python-evdev, on the event loop, frame by frame.

The node is grabbed (EVIOCGRAB) when it can be, so a keypad used as a pendant does not also
type into the console of a headless Raspberry Pi. Events are assembled into frames
(inputs/frames.py); after SYN_DROPPED the device is asked for its whole state (EVIOCGABS per
axis, EVIOCGKEY) so the decoder starts again from the truth. On unplug, read() fails with
ENODEV (a Bluetooth pad going to sleep does the same before udev reports the removal): the fd
is unregistered from the loop at once and the loss reported.

Anything with `fileno()`, `read()` (a batch of evdev.InputEvent, BlockingIOError when none),
`absinfo(code)`, `active_keys()`, `capabilities(absinfo=False)`, `name`, `path`, `info` and
`grab()`/`close()` can be read, which is how the tests run it without a kernel device.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
from collections.abc import AsyncIterator, Iterable
from typing import Any

from smoothjog.inputs.device import (
    EV_ABS,
    EV_KEY,
    EV_REL,
    AbsRange,
    DeviceInfo,
    EvdevEvent,
    EvdevFrame,
)
from smoothjog.inputs.devinput import read_loss
from smoothjog.inputs.frames import FrameAssembler


def evdev_info(device: Any) -> DeviceInfo:
    """Name, ids and capabilities of an open evdev device (python-evdev InputDevice)."""
    caps = device.capabilities(absinfo=True)
    absinfo: dict[int, AbsRange] = {}
    for entry in caps.get(EV_ABS, []):
        code, info = entry
        absinfo[int(code)] = AbsRange(info.value, info.min, info.max, info.fuzz, info.flat)
    ident = device.info
    return DeviceInfo(
        name=str(device.name),
        path=str(device.path),
        vendor=int(ident.vendor),
        product=int(ident.product),
        bus=int(ident.bustype),
        absinfo=absinfo,
        keys=frozenset(int(c) for c in caps.get(EV_KEY, [])),
        rels=frozenset(int(c) for c in caps.get(EV_REL, [])),
    )


def open_evdev(path: str) -> Any:
    """Open an event node with python-evdev; raises OSError (EACCES, ENOENT, ENODEV)."""
    import evdev  # noqa: PLC0415 -- Linux only; nothing else in smoothjog needs it

    return evdev.InputDevice(path)


class EvdevSource:
    """Frames from an evdev device, read on the loop."""

    def __init__(self, device: Any, *, grab: bool = True) -> None:
        """Read device (owned from now on); grab it unless grab is False."""
        self.device = device
        self.info = evdev_info(device)
        self.grabbed = False
        if grab:
            try:
                device.grab()
                self.grabbed = True
            except OSError:
                # Another program grabbed it first (spacenavd, a desktop): its events go there,
                # not here. Said by whoever opened it (grabbed stays False).
                self.grabbed = False
        self._closed = False

    @classmethod
    def open(cls, path: str, *, grab: bool = True) -> EvdevSource:
        """Open and grab an event node."""
        return cls(open_evdev(path), grab=grab)

    def _snapshot(self) -> Iterable[EvdevEvent]:
        state = [
            EvdevEvent(EV_ABS, code, int(self.device.absinfo(code).value))
            for code in sorted(self.info.absinfo)
        ]
        state += [EvdevEvent(EV_KEY, int(code), 1) for code in self.device.active_keys()]
        return state

    async def items(self) -> AsyncIterator[EvdevFrame]:
        """Each frame as its SYN_REPORT arrives; raises DeviceLost when the device goes."""
        loop = asyncio.get_running_loop()
        ready = asyncio.Event()
        fd = self.device.fileno()
        assembler = FrameAssembler(self._snapshot)
        loop.add_reader(fd, ready.set)
        try:
            while True:
                await ready.wait()
                ready.clear()
                try:
                    events = list(self.device.read())
                except BlockingIOError:
                    continue
                except OSError as exc:
                    raise read_loss(exc, "unplugged or asleep") from None
                now = loop.time()
                for ev in events:
                    # The kernel stamps every event of a frame alike: its own time keeps a frame
                    # split across two reads whole; the decoder gets the loop's time.
                    t_kernel = ev.sec + ev.usec / 1e6
                    for frame in assembler.feed(t_kernel, ev.type, ev.code, ev.value):
                        yield EvdevFrame(now, frame.events, frame.resync)
        finally:
            # Always unregister: a dead fd left on the loop is polled forever at full CPU.
            loop.remove_reader(fd)

    def write(self, data: bytes) -> None:
        """evdev devices here have no display."""
        raise OSError(errno.ENOTSUP, "an evdev device has no display")

    def close(self) -> None:
        """Ungrab and close (twice is harmless)."""
        if self._closed:
            return
        self._closed = True
        if self.grabbed:
            with contextlib.suppress(OSError):
                self.device.ungrab()
        with contextlib.suppress(OSError):
            self.device.close()
