"""Grbl's 32-bit float arithmetic: float rounding, read_float, lround, steps <-> mm, printFloat.

Grbl 1.1h runs on an AVR, where avr-gcc makes `double` the same 32-bit IEEE single as `float`:
every length the firmware keeps (parser position, targets, settings, offsets) and every
constant it multiplies by (0.01 and 0.1 in read_float, MM_PER_INCH, INCH_PER_MM) is a single, and
each operation rounds to a single (firmware-facts §1.5, "float32 arithmetic"). Python floats are
doubles; a double holds every single exactly, and one +, -, * or / of two singles done in double
and then rounded to single gives the correctly rounded single result (a double carries more than
2 x 24 + 2 bits), so `f32(a * b)` is the chip's `a * b` when a and b are singles.

The sim applies the same arithmetic to grblHAL and FluidNC, which also keep positions in C
`float`; their number readers were not compared with Grbl's.
"""

from __future__ import annotations

import math

from smoothjog.core.units import f32

#: The constants of nuts_bolts.c:read_float and nuts_bolts.h, as singles (AVR: double is float).
F32_0_01 = f32(0.01)
F32_0_1 = f32(0.1)
MM_PER_INCH_F32 = f32(25.4)
INCH_PER_MM_F32 = f32(0.0393701)

#: f32 is defined once, in core.units (the engine tracks the firmware's sums with it).
__all__ = [
    "F32_0_01",
    "F32_0_1",
    "INCH_PER_MM_F32",
    "MAX_INT_DIGITS",
    "MM_PER_INCH_F32",
    "f32",
    "lround",
    "mm_to_steps",
    "print_coord",
    "print_float",
    "read_float",
    "steps_to_mm",
]

#: read_float's MAX_INT_DIGITS: digits beyond the 8th carry no value (integer ones still scale).
MAX_INT_DIGITS = 8


def lround(x: float) -> int:
    """C's lround: the nearest integer, halves away from zero (exact for any single x)."""
    # x + 0.5 is exact in double for a single of magnitude below 2**28, so no double rounding.
    return math.floor(x + 0.5) if x >= 0.0 else -math.floor(-x + 0.5)


def read_float(text: str, start: int) -> tuple[float, int] | None:
    """nuts_bolts.c:read_float on text[start:]: (single value, index after it), None if no digit.

    Optional sign, digits with at most one '.', no exponent; the digits go into an integer, which
    becomes a single and is scaled by 0.01 and 0.1 (or 10) in single arithmetic, each step
    rounded, so the value can be an ulp or two from the nearest single to the decimal.
    """
    i = start
    end = len(text)
    negative = False
    if i < end and text[i] in "+-":
        negative = text[i] == "-"
        i += 1
    intval = 0
    exp = 0
    ndigit = 0
    decimal = False
    while i < end:
        c = text[i]
        if "0" <= c <= "9":
            ndigit += 1
            if ndigit <= MAX_INT_DIGITS:
                if decimal:
                    exp -= 1
                intval = intval * 10 + (ord(c) - 0x30)
            elif not decimal:
                exp += 1
        elif c == "." and not decimal:
            decimal = True
        else:
            break
        i += 1
    if ndigit == 0:
        return None
    fval = f32(float(intval))
    if fval != 0.0:
        while exp <= -2:
            fval = f32(fval * F32_0_01)
            exp += 2
        if exp < 0:
            fval = f32(fval * F32_0_1)
        while exp > 0:
            fval = f32(fval * 10.0)
            exp -= 1
    return (-fval if negative else fval), i


def mm_to_steps(target_mm: float, steps_per_mm: float) -> int:
    """planner.c:plan_buffer_line's lround(target * steps_per_mm), the product a single."""
    return lround(f32(target_mm * steps_per_mm))


#: Integers up to this magnitude are singles already (24-bit significand).
_EXACT_INT = 1 << 24


def steps_to_mm(steps: int, steps_per_mm: float) -> float:
    """system.c:system_convert_axis_steps_to_mpos: steps / steps_per_mm as singles."""
    # Hot path (every status report and position sync): the int-to-float rounding is skipped
    # where it cannot change the count.
    if -_EXACT_INT <= steps <= _EXACT_INT:
        return f32(steps / steps_per_mm)
    return f32(f32(float(steps)) / steps_per_mm)


def print_float(value: float, decimals: int) -> str:
    """print.c:printFloat of a single: '-' if negative, scaled and rounded (+0.5) in single."""
    negative = value < 0.0
    n = -value if negative else value
    d = decimals
    while d >= 2:
        n = f32(n * 100.0)
        d -= 2
    if d:
        n = f32(n * 10.0)
    n = f32(n + 0.5)
    digits = str(math.trunc(n)).rjust(decimals + 1, "0")
    if decimals:
        digits = f"{digits[:-decimals]}.{digits[-decimals:]}"
    return f"-{digits}" if negative else digits


def print_coord(value_mm: float, inches: bool) -> str:
    """print.c:printFloat_CoordValue: 3 decimals in mm, or x INCH_PER_MM and 4 decimals."""
    if inches:
        return print_float(f32(value_mm * INCH_PER_MM_F32), 4)
    return print_float(value_mm, 3)
