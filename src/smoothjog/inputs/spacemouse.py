"""3Dconnexion SpaceMouse family: the 6-DOF cap's deflection as a continuous jog.

The cap reports three translations and three rotations, each about ±350 (the descriptor's
logical range; real devices overshoot to ±498, devices §5.1, §8.6). Each is scaled by 350 and
clamped to ±1, then shaped as a stick is: a rescaled deadzone, so speed leaves 0 continuously,
and expo (inputs/shaping.py, devices §9.2). Machine axes take a source and a sign from the `axes`
table; rotations move nothing unless mapped (e.g. `A = "rz"`).

- `dominant`: only the most deflected axis moves, so a push that is not quite straight stays on
  one axis; another axis takes over only once it leads by DOMINANT_MARGIN (no flicker on a
  diagonal).
- Buttons (1-based, `buttons` table): "stop", "dominant" (toggle), "faster" / "slower" (double
  or halve the speed), "none", or a machine command (device.DEVICE_COMMANDS). Button n is bit
  n-1 of report 3 on hidraw and BTN_0 + n-1 on evdev (the Pro's are sparse: remap them here).
- Safety: the cap must be seen at rest (every mapped channel within the deadzone, or ARM_BAND
  if that is wider) before it moves: at start-up, after a loss, after the stop button and after
  a watchdog or lost-event stop, so a cap held deflected then does not start a jog.

`SpaceMouseDecoder` reads hidraw, where the device sends its own zeros on release (three
double reports, devices §5.1). `SpaceMouseEvdevDecoder` reads the event node, where the kernel
drops that final zero for EV_REL axes (devices §1 item 2, §5.2), so a stale axis is zeroed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import ClassVar, Final, Literal

from smoothjog.core.intents import ContinuousIntent, StopIntent
from smoothjog.core.options import Table
from smoothjog.core.units import ALL_AXES
from smoothjog.inputs.device import (
    EV_ABS,
    EV_KEY,
    EV_REL,
    AbsRange,
    Action,
    Decoder,
    DeviceCommand,
    DeviceInfo,
    DeviceItem,
    DeviceNotice,
    EvdevFrame,
    HidReport,
    read_command,
)
from smoothjog.inputs.shaping import clamp_unit, deadzone, expo, normalise

#: The six raw channels, in report order (the index is also the evdev REL_/ABS_ code).
SOURCES: Final = ("x", "y", "z", "rx", "ry", "rz")
#: Logical full deflection (devices §5.1).
LOGICAL_MAX: Final = 350
#: Old layout: report 1 (translation) or 2 (rotation), 3 × int16; new layout: report 1, 6 × int16.
OLD_LEN: Final = 7
NEW_LEN: Final = 13
BUTTON_REPORT: Final = 3
MAX_BUTTONS: Final = 64
BTN_0: Final = 0x100
#: How far another axis must lead the dominant one to take over (shaped deflection).
DOMINANT_MARGIN: Final = 0.1
#: Arming needs the cap within this of rest even with no deadzone: the first report of a push
#: from rest is small (at 125 reports/s), a cap held deflected is not.
ARM_BAND: Final = 0.05
#: The slowest speed "slower" goes to (1/32 of full).
SPEED_MIN: Final = 1.0 / 32.0

#: USB ids (devices §2) and the model name each gives.
USB_IDS: Final[Mapping[tuple[int, int], str]] = {
    (0x046D, 0xC626): "SpaceNavigator",
    (0x046D, 0xC62B): "SpaceMouse Pro",
    (0x256F, 0xC62E): "SpaceMouse Wireless",
    (0x256F, 0xC62F): "SpaceMouse Wireless",
    (0x256F, 0xC63A): "SpaceMouse Wireless",
    (0x256F, 0xC631): "SpaceMouse Pro Wireless",
    (0x256F, 0xC632): "SpaceMouse Pro Wireless",
    (0x256F, 0xC638): "SpaceMouse Pro Wireless",
    (0x256F, 0xC635): "SpaceMouse Compact",
    (0x256F, 0xC633): "SpaceMouse Enterprise",
    (0x256F, 0xC636): "SpaceMouse Module",
    (0x256F, 0xC652): "3Dconnexion Universal Receiver",
}

#: Raw frame to machine frame. An assumption from devices §5.1 (PySpaceMouse's signs: y and z
#: negated; spacenavd's swap of Y and Z is not needed when Y is the cap pushed away and Z the
#: cap lifted): check on hardware that pushing the cap away moves +Y and lifting it moves +Z.
DEFAULT_AXES: Final[Mapping[str, str]] = {"X": "x", "Y": "-y", "Z": "-z"}
DEFAULT_BUTTONS: Final[Mapping[str, str]] = {"1": "stop", "2": "dominant"}
_ACTIONS: Final = ("stop", "dominant", "faster", "slower")


def _not_a_spacemouse(name: str) -> bool:
    """The receiver's CadMouse or keyboard side (spacenavd skips them too, devices §5.2)."""
    name = name.lower()
    return (
        "cadmouse" in name or "keyboard" in name or ("mouse" in name and "spacemouse" not in name)
    )


