"""Tests for core/gcode.py: the pre-parser, `$J` dispatch and the parser model against the facts."""

from __future__ import annotations

from dataclasses import replace

import pytest

from smoothjog.core.gcode import (
    ExecResult,
    ParserState,
    Preparsed,
    TravelBox,
    check_jog_dispatch,
    execute_block,
    gc_modes_report,
    preparse,
    read_number,
)

# A machine somewhere inside its travel, with a work offset, so "machine 0" and "work 0" differ.
START_MM = (-5.0, -3.0, -1.0)
G54_MM = (-50.0, -40.0, -30.0)


def _state(**changes: object) -> ParserState:
    base = ParserState.initial(position_mm=START_MM)
    table = list(base.coord_systems_mm)
    table[0] = G54_MM
    return replace(base, coord_systems_mm=tuple(table), **changes)  # type: ignore[arg-type]


def _jog(line: str, state: ParserState | None = None, **kw: object) -> ExecResult:
    st = state if state is not None else _state()
    text = preparse(line.encode()).text
    return execute_block(text, st, jog=True, **kw)  # type: ignore[arg-type]


def _gcode(line: str, state: ParserState | None = None, **kw: object) -> ExecResult:
    st = state if state is not None else _state()
    text = preparse(line.encode()).text
    return execute_block(text, st, jog=False, **kw)  # type: ignore[arg-type]


def _close(a: tuple[float, ...], b: tuple[float, ...], tol: float = 1e-9) -> bool:
    return len(a) == len(b) and all(abs(x - y) <= tol for x, y in zip(a, b, strict=True))


# ---------------------------------------------------------------------------------- §1.1

PREPARSE_ROWS = [
    # (raw bytes, stored text, overflow)
    (b"$j=x1f1000", "$J=X1F1000", False),  # case
    (b"$ j = x 1 f 1 0 0 0", "$J=X1F1000", False),  # spaces
    (b"$J=X1\tF1000\x00\x01", "$J=X1F1000", False),  # control characters
    (b"$J=X1(why?)F100", "$J=X1F100", False),  # comment removed
    (b"$J=X1(a(b)c)F100", "$J=X1C)F100", False),  # no nesting: first ')' closes
    (b"$J=X1F100(unclosed", "$J=X1F100", False),  # unclosed '(' drops the rest
    (b"$J=X1F100;note X9", "$J=X1F100", False),  # ';' drops the rest
    (b"/$J=X1/F100", "$J=X1F100", False),  # block delete ignored
    (b"%", "%", False),  # '%' stays
    (b"", "", False),
    (b"(only a comment)", "", False),
]


@pytest.mark.parametrize(("raw", "text", "overflow"), PREPARSE_ROWS)
def test_preparse_rows(raw: bytes, text: str, overflow: bool) -> None:
    assert preparse(raw) == Preparsed(text, overflow)


def test_preparse_79_chars_fit_and_80_overflow() -> None:
    line79 = "$J=G91X1F" + "1" * 70
    assert len(line79) == 79
    assert preparse(line79.encode()).overflow is False
    over = preparse((line79 + "1").encode())
    assert over.overflow is True
    assert over.text == line79  # what was stored before the overflow


def test_preparse_long_comment_does_not_count() -> None:
    line79 = "$J=G91X1F" + "1" * 70
    padded = line79[:40] + "(" + "c" * 200 + ")" + " " * 30 + line79[40:]
    assert preparse(padded.encode()) == preparse(line79.encode())


def test_preparse_limit_is_a_parameter() -> None:
    line = "$J=G91X1F" + "1" * 100
    assert preparse(line.encode(), max_line_chars=255).overflow is False
    assert preparse(line.encode()).overflow is True


@pytest.mark.parametrize("raw", [b"$J=X1\n", b"\rX1"])
def test_preparse_refuses_end_of_line_bytes(raw: bytes) -> None:
    with pytest.raises(ValueError, match="end-of-line"):
        preparse(raw)


# ---------------------------------------------------------------------------------- §1.2

