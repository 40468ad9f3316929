"""Contour ShuttleXpress / ShuttlePRO / ShuttlePRO v2: the spring ring and jog wheel as jog intents.

The device has a spring-loaded outer ring (the "shuttle", -7..+7, 0 at rest), an inner jog wheel
with detents that turns an absolute 8-bit counter, and 5, 13 or 15 buttons (devices §6.1).

- The ring holds a continuous jog on the active axis: its sign is the direction and |ring| 1..7
  picks a speed from `ring_speeds` (non-linear, as LinuxCNC's table is, devices §6.2). Back at 0
  it sends neutral once.
- The wheel's counter is diffed with a ±128 wrap; the detents become HandwheelIntents (or one
  StepIntent each) on the active axis. The first report only sets the counter's baseline, so a
  first move made with the wheel is lost (devices §6.1).
- The active axis comes from the axis buttons. `enable = "hold"` (LinuxCNC's practice, devices
  §6.2, §9.3): the ring and wheel move only while an axis button is held, and releasing it stops.
  `enable = "select"`: a press selects the axis and it stays selected until "stop".
- Safety: wheel counts made while no axis is active are dropped, never saved up; changing the
  axis or the wheel's step stops what runs first; and the ring moves only once it has been at 0
  since the axis became active, so enabling with the ring held deflected (at start-up, after a
  stop, a loss or a released button) does not start a jog.

Two transports. `ShuttleDecoder` reads hidraw, where every report carries the whole state and
the ring's return to centre is seen. `ShuttleEvdevDecoder` reads the event node, where the
kernel drops zero-valued REL events (devices §1 item 2, §6.3): the ring's return to 0 and the
counter's passing 0 never arrive, so the centre is inferred (see that class).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Final, Literal

from smoothjog.core.intents import (
    STEP_MAX_MM,
    STEP_MIN_MM,
    ContinuousIntent,
    HandwheelIntent,
    StepIntent,
    StopIntent,
)
from smoothjog.core.options import Table
from smoothjog.core.units import ALL_AXES
from smoothjog.inputs.device import (
    EV_KEY,
    EV_REL,
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

#: A hidraw report: ring, counter, unused, buttons (u16 LE) (devices §6.1).
REPORT_LEN: Final = 5
RING_MAX: Final = 7
#: evdev codes of the Shuttle (devices §6.3): the counter value, the ring, and the buttons.
REL_DIAL: Final = 7
REL_WHEEL: Final = 8
#: Newer kernels may add a hi-res copy of a wheel usage (value × 120); never the ring itself.
REL_WHEEL_HI_RES: Final = 11
BTN_0: Final = 0x100

DEFAULT_RING_SPEEDS: Final = (0.01, 0.03, 0.07, 0.15, 0.3, 0.6, 1.0)
DEFAULT_STEPS_MM: Final = (0.01, 0.1, 1.0)


@dataclass(frozen=True)
class ShuttleModel:
    """One model's button count and where its button 1 sits in the 16-bit mask."""

    name: str
    buttons: int
    first_bit: int


#: devices §6.1: the ShuttleXpress's 5 buttons are masks 0x0010..0x0100, the PRO's 13 and the
#: PRO v2's 15 start at 0x0001. The same bit order is assumed for the evdev codes BTN_0 + bit
#: (nanosyzygy/ShuttlePRO names the Xpress's keys K5..K9, i.e. BTN_4..BTN_8).
MODELS: Final[Mapping[str, ShuttleModel]] = {
    "xpress": ShuttleModel("ShuttleXpress", 5, 4),
    "pro": ShuttleModel("ShuttlePRO", 13, 0),
    "pro2": ShuttleModel("ShuttlePRO v2", 15, 0),
}
USB_IDS: Final[Mapping[tuple[int, int], str]] = {
    (0x0B33, 0x0020): "xpress",
    (0x05F3, 0x0240): "pro",
    (0x0B33, 0x0030): "pro2",
}


@dataclass(frozen=True)
class ShuttleReport:
    """One decoded hidraw report."""

    ring: int
    counter: int
    buttons: int


def parse_report(data: bytes) -> ShuttleReport | None:
    """The report's ring (-7..7), counter (0..255) and button mask; None if it is not one."""
    if len(data) != REPORT_LEN:
        return None
    ring = data[0] - 256 if data[0] > 127 else data[0]
    if abs(ring) > RING_MAX:
        return None
    return ShuttleReport(ring, data[1], data[3] | data[4] << 8)