class _SpaceMouse(Decoder):
    """Deflection shaping, arming and buttons, shared by the hidraw and evdev readers."""

    kind: ClassVar[str] = "spacemouse"

    def __init__(self, info: DeviceInfo, options: Table, axes: Sequence[str]) -> None:
        """Read the options (see the module docstring); not armed until the cap is seen at rest."""
        super().__init__(info, options, axes)
        self.model = USB_IDS.get((info.vendor, info.product), "SpaceMouse")
        self.mapping = self._read_axes(options)
        self.deadzone = options.number("deadzone", 0.1, at_least=0.0, at_most=0.9)
        self.expo = options.number("expo", 0.2, at_least=0.0, at_most=1.0)
        self.speed = options.number("speed", 1.0, above=0.0, at_most=1.0)
        self.dominant = options.flag("dominant", False)
        self.buttons = self._read_buttons(options)
        self._read_transport_options(options)
        options.finish()
        #: Reports or events that were not the SpaceMouse's and were ignored.
        self.ignored = 0
        self._reset()

    def _read_transport_options(self, options: Table) -> None:
        """Hook: a transport's own keys, read before finish()."""

    def _read_axes(self, options: Table) -> dict[str, tuple[int, float]]:
        given = {str(k).upper(): v for k, v in options.table("axes").items()}
        merged = {**DEFAULT_AXES, **given}
        mapping: dict[str, tuple[int, float]] = {}
        used: dict[int, str] = {}
        for axis, value in merged.items():
            where = f"axes.{axis}"
            if axis not in ALL_AXES:
                raise options.error(where, f"is not an axis: use one of {', '.join(ALL_AXES)}")
            text = value.strip().lower() if isinstance(value, str) else ""
            if text == "off":
                continue
            sign = -1.0 if text.startswith("-") else 1.0
            source = text.lstrip("+-")
            if source not in SOURCES:
                raise options.error(
                    where,
                    f"= {value!r} is not a source: use one of {', '.join(SOURCES)}, with a - to "
                    'reverse it, or "off"',
                )
            if axis not in self.axes:
                if axis in given:
                    raise options.error(where, f"= {value!r}: the machine has {self.axes}")
                continue  # a default axis the machine lacks
            index = SOURCES.index(source)
            if index in used:
                raise options.error(where, f"= {value!r}: {source} already drives {used[index]}")
            used[index] = axis
            mapping[axis] = (index, sign)
        return {a: mapping[a] for a in self.axes if a in mapping}

    def _read_buttons(self, options: Table) -> dict[int, str | DeviceCommand]:
        given = options.table("buttons")
        table: dict[int, str | DeviceCommand] = {}
        for key, value in {**DEFAULT_BUTTONS, **given}.items():
            where = f"buttons.{key}"
            number = int(key) if isinstance(key, str) and key.isdigit() else 0
            if not 1 <= number <= MAX_BUTTONS:
                raise options.error(where, f"is not a button number: use 1 to {MAX_BUTTONS}")
            action = value.strip() if isinstance(value, str) else ""
            if action == "none":
                table.pop(number, None)
                continue
            if action in _ACTIONS:
                table[number] = action
                continue
            alternatives = f"{', '.join(_ACTIONS)}, none,"
            table[number] = read_command(options, where, value, self.axes, alternatives)
        return table

    def _reset(self) -> None:
        """A cap just plugged in: values unknown, not armed, nothing held."""
        #: Each channel as -1..1 before shaping; None while not yet known.
        self._values: list[float | None] = [None] * len(SOURCES)
        self._armed = False
        #: The deflections and speed of the jog in force, or None at neutral.
        self._sent: tuple[dict[str, float], float] | None = None
        self._held: set[int] = set()
        self._dominant_axis: str | None = None

    @property
    def moving(self) -> bool:
        """True while a non-neutral jog is in force."""
        return self._sent is not None

    def lost(self) -> list[Action]:
        """Forget everything; the next cap must be seen at neutral before it moves."""
        was = self.moving
        self._reset()
        return [DeviceNotice(f"{self.model} lost while jogging: jog stopped")] if was else []

    def describe(self) -> str:
        """The mapping and shaping in one line."""
        axes = " ".join(
            f"{a}={'-' if s < 0 else ''}{SOURCES[i]}" for a, (i, s) in self.mapping.items()
        )
        buttons = " ".join(
            f"{n}={b if isinstance(b, str) else b.name}" for n, b in sorted(self.buttons.items())
        )
        return (
            f"{self.model} ({self.transport}): {axes or 'no axes'}, deadzone {self.deadzone:g}, "
            f"expo {self.expo:g}, speed {self.speed:.0%}, dominant "
            f"{'on' if self.dominant else 'off'}; buttons {buttons or 'none'} (check the axis "
            "directions on the machine)"
        )

    # -- shaping and arming -------------------------------------------------------------------

    def _shaped(self) -> dict[str, float]:
        out = {
            # + 0.0 turns a reversed 0 (-0.0) into a plain one.
            axis: sign * expo(deadzone(self._values[index] or 0.0, self.deadzone), self.expo) + 0.0
            for axis, (index, sign) in self.mapping.items()
        }
        return self._dominant_only(out) if self.dominant else out

    def _dominant_only(self, shaped: dict[str, float]) -> dict[str, float]:
        deflected = {a: abs(v) for a, v in shaped.items() if v != 0.0}
        if not deflected:
            self._dominant_axis = None
            return shaped
        best = max(deflected, key=deflected.__getitem__)  # the first in axis order on a tie
        current = self._dominant_axis
        if current in deflected and deflected[best] < deflected[current] + DOMINANT_MARGIN:
            best = current
        self._dominant_axis = best
        return {a: (v if a == best else 0.0) for a, v in shaped.items()}

    def _near_rest(self) -> bool:
        """Every mapped channel known and within the deadzone (or ARM_BAND, if wider)."""
        band = max(self.deadzone, ARM_BAND)
        values = [self._values[index] for index, _ in self.mapping.values()]
        return all(v is not None and abs(v) <= band for v in values)

    def _evaluate(self) -> list[Action]:
        """The jog for the values now: arm near rest, send changes, neutral once."""
        if not self._armed:
            if not self._near_rest():
                return []
            self._armed = True  # and a cap armed near rest may already move gently
        shaped = self._shaped()
        neutral = all(v == 0.0 for v in shaped.values())
        if neutral:
            if self._sent is None:
                return []
            self._sent = None
            return [ContinuousIntent(dict.fromkeys(shaped, 0.0), self.speed)]
        if self._sent == (shaped, self.speed):
            return []
        self._sent = (shaped, self.speed)
        return [ContinuousIntent(shaped, self.speed)]

    def _stop(self, reason: str | None = None) -> list[Action]:
        """Stop now; the cap must come back to neutral before it moves again."""
        self._sent = None
        self._armed = False
        out: list[Action] = [StopIntent()]
        if reason:
            out.append(DeviceNotice(f"{self.model}: {reason}: jog stopped"))
        return out

    def _buttons_to(self, held: set[int], *, fire: bool = True) -> list[Action]:
        pressed = sorted(held - self._held)
        self._held = held
        out: list[Action] = []
        for number in pressed if fire else ():
            action = self.buttons.get(number)
            if action == "stop":
                out.extend(self._stop())
            elif action == "dominant":
                self.dominant = not self.dominant
                self._dominant_axis = None
                out.append(DeviceNotice(f"dominant axis {'on' if self.dominant else 'off'}"))
            elif action in ("faster", "slower"):
                factor = 2.0 if action == "faster" else 0.5
                self.speed = max(SPEED_MIN, min(1.0, self.speed * factor))
                out.append(DeviceNotice(f"{self.model} speed {self.speed:.0%}"))
            elif isinstance(action, DeviceCommand):
                if action.name == "zero" and not action.axes:
                    action = DeviceCommand("zero", axes=tuple(self.mapping))
                out.append(action)
        return out


