"""Gamepads and joysticks on evdev: sticks, triggers and D-pad to jog intents, buttons to commands.

The same pad reports different codes and ranges under different drivers (devices §7.1), so the
decoder picks its layout from the device's capabilities, never from its brand, and normalises
every axis from the device's own absinfo (devices §9.2):

- right stick on ABS_RX/ABS_RY when the device has them (xpad, xpadneo, hid-playstation), with
  the triggers on ABS_Z/ABS_RZ; otherwise (hid-generic) right stick on ABS_Z/ABS_RZ and the
  triggers on ABS_GAS (right) / ABS_BRAKE (left);
- sticks: centre (min+max)/2, Y inverted (evdev up is negative), radial deadzone rescaled, expo,
  clamp; triggers are one-sided (0..1 from min); the D-pad is ABS_HAT0X/Y, or BTN_DPAD_* and, on
  xpad variants without hat axes, BTN_TRIGGER_HAPPY1-4 (left, right, up, down).

Safety (devices §9.3, the Decoder contract): with a `deadman` button nothing moves unless it is
held, and releasing it sends an explicit StopIntent; after a release, a loss, a resync, a stop
button or a start with a stick deflected, motion resumes only once the sticks have been back
inside the deadzone (with the dead-man held, when there is one).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

from smoothjog.core.intents import (
    STEP_MAX_MM,
    STEP_MIN_MM,
    ContinuousIntent,
    StepIntent,
    StopIntent,
)
from smoothjog.core.options import Table
from smoothjog.core.units import ALL_AXES
from smoothjog.inputs.device import (
    EV_ABS,
    EV_KEY,
    AbsRange,
    Action,
    Decoder,
    DeviceCommand,
    DeviceInfo,
    DeviceItem,
    DeviceNotice,
    EvdevEvent,
    EvdevFrame,
)
from smoothjog.inputs.shaping import clamp_unit, deadzone, expo, normalise, radial_deadzone

# Absolute axis codes (linux/input-event-codes.h).
ABS_X, ABS_Y, ABS_Z, ABS_RX, ABS_RY, ABS_RZ = 0x00, 0x01, 0x02, 0x03, 0x04, 0x05
ABS_GAS, ABS_BRAKE, ABS_HAT0X, ABS_HAT0Y = 0x09, 0x0A, 0x10, 0x11
BTN_DPAD_UP, BTN_DPAD_DOWN, BTN_DPAD_LEFT, BTN_DPAD_RIGHT = 0x220, 0x221, 0x222, 0x223
BTN_TRIGGER_HAPPY1 = 0x2C0
#: BTN_JOYSTICK (0x120..0x12f) and BTN_GAMEPAD (0x130..0x13f): a joystick's or a pad's buttons.
_JOY_BUTTONS = range(0x120, 0x140)

# Ranges used when the device does not give absinfo for a code (a recording without evtest's
# header): xpad's sticks, the Xbox One triggers (xpad, xpadneo) and the hat's -1..1 (devices §7.1).
STICK_DEFAULT = AbsRange(0, -32768, 32767)
TRIGGER_DEFAULT = AbsRange(0, 0, 1023)
HAT_DEFAULT = AbsRange(0, -1, 1)
#: An event value is an s32 from the kernel; anything wider is clamped to it, never raised on.
_S32 = (-(2**31), 2**31 - 1)

#: Button names, the kernel's without "BTN_" (the code's names, not the labels printed on a pad).
BUTTON_CODES: dict[str, int] = {
    "south": 0x130, "a": 0x130, "gamepad": 0x130, "east": 0x131, "b": 0x131, "c": 0x132,
    "north": 0x133, "x": 0x133, "west": 0x134, "y": 0x134, "z": 0x135,
    "tl": 0x136, "tr": 0x137, "tl2": 0x138, "tr2": 0x139, "select": 0x13A, "start": 0x13B,
    "mode": 0x13C, "thumbl": 0x13D, "thumbr": 0x13E,
    "trigger": 0x120, "joystick": 0x120, "thumb": 0x121, "thumb2": 0x122, "top": 0x123,
    "top2": 0x124, "pinkie": 0x125, "base": 0x126, "base2": 0x127, "base3": 0x128,
    "base4": 0x129, "base5": 0x12A, "base6": 0x12B, "dead": 0x12F,
    "dpad_up": BTN_DPAD_UP, "dpad_down": BTN_DPAD_DOWN, "dpad_left": BTN_DPAD_LEFT,
    "dpad_right": BTN_DPAD_RIGHT,
    **{f"trigger_happy{n}": BTN_TRIGGER_HAPPY1 + n - 1 for n in range(1, 41)},
}  # fmt: skip
_BUTTON_NAMES: dict[int, str] = {}
for _name, _code in BUTTON_CODES.items():
    _BUTTON_NAMES.setdefault(_code, "BTN_" + _name.upper())  # the first name listed is shown

STICK_SOURCES = ("left_x", "left_y", "right_x", "right_y")
TRIGGER_SOURCES = ("left_trigger", "right_trigger")
SOURCES = STICK_SOURCES + TRIGGER_SOURCES
DEFAULT_AXES: Mapping[str, str] = {"X": "left_x", "Y": "left_y", "Z": "right_y"}
DEFAULT_SPEEDS = (0.1, 0.25, 0.5, 1.0)
HAT_MODES = ("step", "slow", "off")
#: What a button may do: a StopIntent, or the DeviceCommand of that name ("zero" = all axes).
#: override is left out: it needs a kind and a step, which a plain button name cannot carry.
BUTTON_ACTIONS = ("stop", "zero", "unlock", "home", "reset", "goto_zero", "hold", "resume")
#: Commands that move the machine: with a dead-man configured they need it held.
_MOVING_COMMANDS = frozenset({"home", "goto_zero", "resume"})
#: Commands after which a held stick must come back to neutral before it jogs again (in Grbl a
#: feed hold or a reset cancels a jog too).
_STOPPING_COMMANDS = frozenset({"stop", "hold", "reset"})


def button_code(name: str) -> int | None:
    """The evdev code of a button named "BTN_EAST", "east" or "East"; None if unknown."""
    key = name.strip().lower()
    return BUTTON_CODES.get(key.removeprefix("btn_"))


def button_name(code: int) -> str:
    """A button code as the kernel names it ("BTN_TL"), or in hex when it has no name here."""
    return _BUTTON_NAMES.get(code, f"button 0x{code:x}")


def shape_stick(
    x_raw: int, y_raw: int, x_rng: AbsRange, y_rng: AbsRange, dz: float, k: float
) -> tuple[float, float]:
    """A stick pair as (x, y) in [-1, 1], up positive: centred, radial deadzone, expo, clamp."""
    x = normalise(x_raw, x_rng)
    y = -normalise(y_raw, y_rng)  # evdev up is negative (devices §7.1, xpad)
    x, y = radial_deadzone(x, y, dz)
    return expo(x, k), expo(y, k)


def shape_trigger(raw: int, rng: AbsRange, dz: float, k: float) -> float:
    """A trigger as 0..1 from its rest at min: deadzone rescaled, expo, clamp."""
    return expo(deadzone(normalise(raw, rng, one_sided=True), dz), k)


@dataclass(frozen=True)
class AxisSource:
    """What drives one machine axis: a source, minus another (a trigger pair), times a sign."""

    plus: str
    minus: str | None = None
    sign: float = 1.0


def parse_source(text: str) -> AxisSource | None:
    """ "left_x", "-right_y" or "right_trigger-left_trigger"; None if not one of these."""
    body = text.strip().lower()
    sign = 1.0
    if body.startswith("-"):
        sign, body = -1.0, body[1:]
    parts = body.split("-")
    if len(parts) == 1 and parts[0] in SOURCES:
        return AxisSource(parts[0], None, sign)
    if len(parts) == 2 and set(parts) == set(TRIGGER_SOURCES):
        return AxisSource(parts[0], parts[1], sign)
    return None


@dataclass(frozen=True)
class Layout:
    """Which evdev code carries which control on this device."""

    left: tuple[int, int]
    right: tuple[int, int]
    left_trigger: int
    right_trigger: int

    @classmethod
    def of(cls, info: DeviceInfo) -> Layout:
        """By capabilities; a device with no absinfo (a headerless recording) gets xpad's."""
        caps = info.absinfo
        if not caps or ABS_RX in caps or ABS_RY in caps:
            return cls((ABS_X, ABS_Y), (ABS_RX, ABS_RY), ABS_Z, ABS_RZ)
        # hid-generic: which of GAS/BRAKE is which trigger is not in devices §7.1; assumed as a
        # car's pedals, gas = right, brake = left.
        return cls((ABS_X, ABS_Y), (ABS_Z, ABS_RZ), ABS_BRAKE, ABS_GAS)


