"""Grbl 1.1h error and alarm codes as data: a short name, what it means, and how to get out of it.

The meanings follow facts §5.6 and §5.7, including where the firmware differs from its own docs
(3 also covers `$J` without '=', 8 covers `$J` in Alarm, 26 is not sent for a jog without axis
words, 36 covers S and T in a jog). All text is written for this project. grblHAL and FluidNC
send codes Grbl 1.1h does not have; `error_info` and `alarm_info` answer those with a generic
record so a caller never has to handle a missing key.
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


def _table(rows: tuple[tuple[int, str, str, str], ...]) -> MappingProxyType[int, CodeInfo]:
    return MappingProxyType({row[0]: CodeInfo(*row) for row in rows})


_UNASSIGNED_HINT = "Grbl 1.1h never sends this code; another firmware may use it"

#: Grbl 1.1h `error:N` codes 1..38 (18 and 19 are unassigned in 1.1h).
ERROR_CODES: Final[MappingProxyType[int, CodeInfo]] = _table(
    (
        (1, "Expected command letter",
         "a word did not start with a letter A-Z (for example '%', or a stray '.' in 'X1.2.3')",
         "check the line for characters that are not G-code words"),
        (2, "Bad number format",
         "a letter was not followed by a number (for example 'X' with nothing after it)",
         "give every word a value such as X1.5"),
        (3, "Invalid statement",
         "a '$' command was not recognised; this includes '$J' without '=' after it",
         "write jogs as '$J=' followed by the words; send '$' to list the commands"),
        (4, "Negative value",
         "a value that must not be negative was (F, N, P, S or T, or a negative setting)",
         "use a value of zero or more; a jog's direction goes in the axis word, not in F"),
        (5, "Setting disabled",
         "the command needs a feature that is off, usually '$H' while homing is disabled",
         "enable homing with $22=1 if the machine has homing switches"),
        (6, "Step pulse too short",
         "the step pulse time must be at least 3 microseconds",
         "set $0 to 3 or more"),
        (7, "EEPROM read failed",
         "stored settings could not be read and were reset to defaults",
         "check and re-enter the settings with $$"),
        (8, "Not idle",
         "the command is accepted only in Idle (and '$J=' only in Idle or Jog); it was sent in "
         "another state such as Alarm, Run, Hold or Check",
         "wait for the move to finish, clear an alarm with $H or $X, or leave check mode with "
         "$C, then jog again"),
        (9, "G-code locked out",
         "plain G-code is refused in Alarm and while a jog runs",
         "in Alarm home ($H) or unlock ($X) first; while jogging, wait for Idle or cancel the jog "
         "before sending G-code"),
        (10, "Soft limits need homing",
         "soft limits ($20=1) can only be enabled when homing ($22=1) is enabled",
         "enable homing with $22=1 first, then $20=1"),
        (11, "Line overflow",
         "the line held more characters than the controller stores (79 in Grbl 1.1h, after "
         "spaces and comments are removed)",
         "send shorter lines; a jog line needs only units, mode, the axes and F"),
        (12, "Step rate too high",
         "a setting would need a step rate above what the controller can produce",
         "lower the maximum rate ($110-$112) or the steps per mm ($100-$102)"),
        (13, "Check door",
         "the safety door was detected open",
         "close the door, then resume with '~'"),
        (14, "Line length exceeded",
         "a stored line ($N startup line or $I text) is too long for its EEPROM space",
         "store a shorter line"),
        (15, "Travel exceeded",
         "the jog target lies outside the machine's soft limits, so the jog was dropped whole",
         "home the machine so positions are true, or jog less far"),
        (16, "Invalid jog command",
         "a '$J=' line held a word jogs do not allow: a motion, feed-mode, plane, WCS, TLO or M "
         "command, or a non-modal command other than G53 (even G0, G1 and G94)",
         "a jog may hold only G20/G21, G90/G91, G53, the axis words, F and N"),
        (17, "Laser mode needs PWM",
         "laser mode ($32=1) needs a build with a variable (PWM) spindle output",
         "use a firmware build with variable spindle support, or leave $32=0"),
        (18, "Unassigned", "not used by Grbl 1.1h", _UNASSIGNED_HINT),
        (19, "Unassigned", "not used by Grbl 1.1h", _UNASSIGNED_HINT),
        (20, "Unsupported command",
         "a G or M code, or a letter, that the controller does not support (for example an "
         "axis letter this machine lacks, or an exponent such as 1e3)",
         "remove the word; write numbers without exponents"),
        (21, "Modal group violation",
         "two commands from the same group in one line (for example G90 with G91)",
         "keep one command per group in a line"),
        (22, "Undefined feed rate",
         "a feed move had no feed: F missing from a jog, F0, or G1 before any F was set",
         "give F > 0; every jog needs its own F because a jog's F is never remembered"),
        (23, "Command not an integer",
         "a G or M number had a fraction the controller does not know (for example G59.1)",
         "use whole command numbers, or one of the few supported ones like G38.2 or G43.1"),
        (24, "Axis command conflict",
         "two commands that both use the axis words were in one line (for example G0 and G92)",
         "split them into separate lines"),
        (25, "Word repeated",
         "the same letter appeared twice in one line (for example two X words)",
         "give each letter once per line"),
        (26, "No axis words",
         "a command that needs axis words had none (G10, G92, an arc or a probe); a jog with no "
         "axis word is NOT refused, Grbl sends it to machine zero",
         "add the axis words the command needs"),
        (27, "Invalid line number",
         "the N word was above 10,000,000",
         "use line numbers from 0 to 10,000,000, or none"),
        (28, "Value word missing",
         "a command lacked a value it needs (G4 without P, G10 without P and L)",
         "add the missing P or L word"),
        (29, "Unsupported coordinate system",
         "G10 named a coordinate system beyond G59 (P above 6)",
         "use P0 (active) or P1-P6 (G54-G59)"),
        (30, "G53 needs G0 or G1",
         "G53 was used while an arc, probe or G80 motion mode was active",
         "put G0 or G1 in the line with G53"),
        (31, "Axis words with G80",
         "axis words were given while motion mode G80 (motion cancel) was active",
         "select G0 or G1 before giving axis words"),
        (32, "No axis words in plane",
         "an arc had no axis word in the selected plane",
         "give at least one axis of the arc's plane (G17: X/Y, G18: Z/X, G19: Y/Z)"),
        (33, "Invalid target",
         "the move's target is impossible: an arc whose end is not on its circle, or a probe "
         "to where it already is",
         "check the arc's end point and centre, or the probe target"),
        (34, "Arc radius error",
         "an R-form arc's radius is too small to reach the end point",
         "use a radius of at least half the distance to the end point"),
        (35, "No offsets in plane",
         "an arc had neither I/J/K offsets in its plane nor R",
         "give the arc's centre with I/J/K or its radius with R"),
        (36, "Unused words",
         "the line held words nothing used; in a jog S, T, I, J, K, P, R and L are all unused",
         "remove the extra words; set S and T with plain G-code, not in a jog"),
        (37, "G43.1 axis error",
         "dynamic tool-length offset G43.1 needs exactly one axis word, Z",
         "write G43.1 Z<offset> with no other axis word"),
        (38, "Tool number too large",
         "the T word was above 255",
         "use a tool number from 0 to 255"),
    )
)  # fmt: skip

#: Grbl 1.1h `ALARM:N` codes 1..10 (facts §5.6).
ALARM_CODES: Final[MappingProxyType[int, CodeInfo]] = _table(
    (
        (1, "Hard limit",
         "a limit switch was hit while moving; position is likely lost",
         "reset (Ctrl-X), move off the switch after $X, then home again with $H"),
        (2, "Soft limit",
         "a G-code move would have left the machine's travel; it was not run and position is kept",
         "reset (Ctrl-X) and unlock with $X, then send a target inside the travel"),
        (3, "Abort during cycle",
         "a reset arrived while the machine moved, so steps may have been lost",
         "home again with $H (or unlock with $X if the machine has no homing and you re-zero by "
         "hand)"),
        (4, "Probe start state",
         "the probe was already triggered before the probe move began",
         "check the probe wiring and clear the probe before probing"),
        (5, "Probe not triggered",
         "the probe did not touch anything within the programmed travel",
         "move closer to the workpiece or probe further, then reset and unlock"),
        (6, "Homing reset",
         "a reset arrived during homing",
         "home again with $H"),
        (7, "Homing door",
         "the safety door opened during homing",
         "close the door and home again"),
        (8, "Homing pull-off",
         "after homing the pull-off move did not clear the limit switch",
         "raise the pull-off distance ($27) or check the switch wiring"),
        (9, "Homing not found",
         "no limit switch was found within the search distance",
         "check the switches and $130-$132 (travel), then home again"),
        (10, "Homing dual axis",
         "the second switch of a dual-motor axis was not found",
         "check the second switch of that axis and its wiring"),
    )
)  # fmt: skip


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
