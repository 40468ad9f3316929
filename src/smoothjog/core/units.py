"""Axes and unit conversions; the units convention of smoothjog is stated here once.

Names carry their unit: `_mm` distance in millimetres, `_mm_s` speed in mm/s, `_mm_min` feed in
mm/min (Grbl's F and `$11x`), `_mm_s2` acceleration in mm/s² (Grbl's `$12x`), `_s` time in seconds,
`now_s` a time passed in by the caller (the core never reads a clock). Positions are tuples of
floats in axis order; conversions between mm/min and mm/s happen only through these helpers.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence

#: Every axis letter a Grbl-family controller may accept in a jog, in report order.
ALL_AXES: tuple[str, ...] = ("X", "Y", "Z", "A", "B", "C", "U", "V", "W")
#: The axes of a default Grbl 1.1h build.
GRBL_AXES: tuple[str, ...] = ("X", "Y", "Z")

MM_PER_INCH = 25.4

Vec = tuple[float, ...]

_SINGLE = struct.Struct("<f")


def f32(x: float) -> float:
    """x rounded to the nearest IEEE single, as storing it in a C float does (inf beyond range).

    Grbl keeps every length in singles (firmware-facts §1.5; grblHAL and FluidNC keep positions
    in C floats too), so one single-precision operation is `f32` of the double result.
    """
    try:
        single: float = _SINGLE.unpack(_SINGLE.pack(x))[0]
    except OverflowError:
        return math.copysign(math.inf, x)
    return single


def g91_end(start: Vec, deltas: Vec) -> Vec:
    """Where the controller's parser puts a G91 line's target: each axis the line moves is
    the single-precision sum of its position and the value; the others stay where they are.

    A stream of increments summed in doubles drifts from the firmware's sum by up to half an
    ulp per line, in the same direction while the increment repeats (firmware-facts §1.5): a
    few hundredths of a mm over a long jog, far more than a step.
    """
    return tuple(
        s if d == 0.0 else f32(f32(s) + f32(d)) for s, d in zip(start, deltas, strict=True)
    )


def mm_min_to_mm_s(feed_mm_min: float) -> float:
    """Convert a feed in mm/min to a speed in mm/s."""
    return feed_mm_min / 60.0


def mm_s_to_mm_min(speed_mm_s: float) -> float:
    """Convert a speed in mm/s to a feed in mm/min."""
    return speed_mm_s * 60.0


def inch_to_mm(value_in: float) -> float:
    """Convert inches to millimetres."""
    return value_in * MM_PER_INCH


def mm_to_inch(value_mm: float) -> float:
    """Convert millimetres to inches."""
    return value_mm / MM_PER_INCH


def norm(v: Sequence[float]) -> float:
    """Euclidean length of a vector."""
    return math.sqrt(sum(c * c for c in v))


def unit(v: Sequence[float]) -> Vec:
    """The unit vector along v; the zero vector stays zero."""
    n = norm(v)
    if n == 0.0:
        return tuple(0.0 for _ in v)
    return tuple(c / n for c in v)


def limit_by_axis_maximum(max_per_axis: Sequence[float], unit_vec: Sequence[float]) -> float:
    """The largest vector magnitude whose per-axis components stay within their maxima.

    This is Grbl's `limit_value_by_axis_maximum` (firmware-facts §4.2): the minimum over the axes
    that move of max_i / |u_i|. It gives the feed cap ($11x) and the acceleration (`$12x`) along a
    move.
    """
    best = math.inf
    for limit, component in zip(max_per_axis, unit_vec, strict=True):
        if component != 0.0:
            best = min(best, limit / abs(component))
    return best
