"""Keyboards and numeric keypads as pendants: held keys jog, taps step, other keys run commands.

A USB numeric keypad is the cheapest pendant there is (the author of the smooth-jogging post this
project grew from built one). evdev gives one EV_KEY event per change: value 1 press, 0 release,
2 autorepeat (devices §3.1). Jogging is hold-to-run, the held key being the dead-man (devices
§9.3): each held jog key adds its direction (two axes held = a diagonal), opposite keys on one
axis cancel, and letting go of the last one sends neutral, once. Autorepeat is ignored, so a
held key is one press, never a queue of steps.

At the evdev level KP8 is KEY_KP8 whatever the NumLock light says, and some keypads inject
NumLock presses of their own around other keys (devices §13), so the bindings are on KEY_KP*
and KEY_NUMLOCK is ignored (and cannot be bound).

The DeviceInput should grab the device (EVIOCGRAB): a keypad that is not grabbed also types into
the console of a headless Pi (devices §3.1).

Options (all optional):
- `keys`: a table from key name ("KEY_KP4", "kp4", "left", "f1") to action, merged over the
  default map; "none" unbinds a default. Actions: an axis and direction ("X+", "z-"), "stop",
  "speed+", "speed-", "step" (toggles step mode), or a machine command by DEVICE_COMMANDS'
  names ("home", "zero" for every axis or "zero:XY", "override:feed:+10"). A binding to an axis
  the machine lacks is dropped, so one keymap serves a 2-axis laser and a 3-axis router.
- `speeds` = [0.1, 0.25, 0.5, 1.0] (fractions of the max feed) and `speed_index` = 1.
- `tap_step_mm`: off by default. When set, a jog key released within `tap_s` (0.25 s) steps
  tap_step_mm; held longer it jogs. Off, a press jogs at once.
- `step_mm` = 0.1: the step of step mode, where every press is one step.
- `mode` = "jog" or "step": the mode at start.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final

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
    DEVICE_COMMANDS,
    EV_KEY,
    Action,
    Decoder,
    DeviceCommand,
    DeviceInfo,
    DeviceItem,
    DeviceNotice,
    EvdevFrame,
    parse_command,
)

# -- key names -------------------------------------------------------------------------------

#: Runs of consecutive evdev key codes (linux/input-event-codes.h): the first code, then the
#: names that follow it one code apart. Only the keys a pendant may plausibly use.
_KEY_RUNS: Final = (
    (1, "ESC 1 2 3 4 5 6 7 8 9 0 MINUS EQUAL BACKSPACE TAB Q W E R T Y U I O P LEFTBRACE"),
    (27, "RIGHTBRACE ENTER LEFTCTRL A S D F G H J K L SEMICOLON APOSTROPHE GRAVE LEFTSHIFT"),
    (43, "BACKSLASH Z X C V B N M COMMA DOT SLASH RIGHTSHIFT KPASTERISK LEFTALT SPACE CAPSLOCK"),
    (59, "F1 F2 F3 F4 F5 F6 F7 F8 F9 F10 NUMLOCK SCROLLLOCK KP7 KP8 KP9 KPMINUS KP4 KP5 KP6"),
    (78, "KPPLUS KP1 KP2 KP3 KP0 KPDOT"),
    (87, "F11 F12"),
    (96, "KPENTER RIGHTCTRL KPSLASH SYSRQ RIGHTALT"),
    (102, "HOME UP PAGEUP LEFT RIGHT END DOWN PAGEDOWN INSERT DELETE"),
    (113, "MUTE VOLUMEDOWN VOLUMEUP POWER KPEQUAL"),
    (125, "LEFTMETA RIGHTMETA"),
    (163, "NEXTSONG PLAYPAUSE PREVIOUSSONG STOPCD"),
    (256, "BTN_0 BTN_1 BTN_2 BTN_3 BTN_4 BTN_5 BTN_6 BTN_7 BTN_8 BTN_9"),
    (272, "BTN_LEFT BTN_RIGHT BTN_MIDDLE"),
)

#: evdev key codes by name: KEY_ names without the prefix ("KP4"), BTN_ names with it.
KEY_CODES: Final[Mapping[str, int]] = {
    name: first + i for first, names in _KEY_RUNS for i, name in enumerate(names.split())
}
_KEY_NAMES: Final = {code: name for name, code in KEY_CODES.items()}


def key_code(name: str) -> int | None:
    """The evdev code of a key named "KEY_KP4", "kp4" or "BTN_0", or None if unknown."""
    upper = name.strip().upper()
    return KEY_CODES.get(upper.removeprefix("KEY_"))


def key_name(code: int) -> str:
    """The kernel's name of a key code, for messages ("KEY_KP4", "BTN_0")."""
    name = _KEY_NAMES.get(code)
    if name is None:
        return f"key {code}"
    return name if name.startswith("BTN_") else f"KEY_{name}"


