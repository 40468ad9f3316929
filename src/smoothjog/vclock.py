"""An asyncio event loop on a virtual clock: the product's own tasks, run faster than real time.

The loop is a normal selector event loop whose `time()` is a number that only moves when the loop
has nothing ready to run: then it jumps straight to the next scheduled timer instead of sleeping.
Every `asyncio.sleep`, `asyncio.timeout` and `call_at` therefore behaves as in real time, only no
wall time passes, and two runs of the same program make the same calls in the same order.

This is how the tests and the benchmark drive the real host (host.py) against the in-process
simulator: the code they measure is the code users run, only the clock differs.
"""

from __future__ import annotations

import asyncio
import selectors
from collections.abc import Mapping
from typing import Any

from smoothjog.core.errors import SmoothjogError


class VirtualTimeStallError(SmoothjogError):
    """The loop waits for nothing it can reach: no timer is scheduled and nothing is ready."""


class _JumpingSelector(selectors.BaseSelector):
    """A real selector that answers "nothing happened" by moving the virtual clock on."""

    def __init__(self) -> None:
        self._real = selectors.DefaultSelector()
        self.clock: VirtualClockLoop | None = None

    def register(
        self, fileobj: Any, events: int, data: Any = None
    ) -> selectors.SelectorKey:  # pragma: no cover - delegation
        return self._real.register(fileobj, events, data)

    def unregister(self, fileobj: Any) -> selectors.SelectorKey:  # pragma: no cover
        return self._real.unregister(fileobj)

    def modify(
        self, fileobj: Any, events: int, data: Any = None
    ) -> selectors.SelectorKey:  # pragma: no cover
        return self._real.modify(fileobj, events, data)

    def get_map(self) -> Mapping[Any, selectors.SelectorKey]:
        return self._real.get_map()

    def close(self) -> None:
        self._real.close()

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        # Real file descriptors (the loop's own wake-up pipe) are looked at without waiting.
        ready = self._real.select(0)
        if ready or timeout == 0:
            return ready
        if timeout is None:
            raise VirtualTimeStallError(
                "virtual time stalled: every task waits and no timer is scheduled"
            )
        assert self.clock is not None
        self.clock.advance(timeout)
        return []


class VirtualClockLoop(asyncio.SelectorEventLoop):
    """A selector event loop whose clock jumps to the next timer whenever the loop is idle."""

    def __init__(self, start_s: float = 0.0) -> None:
        """A loop whose time() starts at start_s."""
        self._virtual_now_s = start_s
        selector = _JumpingSelector()
        super().__init__(selector=selector)
        selector.clock = self

    def time(self) -> float:
        """The virtual time in seconds."""
        return self._virtual_now_s

    def advance(self, dt_s: float) -> None:
        """Move the clock dt_s on (the loop does this itself when it is idle)."""
        if dt_s > 0.0:
            self._virtual_now_s += dt_s


async def sleep_until(when_s: float) -> None:
    """Sleep until the running loop's clock reads when_s (at once if it already does)."""
    loop = asyncio.get_running_loop()
    delay_s = when_s - loop.time()
    if delay_s > 0.0:
        await asyncio.sleep(delay_s)
    else:
        await asyncio.sleep(0)
