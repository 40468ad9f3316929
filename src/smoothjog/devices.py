"""The session's physical input devices: find them, open them, run each under the arbiter.

Which devices: every `--input` wish (a kind, a path, vendor:product, part of a name, or
"auto") and every [[device]] table of the config. The manager scans at start and again every
`rescan_s` (sooner when udev says something changed), opens each wanted device that is not
running, builds its decoder with the config's options, and runs it as an Input of the session's
arbiter. A device that ends (unplugged, asleep, a read error) has already stopped any motion it
drove (inputs/devinput.py); when it comes back it is opened afresh, and its new decoder needs
the stick or wheel at neutral before it moves anything.

A device that cannot be opened is told once, with the fix (the udev rule), not on every scan.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final

from smoothjog.authority.arbiter import Arbiter
from smoothjog.authority.commands import COMMAND_NAMES, GOTO_SPEED
from smoothjog.config import DeviceConfig
from smoothjog.control import ControlRefused, MachineControl
from smoothjog.core.errors import ConfigError, InputRefused
from smoothjog.core.intents import GotoIntent, Intent
from smoothjog.core.options import Table
from smoothjog.core.units import ALL_AXES
from smoothjog.host import Host
from smoothjog.inputs.device import Decoder, DeviceCommand, DeviceInfo, DeviceItem, DisplayView
from smoothjog.inputs.devinput import DeviceInput, DeviceSource, NoticeSink, RecordedSource
from smoothjog.inputs.discovery import (
    NAMED_ONLY_KINDS,
    PERMISSION_FIX,
    FoundDevice,
    choose,
    scan,
    wanted_by,
)
from smoothjog.inputs.kinds import DECODERS, decoder_named
from smoothjog.inputs.recording import load_evtest, load_hidraw

log = logging.getLogger(__name__)

#: How often the device list is read again when udev cannot tell us (s).
RESCAN_S: Final = 1.0


def check_device_configs(configs: Sequence[DeviceConfig]) -> None:
    """Build each configured decoder once, so a bad option fails at start, naming its key."""
    for entry in configs:
        cls = decoder_named(entry.kind, where=f"{entry.source}: [{entry.section}] kind")
        if cls.name in NAMED_ONLY_KINDS and entry.match is None:
            # Every keyboard would be grabbed, the one the user types on included.
            raise ConfigError(
                f"{entry.source}: [{entry.section}] match is missing: a {cls.name} table must "
                'name its device, e.g. match = "USB Keypad" (see `smoothjog devices`)'
            )
        cls(DeviceInfo(name="check"), entry.table(), ALL_AXES)


def decoder_for(
    found: FoundDevice, configs: Sequence[DeviceConfig], axes: Sequence[str]
) -> Decoder | None:
    """The decoder for a found device: a [[device]] table that names it (or its kind) first."""
    entry = _entry_for(found, configs)
    if entry is not None:
        cls = decoder_named(entry.kind, where=f"{entry.source}: [{entry.section}] kind")
        if cls.transport != found.transport:
            return None
        return cls(found.info, entry.table(), axes)
    if found.kind is None:
        return None
    cls = decoder_named(found.kind)
    return cls(found.info, Table({}, found.kind, "<defaults>"), axes)


def _entry_for(found: FoundDevice, configs: Sequence[DeviceConfig]) -> DeviceConfig | None:
    for entry in configs:
        if entry.match is not None and wanted_by(found, entry.match):
            cls = decoder_named(entry.kind)
            if cls.transport == found.transport:
                return entry
    for entry in configs:
        if entry.match is None and entry.kind == found.kind:
            return entry
    return None


def _configured(found: FoundDevice, configs: Sequence[DeviceConfig]) -> bool:
    return _entry_for(found, configs) is not None


@dataclass
class _Running:
    input: DeviceInput
    task: asyncio.Task[None]


Opener = Callable[[FoundDevice], DeviceSource]


def open_source(found: FoundDevice) -> DeviceSource:
    """Open a found node with the live reader of its transport."""
    if found.transport == "hidraw":
        from smoothjog.inputs.hidraw_source import HidrawSource  # noqa: PLC0415 -- Linux only

        return HidrawSource.open(found.path, found.info)
    from smoothjog.inputs.evdev_source import EvdevSource  # noqa: PLC0415 -- needs python-evdev

    return EvdevSource.open(found.path)


class MachineCommands:
    """What a device's buttons may ask of the machine, run through MachineControl."""

    def __init__(self, control: MachineControl) -> None:
        """Commands over control."""
        self.control = control

    async def __call__(self, command: DeviceCommand, submit: Callable[[Intent], None]) -> str:
        """Run one command; the outcome in words."""
        c = self.control
        try:
            if command.name == "goto_zero":
                for target in c.work_zero_targets():
                    submit(GotoIntent(target, GOTO_SPEED))
                return "going to work zero"
            if command.name not in COMMAND_NAMES:
                return f"{command.name}: not a machine command"
            kind, step = command.kind or "", command.step or ""
            result = await c.run(command.name, axes=command.axes or (), kind=kind, step=step)
        except (ControlRefused, InputRefused) as exc:
            return f"{command.name} refused: {exc}"
        if result.ok:
            return f"{command.name}: done"
        return f"{command.name} failed: {result.error or 'the controller refused it'}"