KEY_NUMLOCK: Final = KEY_CODES["NUMLOCK"]
_KEYPAD_DIGITS: Final = frozenset(KEY_CODES[f"KP{n}"] for n in range(10))
_LETTERS: Final = frozenset(KEY_CODES[chr(c)] for c in range(ord("A"), ord("Z") + 1))

#: USB ids of encoder knobs that declare a whole keyboard but send only volume keys
#: (devices §13: 413d:553a declares dozens of keys and ABS axes).
KNOB_USB_IDS: Final = frozenset({"413d:553a"})
#: The consumer keys a volume knob sends; a device declaring only these is a knob.
MEDIA_KEYS: Final = frozenset(
    KEY_CODES[n]
    for n in ("MUTE", "VOLUMEDOWN", "VOLUMEUP", "NEXTSONG", "PLAYPAUSE", "PREVIOUSSONG", "STOPCD")
)

_VOLUME_KEYS: Final = frozenset({KEY_CODES["VOLUMEUP"], KEY_CODES["VOLUMEDOWN"]})


def is_media_knob(info: DeviceInfo) -> bool:
    """Whether a keyboard-class device is really a volume knob (its keys say so, or its id)."""
    if info.usb_id in KNOB_USB_IDS:
        return True
    return bool(info.keys) and info.keys <= MEDIA_KEYS and info.keys.issuperset(_VOLUME_KEYS)


# -- bindings --------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Jog:
    """A key that jogs one axis one way."""

    axis: str
    sign: int  # +1 or -1


#: Actions handled inside the decoder (besides jogs and machine commands).
_CONTROLS: Final = ("stop", "speed+", "speed-", "step")

_Binding = _Jog | DeviceCommand | str

#: The default map: the keypad's arrows as a keypad is labelled, the same on the arrow keys.
DEFAULT_KEYS: Final[Mapping[str, str]] = {
    "KP4": "X-",
    "KP6": "X+",
    "KP8": "Y+",
    "KP2": "Y-",
    "KP9": "Z+",
    "KP3": "Z-",
    "LEFT": "X-",
    "RIGHT": "X+",
    "UP": "Y+",
    "DOWN": "Y-",
    "PAGEUP": "Z+",
    "PAGEDOWN": "Z-",
    "KP5": "stop",
    "KP0": "stop",
    "ESC": "stop",
    "KPPLUS": "speed+",
    "KPMINUS": "speed-",
}

DEFAULT_SPEEDS: Final = (0.1, 0.25, 0.5, 1.0)
DEFAULT_TAP_S: Final = 0.25


def list_option(options: Table, key: str) -> list[Any] | None:
    """The raw list under key, marked read (None when absent); the items are the caller's."""
    value = options.raw(key)
    if value is None:
        return None
    if not isinstance(value, list) or not value:
        raise options.error(key, f"= {value!r} is not a list: write e.g. {key} = [0.1, 1.0]")
    return value


