"""Raw byte peers for link tests: the master side of a pseudo-terminal, read from asyncio."""

from __future__ import annotations

import asyncio
import contextlib
import os
from collections.abc import Iterator

import pytest


def _resolve(future: asyncio.Future[None]) -> None:
    """Mark future done (once)."""
    if not future.done():
        future.set_result(None)


class RawPty:
    """A pseudo-terminal whose master side the test drives byte by byte."""

    def __init__(self) -> None:
        """Create the pair; the slave stays open here so the port never reports a hang-up."""
        self.master, self._slave = os.openpty()
        self.path = os.ttyname(self._slave)
        os.set_blocking(self.master, False)
        self.received = bytearray()

    def write(self, data: bytes) -> None:
        """Send bytes to the link under test."""
        os.write(self.master, data)

    async def read_at_least(self, count: int) -> bytes:
        """Collect what the link sent until `count` bytes in total have arrived."""
        loop = asyncio.get_running_loop()
        while len(self.received) < count:
            ready: asyncio.Future[None] = loop.create_future()
            loop.add_reader(self.master, _resolve, ready)
            try:
                await ready
            finally:
                loop.remove_reader(self.master)
            with contextlib.suppress(BlockingIOError):
                self.received += os.read(self.master, 65536)
        return bytes(self.received)

    def vanish(self) -> None:
        """Close the master side, as when a USB adapter is pulled."""
        os.close(self.master)
        self.master = -1

    def close(self) -> None:
        """Release both sides."""
        for fd in (self.master, self._slave):
            if fd >= 0:
                os.close(fd)


@pytest.fixture
def raw_pty() -> Iterator[RawPty]:
    """A fresh pseudo-terminal for one test."""
    pty = RawPty()
    yield pty
    pty.close()