def machine_view(control: MachineControl) -> Callable[[], DisplayView | None]:
    """The machine as a device display shows it (WPos from the host's model)."""
    host = control.host

    def view() -> DisplayView | None:
        model = host.model
        mpos = model.mpos_mm
        if mpos is None:
            return None
        axes = model.axis_letters
        wco = model.wco_mm or tuple(0.0 for _ in axes)
        return DisplayView(
            mpos_mm=dict(zip(axes, mpos, strict=False)),
            wpos_mm={a: m - w for a, m, w in zip(axes, mpos, wco, strict=False)},
            feed_mm_min=float(model.feed_mm_min or 0.0),
            spindle_rpm=float(model.spindle_rpm or 0.0),
            state=control.gate.shown_state(),
        )

    return view


class DeviceManager:
    """Keeps the wanted devices open and attached to the arbiter for the whole session."""

    def __init__(
        self,
        arbiter: Arbiter,
        *,
        wishes: Sequence[str],
        configs: Sequence[DeviceConfig] = (),
        axes: Callable[[], Sequence[str]],
        commands: MachineCommands | None = None,
        view: Callable[[], DisplayView | None] | None = None,
        notices: NoticeSink | None = None,
        sysfs: str = "/sys",
        dev: str = "/dev",
        rescan_s: float = RESCAN_S,
        opener: Opener = open_source,
        decoders: Sequence[type[Decoder]] = DECODERS,
    ) -> None:
        """Manage the devices wished for (and configured) on arbiter."""
        self.arbiter = arbiter
        self.wishes = tuple(wishes)
        self.configs = tuple(configs)
        self._axes = axes
        self._commands = commands
        self._view = view
        self._notices = notices
        self._sysfs = sysfs
        self._dev = dev
        self._rescan_s = rescan_s
        self._opener = opener
        self._decoders = tuple(decoders)
        self._running: dict[str, _Running] = {}
        self._told: dict[str, str] = {}
        self._wake = asyncio.Event()
        #: Every device input started, in order (for tests and the summary).
        self.started: list[DeviceInput] = []

    def _tell(self, text: str) -> None:
        if self._notices is None:
            log.warning("%s", text)
            return
        log.info("%s", text)
        with contextlib.suppress(Exception):
            self._notices(text)

    def wanted(self, found: Sequence[FoundDevice]) -> list[FoundDevice]:
        """The nodes to open now: wished for or configured, one per physical device."""
        wishes = list(self.wishes)
        configured = [d for d in found if _configured(d, self.configs)]
        picked = choose(found, wishes) if wishes else []
        for d in configured:
            if d not in picked and not (
                d.transport == "evdev"
                and any(
                    p.transport == "hidraw"
                    and (p.info.vendor, p.info.product) == (d.info.vendor, d.info.product)
                    for p in picked
                )
            ):
                picked.append(d)
        return picked

    def scan_once(self) -> None:
        """Open every wanted device that is not running (one pass)."""
        found = scan(self._decoders, sysfs=self._sysfs, dev=self._dev)
        for wish in self.wishes:
            if not any(d.kind is not None and wanted_by(d, wish) for d in found):
                self._tell_once(
                    f"wish {wish}",
                    f"no input device matches --input {wish} yet; it is opened when it is "
                    "plugged in (`smoothjog devices` lists what this machine sees)",
                )
            else:
                self._told.pop(f"wish {wish}", None)
        for device in self.wanted(found):
            if device.path in self._running:
                continue
            self._start(device)

    def _start(self, device: FoundDevice) -> None:
        if device.problem is not None:
            self._tell_once(device.path, device.problem)
            return
        try:
            decoder = decoder_for(device, self.configs, self._axes())
        except ConfigError as exc:
            self._tell_once(device.path, str(exc))
            return
        if decoder is None:
            return
        try:
            source = self._opener(device)
        except PermissionError:
            self._tell_once(
                device.path, f"cannot open {device.path}: permission denied; {PERMISSION_FIX}"
            )
            return
        except OSError as exc:
            self._tell_once(device.path, f"cannot open {device.path}: {exc.strerror or exc}")
            return
        # The live node's info (absolute ranges) is better than the scan's.
        if source.info != device.info:
            try:
                decoder = (
                    decoder_for(
                        FoundDevice(device.path, device.transport, source.info, device.kind),
                        self.configs,
                        self._axes(),
                    )
                    or decoder
                )
            except ConfigError as exc:
                source.close()
                self._tell_once(device.path, str(exc))
                return
        self._told.pop(device.path, None)
        if device.transport == "evdev" and not getattr(source, "grabbed", True):
            self._tell(
                f"{device.path}: another program has grabbed it, so its events may not reach "
                "smoothjog (is spacenavd or a desktop session using it?)"
            )
        device_input = DeviceInput(
            decoder,
            source,
            commands=self._commands,
            view=self._view,
            notices=self._notices,
        )
        self._tell(f"{decoder.name} {source.info.name} ({device.path}) ready: {decoder.describe()}")
        task = asyncio.create_task(self.arbiter.run_input(device_input), name=device.path)
        self._running[device.path] = _Running(device_input, task)
        self.started.append(device_input)
        task.add_done_callback(functools.partial(self._ended, device.path))

    def _ended(self, path: str, _task: object) -> None:
        self._running.pop(path, None)
        self._wake.set()

    def _tell_once(self, key: str, text: str) -> None:
        if self._told.get(key) != text:
            self._told[key] = text
            self._tell(text)

    def wake(self) -> None:
        """Scan again now (udev reported a change)."""
        self._wake.set()

    async def run(self) -> None:
        """Scan, open, and scan again until cancelled; every device is closed on the way out."""
        monitor = _udev_monitor(self.wake)
        try:
            while True:
                self.scan_once()
                self._wake.clear()
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(self._wake.wait(), self._rescan_s)
        finally:
            if monitor is not None:
                monitor()
            tasks = [r.task for r in self._running.values()]
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)

    @property
    def running(self) -> Mapping[str, DeviceInput]:
        """The devices open now, by path."""
        return {path: r.input for path, r in self._running.items()}