def _parse_action(options: Table, where: str, text: Any, axes: Sequence[str]) -> _Binding | None:
    """One binding's action; None for "none" or an axis the machine does not have."""
    if not isinstance(text, str) or not text.strip():
        raise options.error(where, f'= {text!r} is not an action: write e.g. {where} = "X+"')
    word = text.strip()
    low = word.lower()
    if low == "none":
        return None
    if len(word) == 2 and word[1] in "+-" and word[0].upper() in ALL_AXES:
        axis = word[0].upper()
        # Dropped, not refused: one keymap may serve machines with and without that axis.
        return _Jog(axis, 1 if word[1] == "+" else -1) if axis in axes else None
    if low in _CONTROLS:
        return low
    try:
        command = parse_command(low)
    except ValueError as exc:
        raise options.error(where, f"= {word!r} {exc}") from None
    if command is not None:
        if command.name != "zero":
            return command
        # A bare "zero" on a keypad means every axis of the machine.
        chosen = command.axes or tuple(axes)
        missing = [a for a in chosen if a not in axes]
        if missing:
            raise options.error(
                where,
                f"= {word!r} names {''.join(missing)}: the machine has {', '.join(axes)}",
            )
        return DeviceCommand("zero", axes=chosen)
    raise options.error(
        where,
        f"= {word!r} is not an action: use an axis and direction (X+, Z-), stop, speed+, "
        f"speed-, step, or a machine command ({', '.join(DEVICE_COMMANDS)}; zero:XY, "
        "override:feed:+10)",
    )


def _read_bindings(options: Table, axes: Sequence[str]) -> dict[int, _Binding]:
    """The default map with the `keys` table merged over it, by key code."""
    named: dict[int, tuple[str, Any]] = {}
    for name, action in DEFAULT_KEYS.items():
        named[KEY_CODES[name]] = (f"keys.{name.lower()}", action)
    for name, action in options.table("keys").items():
        where = f"keys.{name}"
        code = key_code(name)
        if code is None:
            raise options.error(where, "is not a key name: write e.g. kp4, KEY_LEFT or f1")
        if code == KEY_NUMLOCK:
            raise options.error(
                where,
                "cannot be bound: some keypads send NumLock presses of their own around other "
                "keys; bind the KP keys, which do not depend on NumLock",
            )
        named[code] = (where, action)
    bindings: dict[int, _Binding] = {}
    for code, (where, action) in named.items():
        binding = _parse_action(options, where, action, axes)
        if binding is not None:
            bindings[code] = binding
    return bindings


# -- the decoder -----------------------------------------------------------------------------


