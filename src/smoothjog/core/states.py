"""Machine states grouped once, and which lines a controller reads in each (firmware-facts §5.8).

Every module that asks "is the machine moving", "is it at rest", "will it read this line now"
takes its answer from here, so a grouping is written once. smoothjog's own states (the link is
lost, the settings are being read again) sit beside Grbl's so that every page, device display
and the CLI show one state model.
"""

from __future__ import annotations

import re
from enum import Enum
from typing import Final

#: States in which the machine moves, or is about to: nothing but a stop may be sent.
MOVING_STATES: Final = frozenset({"Run", "Jog", "Home"})
#: States in which the main loop reads no line until someone resumes or resets it.
SUSPENDED_STATES: Final = frozenset({"Hold", "Door", "Sleep"})
#: States in which a controller with nothing queued is at rest as far as jogging goes.
REST_STATES: Final = frozenset({"Idle", "Alarm", "Door", "Hold"})
#: States in which a program's motion is over (or never ran).
SETTLED_STATES: Final = frozenset({"Idle", "Alarm", "Check", "Sleep"})

#: Why nothing but a stop goes while the machine moves.
MOVING_TEXT: Final = "the machine is moving: press STOP and wait until it stands still"
#: Sleep ends only with a reset.
SLEEP_TEXT: Final = "the controller is asleep: reset it to wake it"

#: smoothjog's own states, shown where Grbl's would be.
LINK_LOST: Final = "Lost"
READING_SETTINGS: Final = "Reading"


class LineKind(Enum):
    """What a console line is, as far as the firmware's state rules go."""

    HELP = "help"  # `$`: printed in any state that reads lines
    MODES = "modes"  # `$G`: any state that reads lines
    SETTINGS_DUMP = "settings"  # `$$`: refused during a cycle or a hold
    CHECK_MODE = "check"  # `$C`: Idle or Check
    JOG = "jog"  # `$J=`: Idle or Jog
    STORE_STARTUP = "startup"  # `$Nn=line`: Idle only (no motion may be stored in Alarm)
    SYSTEM = "system"  # every other `$` line: Idle or Alarm only
    GCODE = "gcode"  # G-code: refused in Alarm and Jog; queued behind a running program


#: The states in which each kind of line is read and acted on (Grbl 1.1h `system.c`
#: `system_execute_line`, `protocol.c` `protocol_main_loop`; grblHAL and FluidNC keep the same
#: rules for these lines). Hold, Door, Sleep and Home read no line at all.
ACCEPTED_IN: Final[dict[LineKind, frozenset[str]]] = {
    LineKind.HELP: frozenset({"Idle", "Run", "Jog", "Alarm", "Check"}),
    LineKind.MODES: frozenset({"Idle", "Run", "Jog", "Alarm", "Check"}),
    LineKind.SETTINGS_DUMP: frozenset({"Idle", "Jog", "Alarm", "Check"}),
    LineKind.CHECK_MODE: frozenset({"Idle", "Check"}),
    LineKind.JOG: frozenset({"Idle", "Jog"}),
    LineKind.STORE_STARTUP: frozenset({"Idle"}),
    LineKind.SYSTEM: frozenset({"Idle", "Alarm"}),
    LineKind.GCODE: frozenset({"Idle", "Run", "Check"}),
}

_STARTUP = re.compile(r"^\$N[0-9]=", re.ASCII)
_HOMING = re.compile(r"\$H[A-Z]?", re.ASCII)
#: A G-code word that moves the machine (G0-G3, probing, G28/G30, canned motion).
_MOTION_WORD = re.compile(r"G0*[0-3](?![0-9.])|G38|G28(?!\.1)|G30(?!\.1)|G8[0-9]", re.I)
#: An axis word: it moves in the modal motion mode (G0 by default) unless another word takes it.
_AXIS_WORD = re.compile(r"[XYZABC][-+.0-9]", re.I)
#: Words that take the axis words for themselves: offsets and coordinate data, no motion.
_AXIS_TAKERS = re.compile(r"G10(?![0-9.])|G92(?![0-9.])|G43\.1", re.I)


def line_kind(text: str) -> LineKind:
    """The kind of a console line (spaces and case as the user typed them)."""
    line = text.strip().upper().replace(" ", "")
    if not line.startswith("$"):
        return LineKind.GCODE
    if line == "$":
        return LineKind.HELP
    if line == "$G":
        return LineKind.MODES
    if line == "$$":
        return LineKind.SETTINGS_DUMP
    if line == "$C":
        return LineKind.CHECK_MODE
    if line.startswith("$J="):
        return LineKind.JOG
    if _STARTUP.match(line):
        return LineKind.STORE_STARTUP
    return LineKind.SYSTEM


def is_homing(text: str) -> bool:
    """True for a line that starts a homing cycle: `$H`, or one axis (`$HX`,
    HOMING_SINGLE_AXIS_COMMANDS), spaces and case as Grbl's line filter leaves them (§1.1)."""
    return _HOMING.fullmatch("".join(text.split()).upper()) is not None


def moves(text: str) -> bool:
    """True when a G-code line (or a stored startup line) may move the machine."""
    line = text.replace(" ", "")
    if _MOTION_WORD.search(line):
        return True
    return _AXIS_WORD.search(line) is not None and _AXIS_TAKERS.search(line) is None


def line_refusal(text: str, state: str | None) -> str | None:
    """Why the controller would not act on this line in this state, in words; None if it would."""
    if state is None:
        return None  # nothing known yet: the controller's own reply will say
    if state in ACCEPTED_IN[line_kind(text)]:
        return None
    return state_refusal(state, "line")


def state_refusal(state: str, what: str) -> str:
    """Why the controller does not take a line or command (what) in this state, in words."""
    if state in MOVING_STATES:
        return MOVING_TEXT
    if state == "Sleep":
        return SLEEP_TEXT
    if state in SUSPENDED_STATES:
        return f"the controller is in {state} and reads no line: resume (~) or reset it first"
    if state == "Alarm":
        return "the controller is in Alarm: unlock ($X) or home ($H) first, or reset it"
    return f"the controller does not take this {what} in {state}"


__all__ = [
    "ACCEPTED_IN",
    "LINK_LOST",
    "MOVING_STATES",
    "MOVING_TEXT",
    "READING_SETTINGS",
    "REST_STATES",
    "SETTLED_STATES",
    "SLEEP_TEXT",
    "SUSPENDED_STATES",
    "LineKind",
    "is_homing",
    "line_kind",
    "line_refusal",
    "moves",
    "state_refusal",
]
