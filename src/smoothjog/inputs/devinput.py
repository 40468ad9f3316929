"""One physical device as an Input: a source of reports, its decoder, the arbiter in between.

Every device kind runs through this one class, so the safety rules live once:
- whatever ends the source (unplug: ENODEV on evdev, EIO on hidraw; end of file; end of a
  recording; any other read error) ends `run`, and the machine is stopped at once if the
  decoder was driving motion; the arbiter stops it again on detach if this input controlled;
- a decoder's timers (`deadline_s`) are honoured while the device is silent, so a watchdog or a
  staleness timeout fires even when nothing more is ever read;
- a new motion takes control if nobody holds a jog (touching a device is asking to drive);
  a refusal is told to the user once per refusal text, not on every report;
- machine commands from buttons run beside the jog in their own task, one at a time;
- a device with a display is sent the machine's view every `display_period_s`.

A source is anything with `info`, `items()` (an async iterator of `DeviceItem`s stamped on the
loop's clock, ending on EOF and raising `DeviceLost` on a read error) and `write(data)` for
feature/output reports; live sources are in evdev_source.py and hidraw_source.py, the recorded
one is `RecordedSource` below.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import os
from collections.abc import AsyncIterator, Awaitable, Callable, Sequence
from typing import Final, Protocol

from smoothjog.core.errors import InputRefused, SmoothjogError
from smoothjog.core.intents import ContinuousIntent, Intent, StopIntent
from smoothjog.inputs.base import Input, InputHandle, Notice
from smoothjog.inputs.device import (
    Action,
    Decoder,
    DeviceCommand,
    DeviceInfo,
    DeviceItem,
    DeviceNotice,
    DisplayView,
    EvdevFrame,
    HidReport,
)

log = logging.getLogger(__name__)

#: How often a device with a display is sent the machine's position (the WHB04B's LCD).
DISPLAY_PERIOD_S = 0.2


class DeviceLost(SmoothjogError):  # noqa: N818 -- a loss told in words, as InputRefused
    """A device cannot be read any more; the text says why (unplugged, read error, ...)."""


#: Read errors that mean the device is gone (unplugged, asleep), not a passing failure.
GONE_ERRNOS: Final = frozenset({errno.EIO, errno.ENODEV, errno.ENXIO, errno.EBADF})


def read_loss(exc: OSError, gone: str) -> DeviceLost:
    """The DeviceLost a live reader raises for a failed read; gone says how it went."""
    if exc.errno in GONE_ERRNOS:
        return DeviceLost(f"{gone} ({os.strerror(exc.errno or 0)})")
    return DeviceLost(f"read error: {exc.strerror}")


class DeviceSource(Protocol):
    """Where a DeviceInput reads from: a live node or a recording."""

    info: DeviceInfo

    def items(self) -> AsyncIterator[DeviceItem]:
        """What the device produces, stamped on the loop's clock; raises DeviceLost on loss."""
        ...

    def write(self, data: bytes) -> None:
        """Send a feature or output report (a display); raises OSError if it cannot."""
        ...

    def close(self) -> None:
        """Let go of the device (safe to call twice)."""
        ...


#: Runs a device's machine command and returns its outcome in words (None: nothing to say).
#: The second argument submits intents as this device (for go-to-zero's moves); it raises
#: InputRefused in words.
CommandRunner = Callable[[DeviceCommand, Callable[[Intent], None]], Awaitable[str | None]]
#: The machine as a display should show it, or None while it is not known.
ViewSource = Callable[[], DisplayView | None]
#: Where a device's sentences for the user go (the log by default; the pendant shows them too).
NoticeSink = Callable[[str], None]


