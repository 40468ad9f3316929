"""Reading a /dev/hidrawN node: one read() is one report, on the event loop, no HID library.

The kernel's hidraw driver queues whole reports and hands out one per read(); a numbered report
keeps its ID as the first byte. When the device is unplugged, read() fails with EIO (ENODEV
on some paths) and poll reports an error, so the fd is unregistered from the loop at once: a
dead fd left registered makes the loop spin at full CPU. Feature reports (the WHB04B's LCD) go
out through the HIDIOCSFEATURE ioctl, and the device's ids and name come from HIDIOCGRAWINFO
and HIDIOCGRAWNAME (numbers built as linux/hidraw.h builds them; a test pins them).

The same code reads one end of a SOCK_SEQPACKET socketpair, which keeps message boundaries as
hidraw keeps reports and gives b"" when the other end closes: that is how the tests run it.
"""

from __future__ import annotations

import asyncio
import errno
import fcntl
import os
import struct
from collections.abc import AsyncIterator
from typing import Final

from smoothjog.inputs.device import DeviceInfo, HidReport
from smoothjog.inputs.devinput import DeviceLost, read_loss

#: The largest report any supported device sends (the SpaceMouse's 13 bytes, the WHB04B's 8).
READ_SIZE: Final = 64

# ioctl numbers, _IOC(dir, 'H', nr, size) as in linux/hidraw.h.
_IOC_WRITE: Final = 1
_IOC_READ: Final = 2


def _ioc(direction: int, nr: int, size: int) -> int:
    return (direction << 30) | (size << 16) | (ord("H") << 8) | nr


HIDIOCGRAWINFO: Final = _ioc(_IOC_READ, 0x03, 8)


def hidiocgrawname(length: int) -> int:
    """HIDIOCGRAWNAME(len): read the device's name."""
    return _ioc(_IOC_READ, 0x04, length)


def hidiocsfeature(length: int) -> int:
    """HIDIOCSFEATURE(len): send a feature report whose first byte is its number."""
    return _ioc(_IOC_WRITE | _IOC_READ, 0x06, length)


def read_hidraw_info(fd: int, path: str) -> DeviceInfo:
    """The bus, ids and name of an open hidraw node."""
    raw = fcntl.ioctl(fd, HIDIOCGRAWINFO, bytes(8))
    bus, vendor, product = struct.unpack("<Ihh", raw)
    name_raw = fcntl.ioctl(fd, hidiocgrawname(256), bytes(256))
    name = name_raw.split(b"\0", 1)[0].decode("utf-8", "replace") or path
    return DeviceInfo(
        name=name, path=path, vendor=vendor & 0xFFFF, product=product & 0xFFFF, bus=bus
    )


class HidrawSource:
    """Reports from an open hidraw fd (or a SOCK_SEQPACKET stand-in), read on the loop."""

    def __init__(self, fd: int, info: DeviceInfo, *, feature_ioctl: bool = True) -> None:
        """Read fd (non-blocking, owned from now on); feature_ioctl False writes with write()."""
        self.info = info
        self._fd: int | None = fd
        self._feature_ioctl = feature_ioctl
        os.set_blocking(fd, False)

    @classmethod
    def open(cls, path: str, info: DeviceInfo | None = None) -> HidrawSource:
        """Open a /dev/hidrawN node; raises OSError (EACCES, ENOENT) as the kernel says."""
        try:
            fd = os.open(path, os.O_RDWR | os.O_NONBLOCK | os.O_CLOEXEC)
        except PermissionError:
            # Read-only is enough to jog; only a display needs write access.
            fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
        try:
            found = info if info is not None else read_hidraw_info(fd, path)
        except OSError:
            os.close(fd)
            raise
        return cls(fd, found)

    async def items(self) -> AsyncIterator[HidReport]:
        """Each report as it arrives; raises DeviceLost when the device goes."""
        loop = asyncio.get_running_loop()
        ready = asyncio.Event()
        fd = self._fd
        if fd is None:
            raise DeviceLost("the device was closed")
        loop.add_reader(fd, ready.set)
        try:
            while True:
                await ready.wait()
                ready.clear()
                while True:
                    try:
                        data = os.read(fd, READ_SIZE)
                    except BlockingIOError:
                        break
                    except OSError as exc:
                        raise read_loss(exc, "unplugged or switched off") from None
                    if not data:
                        raise DeviceLost("the device closed (end of file)")
                    yield HidReport(loop.time(), data)
        finally:
            # Always unregister: a dead fd left on the loop is polled forever at full CPU.
            loop.remove_reader(fd)

    def write(self, data: bytes) -> None:
        """Send a feature report (first byte = its number)."""
        if self._fd is None:
            raise OSError(errno.EBADF, "the device is closed")
        if self._feature_ioctl:
            fcntl.ioctl(self._fd, hidiocsfeature(len(data)), bytes(data))
        else:
            os.write(self._fd, bytes(data))

    def close(self) -> None:
        """Close the fd (twice is harmless)."""
        fd, self._fd = self._fd, None
        if fd is not None:
            os.close(fd)