DISPATCH_ROWS = [
    ("$J=X1F100", "Idle", None),
    ("$J=X1F100", "Jog", None),
    ("$J=X1F100", "Alarm", 8),
    ("$J=X1F100", "Check", 8),
    ("$J=X1F100", "Run", 8),
    ("$J=X1F100", "Hold:0", 8),
    ("$J=X1F100", "Door:1", 8),
    ("$J=X1F100", "Sleep", 8),
    ("$J=X1F100", "Home", 8),
    ("$J", "Idle", 3),
    ("$JX1F100", "Idle", 3),
    ("$JX1F100", "Jog", 3),
    ("$JX1F100", "Alarm", 8),  # the state check comes first
]


@pytest.mark.parametrize(("line", "state", "code"), DISPATCH_ROWS)
def test_jog_dispatch(line: str, state: str, code: int | None) -> None:
    assert check_jog_dispatch(line, state) == code


# ---------------------------------------------------------------------------------- §1.3

JOG_ROWS = [
    # Accepted forms.
    ("$J=G91X1F100", 0),
    ("$J=G20G91X1F10", 0),
    ("$J=G21G90X1F10", 0),
    ("$J=G53X-1F100", 0),
    ("$J=N5G91X1F100", 0),
    ("$J=N10000000G91X1F100", 0),
    ("$J=G91X.5F100", 0),
    ("$J=G91X1.F100", 0),
    ("$J=G91X+1F100", 0),
    ("$J=F1000", 0),  # accepted: the dangerous no-axis case
    # F.
    ("$J=G91X1", 22),
    ("$J=G91X1F0", 22),
    ("$J=G91X1F-100", 4),
    # G90/G91 together.
    ("$J=G90G91X1F100", 21),
    # N.
    ("$J=N10000001X1F100", 27),
    ("$J=N-1X1F100", 4),
    ("$J=N1N2X1F100", 25),
    # Motion group, even an explicit G1.
    ("$J=G0X1F100", 16),
    ("$J=G1X1F1000", 16),
    ("$J=G38.2X1F100", 16),
    ("$J=G80F100", 16),
    # Arcs: their checks first, then 16.
    ("$J=G2X1F100", 35),
    ("$J=G3X1F100", 35),
    ("$J=G91G2X10R1F100", 34),
    ("$J=G91G2X2I5F100", 33),
    ("$J=G91G2X2I1F100", 16),
    ("$J=G91G2X2R1F100", 16),
    # G80 with axis words.
    ("$J=G80X1F100", 31),
    # Feed-mode group, even G94.
    ("$J=G93X1F100", 16),
    ("$J=G94X1F100", 16),
    # Other modal groups.
    ("$J=G17X1F100", 16),
    ("$J=G18X1F100", 16),
    ("$J=G40X1F100", 16),
    ("$J=G43.1Z1F100", 16),
    ("$J=G43.1X1F100", 37),
    ("$J=G49X1F100", 16),
    ("$J=G54X1F100", 16),
    ("$J=G59X1F100", 16),
    ("$J=G61X1F100", 16),
    ("$J=G91.1X1F100", 16),
    # Non-modal commands other than G53: their own checks first.
    ("$J=G4F100", 28),
    ("$J=G4P1F100", 16),
    ("$J=G10X1F100", 28),
    ("$J=G10L2P1X1F100", 16),
    ("$J=G28F100", 16),
    ("$J=G30F100", 16),
    ("$J=G92F100", 26),
    ("$J=G92X1F100", 16),
    ("$J=G28.1F100", 16),
    ("$J=G30.1F100", 16),
    ("$J=G92.1F100", 16),
    # M codes.
    ("$J=M3X1F100", 16),
    ("$J=M5X1F100", 16),
    ("$J=M8X1F100", 16),
    ("$J=M9X1F100", 16),
    ("$J=M0X1F100", 16),
    # Non-integer and unsupported G.
    ("$J=G1.5X1F100", 23),
    ("$J=G59.1X1F100", 23),
    ("$J=G5X1F100", 20),
    ("$J=G64X1F100", 20),
    ("$J=M3.5X1F100", 23),
    # S and T are unused words, not 16.
    ("$J=G91X1S100F100", 36),
    ("$J=G91X1T1F100", 36),
    ("$J=G91X1T300F100", 38),
    # Unused value words.
    ("$J=G91X1I1F100", 36),
    ("$J=G91X1J1F100", 36),
    ("$J=G91X1K1F100", 36),
    ("$J=G91X1P1F100", 36),
    ("$J=G91X1R1F100", 36),
    ("$J=G91X1L1F100", 36),
    # Unsupported letters and exponents.
    ("$J=G91A1F100", 20),
    ("$J=G91X1B1F100", 20),
    ("$J=G91X1H1F100", 20),
    ("$J=G91X1Q1F100", 20),
    ("$J=G91X1e3F100", 20),
    # Repeated words.
    ("$J=G91X1X5F100", 25),
    ("$J=G91X1F100F200", 25),
    # Non-letters and letters without numbers.
    ("$J=G91X1.2.3F100", 1),
    ("$J=%G91X1F100", 1),
    ("$J=XF100", 2),
    ("$J=G91X-F100", 2),
]