class DeviceInput(Input):
    """A physical device, decoded, as one input of the session's arbiter."""

    # A device that goes silent mid-jog is caught by its read error or its decoder's watchdog;
    # a keyboard reports key-up and an evdev stick held still sends nothing, so no lease.
    lease_s = None

    def __init__(
        self,
        decoder: Decoder,
        source: DeviceSource,
        *,
        commands: CommandRunner | None = None,
        view: ViewSource | None = None,
        notices: NoticeSink | None = None,
        display_period_s: float = DISPLAY_PERIOD_S,
    ) -> None:
        """Run decoder over source; commands and view are the machine's, when there is one."""
        self.decoder = decoder
        self.source = source
        self.name = f"{decoder.name} {source.info.name}"
        self.kind = decoder.kind
        self._commands = commands
        self._view = view
        self._notices = notices
        self._display_period_s = display_period_s
        self._handle: InputHandle | None = None
        self._command_task: asyncio.Task[None] | None = None
        self._last_refusal: str | None = None
        #: What ended the device, in words, once run() has returned.
        self.ended: str | None = None
        #: Every intent this device handed the arbiter (and whether it was taken), for replays.
        self.submitted: list[tuple[Intent, bool]] = []

    # -- Input -------------------------------------------------------------------------------

    def notice(self, notice: Notice) -> None:
        """The arbiter stopped this device's jog (only a device with a lease can trip)."""
        self._tell(notice.text)

    async def run(self, handle: InputHandle) -> None:
        """Read until the device ends; always leave the machine stopped if it drove motion."""
        self._handle = handle
        queue: asyncio.Queue[DeviceItem | BaseException | None] = asyncio.Queue()
        reader = asyncio.create_task(self._read(queue), name=f"read {self.name}")
        display = (
            asyncio.create_task(self._display(), name=f"display {self.name}")
            if self._view is not None
            else None
        )
        try:
            await self._pump(queue)
        finally:
            reader.cancel()
            tasks: list[asyncio.Task[None]] = [reader]
            if display is not None:
                display.cancel()
                tasks.append(display)
            was_moving = self.decoder.moving
            actions = self.decoder.lost()
            if was_moving:
                self._submit(StopIntent())
            self._apply([a for a in actions if not _is_motion(a)])
            with contextlib.suppress(Exception):
                self.source.close()
            await asyncio.gather(*tasks, return_exceptions=True)
            self._tell(f"{self.name}: {self.ended or 'ended'}")

    # -- the loop ----------------------------------------------------------------------------

    async def _read(self, queue: asyncio.Queue[DeviceItem | BaseException | None]) -> None:
        try:
            async for item in self.source.items():
                queue.put_nowait(item)
        except Exception as exc:  # every failure of a device is its end
            queue.put_nowait(exc)
        else:
            queue.put_nowait(None)

    async def _pump(self, queue: asyncio.Queue[DeviceItem | BaseException | None]) -> None:
        loop = asyncio.get_running_loop()
        while True:
            deadline = self.decoder.deadline_s()
            timeout = None if deadline is None else max(0.0, deadline - loop.time())
            try:
                got = await asyncio.wait_for(queue.get(), timeout)
            except TimeoutError:
                self._apply(self.decoder.tick(loop.time()))
                continue
            if got is None:
                self.ended = "the device's stream ended"
                return
            if isinstance(got, BaseException):
                self.ended = _loss_text(got)
                return
            self._apply(self.decoder.feed(got))
            deadline = self.decoder.deadline_s()
            if deadline is not None and loop.time() >= deadline:
                self._apply(self.decoder.tick(loop.time()))

    def _apply(self, actions: Sequence[Action]) -> None:
        for action in actions:
            if isinstance(action, DeviceNotice):
                self._tell(f"{self.name}: {action.text}")
            elif isinstance(action, DeviceCommand):
                self._command(action)
            else:
                self._submit(action)

    def _submit(self, intent: Intent) -> None:
        handle = self._handle
        if handle is None:
            return
        try:
            if not handle.in_control and _starts_motion(intent):
                # Touching a device asks to drive; refused while another input holds a jog.
                handle.take_control()
            handle.submit(intent)
        except InputRefused as exc:
            self.submitted.append((intent, False))
            text = str(exc)
            if text != self._last_refusal:
                self._last_refusal = text
                self._tell(f"{self.name}: {text}")
            return
        self.submitted.append((intent, True))
        self._last_refusal = None

    def _submit_or_raise(self, intent: Intent) -> None:
        handle = self._handle
        if handle is None:
            raise InputRefused("the device is not attached")
        if not handle.in_control:
            handle.take_control()
        handle.submit(intent)
        self.submitted.append((intent, True))

    def _command(self, command: DeviceCommand) -> None:
        if self._commands is None:
            self._tell(f"{self.name}: {command.name} is not available here")
            return
        if self._command_task is not None and not self._command_task.done():
            self._tell(f"{self.name}: {command.name} ignored: another command is running")
            return
        self._command_task = asyncio.create_task(self._run_command(command))

    async def _run_command(self, command: DeviceCommand) -> None:
        assert self._commands is not None
        try:
            outcome = await self._commands(command, self._submit_or_raise)
        except Exception as exc:  # a failed command is told, never the device's end
            outcome = f"{command.name} failed: {exc}"
        if outcome:
            self._tell(f"{self.name}: {outcome}")

    async def _display(self) -> None:
        assert self._view is not None
        failed = False
        while True:
            view = self._view()
            if view is not None:
                try:
                    for report in self.decoder.display(view):
                        self.source.write(report)
                    failed = False
                except OSError as exc:
                    if not failed:  # said once; the read side reports a real loss
                        self._tell(f"{self.name}: cannot write its display: {exc.strerror}")
                    failed = True
            await asyncio.sleep(self._display_period_s)

    def _tell(self, text: str) -> None:
        if self._notices is None:
            log.warning("%s", text)
            return
        log.info("%s", text)
        try:
            self._notices(text)
        except Exception:  # a notice that cannot be shown must not stop the device
            log.exception("could not show a device notice")


def _starts_motion(intent: Intent) -> bool:
    if isinstance(intent, StopIntent):
        return False
    return not (isinstance(intent, ContinuousIntent) and intent.is_neutral())


def _is_motion(action: Action) -> bool:
    return not isinstance(action, DeviceNotice | DeviceCommand)


def _loss_text(exc: BaseException) -> str:
    if isinstance(exc, DeviceLost):
        return str(exc)
    if isinstance(exc, OSError):
        return f"read error: {exc.strerror or exc}"
    return f"failed: {exc}"


class RecordedSource:
    """A recording played on the loop's clock: each item is due at start + its t_s."""

    def __init__(self, info: DeviceInfo, items: Sequence[DeviceItem]) -> None:
        """Play items (times from 0, in order) for the device info."""
        self.info = info
        self._items = tuple(items)
        #: Feature/output reports the decoder wrote (a display), with the loop time.
        self.written: list[tuple[float, bytes]] = []

    async def items(self) -> AsyncIterator[DeviceItem]:
        """Each item at its time, restamped on the loop's clock; then the end of the stream."""
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        for item in self._items:
            await asyncio.sleep(max(0.0, t0 + item.t_s - loop.time()))
            if isinstance(item, EvdevFrame):
                yield EvdevFrame(t0 + item.t_s, item.events, item.resync)
            else:
                yield HidReport(t0 + item.t_s, item.data)

    def write(self, data: bytes) -> None:
        """Keep what a display would have been sent."""
        self.written.append((asyncio.get_running_loop().time(), bytes(data)))

    def close(self) -> None:
        """Nothing to let go of."""
