"""The simulated controller's `$` settings: storage, Grbl's store rules, and `$$` formatting.

Numbers and rules follow firmware-facts §0 (defaults), §2 ($20 needs $22) and §5.3 (print format and
order). Settings are kept as floats keyed by their `$` number; the integer ones are truncated on
store.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from smoothjog.core.codes import (
    ERR_INVALID_STATEMENT,
    ERR_NEGATIVE_VALUE,
    ERR_SETTING_STEP_PULSE_MIN,
    ERR_SOFT_LIMIT_ERROR,
    STATUS_OK,
)
from smoothjog.core.defaults import (
    ACCEL_SETTING,
    AXIS_GROUP_DEFAULTS,
    GRBL_DEFAULTS,
    MAX_RATE_SETTING,
    MAX_TRAVEL_SETTING,
    STEPS_PER_MM_SETTING,
)
from smoothjog.core.errors import SimError

#: Settings printed with 3 decimals by `$$`; every other one prints as an integer (firmware-facts
#: §5.3).
FLOAT_SETTINGS: frozenset[int] = frozenset({11, 12, 24, 25, 27, *range(100, 140)})
#: Settings that are floats in the firmware but print with 0 decimals ($30/$31 spindle rpm).
RPM_SETTINGS: frozenset[int] = frozenset({30, 31})


@dataclass(frozen=True)
class AxisSettings:
    """The four `$1xx` settings of one axis."""

    steps_per_mm: float
    max_rate_mm_min: float
    accel_mm_s2: float
    max_travel_mm: float


def format_setting_value(number: int, value: float) -> str:
    """The text `$$` prints for one setting value."""
    if number in FLOAT_SETTINGS:
        return format_grbl_float(value, 3)
    return format_grbl_float(value, 0)


def format_grbl_float(value: float, decimals: int) -> str:
    """Print a float like Grbl's printFloat: sign first, then the magnitude rounded half up."""
    # Grbl rounds the magnitude half away from zero and keeps a '-' even when the digits are
    # all zero (firmware-facts §5.4 "-0.000"); Python's formatting rounds half to even, so do it
    # here.
    negative = value < 0.0 or (value == 0.0 and math.copysign(1.0, value) < 0.0)
    scaled = math.floor(abs(value) * 10**decimals + 0.5)
    whole, frac = divmod(scaled, 10**decimals)
    text = f"{whole}.{frac:0{decimals}d}" if decimals > 0 else f"{whole}"
    return f"-{text}" if negative and value != 0.0 else text


#: On/off settings: Grbl keeps them as bits of its flags byte, so any non-zero value is stored
#: and printed as 1 (`settings.c`: step-enable, limit and probe invert, report inches, soft and
#: hard limits, homing, laser mode).
FLAG_SETTINGS = frozenset({4, 5, 6, 13, 20, 21, 22, 32})


