"""The XHC WHB04B-4/-6 wireless MPG pendant (and the WMPG-6 clone) read from hidraw.

The input report (devices §4.2) is 8 bytes: `04 rnd key1 key2 feed axis delta crc`. `decode_report`
classifies one as regular, empty or sleep; `Whb04bDecoder` keeps the selectors' state and turns
wheel deltas into HandwheelIntents, keys into commands, and sleep, silence and selector changes
into stops. `encode_display` builds the three LCD feature reports (devices §4.3).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal, NamedTuple

from smoothjog.core.intents import HandwheelIntent, StopIntent
from smoothjog.core.options import Table
from smoothjog.inputs.device import (
    Action,
    Decoder,
    DeviceCommand,
    DeviceInfo,
    DeviceItem,
    DeviceNotice,
    DisplayView,
    HidReport,
)

VENDOR_XHC = 0x10CE
PRODUCTS = (0xEB93, 0xEB91)  # WHB04B-4 and -6 share eb93; the WMPG-6 clone is eb91 (devices §2)
REPORT_ID = 0x04
REPORT_LEN = 8
#: The seed this host writes to the LCD; the pendant's checksum follows it (devices §4.2).
SEED = 0xFE
_SLEEP_BODY = bytes.fromhex("ffffffff81")  # bytes 2-6 of the sleep package

ReportKind = Literal["regular", "empty", "sleep"]


@dataclass(frozen=True)
class WhbReport:
    """One decoded input report; `crc_ok` is None for the empty and sleep packages."""

    kind: ReportKind
    rnd: int
    key1: int
    key2: int
    feed_code: int
    axis_code: int
    delta: int  # signed wheel counts since the previous report (regular reports only)
    crc: int
    crc_ok: bool | None


def checksum(rnd: int, key1: int, seed: int = SEED) -> int:
    """The checksum the pendant sends (devices §4.2; holds for all of §8.1 with seed 0xFE)."""
    if key1:
        return (rnd - (key1 ^ (~seed & rnd))) & 0xFF
    return rnd & seed


def decode_report(data: bytes) -> WhbReport | None:
    """Classify one hidraw report; None when it is not an 8-byte report 4."""
    if len(data) != REPORT_LEN or data[0] != REPORT_ID:
        return None
    rnd, key1, key2, feed, axis, raw_delta, crc = data[1:]
    # Bytes 1 and 7 (timer, checksum) are left out of both comparisons, as LinuxCNC compares
    # the empty package; the sleep package's 0x81 must never reach the wheel as -127 counts.
    body = data[2:7]
    kind: ReportKind = "regular"
    if not any(body):
        kind = "empty"
    elif body == _SLEEP_BODY:
        kind = "sleep"
    regular = kind == "regular"
    delta = raw_delta - 256 if raw_delta > 127 else raw_delta
    return WhbReport(
        kind,
        rnd,
        key1,
        key2,
        feed,
        axis,
        delta if regular else 0,
        crc,
        (checksum(rnd, key1) == crc) if regular else None,
    )


# -- the LCD -----------------------------------------------------------------------------------

LCD_MODE_CONT, LCD_MODE_STEP, LCD_MODE_MPG, LCD_MODE_PERCENT = 0, 1, 2, 3
_U16_MAX = 0xFFFF


def _u16(value: float) -> int:
    """A value for a u16 field: rounded, clamped to 0..65535, NaN as 0."""
    if math.isnan(value):
        return 0
    return int(min(max(round(min(value, _U16_MAX)), 0), _U16_MAX))


def _coordinate(value_mm: float) -> bytes:
    """u16 whole part, then u16 (fraction x 10^4 | sign << 15), clamped to 65535.9999."""
    if math.isnan(value_mm):
        value_mm = 0.0
    scaled = round(min(abs(value_mm), _U16_MAX + 0.9999) * 10_000)
    whole, frac = divmod(scaled, 10_000)
    if whole > _U16_MAX:
        whole, frac = _U16_MAX, 9_999
    sign = 0x8000 if value_mm < 0 and scaled else 0  # no "-0.0000"
    return struct.pack("<HH", whole, frac | sign)


def encode_display(
    coords_mm: Sequence[float],
    *,
    feed: float = 0.0,
    spindle: float = 0.0,
    mode: int = LCD_MODE_STEP,
    work_coords: bool = True,
    reset: bool = False,
    seed: int = SEED,
) -> list[bytes]:
    """The three 8-byte feature reports (0x06 + 7 payload bytes) that set the LCD."""
    rows = [*coords_mm[:3], 0.0, 0.0, 0.0][:3]
    flags = (mode & 0x03) | (0x40 if reset else 0) | (0x80 if work_coords else 0)
    payload = (
        b"\xfe\xfd"
        + bytes([seed & 0xFF, flags])
        + b"".join(_coordinate(v) for v in rows)
        + struct.pack("<HH", _u16(feed), _u16(spindle))
        + b"\x00"
    )
    return [b"\x06" + payload[i : i + 7] for i in range(0, 21, 7)]


# -- selectors and keys ------------------------------------------------------------------------

AXIS_CODES: Mapping[int, str] = {
    0x06: "OFF",
    0x11: "X",
    0x12: "Y",
    0x13: "Z",
    0x14: "A",  # the -4 model's selector ends here
    0x15: "B",
    0x16: "C",
}


class FeedPosition(NamedTuple):
    """One position of the feed/step selector: its step-mode size and continuous-mode percent."""

    label: str
    step_mm: float | None
    percent: int | None


_LEAD = FeedPosition("Lead", None, None)
FEED_CODES: Mapping[int, FeedPosition] = {
    0x0D: FeedPosition("0.001", 0.001, 2),
    0x0E: FeedPosition("0.01", 0.01, 5),
    0x0F: FeedPosition("0.1", 0.1, 10),
    0x10: FeedPosition("1", 1.0, 30),
    0x1A: FeedPosition("60 %", None, 60),
    0x1B: FeedPosition("100 %", None, 100),
    0x1C: _LEAD,
    0x9B: _LEAD,  # what real -4 and -6 units send for Lead (devices §4.2)
}

KEY_STOP, KEY_FN, KEY_CONTINUOUS, KEY_STEP = 0x02, 0x0C, 0x0E, 0x0F
#: Keys whose action the `buttons` table sets, by code.
KEY_NAMES: Mapping[int, str] = {
    0x01: "reset",
    0x03: "start_pause",
    0x04: "feed_plus",
    0x05: "feed_minus",
    0x06: "spindle_plus",
    0x07: "spindle_minus",
    0x08: "m_home",
    0x09: "safe_z",
    0x0A: "w_home",
    0x0B: "spindle_on_off",
    0x0D: "probe_z",
    0x10: "macro_10",
}
#: Fn + a key is "Macro-n" as printed on the keypad; these names say the same as fn_<key>.
_MACRO_KEYS = (0x04, 0x05, 0x06, 0x07, 0x08, 0x09, 0x0A, 0x0B, 0x0D)  # Macro-1 .. Macro-9
MACRO_ALIASES: Mapping[str, str] = {
    f"macro_{n}": f"fn_{KEY_NAMES[code]}" for n, code in enumerate(_MACRO_KEYS, start=1)
}
BUTTONS = (*KEY_NAMES.values(), *(f"fn_{name}" for name in KEY_NAMES.values()))
#: Override actions, as MachineControl.override takes them (kind, step).
_OVERRIDES: Mapping[str, tuple[str, str]] = {
    f"{kind} {step}": (kind, step)
    for kind, steps in (
        ("feed", ("+10", "-10", "+1", "-1", "reset")),
        ("rapid", ("100", "50", "25")),
    )
    for step in steps
}
_PLAIN = ("reset", "unlock", "home", "goto_zero", "hold", "resume")
ACTIONS = ("none", "stop", "hold_resume", "zero_axis", "zero_all", *_PLAIN, *_OVERRIDES)
DEFAULT_BUTTONS: Mapping[str, str] = {
    **dict.fromkeys(BUTTONS, "none"),
    "reset": "reset",
    "start_pause": "hold_resume",
    "feed_plus": "feed +10",
    "feed_minus": "feed -10",
    "m_home": "home",
    "w_home": "goto_zero",
    # W-HOME goes to work zero, so Fn + W-HOME (Macro-7) sets it on the selected axis; Fn +
    # M-HOME (Macro-5) sets it on every axis. Both only write offsets: nothing moves.
    "fn_w_home": "zero_axis",
    "fn_m_home": "zero_all",
}

# How far one detent goes in velocity mode. The engine runs count x step_mm at the selector's
# feed, but never lets the path ahead of the machine exceed v²/2a + v·committed_s (jogger
# _take_wheel) and drops the counts beyond it, so a detent longer than that lead never moves.
# The lead is shortest at the 2 % position: on the hobby router (5000 mm/min, 500 mm/s²) it is
# 0.003 + 1.67 mm/s x 0.05 s = 0.086 mm, less half a motor step. 0.05 mm is the largest round
# step that still moves there; faster positions then cap how fast the detents run (a brisk spin,
# 20-40 detents/s, is 1-2 mm/s) and so how far the machine coasts once the wheel stops. Slow
# machines (Grbl's 500 mm/min defaults) want 0.005 for the 2 % position to move.
DEFAULT_VELOCITY_STEP_MM = 0.05


def read_buttons(options: Table) -> dict[str, str]:
    """The `buttons` table over the defaults; ConfigError naming the key for anything wrong."""
    table: Mapping[str, Any] = options.table("buttons")
    result = dict(DEFAULT_BUTTONS)
    given: dict[str, str] = {}
    for name, action in table.items():
        key = f"buttons.{name}"
        if name == "stop":
            if action != "stop":
                raise options.error(key, f"= {action!r}: the STOP key always stops; remove it")
            continue
        canonical = MACRO_ALIASES.get(name, name)
        if canonical not in result:
            names = ", ".join((*BUTTONS, *MACRO_ALIASES))
            raise options.error(key, f"is not a WHB04B button: the buttons are {names}")
        if canonical in given:
            raise options.error(key, f"names the same key as buttons.{given[canonical]}")
        if action not in ACTIONS:
            raise options.error(key, f"= {action!r} is not one of {', '.join(ACTIONS)}")
        given[canonical] = name
        result[canonical] = action
    return result


# -- the decoder -------------------------------------------------------------------------------


class Whb04bDecoder(Decoder):
    """WHB04B reports -> handwheel intents, commands and stops (devices §4)."""

    name = "whb04b"
    kind = "handwheel"
    transport = "hidraw"

    def __init__(self, info: DeviceInfo, options: Table, axes: Sequence[str]) -> None:
        """Read step_speed, velocity_step_mm, watchdog_s, invert, lcd_coords and buttons."""
        super().__init__(info, options, axes)
        self.step_speed = options.number("step_speed", 0.5, above=0.0, at_most=1.0)
        self.velocity_step_mm = options.number(
            "velocity_step_mm", DEFAULT_VELOCITY_STEP_MM, at_least=0.001, at_most=100.0
        )
        # The idle-report period is UNVERIFIED (devices §4.2); LinuxCNC takes 750 ms as normal.
        self.watchdog_s = options.number("watchdog_s", 2.0, above=0.0, at_most=60.0)
        self.invert = options.flag("invert", False)  # the wheel's sign is UNVERIFIED (§4.2)
        self.lcd_coords = options.choice("lcd_coords", "work", ("work", "machine"))
        self.buttons = read_buttons(options)
        options.finish()
        self.crc_mismatches = 0
        self.ignored = 0  # reports of the wrong length or ID
        self._reset_state()

    def _reset_state(self) -> None:
        # Step mode from start-up: position mode moves exactly what was turned, and a mode key
        # must be pressed to get the faster, lossy velocity mode.
        self._mode: Literal["step", "continuous"] = "step"
        self._known = False  # no regular report yet: selectors unknown, no motion
        self._axis: str | None = None
        self._feed: FeedPosition | None = None
        self._pressed: frozenset[int] = frozenset()
        self._motion = False  # counts sent and no stop since: they may still be running
        self._asleep = False
        self._silent = False
        self._last_s: float | None = None
        self._explained: str | None = None
        self._alternate = "resume"  # so the first blind Start/Pause holds
        self._machine_state = ""
        self._lcd_sent: list[bytes] | None = None

    @classmethod
    def matches(cls, info: DeviceInfo) -> bool:
        """The XHC dongle (10ce:eb93) and the WMPG-6 clone (10ce:eb91)."""
        return info.vendor == VENDOR_XHC and info.product in PRODUCTS

    @property
    def moving(self) -> bool:
        """True from the first count sent until a stop: position counts may run for long."""
        return self._motion

    def feed(self, item: DeviceItem) -> list[Action]:
        """One hidraw report."""
        if not isinstance(item, HidReport):
            return []
        report = decode_report(item.data)
        if report is None:
            self.ignored += 1
            return []
        actions: list[Action] = []
        deadline = self.deadline_s()
        if deadline is not None and item.t_s >= deadline:
            actions += self.tick(item.t_s)  # the gap was real, whether or not tick came
        if report.kind == "regular":
            actions += self._regular(report)
        elif not self._asleep:
            actions += self._stop()
            actions.append(
                DeviceNotice("handwheel switched off or asleep: no motion until it wakes")
            )
            self._reset_selectors()
            self._asleep, self._silent = True, False
        self._last_s = item.t_s
        return actions

    def deadline_s(self) -> float | None:
        """The report watchdog's expiry, armed while counts may be running."""
        if not self._motion or self._last_s is None:
            return None
        return self._last_s + self.watchdog_s

    def tick(self, now_s: float) -> list[Action]:
        """No report for watchdog_s while moving: the pendant left radio range; stop."""
        deadline = self.deadline_s()
        if deadline is None or now_s < deadline:
            return []
        # Position-mode counts still queued are cut too: with the link gone the pendant's own
        # STOP key cannot reach us, so finishing a long queue would be motion nobody can stop.
        self._silent = True
        return [
            *self._stop(),
            DeviceNotice(
                f"handwheel silent for {self.watchdog_s:g} s (out of radio range or battery "
                "flat?): jog stopped"
            ),
        ]

    def lost(self) -> list[Action]:
        """Forget everything; the DeviceInput stops the machine if we were moving."""
        self._reset_state()
        return [DeviceNotice("handwheel lost (dongle unplugged or read error): state forgotten")]

    # -- reports -------------------------------------------------------------------------------
    def _reset_selectors(self) -> None:
        self._known, self._axis, self._feed = False, None, None
        self._pressed, self._explained = frozenset(), None

    def _stop(self) -> list[Action]:
        """A StopIntent if counts may be running."""
        if not self._motion:
            return []
        self._motion = False
        return [StopIntent()]

    def _regular(self, report: WhbReport) -> list[Action]:
        actions: list[Action] = []
        if report.crc_ok is False:
            self.crc_mismatches += 1  # counted, never dropped: it follows the seed we wrote
        drop = False
        if self._asleep:
            self._asleep, self._lcd_sent = False, None
            actions.append(DeviceNotice("handwheel awake"))
            # Its delta is kept: the encoder had no power while asleep, so it is a fresh turn.
        if self._silent:
            self._silent, self._lcd_sent = False, None
            actions.append(DeviceNotice("handwheel reports again"))
            # The delta counts from the pendant's previous send, which may be a report we never
            # got: counts turned during the gap would move seconds late, so they are dropped.
            drop = True
        first = not self._known
        self._known = True
        # Unknown codes (a knob between positions, devices §4.2) keep the last valid value, and
        # that report's counts are dropped: which axis or step the user means is unclear.
        axis = AXIS_CODES.get(report.axis_code, self._axis)
        feed = FEED_CODES.get(report.feed_code, self._feed)
        drop = drop or report.axis_code not in AXIS_CODES or report.feed_code not in FEED_CODES
        changed = not first and (axis != self._axis or feed != self._feed)
        self._axis, self._feed = axis, feed
        pressed = frozenset(k for k in (report.key1, report.key2) if 0x01 <= k <= 0x10)
        # A key counts once, on the report where it first shows: held keys repeat in reports.
        presses = [
            k for k in dict.fromkeys((report.key1, report.key2)) if k in pressed - self._pressed
        ]
        fn = KEY_FN in pressed
        self._pressed = pressed
        # The keys are swapped against their labels: 0x0e (labelled MPG) is continuous and
        # 0x0f (labelled STEP/Continuous) is step (devices §4.2, the LinuxCNC README).
        for key in presses:
            if key in (KEY_CONTINUOUS, KEY_STEP):
                mode: Literal["step", "continuous"] = (
                    "continuous" if key == KEY_CONTINUOUS else "step"
                )
                changed = changed or mode != self._mode
                self._mode = mode
        if changed:
            # Counter hazard (devices §4.2, LinuxCNC PR #3810): counts meant for the old axis,
            # step or mode must not run under the new one. Nothing is kept between reports, so
            # dropping this report's delta is the whole accumulator reset.
            actions += self._stop()
            self._explained, drop = None, True
        for key in presses:
            if key == KEY_STOP:
                actions += [StopIntent(button=True)]
                self._motion, drop = False, True
            elif key in KEY_NAMES:
                actions += self._command(self.buttons[("fn_" if fn else "") + KEY_NAMES[key]])
        if report.delta and not drop:
            actions += self._wheel(-report.delta if self.invert else report.delta)
        return actions

    def _wheel(self, counts: int) -> list[Action]:
        axis, feed = self._axis, self._feed
        if axis is None or axis == "OFF" or feed is None:
            return []
        if axis not in self.axes:
            return self._explain(f"handwheel on {axis}: the machine has no {axis} axis")
        if self._mode == "step":
            if feed.step_mm is None:
                # The LCD shows "STEP: 1.0" here (a firmware bug, devices §4.3): never 1 mm.
                return self._explain(
                    f"handwheel: step mode has no step at {feed.label}: turn the selector to "
                    "0.001-1, or press the continuous-mode key"
                )
            intent = HandwheelIntent(axis, counts, feed.step_mm, "position", self.step_speed)
        else:
            if feed.percent is None:
                return self._explain(f"handwheel: {feed.label} does not jog")
            intent = HandwheelIntent(
                axis, counts, self.velocity_step_mm, "velocity", feed.percent / 100
            )
        self._motion = True
        return [intent]

    def _explain(self, text: str) -> list[Action]:
        """A notice for turns that do nothing, once per selector setting."""
        if text == self._explained:
            return []
        self._explained = text
        return [DeviceNotice(text)]

    def _command(self, action: str) -> list[Action]:
        if action == "none":
            return []
        if action == "stop":
            self._motion = False
            return [StopIntent(button=True)]
        if action == "hold_resume":
            return [DeviceCommand(self._hold_or_resume())]
        if action == "zero_all":
            return [DeviceCommand("zero", axes=self.axes)]
        if action == "zero_axis":
            if self._axis not in self.axes:
                return [DeviceNotice("handwheel: turn the axis selector to an axis to zero it")]
            return [DeviceCommand("zero", axes=(str(self._axis),))]
        if action in _OVERRIDES:
            kind, step = _OVERRIDES[action]
            return [DeviceCommand("override", kind=kind, step=step)]
        return [DeviceCommand(action)]

    def _hold_or_resume(self) -> str:
        """Start/Pause: resume a machine in Hold or Door, hold any other; alternate if unknown.

        The machine's state comes with display(); without one the key alternates, starting
        with hold, since a stray hold is harmless and a resume on a running machine does nothing.
        """
        state = self._machine_state.split(":")[0]
        if state:
            return "resume" if state in ("Hold", "Door") else "hold"
        self._alternate = "hold" if self._alternate == "resume" else "resume"
        return self._alternate

    # -- the LCD and the description -----------------------------------------------------------
    def display(self, view: DisplayView) -> list[bytes]:
        """The LCD's three feature reports when what it shows changed (none while asleep)."""
        self._machine_state = view.state
        if self._asleep:
            return []
        rows = ("A", "B", "C") if self._axis in ("A", "B", "C") else ("X", "Y", "Z")
        positions = view.wpos_mm if self.lcd_coords == "work" else view.mpos_mm
        frames = encode_display(
            [positions.get(axis, 0.0) for axis in rows],
            feed=view.feed_mm_min,
            spindle=view.spindle_rpm,
            mode=LCD_MODE_STEP if self._mode == "step" else LCD_MODE_CONT,
            work_coords=self.lcd_coords == "work",
        )
        if frames == self._lcd_sent:
            return []
        self._lcd_sent = frames
        return frames

    def describe(self) -> str:
        """E.g. "WHB04B: axis X, step 0.01 mm, step mode"."""
        if self._asleep:
            return "WHB04B: asleep"
        if self._silent:
            return f"WHB04B: silent (no report for {self.watchdog_s:g} s)"
        if not self._known:
            return "WHB04B: waiting for the first report (turn a knob or press a key)"
        axis = self._axis or "unknown"
        feed = self._feed
        if feed is None:
            where = "selector unknown"
        elif self._mode == "step":
            where = f"step {feed.label} mm" if feed.step_mm else f"{feed.label} (no step)"
        else:
            where = f"{feed.percent} %" if feed.percent else f"{feed.label} (no motion)"
        return f"WHB04B: axis {axis}, {where}, {self._mode} mode"


__all__ = [
    "ACTIONS",
    "BUTTONS",
    "DEFAULT_BUTTONS",
    "SEED",
    "Whb04bDecoder",
    "WhbReport",
    "checksum",
    "decode_report",
    "encode_display",
]