def _udev_monitor(wake: Callable[[], None]) -> Callable[[], None] | None:
    """Wake the manager when udev adds or removes an input or hidraw node; None without udev.

    Returns the function that stops watching.
    """
    try:
        import pyudev  # noqa: PLC0415 -- Linux only, and optional: the rescan covers its absence
    except ImportError:
        return None
    try:
        context: Any = pyudev.Context()
        monitor: Any = pyudev.Monitor.from_netlink(context)
        monitor.filter_by("input")
        monitor.filter_by("hidraw")
        monitor.start()
    except Exception:  # no netlink in a container: the periodic rescan still finds devices
        log.info("udev monitor unavailable; rescanning every %.1f s", RESCAN_S)
        return None
    loop = asyncio.get_running_loop()

    def readable() -> None:
        while monitor.poll(timeout=0) is not None:
            pass
        wake()

    loop.add_reader(monitor.fileno(), readable)

    def stop() -> None:
        loop.remove_reader(monitor.fileno())

    return stop


@dataclass(frozen=True)
class DeviceReplay:
    """A recorded device stream and the decoder kind that reads it (`jog --input-replay`)."""

    kind: str
    info: DeviceInfo
    items: tuple[DeviceItem, ...]
    configs: tuple[DeviceConfig, ...] = ()

    async def play(self, host: Host) -> list[str]:
        """Play the recording into host through the decoder and an arbiter; what it did."""
        control = MachineControl(host)
        arbiter = Arbiter(control.gate)
        found = FoundDevice(
            self.info.path, decoder_named(self.kind).transport, self.info, self.kind
        )
        decoder = decoder_for(found, self.configs, host.model.axis_letters)
        assert decoder is not None  # the kind gives the transport, so a decoder always fits
        notices: list[str] = []
        source = RecordedSource(self.info, self.items)
        device = DeviceInput(
            decoder,
            source,
            commands=MachineCommands(control),
            view=machine_view(control),
            notices=notices.append,
        )
        await arbiter.run_input(device)
        taken = sum(1 for _, ok in device.submitted if ok)
        refused = len(device.submitted) - taken
        out = [
            f"device          {decoder.name}: {self.info.name}, {len(self.items)} items",
            f"  intents       {taken} taken, {refused} refused",
        ]
        if source.written:
            out.append(f"  display       {len(source.written)} reports written")
        out += [f"  said          {text}" for text in notices]
        return out


def load_device_replay(path: str, kind: str, configs: Sequence[DeviceConfig] = ()) -> DeviceReplay:
    """Read a recording for kind (evtest text for evdev kinds, SECONDS HEX for hidraw ones)."""
    cls = decoder_named(kind)
    items: tuple[DeviceItem, ...]
    if cls.transport == "evdev":
        evdev_rec = load_evtest(path)
        info, items = evdev_rec.info, evdev_rec.frames
    else:
        hid_rec = load_hidraw(path)
        info, items = hid_rec.info, hid_rec.reports
    relevant = tuple(c for c in configs if c.kind == kind)
    # Check the options now, so a typo is reported before anything moves.
    check_device_configs(relevant)
    return DeviceReplay(kind, info, items, relevant)