@pytest.mark.parametrize(("line", "code"), JOG_ROWS)
def test_jog_table(line: str, code: int) -> None:
    assert _jog(line).error == code


DETECTION_ORDER_ROWS = [
    # (1) parse errors, in the order the words appear.
    ("$J=G91X1X2A1F100", 25),
    ("$J=G91A1X1X2F100", 20),
    ("$J=G91X1T300T1F100", 38),
    ("$J=G91X1.2.3A1", 1),
    # (2) N range before missing F.
    ("$J=N20000000G91X1", 27),
    # (3) missing F before the arc, G80 and motion checks.
    ("$J=G2X1", 22),
    ("$J=G80X1", 22),
    # (4) arc / G80 checks before unused words.
    ("$J=G2X1S100F100", 35),
    ("$J=G80X1S100F100", 31),
    # (5) unused words before the jog filter.
    ("$J=G0X1S1F100", 36),
    ("$J=M3X1S100F100", 36),
    # (6) the jog filter: the modal-group rule, then the non-modal rule.
    ("$J=G4P1G20X1F100", 16),
    ("$J=G53G54X1F100", 16),
]


@pytest.mark.parametrize(("line", "code"), DETECTION_ORDER_ROWS)
def test_jog_detection_order(line: str, code: int) -> None:
    assert _jog(line).error == code


def test_jog_filter_before_soft_limit() -> None:
    box = TravelBox((-200.0,) * 3, (0.0,) * 3)
    assert _jog("$J=G1G53X500F100", envelope=box).error == 16
    assert _jog("$J=G53X500F100", envelope=box).error == 15


def test_jog_accepts_the_line_with_or_without_prefix() -> None:
    assert _jog("$J=G91X1F100") == _jog("G91X1F100")


# ---------------------------------------------------------------------------------- §1.5 targets


@pytest.mark.parametrize("line", ["$J=F1000", "$J=G91F1000", "$J=G53F500", "$J=G90F10", "$J=F0"])
def test_jog_without_axis_words_targets_machine_zero(line: str) -> None:
    result = _jog(line, _state(distance="G91"))
    assert result.ok
    assert result.motion is not None
    assert result.motion.target_mm == (0.0, 0.0, 0.0)  # machine 0, not work 0, not "no move"
    assert result.state.position_mm == (0.0, 0.0, 0.0)


def test_jog_g91_is_relative_to_parser_position() -> None:
    result = _jog("$J=G91X1Y-2F100")
    assert result.motion is not None
    assert _close(result.motion.target_mm, (-4.0, -5.0, -1.0))
    # Sequential jogs build on the parser position, not on where the machine is.
    again = _jog("$J=G91X1F100", result.state)
    assert again.motion is not None
    assert _close(again.motion.target_mm, (-3.0, -5.0, -1.0))


def test_jog_g53_uses_machine_coordinates_even_under_g91() -> None:
    result = _jog("$J=G53G91X-1F100")
    assert result.motion is not None
    assert result.motion.target_mm == (-1.0, -3.0, -1.0)