def counter_delta(before: int, after: int) -> int:
    """Detents from one 8-bit counter value to the next, taking the shorter way round (±128)."""
    diff = (after & 0xFF) - (before & 0xFF)
    if diff > 128:
        diff -= 256
    elif diff < -128:
        diff += 256
    return diff


@dataclass(frozen=True)
class _Button:
    """What one button does: select an axis, stop, cycle the step, or a machine command."""

    kind: Literal["axis", "stop", "step", "command"]
    axis: str = ""
    command: DeviceCommand | None = None


#: ShuttleXpress defaults. Assumed physical order (nanosyzygy/ShuttlePRO example.shuttlerc draws
#: the 5-key layout as K6 K7 K8 in the top row, K5 left and K9 right of the wheel): button 1
#: (K5) left of the wheel = X, 2..4 the top row left to right = Y, Z, step, 5 (K9) right of the
#: wheel = stop. UNVERIFIED on hardware.
DEFAULT_BUTTONS: Final[Mapping[str, str]] = {"1": "X", "2": "Y", "3": "Z", "4": "step", "5": "stop"}


class _Shuttle(Decoder):
    """The Shuttle's state machine, shared by the hidraw and evdev readers."""

    kind: ClassVar[str] = "handwheel"

    def __init__(self, info: DeviceInfo, options: Table, axes: Sequence[str]) -> None:
        """Read the options (see the module docstring) and start with nothing active."""
        super().__init__(info, options, axes)
        model = options.choice("model", "auto", ("auto", *MODELS))
        if model == "auto":
            model = USB_IDS.get((info.vendor, info.product), "xpress")
        self.model = MODELS[model]
        self.enable = options.choice("enable", "hold", ("hold", "select"))
        self.ring_speeds = _ring_speeds(options)
        self.invert = options.flag("invert", False)
        self.wheel = options.choice("wheel", "handwheel", ("handwheel", "step"))
        mode = options.choice("wheel_mode", "position", ("position", "velocity"))
        self.wheel_mode: Literal["position", "velocity"] = (
            "velocity" if mode == "velocity" else "position"
        )
        self.invert_wheel = options.flag("invert_wheel", False)
        self.steps_mm = _steps(options)
        self.wheel_speed = options.number("wheel_speed", 0.5, above=0.0, at_most=1.0)
        self.buttons = self._read_buttons(options)
        self._read_transport_options(options)
        options.finish()
        #: Reports or events that were not the Shuttle's and were ignored.
        self.ignored = 0
        self._step_index = 0
        self._reset()

    def _read_transport_options(self, options: Table) -> None:
        """Hook: a transport's own keys, read before finish()."""

    def _read_buttons(self, options: Table) -> dict[int, _Button]:
        given = options.table("buttons")
        table: dict[int, _Button] = {}
        for key, value in {**DEFAULT_BUTTONS, **given}.items():
            where = f"buttons.{key}"
            number = int(key) if isinstance(key, str) and key.isdigit() else 0
            if not 1 <= number <= self.model.buttons:
                raise options.error(
                    where,
                    f"is not a button: the {self.model.name} has buttons 1 to {self.model.buttons}",
                )
            if not isinstance(value, str) or not value.strip():
                raise options.error(where, f'= {value!r} is not an action: write e.g. "X"')
            action = value.strip()
            if action == "none":
                table.pop(number, None)
            elif action.upper() in ALL_AXES and len(action) == 1:
                axis = action.upper()
                if axis in self.axes:
                    table[number] = _Button("axis", axis=axis)
                elif key in given:
                    raise options.error(where, f"= {value!r}: the machine has {self.axes}")
                # A default axis the machine lacks (Z on a plotter) is left unmapped.
            elif action in ("stop", "step"):
                table[number] = _Button("stop" if action == "stop" else "step")
            else:
                alternatives = 'an axis letter, "stop", "step", "none"'
                command = read_command(options, where, value, self.axes, alternatives)
                table[number] = _Button("command", command=command)
        return table

    def _reset(self) -> None:
        """The state of a Shuttle just plugged in: nothing held, counter unknown, ring at rest."""
        self._held: set[int] = set()
        self._held_axes: list[str] = []
        self._selected: str | None = None
        self._counter: int | None = None
        self._ring = 0
        #: The ring has been at 0 since the active axis last changed: it may move.
        self._armed = True
        #: (axis, ring) of the continuous jog in force, or None.
        self._ring_sent: tuple[str, int] | None = None
        #: Wheel counts were sent and no stop since (the engine may still be running them).
        self._wheel_running = False

    # -- state --------------------------------------------------------------------------------

    @property
    def active_axis(self) -> str | None:
        """The axis the ring and wheel drive now, or None when disabled."""
        if self.enable == "hold":
            return self._held_axes[-1] if self._held_axes else None
        return self._selected

    @property
    def step_mm(self) -> float:
        """The wheel's distance per detent now."""
        return self.steps_mm[self._step_index]

    @property
    def moving(self) -> bool:
        """True while the ring holds a jog or wheel counts may still be running."""
        return self._ring_sent is not None or self._wheel_running

    def lost(self) -> list[Action]:
        """Forget everything; the next Shuttle starts disabled with a fresh counter baseline."""
        was = self.moving
        self._reset()
        if was:
            return [DeviceNotice(f"{self.model.name} lost while jogging: jog stopped")]
        return []

    def describe(self) -> str:
        """The mode in one line."""
        how = "hold an axis button to jog" if self.enable == "hold" else "press an axis button"
        buttons = " ".join(f"{n}={_name(b)}" for n, b in sorted(self.buttons.items()))
        wheel = (
            f"wheel {self.step_mm:g} mm/detent ({self.wheel_mode})"
            if self.wheel == "handwheel"
            else f"wheel steps of {self.step_mm:g} mm"
        )
        return (
            f"{self.model.name} ({self.transport}): {how}; buttons {buttons}; {wheel}; "
            f"axis {self.active_axis or 'none'}; the first wheel move after start-up only sets "
            "the counter and is lost"
        )

    def _bit_button(self, bit: int) -> int | None:
        """The 1-based button number of a mask bit, or None if the model has no such button."""
        number = bit - self.model.first_bit + 1
        return number if 1 <= number <= self.model.buttons else None

    def _mask_buttons(self, mask: int) -> set[int]:
        return {n for bit in range(16) if mask >> bit & 1 and (n := self._bit_button(bit))}

    def _moving_stop(self) -> list[Action]:
        """A StopIntent if anything may be moving, forgetting the motion."""
        if not self.moving:
            return []
        self._ring_sent = None
        self._wheel_running = False
        return [StopIntent()]

    # -- the one update -----------------------------------------------------------------------

    def _update(self, ring: int, counts: int, held: set[int], *, fire: bool) -> list[Action]:
        """Apply one report's state: buttons, then the ring, then the wheel's counts.

        `fire` is False when the presses were not seen happen (the first report, a resync):
        held axis buttons then enable as usual, one-shot actions do not run.
        """
        out: list[Action] = []
        before = self.active_axis
        pressed = sorted(held - self._held)
        released = self._held - held
        self._held = set(held)
        for number in released:
            button = self.buttons.get(number)
            if button and button.kind == "axis" and button.axis in self._held_axes:
                self._held_axes.remove(button.axis)
        stopped = False
        for number in pressed:
            button = self.buttons.get(number)
            if button is None:
                continue
            if button.kind == "axis":
                if self.enable == "hold":
                    if button.axis in self._held_axes:
                        self._held_axes.remove(button.axis)
                    self._held_axes.append(button.axis)
                elif fire:
                    self._selected = button.axis
                continue
            if not fire:
                continue
            if button.kind == "stop":
                self._moving_stop()  # forget the motion; the button's stop is always sent
                out.append(StopIntent(button=True))
                self._selected = None
                stopped = True
            elif button.kind == "step":
                out.extend(self._moving_stop() if self._wheel_running else [])
                self._step_index = (self._step_index + 1) % len(self.steps_mm)
                out.append(DeviceNotice(f"wheel step {self.step_mm:g} mm"))
            else:
                out.extend(self._command(button))
        after = self.active_axis
        if after != before or stopped:
            if after != before:
                out.extend(self._moving_stop())
            # Enabling, changing axis or stopping with the ring held: it must pass 0 first.
            self._armed = ring == 0
        out.extend(self._ring_to(ring, after))
        if counts and not stopped and after is not None and after == before:
            out.extend(self._wheel(after, counts))
        return out

    def _ring_to(self, ring: int, axis: str | None) -> list[Action]:
        self._ring = ring
        if ring == 0:
            self._armed = True
        want = (axis, ring) if axis is not None and self._armed and ring != 0 else None
        if want == self._ring_sent:
            return []
        out: list[Action] = []
        if want is None:
            assert self._ring_sent is not None
            out.append(ContinuousIntent({self._ring_sent[0]: 0.0}))
        else:
            if self._wheel_running:
                # One motion source at a time: the ring's jog does not join queued counts.
                self._wheel_running = False
                out.append(StopIntent())
            sign = -1.0 if (ring < 0) != self.invert else 1.0
            out.append(ContinuousIntent({want[0]: sign}, self.ring_speeds[abs(ring) - 1]))
        self._ring_sent = want
        return out

    def _wheel(self, axis: str, counts: int) -> list[Action]:
        if self._ring_sent is not None:
            return []  # the ring owns the axis while it is deflected
        if self.invert_wheel:
            counts = -counts
        self._wheel_running = True
        if self.wheel == "handwheel":
            return [HandwheelIntent(axis, counts, self.step_mm, self.wheel_mode, self.wheel_speed)]
        dist_mm = math.copysign(self.step_mm, counts)
        return [StepIntent(axis, dist_mm, self.wheel_speed) for _ in range(abs(counts))]

    def _command(self, button: _Button) -> list[Action]:
        command = button.command
        assert command is not None
        if command.name == "zero" and not command.axes:
            axis = self.active_axis
            if axis is None:
                return [DeviceNotice("zero: hold or select an axis first")]
            return [DeviceCommand("zero", axes=(axis,))]
        return [command]


