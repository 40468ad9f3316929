"""Physical input devices: the decoder contract every device kind implements.

A device kind (gamepad, keyboard, ShuttleXpress, SpaceMouse, WHB04B handwheel, encoder knob) is
one file in this package holding one `Decoder` subclass. A decoder is pure: it is handed what
the device produced (an evdev frame, or one hidraw report), each stamped with the time it was
read, and it answers with actions. It never reads a device, sleeps or looks at a clock of its
own, so tests feed it recorded data with made-up times. The reading, the timers, the arbiter
and the machine commands are the `DeviceInput`'s (inputs/devinput.py), shared by every kind.

Actions:
- an `Intent` (core/intents.py), handed to the arbiter as it is;
- a `DeviceCommand`, a machine command by the pendant's names (unlock, home, reset, zero,
  goto_zero, override) plus hold/resume, run by MachineControl beside the jog;
- a `DeviceNotice`, a sentence for the user (printed by the command that runs the device).

Rules every decoder follows (the `DeviceInput` relies on them):
- `feed` and `tick` never raise for anything a device can send: unknown codes, short or long
  reports, values out of range are ignored (and may be counted);
- after `lost()` the decoder wants no motion: the `DeviceInput` sends a StopIntent whenever
  `moving` was true, so a decoder need not remember to;
- a decoder that needs time to pass with no input (a watchdog, a staleness timeout) says when
  in `deadline_s()`, and `tick(now_s)` is called at or after that time;
- motion never starts again by itself after a stop the decoder did not see the user ask for
  (a loss, a sleep, a released dead-man): the stick or wheel must come back to neutral first.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import ClassVar, Literal, NamedTuple

from smoothjog.core.intents import Intent
from smoothjog.core.options import Table
from smoothjog.core.realtime import OVERRIDE_STEPS
from smoothjog.core.units import ALL_AXES

# -- what a device produces ------------------------------------------------------------------

#: evdev event types (linux/input-event-codes.h); the decoders use these numbers directly so
#: that they do not need python-evdev to be importable.
EV_SYN = 0x00
EV_KEY = 0x01
EV_REL = 0x02
EV_ABS = 0x03
EV_MSC = 0x04
SYN_REPORT = 0
SYN_DROPPED = 3


class EvdevEvent(NamedTuple):
    """One evdev event: type, code and value (the time is the frame's)."""

    type: int
    code: int
    value: int


@dataclass(frozen=True)
class EvdevFrame:
    """The events of one evdev frame (up to SYN_REPORT), EV_SYN and EV_MSC removed.

    `resync` frames follow a SYN_DROPPED: the kernel's queue overflowed, so changes were lost.
    A resync frame gives the whole current state instead of changes: every absolute axis's value
    and, as EV_KEY value 1, every key held down; keys it does not list are up.
    """

    t_s: float
    events: tuple[EvdevEvent, ...]
    resync: bool = False


@dataclass(frozen=True)
class HidReport:
    """One hidraw report as read (one read() is one report; numbered reports keep the ID)."""

    t_s: float
    data: bytes


DeviceItem = EvdevFrame | HidReport


class AbsRange(NamedTuple):
    """An absolute axis's range as the kernel reports it (the fields of evdev.AbsInfo)."""

    value: int
    min: int
    max: int
    fuzz: int = 0
    flat: int = 0


@dataclass(frozen=True)
class DeviceInfo:
    """Who a device is and what it can send; from the kernel, or from a recording's header."""

    name: str
    path: str = ""
    vendor: int = 0
    product: int = 0
    bus: int = 0
    #: Absolute axes: evdev code -> range (empty for hidraw devices).
    absinfo: Mapping[int, AbsRange] = field(default_factory=dict)
    #: evdev key and button codes the device declares.
    keys: frozenset[int] = frozenset()
    #: evdev relative codes the device declares.
    rels: frozenset[int] = frozenset()

    @property
    def usb_id(self) -> str:
        """vendor:product as lsusb writes it (e.g. "10ce:eb93")."""
        return f"{self.vendor:04x}:{self.product:04x}"


# -- what a decoder answers ------------------------------------------------------------------

#: The machine commands a device button may ask for (MachineControl's, plus hold and resume).
DEVICE_COMMANDS = ("unlock", "home", "reset", "zero", "goto_zero", "override", "hold", "resume")


@dataclass(frozen=True)
class DeviceCommand:
    """A machine command asked for by a device's button.

    zero: `axes` to set to work zero; override: `kind` ("feed" or "rapid") and `step` as
    MachineControl.override takes them.
    """

    name: str
    axes: tuple[str, ...] = ()
    kind: str | None = None
    step: str | None = None


@dataclass(frozen=True)
class DeviceNotice:
    """A sentence for the user about the device ("handwheel asleep: jog stopped")."""

    text: str


Action = Intent | DeviceCommand | DeviceNotice


def parse_command(text: str) -> DeviceCommand | None:
    """A button's machine command ("home", "zero:XY", "override:feed:+10"), None if not one.

    Raises ValueError, with the problem in words, for a malformed command. A bare "zero" has no
    axes: the decoder fills in the ones it means.
    """
    head, _, rest = text.partition(":")
    if head not in DEVICE_COMMANDS:
        return None
    if head == "zero":
        axes = tuple(rest.upper())
        bad = [a for a in axes if a not in ALL_AXES]
        if bad:
            raise ValueError(f'names no axis {bad[0]!r}: write e.g. "zero:XY" or "zero"')
        return DeviceCommand("zero", axes=axes)
    if head == "override":
        kind, _, step = rest.partition(":")
        if step not in OVERRIDE_STEPS.get(kind, ()):
            choices = "; ".join(
                f"override:{k}:{s}" for k, steps in OVERRIDE_STEPS.items() for s in steps
            )
            raise ValueError(f"is not an override: use one of {choices}")
        return DeviceCommand("override", kind=kind, step=step)
    if rest:
        raise ValueError(f"takes nothing after {head!r}: write {head!r}")
    return DeviceCommand(head)


def read_command(
    options: Table, where: str, value: object, axes: Sequence[str], alternatives: str
) -> DeviceCommand:
    """A button's machine command from the config; ConfigError naming `where` otherwise.

    alternatives names the decoder's own actions for the message ("an axis letter, ...").
    """
    action = value.strip() if isinstance(value, str) else ""
    try:
        command = parse_command(action)
    except ValueError as exc:
        raise options.error(where, f"= {value!r} {exc}") from None
    if command is None:
        raise options.error(
            where,
            f"= {value!r} is not an action: use {alternatives} or one of "
            f"{', '.join(DEVICE_COMMANDS)}",
        )
    if any(a not in axes for a in command.axes):
        raise options.error(where, f"= {value!r}: the machine has {tuple(axes)}")
    return command


@dataclass(frozen=True)
class DisplayView:
    """What a device with a display (the WHB04B's LCD) may show; positions in mm."""

    mpos_mm: Mapping[str, float]
    wpos_mm: Mapping[str, float]
    feed_mm_min: float = 0.0
    spindle_rpm: float = 0.0
    state: str = ""


# -- the contract ----------------------------------------------------------------------------


class Decoder(ABC):
    """Turns what one device produces into actions; pure, with time given by the caller."""

    #: The device kind's own name, as `--input-kind` and the config's `kind` say it
    #: ("gamepad", "keyboard", "knob", "shuttle", "spacemouse", "whb04b").
    name: ClassVar[str]
    #: The input kind (inputs/base.py KIND_NOUNS) for messages, e.g. "gamepad", "handwheel".
    kind: ClassVar[str]
    #: Which kernel interface it reads.
    transport: ClassVar[Literal["evdev", "hidraw"]]

    def __init__(self, info: DeviceInfo, options: Table, axes: Sequence[str]) -> None:
        """A decoder for the device `info`, on a machine with `axes` (e.g. ("X", "Y", "Z")).

        `options` is the device's table from the config (the keys that chose the device are
        already read); a subclass reads its own keys with its getters, which raise ConfigError
        naming the file and key, and calls `options.finish()` last so an unknown key (a typo)
        is refused too. `Table({}, "device", "<defaults>")` gives every default.
        """
        self.info = info
        self.axes = tuple(axes)

    @classmethod
    def matches(cls, info: DeviceInfo) -> bool:
        """Whether this kind takes the device by default (by ids, name or capabilities)."""
        return False

    @abstractmethod
    def feed(self, item: DeviceItem) -> list[Action]:
        """What the device just produced, stamped with the time it was read."""

    def tick(self, now_s: float) -> list[Action]:
        """Time passed with nothing from the device; called at or after deadline_s()."""
        return []

    def deadline_s(self) -> float | None:
        """When tick() must next be called, or None when no timer is needed."""
        return None

    @property
    @abstractmethod
    def moving(self) -> bool:
        """True while this device drives or has queued motion (a held stick, wheel counts)."""

    @abstractmethod
    def lost(self) -> list[Action]:
        """The device is gone (unplugged, read error, end of a recording); forget all state.

        Returns any notice to give; the DeviceInput stops the machine itself if `moving` was
        true before the call.
        """

    def display(self, view: DisplayView) -> list[bytes]:
        """Output or feature reports to write to the device now (for a display); usually none."""
        return []

    def describe(self) -> str:
        """One line on the device's current mode, for `smoothjog devices` and logs."""
        return self.kind


__all__ = [
    "DEVICE_COMMANDS",
    "EV_ABS",
    "EV_KEY",
    "EV_MSC",
    "EV_REL",
    "EV_SYN",
    "SYN_DROPPED",
    "SYN_REPORT",
    "AbsRange",
    "Action",
    "Decoder",
    "DeviceCommand",
    "DeviceInfo",
    "DeviceItem",
    "DeviceNotice",
    "DisplayView",
    "EvdevEvent",
    "EvdevFrame",
    "HidReport",
]