class KeyboardDecoder(Decoder):
    """A keyboard or numeric keypad: hold-to-jog on held keys, optional taps, key commands."""

    name = "keyboard"
    kind = "keyboard"
    transport = "evdev"

    def __init__(self, info: DeviceInfo, options: Table, axes: Sequence[str]) -> None:
        """Read the options (see the module docstring); every default is usable."""
        super().__init__(info, options, axes)
        self._bindings = _read_bindings(options, self.axes)
        self._speeds = self._read_speeds(options)
        top = len(self._speeds) - 1
        self._start_speed_index = options.integer(
            "speed_index", min(1, top), at_least=0, at_most=top
        )
        self._tap_step_mm: float | None = None
        if options.data.get("tap_step_mm") is not None:
            self._tap_step_mm = options.number(
                "tap_step_mm", 0.0, at_least=STEP_MIN_MM, at_most=STEP_MAX_MM
            )
        self._tap_s = options.number("tap_s", DEFAULT_TAP_S, above=0.0, at_most=2.0)
        self._step_mm = options.number("step_mm", 0.1, at_least=STEP_MIN_MM, at_most=STEP_MAX_MM)
        self._start_step_mode = options.choice("mode", "jog", ("jog", "step")) == "step"
        options.finish()
        #: The axes the keymap jogs, in the machine's order: every ContinuousIntent names
        #: them all, so equal vectors compare equal and neutral is all of them at 0.
        jogged = {b.axis for b in self._bindings.values() if isinstance(b, _Jog)}
        self._jog_axes = tuple(a for a in self.axes if a in jogged)
        self._reset()

    @staticmethod
    def _read_speeds(options: Table) -> tuple[float, ...]:
        raw = list_option(options, "speeds")
        if raw is None:
            return DEFAULT_SPEEDS
        if len(raw) > 20:
            raise options.error("speeds", f"has {len(raw)} entries: give at most 20")
        return tuple(options.check_number("speeds", v, above=0.0, at_most=1.0) for v in raw)

    def _reset(self) -> None:
        """Forget every key and go back to the configured speed and mode."""
        #: Jog keys driving the continuous jog.
        self._held: set[int] = set()
        #: Jog keys pressed from rest while taps are on, not yet a hold; since when.
        self._pending: set[int] = set()
        self._pending_since_s: float | None = None
        self._speed_index = self._start_speed_index
        self._step_mode = self._start_step_mode
        #: The deflections and speed last sent; neutral at rest.
        self._sent = self._neutral()
        self._sent_speed = self.speed

    # -- the contract ------------------------------------------------------------------------

    @classmethod
    def matches(cls, info: DeviceInfo) -> bool:
        """A device declaring the keypad digits or a full alphabet, unless it is a volume knob."""
        if is_media_knob(info):
            return False
        return info.keys.issuperset(_KEYPAD_DIGITS) or info.keys.issuperset(_LETTERS)

    @property
    def speed(self) -> float:
        """The jog speed now, a fraction of the max feed."""
        return self._speeds[self._speed_index]

    @property
    def moving(self) -> bool:
        """True while a jog key is held or a tap is pending."""
        return bool(self._held or self._pending)

    def deadline_s(self) -> float | None:
        """The end of the tap window of the keys pressed from rest, if any."""
        if self._pending_since_s is None:
            return None
        return self._pending_since_s + self._tap_s

    def feed(self, item: DeviceItem) -> list[Action]:
        """Apply one frame's key changes; the jog is recomputed once at the frame's end."""
        if not isinstance(item, EvdevFrame):
            return []
        self._expire(item.t_s)
        if item.resync:
            notices = self._resync()
            return self._update() + notices  # the stop first, then the words
        out: list[Action] = []
        for ev in item.events:
            if ev.type == EV_KEY:
                out.extend(self._key(ev.code, ev.value, item.t_s))
        out.extend(self._update())
        return out

    def tick(self, now_s: float) -> list[Action]:
        """A tap window ended with the keys still down: they become a hold."""
        self._expire(now_s)
        return self._update()

    def lost(self) -> list[Action]:
        """Forget every key; motion comes back only from keys pressed anew."""
        self._reset()
        return []

    def describe(self) -> str:
        """The mode, speed and taps, e.g. "keyboard: jog at 25 %, taps of 0.1 mm"."""
        mode = f"step of {self._step_mm:g} mm" if self._step_mode else "jog"
        taps = f", taps of {self._tap_step_mm:g} mm" if self._tap_step_mm is not None else ""
        return f"keyboard: {mode} at {self.speed * 100:g} %{taps}"

    # -- keys --------------------------------------------------------------------------------

    def _key(self, code: int, value: int, t_s: float) -> list[Action]:
        if value == 0:
            return self._release(code)
        if value != 1:
            return []  # 2 is autorepeat (devices §3.1): a held key is one press
        binding = self._bindings.get(code)
        if binding is None:
            return []  # unbound, and KEY_NUMLOCK, which can never be bound
        if isinstance(binding, _Jog):
            return self._press_jog(code, binding, t_s)
        if isinstance(binding, DeviceCommand):
            return [binding]
        return self._control(binding)

    def _press_jog(self, code: int, jog: _Jog, t_s: float) -> list[Action]:
        if self._step_mode:
            # Held for `moving`, so a loss during a long step still stops it.
            self._held.add(code)
            return [StepIntent(jog.axis, jog.sign * self._step_mm, self.speed)]
        if self._tap_step_mm is None or self._held:
            # With a jog already running, another key joins it (a diagonal) at once.
            self._held.add(code)
        else:
            self._pending.add(code)
            if self._pending_since_s is None:
                self._pending_since_s = t_s
        return []

    def _release(self, code: int) -> list[Action]:
        if code in self._pending:
            self._pending.discard(code)
            if not self._pending:
                self._pending_since_s = None
            binding = self._bindings.get(code)
            if isinstance(binding, _Jog) and self._tap_step_mm is not None:
                return [StepIntent(binding.axis, binding.sign * self._tap_step_mm, self.speed)]
            return []
        self._held.discard(code)  # a key forgotten by a stop, a resync or a loss: no news
        return []

    def _control(self, control: str) -> list[Action]:
        if control == "stop":
            self._forget_keys()
            self._sent = self._neutral()  # the stop ends the jog; no neutral after it
            return [StopIntent(button=True)]
        if control == "step":
            # Keys held across the switch would start the other mode's motion by themselves.
            self._forget_keys()
            self._step_mode = not self._step_mode
            return [DeviceNotice(self.describe())]
        index = self._speed_index + (1 if control == "speed+" else -1)
        index = max(0, min(len(self._speeds) - 1, index))
        if index == self._speed_index:
            return []
        self._speed_index = index
        return [DeviceNotice(f"keyboard jog speed {self.speed * 100:g} %")]

    def _forget_keys(self) -> None:
        """Keys down now drive nothing more: only a key pressed anew (value 1) moves again."""
        self._held.clear()
        self._pending.clear()
        self._pending_since_s = None

    def _expire(self, now_s: float) -> None:
        """Keys still down at the end of their tap window join the hold."""
        deadline = self.deadline_s()
        if deadline is not None and now_s >= deadline:
            self._held |= self._pending
            self._pending.clear()
            self._pending_since_s = None

    def _resync(self) -> list[Action]:
        """Events were lost (SYN_DROPPED): stop; only a key pressed anew moves again.

        The frame lists the keys held now, but a listed key may have been let go and pressed
        again in the gap, and the jog ran blind for as long as the gap lasted; devices §9.4
        counts SYN_DROPPED while moving among the causes to stop. So every key is forgotten,
        listed or not: the jog stops (neutral, from _update), a listed key's release is then no
        news and its autorepeat is never a press.
        """
        was_moving = self.moving
        self._forget_keys()
        if not was_moving:
            return []
        return [DeviceNotice("keyboard events were lost: jog stopped; press the key again")]

    # -- the continuous jog ------------------------------------------------------------------

    def _neutral(self) -> dict[str, float]:
        return dict.fromkeys(self._jog_axes, 0.0)

    def _vector(self) -> dict[str, float]:
        """Each jogged axis: +1, -1, or 0 when nothing or both directions are held."""
        vector = self._neutral()
        if self._step_mode:
            return vector
        for axis in self._jog_axes:
            signs = {
                b.sign
                for code in self._held
                if isinstance(b := self._bindings.get(code), _Jog) and b.axis == axis
            }
            vector[axis] = float(sum(signs))  # {+1, -1} cancels to 0
        return vector

    def _update(self) -> list[Action]:
        """The ContinuousIntent for the keys now held, when it differs from the one sent."""
        vector = self._vector()
        neutral = all(v == 0.0 for v in vector.values())
        if vector == self._sent and (neutral or self.speed == self._sent_speed):
            return []
        self._sent = vector
        self._sent_speed = self.speed
        return [ContinuousIntent(dict(vector), self.speed)]


__all__ = [
    "DEFAULT_KEYS",
    "DEFAULT_SPEEDS",
    "KEY_CODES",
    "KNOB_USB_IDS",
    "MEDIA_KEYS",
    "KeyboardDecoder",
    "is_media_knob",
    "key_code",
    "key_name",
    "list_option",
]