class ShuttleDecoder(_Shuttle):
    """A Shuttle read from hidraw: one 5-byte report per change, the ring's centre included."""

    name: ClassVar[str] = "shuttle"
    transport: ClassVar[Literal["evdev", "hidraw"]] = "hidraw"

    @classmethod
    def matches(cls, info: DeviceInfo) -> bool:
        """The three Contour models, by USB id."""
        return (info.vendor, info.product) in USB_IDS

    def feed(self, item: DeviceItem) -> list[Action]:
        """One hidraw report."""
        report = parse_report(item.data) if isinstance(item, HidReport) else None
        if report is None:
            self.ignored += 1
            return []
        first = self._counter is None
        counts = 0 if self._counter is None else counter_delta(self._counter, report.counter)
        self._counter = report.counter
        return self._update(report.ring, counts, self._mask_buttons(report.buttons), fire=not first)


class ShuttleEvdevDecoder(_Shuttle):
    """A Shuttle read from its event node, for when hidraw cannot be opened.

    The kernel passes every non-zero REL value in each report and drops the zeros (devices
    §3.1), so a frame of the Shuttle's that carries the counter or a button but no ring event
    means the ring was at 0 in that report: that is the synthesised centre (the ShuttlePRO
    driver does the same on the next counter event, after a 5 ms gap, devices §6.3). A frame
    within `centre_gap_s` of the last ring event is not taken as one (a recording may split one
    report). When the counter sits at 0 nothing at all arrives on release, so a ring with no
    event for `ring_timeout_s` is zeroed as well. That zero stands in for the centre the kernel
    dropped, so the ring counts as having passed 0: a spring ring reported deflected again
    afterwards has a hand on it (and, in hold mode, an axis button held).

    The counter value 0 is dropped too; the counter is absolute, so the next value still gives
    the right count across the wrap (255, then 1, is +2).
    """

    name: ClassVar[str] = "shuttle-evdev"
    transport: ClassVar[Literal["evdev", "hidraw"]] = "evdev"

    def _read_transport_options(self, options: Table) -> None:
        # 0.25 s default. Whether a ring held still repeats its reports is not known (the
        # facts are silent; Goko#51's ring that "jerks and stops", devices §6.3, hints it may
        # not). If it does not, a jog held longer stops after 0.25 s: a false stop, which is
        # safe (nudge the ring, or read hidraw). If the centre was lost, the timeout bounds the
        # runaway to 0.25 s at the last speed seen, usually the gentlest since the ring passes
        # 1 on its way back. A runaway is the worse failure, so the timeout stays short.
        self.ring_timeout_s = options.number("ring_timeout_s", 0.25, above=0.0, at_most=5.0)
        self.centre_gap_s = options.number("centre_gap_s", 0.005, at_least=0.0, at_most=0.1)

    def _reset(self) -> None:
        super()._reset()
        self._ring_t_s = 0.0

    @classmethod
    def matches(cls, info: DeviceInfo) -> bool:
        """By USB id, or by name ("Contour Design Shuttle...", or "Shuttle" with ring and dial)."""
        name = info.name.lower()
        return (
            (info.vendor, info.product) in USB_IDS
            or "contour design shuttle" in name
            or ("shuttle" in name and {REL_DIAL, REL_WHEEL} <= info.rels)
        )

    def feed(self, item: DeviceItem) -> list[Action]:
        """One evdev frame."""
        if not isinstance(item, EvdevFrame):
            self.ignored += 1
            return []
        if item.resync:
            return self._resync(item)
        ring: int | None = None
        dial: int | None = None
        held = set(self._held)
        keys = False
        for ev in item.events:
            if ev.type == EV_REL and ev.code == REL_WHEEL and abs(ev.value) <= RING_MAX:
                ring = ev.value
            elif ev.type == EV_REL and ev.code == REL_DIAL:
                dial = ev.value & 0xFF  # signed or unsigned, the driver's choice
            elif ev.type == EV_KEY and ev.value in (0, 1):
                number = self._bit_button(ev.code - BTN_0)
                if number is None:
                    continue
                keys = True
                if ev.value:
                    held.add(number)
                else:
                    held.discard(number)
            # REL_WHEEL_HI_RES (11), EV_KEY value 2 (repeat) and anything else: ignored.
        if ring is not None:
            self._ring_t_s = item.t_s
        elif (dial is not None or keys) and item.t_s - self._ring_t_s > self.centre_gap_s:
            ring = 0
        counts = 0
        if dial is not None:
            if self._counter is not None:
                counts = counter_delta(self._counter, dial)
            self._counter = dial
        new_ring = self._ring if ring is None else ring
        return self._update(new_ring, counts, held, fire=True)

    def _resync(self, frame: EvdevFrame) -> list[Action]:
        """Events were lost: stop, take the held buttons as given, the ring and counter unknown."""
        out = self._moving_stop()
        if out:
            out.append(DeviceNotice(f"{self.model.name}: events were lost: jog stopped"))
        held = {
            n
            for ev in frame.events
            if ev.type == EV_KEY and ev.value and (n := self._bit_button(ev.code - BTN_0))
        }
        out.extend(self._update(0, 0, held, fire=False))
        self._armed = False  # the ring's position is unknown: it must be seen at 0 again
        self._counter = None
        self._ring_t_s = frame.t_s
        return out

    def deadline_s(self) -> float | None:
        """When a deflected ring with no news is taken as back at centre."""
        return self._ring_t_s + self.ring_timeout_s if self._ring != 0 else None

    def tick(self, now_s: float) -> list[Action]:
        """Zero a ring whose centre the kernel did not deliver."""
        if self._ring == 0 or now_s < self._ring_t_s + self.ring_timeout_s:
            return []
        return self._update(0, 0, set(self._held), fire=False)


