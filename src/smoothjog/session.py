"""The real-time driver: wires a link, the jog engine and an input with asyncio and the loop clock.

Two tasks run while a session is open. The reader turns every received line into a response for
the engine (and re-runs the connect handshake when a banner says the controller was reset). The
ticker calls `Jogger.poll` whenever a reply or an intent arrives, or the engine's deadline passes,
and writes what it returns: lines through the link (the engine already did the character
counting), realtime bytes straight away.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable, Mapping, Sequence

from smoothjog.core.errors import LinkError, SmoothjogError
from smoothjog.core.jogger import (
    ContinuousIntent,
    EngineEvent,
    EngineLimits,
    EngineView,
    Intent,
    Jogger,
    JogTuning,
    SendLine,
    StopIntent,
)
from smoothjog.core.machine import KeepOut, MachineModel
from smoothjog.core.responses import Banner, parse_response
from smoothjog.handshake import handshake
from smoothjog.links.base import Link

logger = logging.getLogger(__name__)


class JogSession:
    """One controller connection driven by the jog engine in real time."""

    def __init__(
        self,
        link: Link,
        *,
        tuning: JogTuning | None = None,
        keepouts: Sequence[KeepOut] = (),
        handshake_timeout_s: float = 5.0,
        on_event: Callable[[EngineEvent], None] | None = None,
    ) -> None:
        """Prepare a session over an opened link; call start() next."""
        self.link = link
        self.tuning = tuning or JogTuning()
        self.keepouts = tuple(keepouts)
        self.handshake_timeout_s = handshake_timeout_s
        self.on_event = on_event
        self.model = MachineModel()
        self.engine: Jogger | None = None
        self.link_error: LinkError | None = None
        #: An unexpected failure inside the session (it stopped driving the machine).
        self.error: BaseException | None = None
        self._wake = asyncio.Event()
        self._tasks: list[asyncio.Task[None]] = []
        self._rehandshaking = False
        self._view_listeners: list[Callable[[], None]] = []

    # ----------------------------------------------------------------- lifecycle
    async def start(self) -> MachineModel:
        """Run the connect handshake, build the engine and start the reader and ticker."""
        await handshake(self.link, timeout_s=self.handshake_timeout_s, model=self.model)
        self.model.set_keep_outs(self.keepouts)
        self.engine = Jogger(self.model, EngineLimits.from_model(self.model), self.tuning)
        self._tasks = [
            asyncio.create_task(self._reader(), name="smoothjog-reader"),
            asyncio.create_task(self._ticker(), name="smoothjog-ticker"),
        ]
        return self.model

    async def close(self, *, stop_timeout_s: float = 2.0) -> None:
        """Stop any jog with the full handshake (bounded in time), then close the link."""
        if self.engine is not None and self.link_error is None:
            with contextlib.suppress(LinkError, ValueError):
                self.set_intent(StopIntent())
            with contextlib.suppress(TimeoutError):
                await self.wait_idle(stop_timeout_s)
        for task in self._tasks:
            task.cancel()
        # A task that died earlier has its error stored in self.error already; closing the
        # link must not be skipped because of it.
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._tasks = []
        await self.link.close()

    # ----------------------------------------------------------------- inputs
    def set_intent(self, intent: Intent) -> None:
        """Hand the engine the newest intent; raises JogBuildError for an invalid one."""
        engine = self._engine()
        engine.set_intent(intent, self._now())
        self._wake.set()

    def jog(self, axes: Mapping[str, float], speed: float) -> None:
        """Shorthand for a continuous intent."""
        self.set_intent(ContinuousIntent(dict(axes), speed))

    def set_speed_ratios(self, ratios: Mapping[str, float]) -> None:
        """Per-axis speed ratios in (0, 1]."""
        self._engine().set_speed_ratios(ratios)

    # ----------------------------------------------------------------- observation
    def view(self) -> EngineView:
        """The engine's snapshot now."""
        return self._engine().view(self._now())

    def busy(self) -> bool:
        """True while anything is queued, streaming or stopping."""
        return self._engine().busy()

    async def wait_idle(self, timeout_s: float) -> None:
        """Wait until the engine is idle and the controller reports Idle; TimeoutError if not."""
        async with asyncio.timeout(timeout_s):
            while True:
                if self.link_error is not None:
                    raise self.link_error  # a controller that is gone is not idle
                if not self.busy() and self.model.state in ("Idle", "Alarm", "Door", "Hold"):
                    return
                await asyncio.sleep(0.01)

    def add_listener(self, callback: Callable[[], None]) -> None:
        """Call callback (no arguments) after every received line: the pendant's change signal."""
        self._view_listeners.append(callback)

    # ----------------------------------------------------------------- tasks
    def _engine(self) -> Jogger:
        if self.engine is None:
            raise RuntimeError("JogSession.start() has not run")
        return self.engine

    def _now(self) -> float:
        return asyncio.get_running_loop().time()

    async def _reader(self) -> None:
        engine = self._engine()
        try:
            while True:
                raw = await self.link.read_line()
                response = parse_response(raw)
                now = self._now()
                engine.on_response(response, now)
                if isinstance(response, Banner):
                    await self._rehandshake()
                self._flush_events()
                for callback in self._view_listeners:
                    callback()
                self._wake.set()
        except LinkError as exc:
            self.link_error = exc
            logger.error("%s", exc)
            self._wake.set()
        except SmoothjogError as exc:  # e.g. a controller that keeps resetting
            self._fail(exc)

    def _fail(self, exc: BaseException) -> None:
        """Something broke inside the session: stop the machine if possible and say so."""
        self.error = exc
        logger.error("smoothjog stopped driving the controller: %s", exc)
        with contextlib.suppress(LinkError, ValueError):
            # Cancel whatever jog runs: the engine can no longer finish its handshake.
            self.link.send_realtime(b"\x85")
        if self.link_error is None:
            self.link_error = LinkError(f"the session stopped: {exc}")
        self._wake.set()

    async def _rehandshake(self) -> None:
        """The controller reset mid-session: read its settings again before any jog."""
        self._rehandshaking = True
        try:
            await handshake(self.link, timeout_s=self.handshake_timeout_s, model=self.model)
            self._engine().reset_machine(EngineLimits.from_model(self.model, self.keepouts))
        finally:
            self._rehandshaking = False

    async def _ticker(self) -> None:
        engine = self._engine()
        try:
            while self.link_error is None:
                # Cleared before polling: a wake-up set while the outputs are written is kept.
                self._wake.clear()
                if not self._rehandshaking:
                    now = self._now()
                    for output in engine.poll(now):
                        if isinstance(output, SendLine):
                            await self.link.send_line(output.text)
                        else:
                            self.link.send_realtime(output.byte)
                    self._flush_events()
                    deadline = engine.next_deadline_s(now)
                else:
                    deadline = self._now() + 0.01
                # asyncio.timeout, not wait_for: on Python 3.11 wait_for can swallow a
                # cancellation that lands as the event fires, and close() would wait forever.
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(max(deadline - self._now(), 0.0)):
                        await self._wake.wait()
        except LinkError as exc:
            self.link_error = exc
            logger.error("%s", exc)
        except Exception as exc:  # a bug must stop the machine, not vanish quietly
            self._fail(exc)

    def _flush_events(self) -> None:
        engine = self._engine()
        events, engine.events = engine.events, []
        for event in events:
            log = logger.warning if event.kind == "fault" else logger.info
            log("%s%s", event.text, f" ({event.hint})" if event.hint else "")
            if self.on_event is not None:
                try:
                    self.on_event(event)
                except Exception:  # a listener's bug must not stop the machine's driver
                    logger.exception("an event listener failed")
