"""The real host against the in-process simulator on a virtual clock, with a synchronous face.

Nothing here drives the controller: `Host` (host.py) does, exactly as in the product, on an event
loop whose clock jumps ahead whenever nothing is ready (vclock.py). This module only owns that
loop and lets a test, the benchmark or `jog --replay` say "run to time t" or "press the stick now"
from ordinary synchronous code. A minute of jogging takes well under a minute of wall time, and two
runs of one script are identical.
"""

from __future__ import annotations

import asyncio
import weakref
from collections.abc import Awaitable, Callable, Iterable, Sequence
from typing import TypeVar

from smoothjog.core.engine import EngineEvent, Jogger, JogTuning
from smoothjog.core.intents import Intent
from smoothjog.core.machine import KeepOut, MachineModel
from smoothjog.core.responses import Response
from smoothjog.host import EngineFactory, Host, JogEngine
from smoothjog.inputs.replay import TimedIntent
from smoothjog.links.sim import SimLink
from smoothjog.sim.rig import SimRig
from smoothjog.vclock import VirtualClockLoop, sleep_until

T = TypeVar("T")


def _shut(loop: VirtualClockLoop) -> None:
    """Cancel what still runs on loop and close it (also as a finaliser, if nobody closed it)."""
    if loop.is_closed() or loop.is_running():
        return
    tasks = asyncio.all_tasks(loop)
    for task in tasks:
        task.cancel()
    if tasks:
        loop.run_until_complete(asyncio.gather(*tasks, return_exceptions=True))
    loop.close()


class VirtualHost:
    """A Host over a SimLink to rig, on its own virtual-clock loop; call handshake() first."""

    def __init__(
        self,
        rig: SimRig,
        *,
        tuning: JogTuning | None = None,
        keepouts: Sequence[KeepOut] = (),
        engine_factory: EngineFactory | None = None,
        on_event: Callable[[EngineEvent], None] | None = None,
    ) -> None:
        """Prepare the loop, the link and the host; nothing runs yet."""
        self.rig = rig
        self.loop = VirtualClockLoop(start_s=rig.now_s)
        self.link = SimLink(rig=rig)
        #: Every event the engine reported, oldest first (and also given to on_event).
        self.events: list[EngineEvent] = []

        def take_event(event: EngineEvent) -> None:
            self.events.append(event)
            if on_event is not None:
                on_event(event)

        self.host = Host(
            self.link,
            tuning=tuning,
            keepouts=keepouts,
            engine_factory=engine_factory,
            on_event=take_event,
        )
        #: Every line the host received, with its arrival time.
        self.received: list[tuple[float, Response]] = []
        self.host.add_line_listener(lambda resp, now_s: self.received.append((now_s, resp)))
        self._finalizer = weakref.finalize(self, _shut, self.loop)

    def _run(self, aw: Awaitable[T]) -> T:
        return self.loop.run_until_complete(aw)

    # ----------------------------------------------------------------- set-up and end
    def handshake(self, timeout_s: float = 5.0) -> MachineModel:
        """Open the link and start the host: the real connect handshake, then the engine."""
        self.host.handshake_timeout_s = timeout_s

        async def start() -> MachineModel:
            await self.link.open()
            return await self.host.start()

        return self._run(start())

    def close(self) -> None:
        """Stop the host (with its stop handshake unless it was killed) and close the loop."""
        if self.loop.is_closed():
            return
        if self.host.driver is not None and not self.host.abandoned:
            self._run(self.host.close())
        self._finalizer()

    def __enter__(self) -> VirtualHost:
        """Use as a context manager that closes the loop."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close the loop."""
        self.close()

    # ----------------------------------------------------------------- observation
    @property
    def now_s(self) -> float:
        """The virtual time."""
        return self.loop.time()

    @property
    def model(self) -> MachineModel:
        """The host's machine model."""
        return self.host.model

    @property
    def engine(self) -> Jogger | None:
        """smoothjog's engine, when the host drives it (None for a reference method)."""
        return self.host.engine

    @property
    def driver(self) -> JogEngine | None:
        """Whatever engine the host drives."""
        return self.host.driver

    def idle(self) -> bool:
        """True when the engine has nothing to do and the controller is at rest."""
        return self.host.abandoned or self.host.at_rest()

    # ----------------------------------------------------------------- running
    def set_intent(self, intent: Intent) -> None:
        """Give the host an intent now (nothing, once the host was killed)."""
        if not self.host.abandoned:
            self.host.set_intent(intent)

    def kill(self) -> None:
        """The host dies now: it sends and reads nothing more; the controller runs on."""
        self.host.abandon()

    def run_until(self, until_s: float) -> None:
        """Let virtual time pass to until_s, the host reacting to everything on the way."""
        self._run(sleep_until(until_s))

    def run_script(self, script: Iterable[TimedIntent], *, settle_s: float = 5.0) -> None:
        """Apply timed intents (times relative to now), then run until idle or settle_s passes."""
        t0 = self.now_s
        for item in script:
            self.run_until(t0 + item.t_s)
            self.set_intent(item.intent)
        self.run_until_idle(settle_s)

    def run_until_idle(self, timeout_s: float) -> bool:
        """Run until idle (True) or timeout_s of virtual time passes (False)."""
        end_s = self.now_s + timeout_s
        while self.now_s < end_s:
            self.run_until(min(self.now_s + 0.02, end_s))
            if self.idle():
                return True
        return self.idle()

    def query_line(self, line: str, timeout_s: float = 2.0) -> list[Response]:
        """Send a console line (e.g. `$G`) through the ledger; what came back with its reply."""
        return self._run(self.host.query(line, timeout_s=timeout_s))