def _name(button: _Button) -> str:
    if button.kind == "axis":
        return button.axis
    if button.kind == "command" and button.command is not None:
        return button.command.name
    return button.kind


def _number_list(options: Table, key: str, at_least: int, at_most: int, what: str) -> Any:
    """The raw list under key (None when absent), its length checked; marks the key read."""
    raw: Any = options.raw(key)
    if raw is None:
        return None
    count = f"{at_least}" if at_least == at_most else f"{at_least} to {at_most}"
    if not isinstance(raw, list) or not at_least <= len(raw) <= at_most:
        raise options.error(key, f"= {raw!r} is not a list of {count} {what}")
    options.numbers(key)  # marks it read; every item a finite number
    return raw


def _ring_speeds(options: Table) -> tuple[float, ...]:
    """Seven speeds in (0, 1], for |ring| 1..7, never decreasing."""
    raw = _number_list(options, "ring_speeds", 7, 7, "speeds (fractions of full speed)")
    if raw is None:
        return DEFAULT_RING_SPEEDS
    values = tuple(options.check_number("ring_speeds", v, above=0.0, at_most=1.0) for v in raw)
    if any(b < a for a, b in itertools.pairwise(values)):
        raise options.error(
            "ring_speeds", f"= {raw!r} must not decrease: list the speed for |ring| = 1 first"
        )
    return values


def _steps(options: Table) -> tuple[float, ...]:
    """The wheel's step sizes, each within what a StepIntent may move."""
    raw = _number_list(options, "steps_mm", 1, 9, "step sizes in mm")
    if raw is None:
        return DEFAULT_STEPS_MM
    return tuple(
        options.check_number("steps_mm", v, at_least=STEP_MIN_MM, at_most=STEP_MAX_MM) for v in raw
    )


__all__ = [
    "MODELS",
    "USB_IDS",
    "ShuttleDecoder",
    "ShuttleEvdevDecoder",
    "ShuttleModel",
    "ShuttleReport",
    "counter_delta",
    "parse_report",
]
