"""USB encoder knobs and MPGs on evdev: each detent is a handwheel count on the selected axis.

Two kinds of device (devices §8.5, §13):
- knobs that pose as keyboards (413d:553a and its kin): one detent is a KEY_VOLUMEUP or
  KEY_VOLUMEDOWN press and release about 10 ms apart, and pushing the knob is KEY_MUTE. The
  press is the detent; releases and autorepeat are ignored.
- dials and wheels: REL_DIAL (or REL_WHEEL) carries the signed detents of one report. Newer
  kernels send REL_WHEEL_HI_RES / REL_HWHEEL_HI_RES beside a wheel in 1/120 detents (devices
  §6.3); those are ignored, or each detent would count 121 times.

A frame's detents are summed into one HandwheelIntent; the engine runs position mode (every
count, on the step grid) or velocity mode (stops when the knob stops) as the intent says.

Pushing the knob picks the next axis, the next step size, or stops (option `push`). An axis or
step change stops first when counts were sent since the last stop: a count still queued in the
engine must never run after the user chose another axis or scale (the counter hazard, devices
§4.2).

Options (all optional): `axis` = "X"; `axes`, the cycle of the push (the machine's axes);
`step_mm` = 0.1; `steps_mm` = [0.01, 0.1, 1.0], the step cycle; `mode` = "position" or
"velocity"; `speed` = 0.5 (fraction of the max feed); `push` = "axis", "step" or "stop";
`invert` = false (the knob's direction); `push_key` = "KEY_MUTE", `up_key` = "KEY_VOLUMEUP",
`down_key` = "KEY_VOLUMEDOWN" (any key name keyboard.key_code knows, e.g. "BTN_0").
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final, Literal

from smoothjog.core.intents import STEP_MAX_MM, STEP_MIN_MM, HandwheelIntent, StopIntent
from smoothjog.core.options import Table
from smoothjog.inputs.device import (
    EV_KEY,
    EV_REL,
    Action,
    Decoder,
    DeviceInfo,
    DeviceItem,
    DeviceNotice,
    EvdevFrame,
)
from smoothjog.inputs.keyboard import is_media_knob, key_code, list_option

REL_X: Final = 0x00
REL_Y: Final = 0x01
REL_DIAL: Final = 0x07
REL_WHEEL: Final = 0x08

#: Contour's Shuttles also send REL_DIAL with no REL_X, but theirs carries an absolute 8-bit
#: counter, not detents (devices §6.3): the shuttle decoder's, never this one's.
_CONTOUR_VENDOR: Final = 0x0B33
_CONTOUR_IDS: Final = frozenset({"05f3:0240"})

DEFAULT_STEPS_MM: Final = (0.01, 0.1, 1.0)
#: How long after its last detent a knob counts as turning. Detents come tens of milliseconds
#: apart while it turns (devices §8.5: about 60 ms on a slow turn), so half a second of quiet
#: means the hand stopped; velocity-mode motion then ends by itself within its stopping
#: distance, and position-mode counts already sent are what the user turned.
MOVING_S: Final = 0.5
#: An assumption, the facts being silent: these knobs report a few detents per report (a HID
#: relative field of at most 8 bits), so a larger value is garbage, not a turn to run.
MAX_DETENTS_PER_EVENT: Final = 127

_PUSH_ACTIONS: Final = ("axis", "step", "stop")


class KnobDecoder(Decoder):
    """An encoder knob or MPG: detents as handwheel counts, the push cycles axis or step."""

    name = "knob"
    kind = "handwheel"
    transport = "evdev"

    def __init__(self, info: DeviceInfo, options: Table, axes: Sequence[str]) -> None:
        """Read the options (see the module docstring); every default is usable."""
        super().__init__(info, options, axes)
        self._start_axis = self._read_axis(options)
        self._axes_cycle = self._read_axes(options)
        self._start_step_mm = options.number(
            "step_mm", 0.1, at_least=STEP_MIN_MM, at_most=STEP_MAX_MM
        )
        self._steps_mm = self._read_steps(options)
        mode = options.choice("mode", "position", ("position", "velocity"))
        self._mode: Literal["position", "velocity"] = (
            "velocity" if mode == "velocity" else "position"
        )
        self._speed = options.number("speed", 0.5, above=0.0, at_most=1.0)
        self._push = options.choice("push", "axis", _PUSH_ACTIONS)
        self._sign = -1 if options.flag("invert", False) else 1
        self._push_key = self._read_key(options, "push_key", "KEY_MUTE")
        self._up_key = self._read_key(options, "up_key", "KEY_VOLUMEUP")
        self._down_key = self._read_key(options, "down_key", "KEY_VOLUMEDOWN")
        if len({self._push_key, self._up_key, self._down_key}) < 3:
            raise options.error(
                "push_key", "is the same key as up_key or down_key: give three different keys"
            )
        options.finish()
        # One detent may come as both REL_DIAL and REL_WHEEL on a device declaring both, so
        # only the first declared counts; unknown capabilities (a bare recording) take either.
        if REL_DIAL in info.rels:
            self._rel_codes = frozenset({REL_DIAL})
        elif REL_WHEEL in info.rels:
            self._rel_codes = frozenset({REL_WHEEL})
        else:
            self._rel_codes = frozenset({REL_DIAL, REL_WHEEL})
        self._reset()

    def _read_axis(self, options: Table) -> str:
        default = "X" if "X" in self.axes else self.axes[0]
        axis = (options.text("axis", default) or default).strip().upper()
        if axis not in self.axes:
            raise options.error(
                "axis", f"= {axis!r} is not an axis of this machine: use {', '.join(self.axes)}"
            )
        return axis

    def _read_axes(self, options: Table) -> tuple[str, ...]:
        raw = list_option(options, "axes")
        if raw is None:
            return self.axes
        cycle: list[str] = []
        for item in raw:
            axis = item.strip().upper() if isinstance(item, str) else item
            if axis not in self.axes:
                raise options.error(
                    "axes",
                    f"holds {item!r}, not an axis of this machine: use {', '.join(self.axes)}",
                )
            if axis not in cycle:
                cycle.append(axis)
        return tuple(cycle)

    @staticmethod
    def _read_steps(options: Table) -> tuple[float, ...]:
        raw = list_option(options, "steps_mm")
        if raw is None:
            return DEFAULT_STEPS_MM
        steps = {
            options.check_number("steps_mm", v, at_least=STEP_MIN_MM, at_most=STEP_MAX_MM)
            for v in raw
        }
        return tuple(sorted(steps))  # the push goes from fine to coarse, then wraps

    @staticmethod
    def _read_key(options: Table, key: str, default: str) -> int:
        name = options.text(key, default) or default
        code = key_code(name)
        if code is None:
            raise options.error(key, f"= {name!r} is not a key name: write e.g. KEY_MUTE or BTN_0")
        return code

    def _reset(self) -> None:
        """Back to the configured axis and step, with nothing sent."""
        self._axis = self._start_axis
        self._step_mm = self._start_step_mm
        #: Counts were sent since the last stop: the engine may still hold some.
        self._queued = False
        #: When the last detent was sent, while the knob counts as turning.
        self._last_detent_s: float | None = None

    # -- the contract ------------------------------------------------------------------------

    @classmethod
    def matches(cls, info: DeviceInfo) -> bool:
        """A dial without pointer axes (not a mouse, not a Shuttle), or a volume-key knob."""
        if info.vendor == _CONTOUR_VENDOR or info.usb_id in _CONTOUR_IDS:
            return False
        if REL_DIAL in info.rels and not {REL_X, REL_Y} & info.rels:
            return True
        return is_media_knob(info)

    @property
    def axis(self) -> str:
        """The axis the knob turns now."""
        return self._axis

    @property
    def step_mm(self) -> float:
        """The distance of one detent now, in mm."""
        return self._step_mm

    @property
    def moving(self) -> bool:
        """True from a detent until MOVING_S passes with none."""
        return self._last_detent_s is not None

    def deadline_s(self) -> float | None:
        """When the knob stops counting as turning."""
        if self._last_detent_s is None:
            return None
        return self._last_detent_s + MOVING_S

    def tick(self, now_s: float) -> list[Action]:
        """Quiet for MOVING_S: the knob has stopped (no intent: the engine needs none)."""
        deadline = self.deadline_s()
        if deadline is not None and now_s >= deadline:
            self._last_detent_s = None
        return []

    def feed(self, item: DeviceItem) -> list[Action]:
        """One frame: its detents summed into one HandwheelIntent, and any push acted on."""
        if not isinstance(item, EvdevFrame):
            return []
        if item.resync:
            return self._resync()
        out: list[Action] = []
        counts = 0
        for ev in item.events:
            if ev.type == EV_REL and ev.code in self._rel_codes:
                # Hi-res codes never get here: they are not in _rel_codes.
                if abs(ev.value) <= MAX_DETENTS_PER_EVENT:
                    counts += ev.value
            elif ev.type == EV_KEY and ev.value == 1:  # 0 release, 2 autorepeat: ignored
                if ev.code == self._up_key:
                    counts += 1
                elif ev.code == self._down_key:
                    counts -= 1
                elif ev.code == self._push_key:
                    # Counts of this frame before the push belong to the old choice: dropped
                    # with the stop, like those still queued.
                    out.extend(self._pushed(pending=counts != 0))
                    counts = 0
        if counts:
            out.append(
                HandwheelIntent(
                    self._axis, self._sign * counts, self._step_mm, self._mode, self._speed
                )
            )
            self._queued = True
            self._last_detent_s = item.t_s
        return out

    def lost(self) -> list[Action]:
        """Forget the counts and go back to the configured axis and step."""
        self._reset()
        return []

    def describe(self) -> str:
        """The axis, step and mode, e.g. "knob: X at 0.1 mm per detent, position mode"."""
        return f"knob: {self._axis} at {self._step_mm:g} mm per detent, {self._mode} mode"

    # -- the push ----------------------------------------------------------------------------

    def _stop(self) -> list[Action]:
        self._queued = False
        self._last_detent_s = None
        return [StopIntent()]

    def _pushed(self, *, pending: bool) -> list[Action]:
        if self._push == "stop":
            return self._stop()
        if self._push == "axis":
            axis, step_mm = self._next_axis(), self._step_mm
        else:
            axis, step_mm = self._axis, self._next_step()
        out: list[Action] = []
        if (axis, step_mm) != (self._axis, self._step_mm):
            if self._queued or pending:
                out.extend(self._stop())
            self._axis, self._step_mm = axis, step_mm
        out.append(DeviceNotice(f"knob on {self._axis}, {self._step_mm:g} mm per detent"))
        return out

    def _next_axis(self) -> str:
        cycle = self._axes_cycle
        if self._axis not in cycle:
            return cycle[0]
        return cycle[(cycle.index(self._axis) + 1) % len(cycle)]

    def _next_step(self) -> float:
        larger = [s for s in self._steps_mm if s > self._step_mm]
        return larger[0] if larger else self._steps_mm[0]

    def _resync(self) -> list[Action]:
        """Events were lost (SYN_DROPPED): detents or a push may be among them.

        A lost push would leave the user on another axis than they think, so anything queued
        is stopped and the notice names the axis and step the knob is on. Held keys listed in
        the frame need nothing: only presses act.
        """
        out: list[Action] = []
        if self._queued or self.moving:
            out.extend(self._stop())
        stopped = "jog stopped; " if out else ""
        out.append(
            DeviceNotice(
                f"knob events were lost: {stopped}the knob is on {self._axis} at "
                f"{self._step_mm:g} mm per detent"
            )
        )
        return out


__all__ = ["MAX_DETENTS_PER_EVENT", "MOVING_S", "KnobDecoder"]
