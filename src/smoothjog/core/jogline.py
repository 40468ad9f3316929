"""Build `$J=` lines that Grbl accepts and that mean exactly what the caller asked for.

Every line names its units (G21/G20) and its distance mode (G91/G90) or G53, so whatever modal
state the controller is in cannot change its meaning (firmware-facts §1.5). It always has at least
one axis word, so the firmware's "no axis word goes to machine zero" flaw (firmware-facts §1.3)
cannot fire. It always has F, since a jog's F is never modal. Numbers have no exponent and at most 8
digits, because Grbl's reader drops any digit past the 8th (firmware-facts §1.3 "Number format").

Decimals kept: 4 for mm (0.1 µm, far below one step at any real steps/mm, so sub-step
increments still add up over a series of jogs, firmware-facts §1.5) and 5 for inches (0.25 µm). A
feed keeps 3 decimals in mm/min and 4 in in/min. A value too large for 8 digits at that precision
loses decimals, never integer digits.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from decimal import ROUND_HALF_EVEN, Decimal
from typing import Final, Literal

from smoothjog.core.codes import ERR_GCODE_UNDEFINED_FEED_RATE, ERR_NEGATIVE_VALUE, ERR_OVERFLOW
from smoothjog.core.errors import JogBuildError
from smoothjog.core.firmware import GRBL
from smoothjog.core.gcode import MAX_NUMBER_DIGITS
from smoothjog.core.units import ALL_AXES, GRBL_AXES, MM_PER_INCH

JogMode = Literal["G91", "G90", "G53"]
JogUnits = Literal["G21", "G20"]

#: Decimals of an axis value written in mm (G21).
MM_DECIMALS: Final = 4
#: Decimals of an axis value written in inches (G20).
INCH_DECIMALS: Final = 5
#: Decimals of F in mm/min (G21).
FEED_MM_DECIMALS: Final = 3
#: Decimals of F in in/min (G20).
FEED_INCH_DECIMALS: Final = 4

_MODES: Final = ("G91", "G90", "G53")
_UNITS: Final = ("G21", "G20")


def _fixed(value: Decimal) -> str:
    """Fixed-point text of a Decimal, trailing zeros and a bare point removed, never '-0'."""
    if value.is_zero():
        return "0"
    text = f"{value:f}"
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return text


@functools.lru_cache(maxsize=4096)
def format_number(value: float, decimals: int) -> str:
    """Write value for Grbl: no exponent, at most `decimals` decimals and 8 digits, never '-0'.

    Rounds half to even on the exact binary value. Raises JogBuildError for NaN or infinity, and
    for a value whose integer part alone needs more than 8 digits. Cached (hot path: a held jog
    writes the same increment and feed about a hundred times a second; 0.0 and -0.0 share an
    entry, which is right since both are written "0").
    """
    if decimals < 0:
        raise ValueError(f"format_number: decimals must be >= 0, got {decimals}")
    if not math.isfinite(value):
        raise JogBuildError(
            f"cannot write {value!r} in a jog line: Grbl only reads finite numbers; "
            "check the input that produced it"
        )
    exact = Decimal(value)
    places = decimals
    while True:
        rounded = exact.quantize(Decimal(1).scaleb(-places), rounding=ROUND_HALF_EVEN)
        text = _fixed(rounded)
        digits = sum(c.isdigit() for c in text)
        if digits <= MAX_NUMBER_DIGITS:
            return text
        if places == 0:
            raise JogBuildError(
                f"cannot write {value!r} in a jog line: it needs {digits} digits and Grbl keeps "
                f"only {MAX_NUMBER_DIGITS}; no machine travels that far, so check the units"
            )
        # Drop as many decimals as there are excess digits, then re-round from the exact value.
        places = max(0, places - (digits - MAX_NUMBER_DIGITS))


def build_jog_line(
    *,
    moves: Mapping[str, float],
    feed_mm_min: float,
    mode: JogMode = "G91",
    units: JogUnits = "G21",
    axes: Sequence[str] = GRBL_AXES,
    max_line_chars: int = GRBL.max_line_chars,
) -> str:
    """The `$J=` line (without newline) for moves in mm at feed_mm_min, or JogBuildError.

    `moves` maps axis letters to mm: a distance under G91, a work coordinate under G90, a machine
    coordinate under G53. Under G20 values and feed are written in inches. Axis words follow the
    order of `axes` (the machine's axes). Under G91 an axis whose written value is 0 is left out.
    """
    if mode not in _MODES:
        raise JogBuildError(f"jog mode {mode!r} is not one of {', '.join(_MODES)}")
    if units not in _UNITS:
        raise JogBuildError(f"jog units {units!r} is not one of {', '.join(_UNITS)}")
    unknown_axes = [a for a in axes if a not in ALL_AXES]
    if unknown_axes:
        raise JogBuildError(
            f"machine axes {unknown_axes} are not axis letters; "
            f"use letters from {''.join(ALL_AXES)}"
        )
    if not moves:
        raise JogBuildError(
            "a jog needs at least one axis word: Grbl sends a jog with none to machine zero"
        )
    for axis, value in moves.items():
        if axis not in axes:
            raise JogBuildError(
                f"cannot jog axis {axis!r}: this machine has only {', '.join(axes)}; "
                "check the axis mapping of the input"
            )
        if not math.isfinite(value):
            raise JogBuildError(
                f"cannot jog {axis} by {value!r}: the value must be a finite number of mm"
            )
    if not math.isfinite(feed_mm_min) or feed_mm_min <= 0:
        raise JogBuildError(
            f"jog feed {feed_mm_min!r} mm/min is not a positive number; Grbl needs F > 0 "
            f"(error:{ERR_GCODE_UNDEFINED_FEED_RATE} for F0, error:{ERR_NEGATIVE_VALUE} for a "
            "negative F)"
        )

    inches = units == "G20"
    scale = 1.0 / MM_PER_INCH if inches else 1.0
    decimals = INCH_DECIMALS if inches else MM_DECIMALS
    words: list[str] = []
    for axis in axes:
        if axis not in moves:
            continue
        text = format_number(moves[axis] * scale, decimals)
        if mode == "G91" and text == "0":
            continue  # a zero step is no move; leaving it out keeps the line short
        words.append(axis + text)
    if not words:
        raise JogBuildError(
            "every jog distance rounds to 0 at the precision written, so there is nothing to "
            "send (a jog with no axis word would go to machine zero)"
        )
    feed_text = format_number(
        feed_mm_min * scale, FEED_INCH_DECIMALS if inches else FEED_MM_DECIMALS
    )
    if feed_text == "0":
        raise JogBuildError(
            f"jog feed {feed_mm_min!r} mm/min rounds to F0, which Grbl refuses "
            f"(error:{ERR_GCODE_UNDEFINED_FEED_RATE})"
        )
    line = f"$J={units}{mode}{''.join(words)}F{feed_text}"
    if len(line) > max_line_chars:
        raise JogBuildError(
            f"the jog line {line!r} has {len(line)} characters but the controller stores at most "
            f"{max_line_chars} (error:{ERR_OVERFLOW}); jog fewer axes at once"
        )
    return line
