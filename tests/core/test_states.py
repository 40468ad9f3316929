"""The state groupings and the line table (core/states.py), read against Grbl 1.1h's rules."""

from __future__ import annotations

import pytest

from smoothjog.core.states import LineKind, is_homing, line_kind, line_refusal, moves


@pytest.mark.parametrize(
    ("line", "kind"),
    [
        ("$", LineKind.HELP),
        ("$g", LineKind.MODES),
        ("$$", LineKind.SETTINGS_DUMP),
        ("$C", LineKind.CHECK_MODE),
        ("$J=G91X1F100", LineKind.JOG),
        ("$N0=G0X-5", LineKind.STORE_STARTUP),
        ("$N", LineKind.SYSTEM),
        ("$110=1000", LineKind.SYSTEM),
        ("$H", LineKind.SYSTEM),
        ("$#", LineKind.SYSTEM),
        ("G0 X10", LineKind.GCODE),
        ("g21", LineKind.GCODE),
    ],
)
def test_every_line_has_its_kind(line: str, kind: LineKind) -> None:
    assert line_kind(line) is kind


@pytest.mark.parametrize(
    ("line", "moving"),
    [
        ("G0 X10", True),
        ("G1X-150F3000", True),
        ("X5", True),  # the modal motion mode
        ("G38.2 Z-10 F100", True),
        ("G28", True),
        ("G2 X1 Y1 I1", True),
        ("G10 L20 P0 X0 Y0", False),
        ("G92 X0", False),
        ("G28.1", False),
        ("G21 G90", False),
        ("G20", False),
        ("M3 S1000", False),
        ("G43.1 Z2", False),
    ],
)
def test_which_lines_move(line: str, moving: bool) -> None:
    assert moves(line) is moving


@pytest.mark.parametrize(
    ("line", "state", "refused"),
    [
        ("$$", "Run", "the machine is moving"),
        ("$$", "Jog", None),  # Grbl prints settings in Jog, not during a cycle
        ("$$", "Alarm", None),
        ("$G", "Run", None),
        ("$H", "Alarm", None),
        ("$N0=G0X-5", "Alarm", "the controller is in Alarm"),  # stored only in Idle
        ("$J=G91X1F100", "Run", "the machine is moving"),
        ("$C", "Alarm", "the controller is in Alarm"),
        ("G0 X10", "Alarm", "the controller is in Alarm"),  # error:9 otherwise
        ("G0 X10", "Jog", "the machine is moving"),  # error:9 otherwise
        ("G0 X10", "Hold", "reads no line"),
        ("G0 X10", None, None),  # nothing known: the controller's reply will say
        ("$X", "Check", "does not take this line in Check"),
    ],
)
def test_the_line_table_follows_the_firmware(
    line: str, state: str | None, refused: str | None
) -> None:
    why = line_refusal(line, state)
    if refused is None:
        assert why is None
    else:
        assert why is not None
        assert refused in why


@pytest.mark.parametrize(
    ("line", "homing"),
    [("$H", True), ("$h", True), ("$ H X", True), ("$HZ", True), ("$HX1", False), ("$#", False)],
)
def test_homing_lines_are_known_as_grbl_reads_them(line: str, homing: bool) -> None:
    assert is_homing(line) is homing