def test_jog_g90_adds_wcs_g92_and_tlo() -> None:
    st = _state(g92_offset_mm=(1.0, 2.0, 3.0), tool_length_offset_mm=0.5)
    result = _jog("$J=G90X1Z2F100", st)
    assert result.motion is not None
    assert _close(result.motion.target_mm, (1 - 50 + 1, -3.0, 2 - 30 + 3 + 0.5))


def test_jog_g20_scales_axes_and_feed() -> None:
    result = _jog("$J=G20G91X1F10")
    assert result.motion is not None
    assert _close(result.motion.target_mm, (-5.0 + 25.4, -3.0, -1.0))
    assert result.motion.feed_mm_min == pytest.approx(254.0)


def test_jog_uses_modal_state_when_line_is_silent() -> None:
    result = _jog("$J=X-1F100", _state(distance="G91", units="G20"))
    assert result.motion is not None
    assert _close(result.motion.target_mm, (-5.0 - 25.4, -3.0, -1.0))


def test_jog_changes_only_the_parser_position() -> None:
    st = _state(distance="G91", feed_mm_min=123.0, motion="G0", feed_mode="G93")
    result = _jog("$J=G21G90X1F999", st)
    assert result.ok
    assert result.state == replace(st, position_mm=result.state.position_mm)
    assert result.state.feed_mm_min == 123.0
    assert result.motion is not None
    assert result.motion.is_jog
    assert not result.motion.rapid
    assert result.motion.feed_mm_min == 999.0


def test_jog_line_number_rides_with_the_motion() -> None:
    result = _jog("$J=N42G91X1F100")
    assert result.motion is not None
    assert result.motion.line_number == 42


# ---------------------------------------------------------------------------------- §2 soft limits

SOFT_LIMIT_ROWS = [
    ("$J=G53X-200.000F100", 0),
    ("$J=G53X-200.001F100", 15),
    ("$J=G53X0F100", 0),
    ("$J=G53X0.001F100", 15),
    ("$J=G53Y-200Z-200F100", 0),
    ("$J=G53Z0.001F100", 15),
    ("$J=F100", 0),  # machine 0 lies in the box: nothing stops the flawed jog
]


@pytest.mark.parametrize(("line", "code"), SOFT_LIMIT_ROWS)
def test_jog_soft_limit_edges_are_inclusive(line: str, code: int) -> None:
    box = TravelBox((-200.0,) * 3, (0.0,) * 3)
    st = _state()
    result = _jog(line, st, envelope=box)
    assert result.error == code
    if code:
        assert result.state is st
        assert result.motions == ()


