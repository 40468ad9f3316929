"""Tests for core/jogline.py: number format, refusals, and a round trip through the parser model."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from smoothjog.core.errors import JogBuildError
from smoothjog.core.gcode import ParserState, execute_block, preparse
from smoothjog.core.jogline import (
    FEED_INCH_DECIMALS,
    FEED_MM_DECIMALS,
    INCH_DECIMALS,
    MM_DECIMALS,
    JogMode,
    JogUnits,
    build_jog_line,
    format_number,
)
from smoothjog.core.units import MM_PER_INCH

FORMAT_ROWS = [
    (0.833333, 4, "0.8333"),
    (1.5, 4, "1.5"),
    (100.0, 4, "100"),
    (-2.0, 4, "-2"),
    (-0.00004, 4, "0"),  # never "-0"
    (-0.0, 4, "0"),
    (2.25, 1, "2.2"),  # half to even on the exact binary value
    (2.75, 1, "2.8"),
    (1e-7, 4, "0"),
    (1e20 / 1e15, 4, "100000"),  # no exponent
    (123456.789, 4, "123456.79"),  # 8 digits at most: decimals give way
    (12345678.4, 4, "12345678"),
    (0.000012345678, 9, "0.0000123"),  # leading zeros count as digits
]


@pytest.mark.parametrize(("value", "decimals", "text"), FORMAT_ROWS)
def test_format_number(value: float, decimals: int, text: str) -> None:
    assert format_number(value, decimals) == text


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 1e9, 123456789.0])
def test_format_number_refuses(value: float) -> None:
    with pytest.raises(JogBuildError, match="cannot write"):
        format_number(value, 4)


BUILD_ROWS = [
    ({"X": 0.83333333}, 5000.0, "G91", "G21", "$J=G21G91X0.8333F5000"),
    ({"Z": -1.0, "X": 2.0}, 300.0, "G91", "G21", "$J=G21G91X2Z-1F300"),  # machine axis order
    ({"X": 0.0, "Y": 1.0}, 300.0, "G91", "G21", "$J=G21G91Y1F300"),  # zero step left out
    ({"X": 0.0}, 300.0, "G90", "G21", "$J=G21G90X0F300"),  # zero kept as a coordinate
    ({"Y": -10.0}, 1000.5, "G53", "G21", "$J=G21G53Y-10F1000.5"),
    ({"X": 25.4}, 254.0, "G91", "G20", "$J=G20G91X1F10"),
]


@pytest.mark.parametrize(("moves", "feed", "mode", "units", "line"), BUILD_ROWS)
def test_build_jog_line(
    moves: dict[str, float], feed: float, mode: JogMode, units: JogUnits, line: str
) -> None:
    assert build_jog_line(moves=moves, feed_mm_min=feed, mode=mode, units=units) == line


REFUSE_ROWS = [
    ({}, 100.0, {}, "at least one axis word"),
    ({"X": 0.0, "Y": 0.00001}, 100.0, {}, "rounds to 0"),
    ({"X": 1.0}, 0.0, {}, "not a positive number"),
    ({"X": 1.0}, -5.0, {}, "not a positive number"),
    ({"X": 1.0}, math.nan, {}, "not a positive number"),
    ({"X": 1.0}, math.inf, {}, "not a positive number"),
    ({"X": 1.0}, 0.0001, {}, "rounds to F0"),
    ({"X": math.nan}, 100.0, {}, "finite"),
    ({"Y": -math.inf}, 100.0, {}, "finite"),
    ({"A": 1.0}, 100.0, {}, "only X, Y, Z"),
    ({"x": 1.0}, 100.0, {}, "cannot jog axis 'x'"),
    ({"X": 1.0}, 100.0, {"axes": ("X", "F")}, "not axis letters"),
    ({"X": 1.0}, 100.0, {"mode": "G92"}, "jog mode"),
    ({"X": 1.0}, 100.0, {"units": "G22"}, "jog units"),
    ({"X": 1.0, "Y": 2.0}, 100.0, {"max_line_chars": 15}, "at most 15"),
    ({"X": 1e9}, 100.0, {}, "cannot write"),
]


@pytest.mark.parametrize(("moves", "feed", "extra", "message"), REFUSE_ROWS)
def test_build_refuses(
    moves: dict[str, float], feed: float, extra: dict[str, object], message: str
) -> None:
    with pytest.raises(JogBuildError, match=message):
        build_jog_line(moves=moves, feed_mm_min=feed, **extra)  # type: ignore[arg-type]


def test_build_allows_more_axes_when_the_machine_has_them() -> None:
    line = build_jog_line(moves={"A": 90.0, "X": 1.0}, feed_mm_min=100.0, axes=("X", "Y", "Z", "A"))
    assert line == "$J=G21G91X1A90F100"


def test_longest_three_axis_line_fits_grbl() -> None:
    big = -1234.5678
    line = build_jog_line(moves={"X": big, "Y": big, "Z": big}, feed_mm_min=12345.678)
    assert len(line) <= 79
    assert not preparse(line.encode()).overflow


# ---------------------------------------------------------------------------------- round trip

# A state whose modal words are the opposite of the usual ones, with offsets everywhere, so the
# round trip only passes if the line's own words decide everything.
_KNOWN_STATE = replace(
    ParserState.initial(position_mm=(-12.5, -33.25, -4.0)),
    units="G20",
    distance="G91",
    feed_mode="G93",
    motion="G2",
    feed_mm_min=7.0,
    coord_systems_mm=((-100.0, -80.0, -20.0), *((0.0, 0.0, 0.0),) * 5),
    g92_offset_mm=(1.5, -2.5, 0.25),
    tool_length_offset_mm=0.75,
)

_values_mm = st.floats(min_value=-2000.0, max_value=2000.0, allow_nan=False)
_moves = st.dictionaries(st.sampled_from(("X", "Y", "Z")), _values_mm, min_size=1)
_feeds = st.floats(min_value=0.1, max_value=100_000.0, allow_nan=False)
_modes = st.sampled_from(("G91", "G90", "G53"))
_units = st.sampled_from(("G21", "G20"))


def _expected_target(moves: dict[str, float], mode: str) -> tuple[float, ...]:
    st_ = _KNOWN_STATE
    target = list(st_.position_mm)
    for index, axis in enumerate(("X", "Y", "Z")):
        if axis not in moves:
            continue
        if mode == "G91":
            target[index] += moves[axis]
        elif mode == "G90":
            target[index] = moves[axis] + st_.work_offset_mm[index]
        else:
            target[index] = moves[axis]
    return tuple(target)


@given(moves=_moves, feed=_feeds, mode=_modes, units=_units)
def test_round_trip_through_the_parser(
    moves: dict[str, float], feed: float, mode: JogMode, units: JogUnits
) -> None:
    inches = units == "G20"
    scale = 1.0 / MM_PER_INCH if inches else 1.0
    decimals = INCH_DECIMALS if inches else MM_DECIMALS
    # The one legitimate refusal here (tested above): every G91 step rounds to nothing.
    assume(mode != "G91" or any(format_number(v * scale, decimals) != "0" for v in moves.values()))
    line = build_jog_line(moves=moves, feed_mm_min=feed, mode=mode, units=units)
    stored = preparse(line.encode())
    assert stored.text == line
    assert not stored.overflow
    result = execute_block(stored.text, _KNOWN_STATE, jog=True)
    assert result.error == 0, line
    assert result.motion is not None
    step_mm = 0.5 * 10.0 ** -(INCH_DECIMALS if inches else MM_DECIMALS)
    step_mm *= MM_PER_INCH if inches else 1.0
    for got, want in zip(result.motion.target_mm, _expected_target(moves, mode), strict=True):
        assert abs(got - want) <= step_mm + 1e-9 * max(1.0, abs(want)), line
    feed_step = 0.5 * 10.0 ** -(FEED_INCH_DECIMALS if inches else FEED_MM_DECIMALS)
    feed_step *= MM_PER_INCH if inches else 1.0
    # Above 8 digits decimals give way, so the error is also bounded relatively.
    assert abs(result.motion.feed_mm_min - feed) <= max(feed_step, 1e-7 * feed), line
    assert result.state.feed_mm_min == _KNOWN_STATE.feed_mm_min


@given(value=st.floats(allow_nan=False, allow_infinity=False, min_value=-1e7, max_value=1e7))
def test_format_number_is_readable_by_grbl(value: float) -> None:
    text = format_number(value, MM_DECIMALS)
    assert text != "-0"
    assert "e" not in text.lower()
    assert sum(c.isdigit() for c in text) <= 8
    assert abs(float(text) - value) <= max(0.5e-4, 1e-7 * abs(value)) + 1e-12


def test_format_number_refuses_negative_decimals() -> None:
    """A caller's bug, not a user's input: ValueError, not JogBuildError."""
    with pytest.raises(ValueError, match="decimals must be >= 0"):
        format_number(1.0, -1)