class SpaceMouseDecoder(_SpaceMouse):
    """A SpaceMouse read from hidraw, old (reports 1 and 2) or new (one 13-byte report 1)."""

    name: ClassVar[str] = "spacemouse"
    transport: ClassVar[Literal["evdev", "hidraw"]] = "hidraw"

    def _read_transport_options(self, options: Table) -> None:
        # The cap streams reports while deflected (125/s alternating, or every 16 ms, devices
        # §5.1), so silence while moving is a lost link (a wireless receiver stays enumerated
        # and never gives EIO). 0.25 s is 15 or more report periods: no false stop from a
        # late report, and a bounded runaway. 0 turns the watchdog off.
        self.watchdog_s = options.number("watchdog_s", 0.25, at_least=0.0, at_most=5.0)

    def _reset(self) -> None:
        super()._reset()
        self._last_t_s = 0.0

    @classmethod
    def matches(cls, info: DeviceInfo) -> bool:
        """The SpaceMouse ids, not the receiver's CadMouse or keyboard."""
        return (info.vendor, info.product) in USB_IDS and not _not_a_spacemouse(info.name)

    def feed(self, item: DeviceItem) -> list[Action]:
        """One hidraw report."""
        data = item.data if isinstance(item, HidReport) else b""
        held = self._held
        if len(data) == NEW_LEN and data[0] == 1:
            self._values[:] = _int16s(data[1:])
        elif len(data) == OLD_LEN and data[0] in (1, 2):
            start = 0 if data[0] == 1 else 3
            self._values[start : start + 3] = _int16s(data[1:])
        elif len(data) >= 2 and data[0] == BUTTON_REPORT:
            mask = int.from_bytes(data[1:9], "little")
            held = {bit + 1 for bit in range(MAX_BUTTONS) if mask >> bit & 1}
        else:
            self.ignored += 1  # battery (0x17), LED echoes, anything unknown
            return []
        self._last_t_s = item.t_s
        out = self._buttons_to(held)
        out.extend(self._evaluate())
        return out

    def deadline_s(self) -> float | None:
        """When a jog with no report since stops."""
        if self._sent is None or self.watchdog_s <= 0.0:
            return None
        return self._last_t_s + self.watchdog_s

    def tick(self, now_s: float) -> list[Action]:
        """Stop a jog the device went silent in."""
        deadline = self.deadline_s()
        if deadline is None or now_s < deadline:
            return []
        self._values = [None] * len(SOURCES)
        return self._stop(f"no report for {self.watchdog_s * 1000:.0f} ms")