class GrblSettings:
    """The `$` settings of one simulated controller, with Grbl's store rules."""

    def __init__(
        self,
        n_axes: int = 3,
        extra_defaults: Mapping[int, float] | None = None,
        word_settings: frozenset[int] = frozenset(),
    ) -> None:
        """Start from Grbl's defaults for n_axes axes plus a firmware's extra settings;
        word_settings are integers kept in 16 bits rather than one byte."""
        self.n_axes = n_axes
        self._word_settings = word_settings
        self._values: dict[int, float] = {}
        for number, value in GRBL_DEFAULTS.items():
            if number < STEPS_PER_MM_SETTING:
                self._values[number] = float(value)
        # The per-axis groups repeat the default build's value on every axis there is.
        for group, default in AXIS_GROUP_DEFAULTS.items():
            for axis in range(n_axes):
                self._values[group + axis] = default
        for number, value in (extra_defaults or {}).items():
            self._values[number] = float(value)

    def __getitem__(self, number: int) -> float:
        """The value of setting `$number`."""
        return self._values[number]

    def int_value(self, number: int) -> int:
        """An integer setting ($10, $13, $22 ...) as an int."""
        return int(self._values[number])

    def numbers(self) -> list[int]:
        """Every setting number, in the order `$$` prints them (ascending, as in firmware-facts
        §5.3)."""
        return sorted(self._values)

    def items(self) -> Iterable[tuple[int, float]]:
        """Pairs of (number, value) in `$$` order."""
        return ((n, self._values[n]) for n in self.numbers())

    def axis(self, index: int) -> AxisSettings:
        """The steps/mm, max rate, acceleration and travel of one axis."""
        return AxisSettings(
            steps_per_mm=self._values[STEPS_PER_MM_SETTING + index],
            max_rate_mm_min=self._values[MAX_RATE_SETTING + index],
            accel_mm_s2=self._values[ACCEL_SETTING + index],
            max_travel_mm=self._values[MAX_TRAVEL_SETTING + index],
        )

    def store(self, number: int, value: float) -> int:
        """Store `$number=value` with Grbl's checks; returns a Grbl status code (0 = ok)."""
        if value < 0.0:
            return ERR_NEGATIVE_VALUE
        if number not in self._values:
            return ERR_INVALID_STATEMENT
        if number in FLOAT_SETTINGS or number in RPM_SETTINGS:
            self._values[number] = value
            return STATUS_OK
        # Integer settings are single bytes in Grbl; a value above 255 wraps (assumed, as the
        # AVR's float-to-byte conversion does in practice).
        int_value = math.trunc(value) % (65536 if number in self._word_settings else 256)
        if number == 0 and int_value < 3:
            return ERR_SETTING_STEP_PULSE_MIN
        if number == 20 and int_value and not self.int_value(22):
            return ERR_SOFT_LIMIT_ERROR
        if number in FLAG_SETTINGS:
            int_value = 1 if int_value else 0
        self._values[number] = float(int_value)
        if number == 22 and not int_value:
            # Turning homing off also turns soft limits off (firmware-facts §2).
            self._values[20] = 0.0
        return STATUS_OK

    def force(self, number: int, value: float) -> None:
        """Set a value without Grbl's checks (machine profiles, settings files)."""
        if number not in self._values:
            raise SimError(
                f"setting ${number} does not exist on this controller; "
                f"valid numbers are {', '.join('$' + str(n) for n in self.numbers())}"
            )
        self._values[number] = float(value)

    def dollar_lines(self) -> list[str]:
        """The lines `$$` prints, without the final ok."""
        return [f"${n}={format_setting_value(n, v)}" for n, v in self.items()]

    def snapshot(self) -> dict[int, float]:
        """A copy of every value."""
        return dict(self._values)


@dataclass(frozen=True)
class Eeprom:
    """What Grbl keeps in EEPROM: settings, G54-G59, G28/G30, startup lines, the $I string."""

    settings: dict[int, float]
    coord_systems_mm: tuple[tuple[float, ...], ...]
    g28_mm: tuple[float, ...]
    g30_mm: tuple[float, ...]
    startup_lines: tuple[str, str] = ("", "")
    build_info: str = ""

    def to_json(self) -> str:
        """The image as a JSON text (the `--settings FILE` format)."""
        data = {
            "settings": {str(k): v for k, v in sorted(self.settings.items())},
            "coord_systems_mm": [list(c) for c in self.coord_systems_mm],
            "g28_mm": list(self.g28_mm),
            "g30_mm": list(self.g30_mm),
            "startup_lines": list(self.startup_lines),
            "build_info": self.build_info,
        }
        return json.dumps(data, indent=1) + "\n"

    @classmethod
    def from_json(cls, text: str, source: str) -> Eeprom:
        """Parse a saved image; errors name the file and the key."""
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise SimError(f"{source}: not a smoothjog settings file ({exc})") from None
        if not isinstance(data, dict):
            raise SimError(f"{source}: expected a JSON object of settings")
        try:
            settings = {int(k): float(v) for k, v in data["settings"].items()}
            coords = tuple(tuple(float(x) for x in c) for c in data["coord_systems_mm"])
            g28 = tuple(float(x) for x in data["g28_mm"])
            g30 = tuple(float(x) for x in data["g30_mm"])
            lines = [str(s) for s in data.get("startup_lines", ["", ""])]
            info = str(data.get("build_info", ""))
        except KeyError as exc:
            raise SimError(f"{source}: missing key {exc}; delete the file to start anew") from None
        except (TypeError, ValueError, AttributeError) as exc:
            raise SimError(f"{source}: a value has the wrong type ({exc})") from None
        if len(lines) != 2 or len(coords) != 6:
            raise SimError(f"{source}: 'startup_lines' needs 2 entries, 'coord_systems_mm' 6")
        return cls(settings, coords, g28, g30, (lines[0], lines[1]), info)


def load_eeprom(path: Path) -> Eeprom | None:
    """The image saved at path, or None when the file does not exist yet."""
    if not path.exists():
        return None
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise SimError(f"cannot read settings file {path}: {exc.strerror}") from None
    return Eeprom.from_json(text, str(path))


def save_eeprom(path: Path, image: Eeprom) -> None:
    """Write the image atomically (a crash never leaves half a file)."""
    tmp = path.with_name(path.name + ".tmp")
    try:
        tmp.write_text(image.to_json(), encoding="utf-8")
        os.replace(tmp, path)
    except OSError as exc:
        raise SimError(f"cannot write settings file {path}: {exc.strerror}") from None
