"""A Link to the in-process simulator, running in real time on the event loop's clock."""

from __future__ import annotations

import asyncio
import contextlib

from smoothjog.core.errors import LinkError
from smoothjog.links.base import LineInbox, Link
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.rig import LinkModel, SimRig
from smoothjog.sim.serve import RealtimeSim


class SimLink(Link):
    """The embedded simulated controller behind a modelled serial wire (115200 baud default)."""

    def __init__(
        self,
        firmware: GrblFirmware | None = None,
        link: LinkModel | None = None,
        *,
        rig: SimRig | None = None,
    ) -> None:
        """Wrap a firmware (default: Grbl 1.1h with default settings), or a ready rig.

        open() starts it on the event loop's clock (a virtual one in tests and the benchmark).
        """
        if rig is None:
            rig = SimRig(firmware if firmware is not None else GrblFirmware(), link)
        self.rig = rig
        self.firmware = rig.firmware
        self._inbox = LineInbox()
        self._sim = RealtimeSim(self.rig, self._on_line)
        self._task: asyncio.Task[None] | None = None
        self._closed = False

    def describe(self) -> str:
        """Which simulated controller this is."""
        return (
            f"simulated {self.firmware.profile.name} ({self.firmware.machine.name})"
            f" at {self.rig.link.baud} baud"
        )

    async def open(self) -> None:
        """Start the simulator; the banner it printed at power-up is the first line read."""
        if self._closed:
            raise LinkError(f"{self.describe()} was closed; make a new SimLink")
        if self._task is None:
            self._task = asyncio.create_task(self._sim.run())
            await asyncio.sleep(0)

    async def read_line(self) -> bytes:
        """The next line the controller sent; LinkError once closed."""
        return await self._inbox.get()

    async def close(self) -> None:
        """Stop the simulator; readers get LinkError."""
        self._closed = True
        self._inbox.close(LinkError(f"{self.describe()} is closed"))
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None

    async def _write_line(self, data: bytes) -> None:
        """Put the line on the modelled wire now."""
        self._check_open()
        self._sim.send(data)

    def _write_line_nowait(self, data: bytes) -> bool:
        """Put the line on the modelled wire now (it never waits)."""
        self._check_open()
        self._sim.send(data)
        return True

    def byte_time_s(self) -> float:
        """The modelled wire's byte time."""
        return self.rig.link.byte_time_s

    def _line_inbox(self) -> LineInbox:
        return self._inbox

    def _write_realtime(self, byte: bytes) -> None:
        """Put the byte on the wire now; no line waits in this link, so nothing is overtaken."""
        self._check_open()
        self._sim.send(byte)

    def _check_open(self) -> None:
        if self._task is None or self._closed:
            raise LinkError(f"{self.describe()} is not open; call open() first")

    def _on_line(self, line: bytes) -> None:
        self._inbox.feed(line + b"\n")