class SpaceMouseEvdevDecoder(_SpaceMouse):
    """A SpaceMouse read from its event node.

    EV_REL axes carry deflections, not deltas (devices §5.2). The kernel passes every non-zero
    one in each report and drops the zeros, so the channels of a report's group (translation
    or rotation) absent from a frame that holds one of them are 0, and a channel not refreshed
    within `stale_s` is 0 too. EV_ABS axes come only on change, so they keep their value.
    """

    name: ClassVar[str] = "spacemouse-evdev"
    transport: ClassVar[Literal["evdev", "hidraw"]] = "evdev"

    def _read_transport_options(self, options: Table) -> None:
        # Translation and rotation reports alternate, each every 16 ms (125 reports/s in all;
        # the Wireless sends all six every 16 ms), so 0.05 s is three periods of one group:
        # one late report does not stop the jog, and the zero the kernel dropped on release is
        # noticed within 50 ms (devices §5.2 suggests 25-50 ms).
        self.stale_s = options.number("stale_s", 0.05, above=0.0, at_most=1.0)

    def _reset(self) -> None:
        super()._reset()
        #: When each REL channel was last refreshed (or started to be waited for).
        self._seen_t_s: list[float | None] = [None] * len(SOURCES)
        self._abs: set[int] = set()
        for code, rng in self.info.absinfo.items():
            if 0 <= code < len(SOURCES):
                self._abs.add(code)
                self._values[code] = normalise(rng.value, rng)
        # Absolute axes are known from the start: a cap at rest when opened is armed at once.
        self._armed = self._near_rest()

    @classmethod
    def matches(cls, info: DeviceInfo) -> bool:
        """By id or by a 3Dconnexion name, with translation axes if the kernel lists any."""
        if _not_a_spacemouse(info.name):
            return False
        known = (info.vendor, info.product) in USB_IDS
        named = info.vendor == 0x256F or "3dconnexion" in info.name.lower()
        axes = {0, 1, 2} <= info.rels or {0, 1, 2} <= set(info.absinfo)
        listed = bool(info.rels or info.absinfo)
        return (known and (axes or not listed)) or (named and axes)

    def feed(self, item: DeviceItem) -> list[Action]:
        """One evdev frame."""
        if not isinstance(item, EvdevFrame):
            self.ignored += 1
            return []
        t_s = item.t_s
        out: list[Action] = []
        if item.resync:
            if self._sent is not None:
                out.extend(self._stop("events were lost"))
            self._armed = False
            for code in range(len(SOURCES)):
                if code not in self._abs:
                    self._values[code] = None  # unknown until refreshed or stale
                    self._seen_t_s[code] = t_s
        held = set() if item.resync else set(self._held)
        present: set[int] = set()
        for ev in item.events:
            code = ev.code
            if ev.type == EV_REL and 0 <= code < len(SOURCES) and code not in self._abs:
                self._values[code] = clamp_unit(ev.value / LOGICAL_MAX)
                self._seen_t_s[code] = t_s
                present.add(code)
            elif ev.type == EV_ABS and 0 <= code < len(SOURCES):
                self._abs.add(code)
                self._values[code] = normalise(ev.value, self._range(code))
            elif ev.type == EV_KEY and BTN_0 <= code < BTN_0 + MAX_BUTTONS and ev.value in (0, 1):
                (held.add if ev.value else held.discard)(code - BTN_0 + 1)
            # EV_MSC is dropped by the frames; LEDs, repeats and other codes are ignored.
        for group in {code // 3 for code in present}:
            for code in range(3 * group, 3 * group + 3):
                if code not in present and code not in self._abs:
                    self._values[code] = 0.0
                    self._seen_t_s[code] = t_s
        for code, seen in enumerate(self._seen_t_s):
            if seen is None and code not in self._abs:
                self._seen_t_s[code] = t_s  # start waiting: unknown becomes 0 when stale
        self._expire(t_s)
        out.extend(self._buttons_to(held, fire=not item.resync))
        out.extend(self._evaluate())
        return out

    def _range(self, code: int) -> AbsRange:
        return self.info.absinfo.get(code, AbsRange(0, -LOGICAL_MAX, LOGICAL_MAX))

    def _expire(self, now_s: float) -> None:
        # The same sum as deadline_s(), so a tick at the deadline always expires the channel.
        for code, seen in enumerate(self._seen_t_s):
            if seen is not None and code not in self._abs and now_s >= seen + self.stale_s:
                self._values[code] = 0.0

    def deadline_s(self) -> float | None:
        """When the next deflected or unknown REL channel goes stale."""
        times = [
            seen + self.stale_s
            for code, seen in enumerate(self._seen_t_s)
            if seen is not None and code not in self._abs and self._values[code] != 0.0
        ]
        return min(times) if times else None

    def tick(self, now_s: float) -> list[Action]:
        """Zero the channels whose final zero the kernel dropped."""
        self._expire(now_s)
        return self._evaluate()


def _int16s(data: bytes) -> list[float | None]:
    """Little-endian int16 values, scaled by the logical range and clamped to ±1."""
    return [
        clamp_unit(int.from_bytes(data[i : i + 2], "little", signed=True) / LOGICAL_MAX)
        for i in range(0, len(data) - 1, 2)
    ]


__all__ = ["SOURCES", "USB_IDS", "SpaceMouseDecoder", "SpaceMouseEvdevDecoder"]
