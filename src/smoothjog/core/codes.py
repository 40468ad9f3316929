"""Grbl 1.1h error and alarm codes as data: a short name, what it means, and how to get out of it.

The meanings follow firmware-facts §5.6 and §5.7, including where the firmware differs from its own
docs (3 also covers `$J` without '=', 8 covers `$J` in Alarm, 26 is not sent for a jog without axis
words, 36 covers S and T in a jog). All text is written for this project. grblHAL and FluidNC
send codes Grbl 1.1h does not have; `error_info` and `alarm_info` answer those with a generic
record so a caller never has to handle a missing key.

Code that tests for a code uses the named constants below, never a bare number. Each is named
after the firmware's own identifier (`report.h` STATUS_*, `system.h` EXEC_ALARM_*), which the
table keeps as `symbol`; tests/core/test_codes.py checks every constant against its row.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Final


@dataclass(frozen=True, slots=True)
class CodeInfo:
    """One error or alarm code: its number, a short name, its meaning and a fix hint."""

    code: int
    name: str
    meaning: str
    hint: str
    #: The firmware's identifier for the code (`STATUS_TRAVEL_EXCEEDED`); None when unassigned.
    symbol: str | None = None


def _table(
    rows: tuple[tuple[int, str | None, str, str, str], ...],
) -> MappingProxyType[int, CodeInfo]:
    """Records keyed by code from (code, symbol, name, meaning, hint) rows."""
    return MappingProxyType(
        {
            code: CodeInfo(code, name, meaning, hint, symbol)
            for code, symbol, name, meaning, hint in rows
        }
    )


_UNASSIGNED_HINT = "Grbl 1.1h never sends this code; another firmware may use it"

#: Grbl 1.1h `error:N` codes 1..38 (18 and 19 are unassigned in 1.1h).
ERROR_CODES: Final[MappingProxyType[int, CodeInfo]] = _table(
    (
        (1, "STATUS_EXPECTED_COMMAND_LETTER", "Expected command letter",
         "a word did not start with a letter A-Z (for example '%', or a stray '.' in 'X1.2.3')",
         "check the line for characters that are not G-code words"),
        (2, "STATUS_BAD_NUMBER_FORMAT", "Bad number format",
         "a letter was not followed by a number (for example 'X' with nothing after it)",
         "give every word a value such as X1.5"),
        (3, "STATUS_INVALID_STATEMENT", "Invalid statement",
         "a '$' command was not recognised; this includes '$J' without '=' after it",
         "write jogs as '$J=' followed by the words; send '$' to list the commands"),
        (4, "STATUS_NEGATIVE_VALUE", "Negative value",
         "a value that must not be negative was (F, N, P, S or T, or a negative setting)",
         "use a value of zero or more; a jog's direction goes in the axis word, not in F"),
        (5, "STATUS_SETTING_DISABLED", "Setting disabled",
         "the command needs a feature that is off, usually '$H' while homing is disabled",
         "enable homing with $22=1 if the machine has homing switches"),
        (6, "STATUS_SETTING_STEP_PULSE_MIN", "Step pulse too short",
         "the step pulse time must be at least 3 microseconds",
         "set $0 to 3 or more"),
        (7, "STATUS_SETTING_READ_FAIL", "EEPROM read failed",
         "stored settings could not be read and were reset to defaults",
         "check and re-enter the settings with $$"),
        (8, "STATUS_IDLE_ERROR", "Not idle",
         "the command is accepted only in Idle (and '$J=' only in Idle or Jog); it was sent in "
         "another state such as Alarm, Run, Hold or Check",
         "wait for the move to finish, clear an alarm with $H or $X, or leave check mode with "
         "$C, then jog again"),
        (9, "STATUS_SYSTEM_GC_LOCK", "G-code locked out",
         "plain G-code is refused in Alarm and while a jog runs",
         "in Alarm home ($H) or unlock ($X) first; while jogging, wait for Idle or cancel the jog "
         "before sending G-code"),
        (10, "STATUS_SOFT_LIMIT_ERROR", "Soft limits need homing",
         "soft limits ($20=1) can only be enabled when homing ($22=1) is enabled",
         "enable homing with $22=1 first, then $20=1"),
        (11, "STATUS_OVERFLOW", "Line overflow",
         "the line held more characters than the controller stores (79 in Grbl 1.1h, after "
         "spaces and comments are removed)",
         "send shorter lines; a jog line needs only units, mode, the axes and F"),
        (12, "STATUS_MAX_STEP_RATE_EXCEEDED", "Step rate too high",
         "a setting would need a step rate above what the controller can produce",
         "lower the maximum rate ($110-$112) or the steps per mm ($100-$102)"),
        (13, "STATUS_CHECK_DOOR", "Check door",
         "the safety door was detected open",
         "close the door, then resume with '~'"),
        (14, "STATUS_LINE_LENGTH_EXCEEDED", "Line length exceeded",
         "a stored line ($N startup line or $I text) is too long for its EEPROM space",
         "store a shorter line"),
        (15, "STATUS_TRAVEL_EXCEEDED", "Travel exceeded",
         "the jog target lies outside the machine's soft limits, so the jog was dropped whole",
         "home the machine so positions are true, or jog less far"),
        (16, "STATUS_INVALID_JOG_COMMAND", "Invalid jog command",
         "a '$J=' line held a word jogs do not allow: a motion, feed-mode, plane, WCS, TLO or M "
         "command, or a non-modal command other than G53 (even G0, G1 and G94)",
         "a jog may hold only G20/G21, G90/G91, G53, the axis words, F and N"),
        (17, "STATUS_SETTING_DISABLED_LASER", "Laser mode needs PWM",
         "laser mode ($32=1) needs a build with a variable (PWM) spindle output",
         "use a firmware build with variable spindle support, or leave $32=0"),
        (18, None, "Unassigned", "not used by Grbl 1.1h", _UNASSIGNED_HINT),
        (19, None, "Unassigned", "not used by Grbl 1.1h", _UNASSIGNED_HINT),
        (20, "STATUS_GCODE_UNSUPPORTED_COMMAND", "Unsupported command",
         "a G or M code, or a letter, that the controller does not support (for example an "
         "axis letter this machine lacks, or an exponent such as 1e3)",
         "remove the word; write numbers without exponents"),
        (21, "STATUS_GCODE_MODAL_GROUP_VIOLATION", "Modal group violation",
         "two commands from the same group in one line (for example G90 with G91)",
         "keep one command per group in a line"),
        (22, "STATUS_GCODE_UNDEFINED_FEED_RATE", "Undefined feed rate",
         "a feed move had no feed: F missing from a jog, F0, or G1 before any F was set",
         "give F > 0; every jog needs its own F because a jog's F is never remembered"),
        (23, "STATUS_GCODE_COMMAND_VALUE_NOT_INTEGER", "Command not an integer",
         "a G or M number had a fraction the controller does not know (for example G59.1)",
         "use whole command numbers, or one of the few supported ones like G38.2 or G43.1"),
        (24, "STATUS_GCODE_AXIS_COMMAND_CONFLICT", "Axis command conflict",
         "two commands that both use the axis words were in one line (for example G0 and G92)",
         "split them into separate lines"),
        (25, "STATUS_GCODE_WORD_REPEATED", "Word repeated",
         "the same letter appeared twice in one line (for example two X words)",
         "give each letter once per line"),
        (26, "STATUS_GCODE_NO_AXIS_WORDS", "No axis words",
         "a command that needs axis words had none (G10, G92, an arc or a probe); a jog with no "
         "axis word is NOT refused, Grbl sends it to machine zero",
         "add the axis words the command needs"),
        (27, "STATUS_GCODE_INVALID_LINE_NUMBER", "Invalid line number",
         "the N word was above 10,000,000",
         "use line numbers from 0 to 10,000,000, or none"),
        (28, "STATUS_GCODE_VALUE_WORD_MISSING", "Value word missing",
         "a command lacked a value it needs (G4 without P, G10 without P and L)",
         "add the missing P or L word"),
        (29, "STATUS_GCODE_UNSUPPORTED_COORD_SYS", "Unsupported coordinate system",
         "G10 named a coordinate system beyond G59 (P above 6)",
         "use P0 (active) or P1-P6 (G54-G59)"),
        (30, "STATUS_GCODE_G53_INVALID_MOTION_MODE", "G53 needs G0 or G1",
         "G53 was used while an arc, probe or G80 motion mode was active",
         "put G0 or G1 in the line with G53"),
        (31, "STATUS_GCODE_AXIS_WORDS_EXIST", "Axis words with G80",
         "axis words were given while motion mode G80 (motion cancel) was active",
         "select G0 or G1 before giving axis words"),
        (32, "STATUS_GCODE_NO_AXIS_WORDS_IN_PLANE", "No axis words in plane",
         "an arc had no axis word in the selected plane",
         "give at least one axis of the arc's plane (G17: X/Y, G18: Z/X, G19: Y/Z)"),
        (33, "STATUS_GCODE_INVALID_TARGET", "Invalid target",
         "the move's target is impossible: an arc whose end is not on its circle, or a probe "
         "to where it already is",
         "check the arc's end point and centre, or the probe target"),
        (34, "STATUS_GCODE_ARC_RADIUS_ERROR", "Arc radius error",
         "an R-form arc's radius is too small to reach the end point",
         "use a radius of at least half the distance to the end point"),
        (35, "STATUS_GCODE_NO_OFFSETS_IN_PLANE", "No offsets in plane",
         "an arc had neither I/J/K offsets in its plane nor R",
         "give the arc's centre with I/J/K or its radius with R"),
        (36, "STATUS_GCODE_UNUSED_WORDS", "Unused words",
         "the line held words nothing used; in a jog S, T, I, J, K, P, R and L are all unused",
         "remove the extra words; set S and T with plain G-code, not in a jog"),
        (37, "STATUS_GCODE_G43_DYNAMIC_AXIS_ERROR", "G43.1 axis error",
         "dynamic tool-length offset G43.1 needs exactly one axis word, Z",
         "write G43.1 Z<offset> with no other axis word"),
        (38, "STATUS_GCODE_MAX_VALUE_EXCEEDED", "Tool number too large",
         "the T word was above 255",
         "use a tool number from 0 to 255"),
    )
)  # fmt: skip

#: Grbl 1.1h `ALARM:N` codes 1..10 (firmware-facts §5.6).
ALARM_CODES: Final[MappingProxyType[int, CodeInfo]] = _table(
    (
        (1, "EXEC_ALARM_HARD_LIMIT", "Hard limit",
         "a limit switch was hit while moving; position is likely lost",
         "reset (Ctrl-X), move off the switch after $X, then home again with $H"),
        (2, "EXEC_ALARM_SOFT_LIMIT", "Soft limit",
         "a G-code move would have left the machine's travel; it was not run and position is kept",
         "reset (Ctrl-X) and unlock with $X, then send a target inside the travel"),
        (3, "EXEC_ALARM_ABORT_CYCLE", "Abort during cycle",
         "a reset arrived while the machine moved, so steps may have been lost",
         "home again with $H (or unlock with $X if the machine has no homing and you re-zero by "
         "hand)"),
        (4, "EXEC_ALARM_PROBE_FAIL_INITIAL", "Probe start state",
         "the probe was already triggered before the probe move began",
         "check the probe wiring and clear the probe before probing"),
        (5, "EXEC_ALARM_PROBE_FAIL_CONTACT", "Probe not triggered",
         "the probe did not touch anything within the programmed travel",
         "move closer to the workpiece or probe further, then reset and unlock"),
        (6, "EXEC_ALARM_HOMING_FAIL_RESET", "Homing reset",
         "a reset arrived during homing",
         "home again with $H"),
        (7, "EXEC_ALARM_HOMING_FAIL_DOOR", "Homing door",
         "the safety door opened during homing",
         "close the door and home again"),
        (8, "EXEC_ALARM_HOMING_FAIL_PULLOFF", "Homing pull-off",
         "after homing the pull-off move did not clear the limit switch",
         "raise the pull-off distance ($27) or check the switch wiring"),
        (9, "EXEC_ALARM_HOMING_FAIL_APPROACH", "Homing not found",
         "no limit switch was found within the search distance",
         "check the switches and $130-$132 (travel), then home again"),
        (10, "EXEC_ALARM_HOMING_FAIL_DUAL_APPROACH", "Homing dual axis",
         "the second switch of a dual-motor axis was not found",
         "check the second switch of that axis and its wiring"),
    )
)  # fmt: skip


# --- the codes by name ------------------------------------------------------------------------
# Grbl's names do not always say what a jog host expects: STATUS_SOFT_LIMIT_ERROR (10) means "soft
# limits need homing"; a jog outside the travel is STATUS_TRAVEL_EXCEEDED (15). IDLE_ERROR (8) is
# "not idle", and SYSTEM_GC_LOCK (9) is G-code refused in Alarm or Jog.

#: Not an error: Grbl's status for success, answered `ok` instead of `error:0`.
STATUS_OK: Final = 0

ERR_EXPECTED_COMMAND_LETTER: Final = 1
ERR_BAD_NUMBER_FORMAT: Final = 2
ERR_INVALID_STATEMENT: Final = 3
ERR_NEGATIVE_VALUE: Final = 4
ERR_SETTING_DISABLED: Final = 5
ERR_SETTING_STEP_PULSE_MIN: Final = 6
ERR_SETTING_READ_FAIL: Final = 7
ERR_IDLE_ERROR: Final = 8
ERR_SYSTEM_GC_LOCK: Final = 9
ERR_SOFT_LIMIT_ERROR: Final = 10
ERR_OVERFLOW: Final = 11
ERR_MAX_STEP_RATE_EXCEEDED: Final = 12
ERR_CHECK_DOOR: Final = 13
ERR_LINE_LENGTH_EXCEEDED: Final = 14
ERR_TRAVEL_EXCEEDED: Final = 15
ERR_INVALID_JOG_COMMAND: Final = 16
ERR_SETTING_DISABLED_LASER: Final = 17
ERR_GCODE_UNSUPPORTED_COMMAND: Final = 20
ERR_GCODE_MODAL_GROUP_VIOLATION: Final = 21
ERR_GCODE_UNDEFINED_FEED_RATE: Final = 22
ERR_GCODE_COMMAND_VALUE_NOT_INTEGER: Final = 23
ERR_GCODE_AXIS_COMMAND_CONFLICT: Final = 24
ERR_GCODE_WORD_REPEATED: Final = 25
ERR_GCODE_NO_AXIS_WORDS: Final = 26
ERR_GCODE_INVALID_LINE_NUMBER: Final = 27
ERR_GCODE_VALUE_WORD_MISSING: Final = 28
ERR_GCODE_UNSUPPORTED_COORD_SYS: Final = 29
ERR_GCODE_G53_INVALID_MOTION_MODE: Final = 30
ERR_GCODE_AXIS_WORDS_EXIST: Final = 31
ERR_GCODE_NO_AXIS_WORDS_IN_PLANE: Final = 32
ERR_GCODE_INVALID_TARGET: Final = 33
ERR_GCODE_ARC_RADIUS_ERROR: Final = 34
ERR_GCODE_NO_OFFSETS_IN_PLANE: Final = 35
ERR_GCODE_UNUSED_WORDS: Final = 36
ERR_GCODE_G43_DYNAMIC_AXIS_ERROR: Final = 37
ERR_GCODE_MAX_VALUE_EXCEEDED: Final = 38

ALARM_HARD_LIMIT: Final = 1
ALARM_SOFT_LIMIT: Final = 2
ALARM_ABORT_CYCLE: Final = 3
ALARM_PROBE_FAIL_INITIAL: Final = 4
ALARM_PROBE_FAIL_CONTACT: Final = 5
ALARM_HOMING_FAIL_RESET: Final = 6
ALARM_HOMING_FAIL_DOOR: Final = 7
ALARM_HOMING_FAIL_PULLOFF: Final = 8
ALARM_HOMING_FAIL_APPROACH: Final = 9
ALARM_HOMING_FAIL_DUAL_APPROACH: Final = 10


def error_info(code: int) -> CodeInfo:
    """The record for `error:<code>`; codes Grbl 1.1h lacks get a generic record."""
    known = ERROR_CODES.get(code)
    if known is not None:
        return known
    return CodeInfo(
        code,
        "Unknown error",
        f"error {code} is not a Grbl 1.1h code (grblHAL and FluidNC add their own)",
        "look the code up in your controller firmware's documentation",
    )


def alarm_info(code: int) -> CodeInfo:
    """The record for `ALARM:<code>`; codes Grbl 1.1h lacks get a generic record."""
    known = ALARM_CODES.get(code)
    if known is not None:
        return known
    return CodeInfo(
        code,
        "Unknown alarm",
        f"alarm {code} is not a Grbl 1.1h code (grblHAL and FluidNC add their own)",
        "look the code up in your controller firmware's documentation, then reset and unlock",
    )


def _sentence(prefix: str, info: CodeInfo) -> str:
    # One sentence: what happened, a dash, then what to do.
    return f"{prefix}:{info.code} ({info.name}): {info.meaning} — {info.hint}."


def describe_error(code: int) -> str:
    """One readable sentence for `error:<code>`: name, meaning and how to fix it."""
    return _sentence("error", error_info(code))


def describe_alarm(code: int) -> str:
    """One readable sentence for `ALARM:<code>`: name, meaning and how to recover."""
    return _sentence("ALARM", alarm_info(code))