def test_travel_box_checks_its_corners() -> None:
    with pytest.raises(ValueError, match="exceeds"):
        TravelBox((0.0, 0.0, 0.0), (-1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="same number"):
        TravelBox((0.0, 0.0), (0.0, 0.0, 0.0))


# ---------------------------------------------------------------------------------- numbers

NUMBER_ROWS = [
    ("1", 1.0),
    ("-2.5", -2.5),
    ("+3", 3.0),
    (".5", 0.5),
    ("1.", 1.0),
    ("12345678", 12345678.0),
    ("123456789", 123456780.0),  # the 9th digit is dropped but still scales
    ("0.123456789", 0.1234567),  # the leading zero counts as one of the 8 digits
    ("0.000000001", 0.0),
]


@pytest.mark.parametrize(("text", "value"), NUMBER_ROWS)
def test_read_number(text: str, value: float) -> None:
    got = read_number(text + "F", 0)
    assert got is not None
    assert got[0] == pytest.approx(value, rel=1e-12, abs=1e-15)
    assert got[1] == len(text)


@pytest.mark.parametrize("text", ["", "-", "+", ".", "-.", "F1"])
def test_read_number_needs_a_digit(text: str) -> None:
    assert read_number(text, 0) is None


# ---------------------------------------------------------------------------------- plain G-code


def test_g1_needs_a_feed_and_then_keeps_it() -> None:
    assert _gcode("G1X1").error == 22
    first = _gcode("G1X1F200")
    assert first.ok
    assert first.motion is not None
    assert not first.motion.rapid
    assert not first.motion.is_jog
    assert _close(first.motion.target_mm, (1 - 50, -3.0, -1.0))
    second = _gcode("X2", first.state)
    assert second.motion is not None
    assert second.motion.feed_mm_min == 200.0
    assert _close(second.motion.target_mm, (2 - 50, -3.0, -1.0))


def test_g0_is_rapid_and_g0_g1_together_conflict() -> None:
    result = _gcode("G0G91X1")
    assert result.motion is not None
    assert result.motion.rapid
    assert _gcode("G0G1X1").error == 24


def test_motion_mode_alone_moves_nothing() -> None:
    result = _gcode("G1F100")
    assert result.ok
    assert result.motions == ()
    assert result.state.motion == "G1"


def test_g20_feed_is_stored_in_mm() -> None:
    result = _gcode("G20G1G91X1F10")
    assert result.state.feed_mm_min == pytest.approx(254.0)
    assert result.motion is not None
    assert result.motion.target_mm[0] == pytest.approx(-5.0 + 25.4)


def test_g93_inverse_time_feed() -> None:
    assert _gcode("G93G1G91X3").error == 22
    result = _gcode("G93G1G91X3Y4F2")  # 5 mm in 1/2 min
    assert result.motion is not None
    assert result.motion.feed_mm_min == pytest.approx(10.0)


@pytest.mark.parametrize(("line", "dwell_s", "code"), [
    ("G4P0", 0.0, 0), ("G4P1.5", 1.5, 0), ("G4P-1", None, 4), ("G4", None, 28),
])  # fmt: skip
def test_dwell(line: str, dwell_s: float | None, code: int) -> None:
    result = _gcode(line)
    assert result.error == code
    assert result.dwell_s == dwell_s


def test_g53_needs_g0_or_g1() -> None:
    assert _gcode("G53X0", _state(motion="G2")).error == 30
    result = _gcode("G53G0X-7")
    assert result.motion is not None
    assert result.motion.target_mm == (-7.0, -3.0, -1.0)


def test_g92_sets_and_g92_1_clears_the_offset() -> None:
    set_ = _gcode("G92X0Y0")
    assert set_.wco_changed
    assert _close(set_.state.g92_offset_mm, (-5 + 50, -3 + 40, 0.0))
    back = _gcode("G90G0X0Y0", set_.state)
    assert back.motion is not None
    assert _close(back.motion.target_mm, (-5.0, -3.0, -1.0))
    cleared = _gcode("G92.1", set_.state)
    assert cleared.wco_changed
    assert cleared.state.g92_offset_mm == (0.0, 0.0, 0.0)
    assert _gcode("G92").error == 26


def test_g10_l2_and_l20() -> None:
    active = _gcode("G10L2P1X7")
    assert active.wco_changed
    assert active.state.coord_systems_mm[0] == (7.0, -40.0, -30.0)
    other = _gcode("G10L2P2Y3")
    assert not other.wco_changed
    assert other.state.coord_systems_mm[1] == (0.0, 3.0, 0.0)
    l20 = _gcode("G10L20P1X0")
    assert l20.state.coord_systems_mm[0][0] == -5.0  # current position now reads X0
    assert _gcode("G10L2P7X1").error == 29
    assert _gcode("G10L3P1X1").error == 20
    assert _gcode("G10L2P1").error == 26


def test_wcs_switch_and_tlo_flag_wco() -> None:
    g55 = _gcode("G55")
    assert g55.wco_changed
    assert g55.state.wcs_index == 1
    assert not _gcode("G54").wco_changed
    tlo = _gcode("G43.1Z2")
    assert tlo.wco_changed
    assert tlo.state.tool_length_offset_mm == 2.0
    assert tlo.state.work_offset_mm == (-50.0, -40.0, -28.0)
    assert _gcode("G49", tlo.state).wco_changed
    assert not _gcode("G49").wco_changed


def test_spindle_and_coolant_changes() -> None:
    on = _gcode("M3S1000")
    assert on.spindle_changed
    assert on.state.spindle == "M3"
    assert _gcode("S2000", on.state).spindle_changed
    assert not _gcode("S2000").spindle_changed  # speed alone while off
    flood = _gcode("M8")
    assert flood.coolant_changed
    assert flood.state.coolant_flood
    assert _gcode("M7").error == 20  # ENABLE_M7 is off in the default build
    mist = _gcode("M7", m7=True)
    assert mist.ok
    assert mist.state.coolant_mist
    assert _gcode("M3M5").error == 21


def test_program_end_resets_some_groups() -> None:
    busy = _gcode("G1G91G20G55M3M8S100T2F10").state
    end = _gcode("M2", busy)
    assert end.program_end
    assert end.wco_changed
    assert end.spindle_changed
    assert end.coolant_changed
    st = end.state
    assert (st.motion, st.distance, st.wcs_index, st.spindle, st.coolant_flood) == (
        "G1", "G90", 0, "M5", False,
    )  # fmt: skip
    assert st.units == "G20"  # units are not reset by M2
    assert _gcode("M0").program_flow == "M0"
    assert not _gcode("M0").program_end


def test_non_jog_soft_limit_is_flagged_not_refused() -> None:
    box = TravelBox((-200.0,) * 3, (0.0,) * 3)
    result = _gcode("G53G0X5", envelope=box)
    assert result.ok
    assert result.soft_limit_violation
    assert result.motions == ()
    inside = _gcode("G53G0X-5", envelope=box)
    assert not inside.soft_limit_violation
    assert len(inside.motions) == 1


def test_arc_is_executed_as_chords_on_the_circle() -> None:
    st = ParserState.initial()
    result = _gcode("G17G2X10Y0I5J0F100", st)
    assert result.ok
    assert len(result.motions) > 10
    assert result.motions[-1].target_mm == (10.0, 0.0, 0.0)
    for m in result.motions:
        x, y, _ = m.target_mm
        assert ((x - 5) ** 2 + y**2) ** 0.5 == pytest.approx(5.0, abs=1e-9)
        assert y >= -1e-9  # clockwise from (0,0) to (10,0) about (5,0) passes above the X axis


def test_g28_goes_home_through_the_intermediate_point() -> None:
    st = replace(ParserState.initial(), g28_mm=(-1.0, -2.0, -3.0))
    direct = _gcode("G28", st)
    assert [m.target_mm for m in direct.motions] == [(-1.0, -2.0, -3.0)]
    via = _gcode("G28G91Z1", st)
    assert [m.target_mm for m in via.motions] == [(0.0, 0.0, 1.0), (0.0, 0.0, -3.0)]
    assert all(m.rapid for m in via.motions)


def test_gc_report_and_tool() -> None:
    assert gc_modes_report(ParserState.initial(), False) == (
        "[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]"
    )
    st = _gcode("G1G55G18G20G91M4M8T5F10S1200").state
    assert gc_modes_report(st, False) == "[GC:G1 G55 G18 G20 G91 G94 M4 M8 T5 F254 S1200]"
    assert gc_modes_report(st, True) == "[GC:G1 G55 G18 G20 G91 G94 M4 M8 T5 F10.0 S1200]"
    assert gc_modes_report(replace(st, program_flow="M0"), False).find(" M0 M4 ") > 0


def test_reset_keeps_stored_offsets_and_clears_the_rest() -> None:
    st = _gcode("G92X0G43.1Z1", _state()).state
    busy = replace(_gcode("G91G1F100M3S10", st).state, g92_offset_mm=(1.0, 1.0, 1.0))
    after = busy.after_reset()
    assert after.coord_systems_mm == busy.coord_systems_mm
    assert after.g92_offset_mm == (0.0, 0.0, 0.0)
    assert after.tool_length_offset_mm == 0.0
    assert (after.distance, after.spindle, after.feed_mm_min) == ("G90", "M5", 0.0)


def test_four_axis_machine_reads_a() -> None:
    st = ParserState.initial(4)
    result = execute_block("$J=G91A5F100", st, jog=True, n_axes=4)
    assert result.motion is not None
    assert result.motion.target_mm == (0.0, 0.0, 0.0, 5.0)


def test_axis_count_must_match_the_state() -> None:
    with pytest.raises(ValueError, match="n_axes"):
        execute_block("X1", ParserState.initial(4), jog=False)