class GamepadDecoder(Decoder):
    """A gamepad or joystick on evdev: continuous jogs from the sticks, steps from the D-pad.

    Options, with their defaults: deadzone 0.15 (gSender's; xpadneo rests 12.5 % off centre),
    expo 0.3, axes { X = "left_x", Y = "left_y", Z = "right_y" } (sources: left_x, left_y,
    right_x, right_y with up positive, left_trigger, right_trigger 0..1, "-" in front inverts,
    "right_trigger-left_trigger" makes a two-way axis of the triggers), hat "step" (each D-pad
    press one step of hat_step_mm 1.0; "slow": held = a jog at hat_speed 0.1; "off"), speeds
    [0.1, 0.25, 0.5, 1.0] from speed_index 2 stepped by speed_up "BTN_TR" / speed_down
    "BTN_TL", deadman (none), buttons { east = "stop" } (a command from BUTTON_ACTIONS or
    "none"). A button given "none" is unused; a default gives way to a button bound elsewhere.
    """

    name: ClassVar[str] = "gamepad"
    kind: ClassVar[str] = "gamepad"
    transport: ClassVar[Literal["evdev", "hidraw"]] = "evdev"

    def __init__(self, info: DeviceInfo, options: Table, axes: Sequence[str]) -> None:
        """Read the options (see the class docstring); raises ConfigError naming the key."""
        super().__init__(info, options, axes)
        self.deadzone = options.number("deadzone", 0.15, at_least=0.0, at_most=0.9)
        self.expo = options.number("expo", 0.3, at_least=0.0, at_most=1.0)
        self.mapping = self._read_axes(options)
        self.hat_mode = options.choice("hat", "step", HAT_MODES)
        self.hat_step_mm = options.number(
            "hat_step_mm", 1.0, at_least=STEP_MIN_MM, at_most=STEP_MAX_MM
        )
        self.hat_speed = options.number("hat_speed", 0.1, above=0.0, at_most=1.0)
        self.speeds = self._read_speeds(options)
        last = len(self.speeds) - 1
        self.speed_index = options.integer("speed_index", min(2, last), at_least=0, at_most=last)
        self._bound: dict[int, str] = {}  # code -> the key that bound it
        self.deadman = self._explicit_button(options, "deadman")
        self.commands = self._read_buttons(options)
        self.speed_up = self._explicit_button(options, "speed_up")
        self.speed_down = self._explicit_button(options, "speed_down")
        # Defaults give way to a button the user bound (deadman = "tl" drops speed_down's tl).
        if "speed_up" not in options.data:
            self.speed_up = self._default_button("speed_up", "tr")
        if "speed_down" not in options.data:
            self.speed_down = self._default_button("speed_down", "tl")
        if self._default_button("buttons.east", "east") is not None:
            self.commands[BUTTON_CODES["east"]] = "stop"
        options.finish()

        self.layout = lay = Layout.of(info)
        defaults = dict.fromkeys((*lay.left, *lay.right), STICK_DEFAULT)
        defaults |= dict.fromkeys((lay.left_trigger, lay.right_trigger), TRIGGER_DEFAULT)
        defaults |= dict.fromkeys((ABS_HAT0X, ABS_HAT0Y), HAT_DEFAULT)
        self._ranges = {code: info.absinfo.get(code, d) for code, d in defaults.items()}
        # D-pad buttons; xpad's TRIGGER_HAPPY1-4 only where there are no hat axes, since other
        # drivers use those codes for extra buttons (xpadneo's paddles). A button bound to
        # something else is that, not a direction.
        dpad = {BTN_DPAD_LEFT: (-1, 0), BTN_DPAD_RIGHT: (1, 0)}
        dpad |= {BTN_DPAD_UP: (0, 1), BTN_DPAD_DOWN: (0, -1)}
        if ABS_HAT0X not in info.absinfo:
            dirs = ((-1, 0), (1, 0), (0, 1), (0, -1))  # xpad_btn_pad: left, right, up, down
            dpad |= {BTN_TRIGGER_HAPPY1 + i: d for i, d in enumerate(dirs)}
        self._dpad = {c: d for c, d in dpad.items() if c not in self._bound}

        hat_axes = ("X", "Y") if self.hat_mode == "slow" else ()
        self.jog_axes = tuple(a for a in self.axes if a in self.mapping or a in hat_axes)
        # The codes whose value must be known before a jog may start (after a loss): those
        # the device has (all, for a headerless recording) that feed a mapped axis; both of a
        # stick's, since its deadzone is radial.
        feeds: dict[str, tuple[int, ...]] = {"left_x": lay.left, "left_y": lay.left}
        feeds |= {"right_x": lay.right}
        feeds |= {"right_y": lay.right, "left_trigger": (lay.left_trigger,)}
        feeds |= {"right_trigger": (lay.right_trigger,), "hat": (ABS_HAT0X, ABS_HAT0Y)}
        used = {s for src in self.mapping.values() for s in (src.plus, src.minus) if s}
        if self.hat_mode == "slow":
            used.add("hat")
        present = info.absinfo.keys() if info.absinfo else self._ranges.keys()
        self._needed = frozenset(c for s in used for c in feeds[s] if c in present)
        self._reset()
        # Start-up: absinfo's value is where each axis is now; a stick already deflected
        # must come back to neutral first.
        for code, rng in self._ranges.items():
            self._values[code] = rng.value if code in info.absinfo else self._rest(code)
        self._hat_prev = self._hat()
        self._arm_if_neutral(not any(self._demand()[0].values()))

    # -- options -----------------------------------------------------------------------------

    def _read_axes(self, options: Table) -> dict[str, AxisSource]:
        raw: Mapping[str, Any] = options.table("axes") if "axes" in options.data else DEFAULT_AXES
        mapping: dict[str, AxisSource] = {}
        for key, value in raw.items():
            axis = str(key).upper()
            if axis not in ALL_AXES or axis in mapping:
                problem = "is given twice" if axis in mapping else "is not a machine axis"
                raise options.error(f"axes.{key}", f"{problem}: use one of {', '.join(ALL_AXES)}")
            source = parse_source(value) if isinstance(value, str) else None
            if source is None:
                raise options.error(
                    f"axes.{key}",
                    f"= {value!r} is not a source: use one of {', '.join(SOURCES)}, with '-' in "
                    "front to invert, or 'right_trigger-left_trigger'",
                )
            if axis in self.axes:  # an axis the machine lacks is dropped
                mapping[axis] = source
        return mapping

    @staticmethod
    def _read_speeds(options: Table) -> tuple[float, ...]:
        raw = options.raw("speeds")
        if raw is None:
            return DEFAULT_SPEEDS
        if not isinstance(raw, list) or not 1 <= len(raw) <= len(ALL_AXES):
            raise options.error(
                "speeds",
                f"= {raw!r} is not a list of 1 to {len(ALL_AXES)} speeds: write e.g. "
                "speeds = [0.1, 0.25, 0.5, 1.0] (fractions of the max feed)",
            )
        values = options.numbers("speeds")
        for v in values:
            options.check_number("speeds", v, above=0.0, at_most=1.0)
        return values

    def _button(self, options: Table, key: str, name: str) -> int:
        code = button_code(name)
        if code is None:
            raise options.error(
                key, f"= {name!r} is not a button: use a name like BTN_EAST, east, tl or start"
            )
        if code in self._bound:
            raise options.error(
                key,
                f"= {name!r} is {button_name(code)}, already used by {self._bound[code]}: "
                "pick another button",
            )
        self._bound[code] = key
        return code

    def _explicit_button(self, options: Table, key: str) -> int | None:
        name = options.text(key, None)
        if name is None or name.strip().lower() == "none":
            return None
        return self._button(options, key, name)

    def _default_button(self, key: str, name: str) -> int | None:
        code = BUTTON_CODES[name]
        if code in self._bound:
            return None
        self._bound[code] = key
        return code

    def _read_buttons(self, options: Table) -> dict[int, str]:
        commands: dict[int, str] = {}
        for name, value in options.table("buttons").items():
            key = f"buttons.{name}"
            action = value.strip().lower() if isinstance(value, str) else None
            if action not in (*BUTTON_ACTIONS, "none"):
                raise options.error(
                    key,
                    f"= {value!r} is not a command: use one of {', '.join(BUTTON_ACTIONS)}, "
                    "or 'none' to leave the button unused",
                )
            code = self._button(options, key, str(name))
            if action != "none":
                commands[code] = str(action)
        return commands

    # -- state -------------------------------------------------------------------------------

    def _reset(self) -> None:
        self._values: dict[int, int] = {}  # absent = not known (after a loss)
        self._held: set[int] = set()
        self._armed = False  # False: the sticks must come back to neutral before a jog
        self._last: tuple[tuple[float, ...], float] | None = None  # the jog sent, None = none
        self._step_held = False  # a D-pad step was sent and the D-pad is still pressed
        self._sent_motion = False  # anything moved since the dead-man was pressed
        self._told_neutral = False
        self._hat_prev = (0, 0)

    @property
    def speed(self) -> float:
        """The current entry of the speed list (a fraction of the max feed)."""
        return self.speeds[self.speed_index]

    @property
    def moving(self) -> bool:
        """True while a stick or slow D-pad jog is held, or the D-pad is held after a step."""
        return self._last is not None or self._step_held

    def _rest(self, code: int) -> int:
        rng = self._ranges[code]
        if code in (self.layout.left_trigger, self.layout.right_trigger):
            return rng.min
        return (rng.min + rng.max) // 2

    def _value(self, code: int) -> int:
        return self._values.get(code, self._rest(code))

    def _deadman_ok(self) -> bool:
        return self.deadman is None or self.deadman in self._held

    def _sources(self) -> dict[str, float]:
        dz, k, r = self.deadzone, self.expo, self._ranges
        (lx, ly), (rx, ry) = self.layout.left, self.layout.right
        lt, rt = self.layout.left_trigger, self.layout.right_trigger
        left = shape_stick(self._value(lx), self._value(ly), r[lx], r[ly], dz, k)
        right = shape_stick(self._value(rx), self._value(ry), r[rx], r[ry], dz, k)
        return {
            "left_x": left[0],
            "left_y": left[1],
            "right_x": right[0],
            "right_y": right[1],
            "left_trigger": shape_trigger(self._value(lt), r[lt], dz, k),
            "right_trigger": shape_trigger(self._value(rt), r[rt], dz, k),
        }

    def _hat(self) -> tuple[int, int]:
        """The D-pad as (x, y), right and up positive, from the hat axes and D-pad buttons."""
        if self.hat_mode == "off":
            return (0, 0)

        def sign(code: int) -> int:
            n = normalise(self._value(code), self._ranges[code])
            return 1 if n > 0.5 else -1 if n < -0.5 else 0

        x, y = sign(ABS_HAT0X), -sign(ABS_HAT0Y)  # evdev up is -1
        for code in self._held & self._dpad.keys():
            dx, dy = self._dpad[code]
            x, y = x + dx, y + dy
        return max(-1, min(1, x)), max(-1, min(1, y))

    def _demand(self) -> tuple[dict[str, float], float]:
        """What the controls ask for now, over jog_axes, with its speed."""
        hat = self._hat() if self.hat_mode == "slow" else (0, 0)
        if hat != (0, 0):  # a held slow D-pad takes over from the sticks
            dirs = {"X": float(hat[0]), "Y": float(hat[1])}
            return {a: dirs.get(a, 0.0) for a in self.jog_axes}, self.hat_speed
        src = self._sources()
        demand: dict[str, float] = {}
        for axis in self.jog_axes:
            s = self.mapping.get(axis)
            if s is None:
                demand[axis] = 0.0
                continue
            value = src[s.plus] - (src[s.minus] if s.minus else 0.0)
            demand[axis] = clamp_unit(s.sign * value)
        return demand, self.speed

    # -- the contract ------------------------------------------------------------------------

    def feed(self, item: DeviceItem) -> list[Action]:
        """One evdev frame (hidraw reports are ignored)."""
        if not isinstance(item, EvdevFrame):
            return []
        out: list[Action] = []
        if item.resync:
            released = self._resync(item.events, out)
        else:
            released = False
            for ev in item.events:
                released = self._event(ev, out) or released
        if released:
            # The dead-man let go: an explicit stop (devices §9.3, teleop_twist_joy#29), which
            # also drops queued D-pad steps; a jog needs neutral with the dead-man held again.
            if self._sent_motion or self.moving:
                out.append(StopIntent())
            self._armed, self._last, self._step_held, self._sent_motion = False, None, False, False
        hat = self._hat()
        if self.hat_mode == "step" and not item.resync:
            self._steps(self._hat_prev, hat, out)
        if hat == (0, 0):
            self._step_held = False
        self._hat_prev = hat
        self._update(out)
        return out

    def _event(self, ev: EvdevEvent, out: list[Action]) -> bool:
        """Apply one event; True when it released the dead-man."""
        if ev.type == EV_ABS and ev.code in self._ranges:
            self._values[ev.code] = max(_S32[0], min(_S32[1], ev.value))
        elif ev.type == EV_KEY and ev.value == 1:
            self._held.add(ev.code)
            self._press(ev.code, out)
        elif ev.type == EV_KEY and ev.value == 0 and ev.code in self._held:
            self._held.discard(ev.code)
            return ev.code == self.deadman
        # EV_KEY value 2 is autorepeat: a held button is one press (devices §3.1).
        return False

    def _resync(self, events: Sequence[EvdevEvent], out: list[Action]) -> bool:
        """A full state after SYN_DROPPED; True when it shows the dead-man let go."""
        held: set[int] = set()
        for ev in events:
            if ev.type == EV_ABS and ev.code in self._ranges:
                self._values[ev.code] = max(_S32[0], min(_S32[1], ev.value))
            elif ev.type == EV_KEY and ev.value:
                held.add(ev.code)
        # Presses lost in the gap are not replayed, except a stop: stopping is always safe.
        if any(self.commands.get(c) == "stop" for c in held - self._held):
            out.extend(self._command("stop"))
        released = self.deadman in self._held and self.deadman not in held
        self._held = held
        if any(self._demand()[0].values()):
            self._armed = False  # deflected after lost events: back to neutral first
        return released

    def _press(self, code: int, out: list[Action]) -> None:
        if code == self.deadman:
            self._sent_motion = False
        elif code in (self.speed_up, self.speed_down):
            step = 1 if code == self.speed_up else -1
            index = max(0, min(len(self.speeds) - 1, self.speed_index + step))
            if index != self.speed_index:
                self.speed_index = index
                out.append(DeviceNotice(f"gamepad speed {self.speed * 100:g} %"))
        elif code in self.commands:
            out.extend(self._command(self.commands[code]))

    def _command(self, action: str) -> list[Action]:
        if action in _MOVING_COMMANDS and not self._deadman_ok():
            assert self.deadman is not None
            return [DeviceNotice(f"gamepad: hold {button_name(self.deadman)} to {action}")]
        if action in _STOPPING_COMMANDS:
            self._armed = False
        if action == "stop":
            self._last, self._step_held = None, False  # the StopIntent ends the jog
            return [StopIntent(button=True)]
        if action == "zero":
            return [DeviceCommand("zero", axes=self.axes)]
        return [DeviceCommand(action)]

    def _steps(self, before: tuple[int, int], now: tuple[int, int], out: list[Action]) -> None:
        """One step per new D-pad direction: X for left/right, Y for up/down."""
        if not self._deadman_ok():
            return
        for axis, old, new in (("X", before[0], now[0]), ("Y", before[1], now[1])):
            if new and new != old and axis in self.axes:
                out.append(StepIntent(axis, new * self.hat_step_mm, self.speed))
                self._step_held = self._sent_motion = True

    def _arm_if_neutral(self, neutral: bool) -> None:
        """Ready to jog once every needed stick is known and at rest, with the dead-man held."""
        if neutral and self._needed <= self._values.keys() and self._deadman_ok():
            self._armed, self._told_neutral = True, False

    def _update(self, out: list[Action]) -> None:
        """Send the jog when it changed; neutral once when it ends."""
        demand, speed = self._demand()
        neutral = not any(demand.values())
        self._arm_if_neutral(neutral)
        # Armed implies the dead-man held (released disarms); checked again for safety's sake.
        if self._armed and self._deadman_ok() and not neutral:
            key = (tuple(demand.values()), speed)
            if key != self._last:
                out.append(ContinuousIntent(demand, speed))
                self._last, self._sent_motion = key, True
            return
        if self._last is not None:
            out.append(ContinuousIntent(dict.fromkeys(self.jog_axes, 0.0), self.speed))
            self._last = None
        if not neutral and not self._armed and self._deadman_ok() and not self._told_neutral:
            self._told_neutral = True
            out.append(DeviceNotice("gamepad: let the sticks return to centre before jogging"))

    def lost(self) -> list[Action]:
        """Forget everything; a jog needs every stick reported back at rest first."""
        self._reset()
        name = self.info.name
        return [DeviceNotice(f"gamepad {name!r} lost: it jogs again once its sticks are at rest")]

    @classmethod
    def matches(cls, info: DeviceInfo) -> bool:
        """A device with ABS_X, ABS_Y and joystick or gamepad buttons (0x120..0x13f)."""
        has_sticks = ABS_X in info.absinfo and ABS_Y in info.absinfo
        return has_sticks and any(code in _JOY_BUTTONS for code in info.keys)

    def describe(self) -> str:
        """E.g. "gamepad: speed 50 %, dead-man BTN_TL"."""
        guard = f"dead-man {button_name(self.deadman)}" if self.deadman is not None else ""
        return f"gamepad: speed {self.speed * 100:g} %, {guard or 'no dead-man'}"
