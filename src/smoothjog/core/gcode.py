"""Model Grbl 1.1h's handling of one line: the pre-parser, the G-code and `$J=` parser, its errors.

This is a pure model of `protocol_main_loop`'s line filter (firmware-facts §1.1), the `$J` dispatch
of `system_execute_line` (firmware-facts §1.2) and `gc_execute_line` (firmware-facts §1.3, §1.5),
written from the facts and from a reading of the firmware's structure, not copied. The simulator
drives it; tests of the jog-line builder use it as the referee.

Conventions: every length in `ParserState` and in results is in machine millimetres, whatever G20
or G21 says; feeds are mm/min (except the G93 value, an inverse time in 1/min). Error codes are the
plain ints Grbl sends after `error:`, named as in core/codes.py. Where the facts are silent a
comment says "reading:" and gives the behaviour taken from the structure of `gc_execute_line`.

Numbers are held as Python floats (doubles) where the firmware uses 32-bit floats, so a value can
differ from the firmware's in the 7th or 8th significant digit; the planner's step rounding hides
this for any sane jog.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, replace
from typing import Final, Literal

from smoothjog.core.codes import (
    ERR_BAD_NUMBER_FORMAT,
    ERR_EXPECTED_COMMAND_LETTER,
    ERR_GCODE_ARC_RADIUS_ERROR,
    ERR_GCODE_AXIS_COMMAND_CONFLICT,
    ERR_GCODE_AXIS_WORDS_EXIST,
    ERR_GCODE_COMMAND_VALUE_NOT_INTEGER,
    ERR_GCODE_G43_DYNAMIC_AXIS_ERROR,
    ERR_GCODE_G53_INVALID_MOTION_MODE,
    ERR_GCODE_INVALID_LINE_NUMBER,
    ERR_GCODE_INVALID_TARGET,
    ERR_GCODE_MAX_VALUE_EXCEEDED,
    ERR_GCODE_MODAL_GROUP_VIOLATION,
    ERR_GCODE_NO_AXIS_WORDS,
    ERR_GCODE_NO_AXIS_WORDS_IN_PLANE,
    ERR_GCODE_NO_OFFSETS_IN_PLANE,
    ERR_GCODE_UNDEFINED_FEED_RATE,
    ERR_GCODE_UNSUPPORTED_COMMAND,
    ERR_GCODE_UNSUPPORTED_COORD_SYS,
    ERR_GCODE_UNUSED_WORDS,
    ERR_GCODE_VALUE_WORD_MISSING,
    ERR_GCODE_WORD_REPEATED,
    ERR_IDLE_ERROR,
    ERR_INVALID_JOG_COMMAND,
    ERR_INVALID_STATEMENT,
    ERR_NEGATIVE_VALUE,
    ERR_TRAVEL_EXCEEDED,
    STATUS_OK,
)
from smoothjog.core.defaults import DEFAULT_ARC_TOLERANCE_MM
from smoothjog.core.firmware import GRBL
from smoothjog.core.units import ALL_AXES, MM_PER_INCH, Vec

MotionMode = Literal["G0", "G1", "G2", "G3", "G38.2", "G38.3", "G38.4", "G38.5", "G80"]
FeedMode = Literal["G93", "G94"]
UnitsMode = Literal["G20", "G21"]
DistanceMode = Literal["G90", "G91"]
PlaneMode = Literal["G17", "G18", "G19"]
SpindleMode = Literal["M3", "M4", "M5"]
ToolLengthMode = Literal["G43.1", "G49"]
ProgramFlow = Literal["M0", "M2", "M30"]
NonModal = Literal["G4", "G10", "G28", "G28.1", "G30", "G30.1", "G53", "G92", "G92.1"]

#: Largest N word accepted (`MAX_LINE_NUMBER`).
MAX_LINE_NUMBER: Final = 10_000_000
#: Largest T word accepted (`MAX_TOOL_NUMBER`).
MAX_TOOL_NUMBER: Final = 255
#: Digits `read_float` keeps; it counts every digit, leading zeros included.
MAX_NUMBER_DIGITS: Final = 8
#: G54..G59.
N_COORDINATE_SYSTEMS: Final = 6
#: Index of the axis the tool-length offset applies to (Z).
TLO_AXIS: Final = 2


_JOG_PREFIX: Final = "$J="
# Angles closer than this to zero count as "start equals end" for a full-circle arc (mc_arc).
_ARC_ANGLE_EPSILON: Final = 5e-7
# Arc centre consistency limits, mm (gc_execute_line, offset mode): above 0.005 mm the radii must
# also agree within 0.1 % and never differ by more than 0.5 mm.
_ARC_RADIUS_SLACK_MM: Final = 0.005
_ARC_RADIUS_MAX_DIFF_MM: Final = 0.5
_ARC_RADIUS_REL: Final = 0.001

# Axis-command kinds (what the axis words of a block are for).
_AXIS_NONE: Final = 0
_AXIS_NON_MODAL: Final = 1
_AXIS_MOTION: Final = 2
_AXIS_TLO: Final = 3

# Modal groups a jog may name (firmware-facts §1.3 jog filter): non-modal (only G53), distance,
# units.
_JOG_ALLOWED_GROUPS: Final = frozenset({"non_modal", "distance", "units"})

# Word number (and fraction x100) to mode name, so the parser never builds names from numbers.
_NON_MODAL: Final[dict[tuple[int, int], NonModal]] = {
    (4, 0): "G4", (10, 0): "G10", (28, 0): "G28", (28, 10): "G28.1", (30, 0): "G30",
    (30, 10): "G30.1", (53, 0): "G53", (92, 0): "G92", (92, 10): "G92.1",
}  # fmt: skip
_MOTION: Final[dict[int, MotionMode]] = {0: "G0", 1: "G1", 2: "G2", 3: "G3", 80: "G80"}
_PROBE: Final[dict[int, MotionMode]] = {20: "G38.2", 30: "G38.3", 40: "G38.4", 50: "G38.5"}
_PLANE: Final[dict[int, PlaneMode]] = {17: "G17", 18: "G18", 19: "G19"}
_DISTANCE: Final[dict[int, DistanceMode]] = {90: "G90", 91: "G91"}
_FEED_MODE: Final[dict[int, FeedMode]] = {93: "G93", 94: "G94"}
_UNITS: Final[dict[int, UnitsMode]] = {20: "G20", 21: "G21"}
_SPINDLE: Final[dict[int, SpindleMode]] = {3: "M3", 4: "M4", 5: "M5"}
_PROGRAM_FLOW: Final[dict[int, ProgramFlow]] = {0: "M0", 2: "M2", 30: "M30"}


# --------------------------------------------------------------------------------------------
# Pre-parser (firmware-facts §1.1)


@dataclass(frozen=True, slots=True)
class Preparsed:
    """One line after Grbl's filter: the stored text, and whether the line buffer overflowed."""

    text: str
    overflow: bool


def preparse(raw: bytes, *, max_line_chars: int = GRBL.max_line_chars) -> Preparsed:
    """Filter one line's bytes (without its EOL) the way Grbl's main loop stores them.

    Realtime bytes must already be gone (the simulator's ISR model removes them, firmware-facts
    §5.2). On overflow `text` holds the characters stored before it; Grbl answers such a line
    `error:11`.
    """
    if b"\n" in raw or b"\r" in raw:
        raise ValueError("preparse() takes one line without its end-of-line byte")
    stored: list[str] = []
    in_parentheses = False
    dropping_rest = False  # after ';' or after an overflow: nothing more is stored
    overflow = False
    for byte in raw:
        if dropping_rest:
            continue
        if in_parentheses:
            # No nesting: the first ')' ends the comment (firmware-facts §1.1).
            in_parentheses = byte != 0x29
            continue
        if byte <= 0x20 or byte == 0x2F:  # whitespace/control, and '/' (block delete ignored)
            continue
        if byte == 0x28:  # '('
            in_parentheses = True
        elif byte == 0x3B:  # ';' comments to the end of the line
            dropping_rest = True
        elif len(stored) >= max_line_chars:
            overflow = True
            dropping_rest = True
        elif 0x61 <= byte <= 0x7A:
            stored.append(chr(byte - 0x20))
        else:
            stored.append(chr(byte))
    return Preparsed("".join(stored), overflow)


# --------------------------------------------------------------------------------------------
# `$J` dispatch (firmware-facts §1.2)


def check_jog_dispatch(line: str, state_name: str) -> int | None:
    """The `$J` gate of system_execute_line: an error code, or None to go on to execute_block.

    `line` is the preparsed line starting `$J`; `state_name` is a status-report state such as
    `Idle`, `Jog` or `Hold:0` (the substate is ignored).
    """
    if state_name.split(":", 1)[0] not in ("Idle", "Jog"):
        return ERR_IDLE_ERROR
    if len(line) < 3 or line[2] != "=":
        # Facts §1.2/§8.3: error 3, not the 16 the docs promise.
        return ERR_INVALID_STATEMENT
    return None


# --------------------------------------------------------------------------------------------
# Number reader (nuts_bolts.c:read_float, firmware-facts §1.3 "Number format")


def read_number(text: str, start: int) -> tuple[float, int] | None:
    """Read a number at text[start:] as Grbl does; (value, index after it), or None if no digit.

    Optional sign, digits with at most one '.', no exponent. Only the first 8 digits carry value
    (Grbl counts every digit, leading zeros too); later integer digits still scale the value.
    """
    i = start
    end = len(text)
    negative = False
    if i < end and text[i] in "+-":
        negative = text[i] == "-"
        i += 1
    mantissa = 0
    exponent = 0
    digits = 0
    seen_point = False
    while i < end:
        c = text[i]
        if "0" <= c <= "9":
            digits += 1
            if digits <= MAX_NUMBER_DIGITS:
                mantissa = mantissa * 10 + (ord(c) - 0x30)
                if seen_point:
                    exponent -= 1
            elif not seen_point:
                exponent += 1
        elif c == "." and not seen_point:
            seen_point = True
        else:
            break
        i += 1
    if digits == 0:
        return None
    # Exact decimal to nearest double: divide by a power of ten rather than multiply by 0.1s.
    value = mantissa * 10.0**exponent if exponent >= 0 else mantissa / 10.0**-exponent
    return (-value if negative else value), i


def _round_half_away(x: float) -> int:
    """C's round(): halves go away from zero."""
    return math.floor(abs(x) + 0.5) * (1 if x >= 0 else -1)


# --------------------------------------------------------------------------------------------
# Parser state and results


def _zeros(n: int) -> Vec:
    return (0.0,) * n


@dataclass(frozen=True, slots=True)
class ParserState:
    """Grbl's gc_state: the modal state and the parser position, all lengths in machine mm.

    `coord_systems_mm` holds G54..G59 (the firmware keeps them in EEPROM and the active one in
    RAM; here the table is the single source). `feed_mm_min` holds 1/min under G93.
    """

    motion: MotionMode = "G0"
    feed_mode: FeedMode = "G94"
    units: UnitsMode = "G21"
    distance: DistanceMode = "G90"
    plane: PlaneMode = "G17"
    wcs_index: int = 0
    coord_systems_mm: tuple[Vec, ...] = field(
        default_factory=lambda: tuple(_zeros(3) for _ in range(N_COORDINATE_SYSTEMS))
    )
    g92_offset_mm: Vec = field(default_factory=lambda: _zeros(3))
    tool_length_mode: ToolLengthMode = "G49"
    tool_length_offset_mm: float = 0.0
    feed_mm_min: float = 0.0
    spindle: SpindleMode = "M5"
    spindle_speed_rpm: float = 0.0
    coolant_flood: bool = False
    coolant_mist: bool = False
    tool: int = 0
    program_flow: ProgramFlow | None = None
    line_number: int = 0
    position_mm: Vec = field(default_factory=lambda: _zeros(3))
    g28_mm: Vec = field(default_factory=lambda: _zeros(3))
    g30_mm: Vec = field(default_factory=lambda: _zeros(3))

    def __post_init__(self) -> None:
        """Check that every vector has one entry per axis and the WCS index is in range."""
        n = len(self.position_mm)
        if not 3 <= n <= len(ALL_AXES):
            raise ValueError(f"ParserState needs 3..{len(ALL_AXES)} axes, got {n}")
        vectors = (self.g92_offset_mm, self.g28_mm, self.g30_mm, *self.coord_systems_mm)
        if len(self.coord_systems_mm) != N_COORDINATE_SYSTEMS or any(len(v) != n for v in vectors):
            raise ValueError(f"ParserState vectors must all have {n} axes and 6 coord systems")
        if not 0 <= self.wcs_index < N_COORDINATE_SYSTEMS:
            raise ValueError(f"wcs_index must be 0..5 (G54..G59), got {self.wcs_index}")

    @classmethod
    def initial(
        cls,
        n_axes: int = 3,
        *,
        position_mm: Vec | None = None,
        coord_systems_mm: tuple[Vec, ...] | None = None,
        g28_mm: Vec | None = None,
        g30_mm: Vec | None = None,
    ) -> ParserState:
        """The state after power-up (gc_init) for a machine with n_axes axes."""
        return cls(
            coord_systems_mm=coord_systems_mm
            or tuple(_zeros(n_axes) for _ in range(N_COORDINATE_SYSTEMS)),
            g92_offset_mm=_zeros(n_axes),
            position_mm=position_mm if position_mm is not None else _zeros(n_axes),
            g28_mm=g28_mm if g28_mm is not None else _zeros(n_axes),
            g30_mm=g30_mm if g30_mm is not None else _zeros(n_axes),
        )

    @property
    def n_axes(self) -> int:
        """Number of axes this state describes."""
        return len(self.position_mm)

    @property
    def work_offset_mm(self) -> Vec:
        """WCO as Grbl reports it: active WCS + G92, plus the tool-length offset on Z, in mm."""
        wcs = self.coord_systems_mm[self.wcs_index]
        return tuple(
            wcs[i] + self.g92_offset_mm[i] + (self.tool_length_offset_mm if i == TLO_AXIS else 0.0)
            for i in range(self.n_axes)
        )

    def with_position(self, position_mm: Vec) -> ParserState:
        """gc_sync_position: the parser position set to the machine position (mm)."""
        if len(position_mm) != self.n_axes:
            raise ValueError(f"position needs {self.n_axes} axes, got {len(position_mm)}")
        return replace(self, position_mm=tuple(position_mm))

    def after_reset(self) -> ParserState:
        """gc_init after a soft reset: modes to defaults, G92 and TLO cleared, stored data kept.

        The coordinate systems and G28/G30 live in EEPROM and survive; the position is kept here
        and the caller syncs it to MPos (firmware-facts §3.4).
        """
        n = self.n_axes
        return ParserState(
            coord_systems_mm=self.coord_systems_mm,
            g92_offset_mm=_zeros(n),
            position_mm=self.position_mm,
            g28_mm=self.g28_mm,
            g30_mm=self.g30_mm,
        )


def _grbl_print_float(value: float, decimals: int) -> str:
    """Grbl's printFloat: sign first, then the magnitude rounded half up."""
    sign = "-" if value < 0 else ""
    scaled = math.floor(abs(value) * 10**decimals + 0.5)
    if decimals == 0:
        return f"{sign}{scaled}"
    whole, frac = divmod(scaled, 10**decimals)
    return f"{sign}{whole}.{frac:0{decimals}d}"


def gc_modes_report(state: ParserState, inches_report: bool) -> str:
    """The `[GC:...]` line of `$G` (firmware-facts §5.3); inches_report is `$13=1` (F in in/min)."""
    words = [
        state.motion,
        f"G{54 + state.wcs_index}",
        state.plane,
        state.units,
        state.distance,
        state.feed_mode,
    ]
    if state.program_flow is not None:
        words.append(state.program_flow)
    words.append(state.spindle)
    if state.coolant_mist or state.coolant_flood:
        words.append(
            "M" + ("7" if state.coolant_mist else "") + ("8" if state.coolant_flood else "")
        )
    else:
        words.append("M9")
    words.append(f"T{state.tool}")
    feed = (
        _grbl_print_float(state.feed_mm_min / MM_PER_INCH, 1)
        if inches_report
        else _grbl_print_float(state.feed_mm_min, 0)
    )
    words.append(f"F{feed}")
    words.append(f"S{_grbl_print_float(state.spindle_speed_rpm, 0)}")
    return "[GC:" + " ".join(words) + "]"


@dataclass(frozen=True, slots=True)
class TravelBox:
    """The soft-limit box in machine mm, inclusive at both ends (firmware-facts §2)."""

    min_mm: Vec
    max_mm: Vec

    def __post_init__(self) -> None:
        """Check the two corners have the same axes and are ordered."""
        if len(self.min_mm) != len(self.max_mm):
            raise ValueError("TravelBox corners must have the same number of axes")
        if any(lo > hi for lo, hi in zip(self.min_mm, self.max_mm, strict=True)):
            raise ValueError(f"TravelBox min {self.min_mm} exceeds max {self.max_mm}")

    def contains(self, target_mm: Vec) -> bool:
        """True when every axis of target_mm lies within [min, max] (system_check_travel_limits)."""
        return all(
            lo <= t <= hi for t, lo, hi in zip(target_mm, self.min_mm, self.max_mm, strict=True)
        )


@dataclass(frozen=True, slots=True)
class Motion:
    """One straight move to plan: target in machine mm and its feed.

    `feed_mm_min` is the parser feed for a rapid (the planner uses the rapid rate instead), and is
    already converted from inverse time under G93. It can be 0 for `$J=F0` with no axis word,
    which the planner floors to 1 mm/min (firmware-facts §4.2). `probe` names the G38 mode of a
    probing move: it stops at contact, so the simulator must then sync the parser position to MPos.
    """

    target_mm: Vec
    feed_mm_min: float
    rapid: bool
    is_jog: bool
    line_number: int = 0
    probe: MotionMode | None = None


@dataclass(frozen=True, slots=True)
class ExecResult:
    """What one line does: `error` (0 = accepted) or the new state and the actions to perform.

    On an error nothing else is set and `state` is the unchanged input state.
    `soft_limit_violation` means a non-jog move left the travel box: the simulator raises ALARM:2
    instead of planning; `motions` then holds only the moves Grbl would have planned before it.
    `program_flow` is the M0/M2/M30 just executed; `state.program_flow` is already cleared as in
    the firmware, so while an M0 pause lasts the simulator sets it back for `$G` to show M0.
    """

    error: int
    state: ParserState
    motions: tuple[Motion, ...] = ()
    dwell_s: float | None = None
    wco_changed: bool = False
    program_flow: ProgramFlow | None = None
    soft_limit_violation: bool = False
    spindle_changed: bool = False
    coolant_changed: bool = False

    @property
    def ok(self) -> bool:
        """True when Grbl would accept the line."""
        return self.error == STATUS_OK

    @property
    def motion(self) -> Motion | None:
        """The last (for G0/G1/jog: the only) motion, or None."""
        return self.motions[-1] if self.motions else None

    @property
    def program_end(self) -> bool:
        """M2 or M30 was executed."""
        return self.program_flow in ("M2", "M30")


# --------------------------------------------------------------------------------------------
# gc_execute_line


class _BlockError(Exception):
    """Internal: abort the block with a Grbl error code (the firmware's FAIL macro)."""

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


@dataclass(slots=True)
class _Block:
    """Scratch copy of the modal state plus the words of one block (Grbl's gc_block)."""

    motion: MotionMode
    feed_mode: FeedMode
    units: UnitsMode
    distance: DistanceMode
    plane: PlaneMode
    wcs_index: int
    spindle: SpindleMode
    coolant_flood: bool
    coolant_mist: bool
    tool_length_mode: ToolLengthMode
    program_flow: ProgramFlow | None
    xyz: list[float]
    non_modal: NonModal | None = None
    axis_command: int = _AXIS_NONE
    groups: set[str] = field(default_factory=set)
    words: set[str] = field(default_factory=set)
    axis_words: set[int] = field(default_factory=set)
    ijk_words: set[int] = field(default_factory=set)
    f: float = 0.0
    ijk: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    l_word: int = 0
    n: int = 0
    p: float = 0.0
    r: float = 0.0
    s: float = 0.0
    t: int = 0

    @classmethod
    def from_state(cls, st: ParserState) -> _Block:
        # Values start at zero (the firmware zeroes the block), modes start as the current state;
        # program flow is not carried over (it is reset after every block that sets it).
        return cls(
            motion=st.motion,
            feed_mode=st.feed_mode,
            units=st.units,
            distance=st.distance,
            plane=st.plane,
            wcs_index=st.wcs_index,
            spindle=st.spindle,
            coolant_flood=st.coolant_flood,
            coolant_mist=st.coolant_mist,
            tool_length_mode=st.tool_length_mode,
            program_flow=None,
            xyz=[0.0] * st.n_axes,
        )


def _claim_group(blk: _Block, group: str) -> None:
    if group in blk.groups:
        raise _BlockError(ERR_GCODE_MODAL_GROUP_VIOLATION)
    blk.groups.add(group)


def _g_word(blk: _Block, number: int, mantissa: int) -> None:
    """Apply one G word (STEP 2, 'G' case), keeping the firmware's order of checks."""
    group: str
    if number in (10, 28, 30, 92) and mantissa == 0:
        if blk.axis_command != _AXIS_NONE:
            raise _BlockError(ERR_GCODE_AXIS_COMMAND_CONFLICT)
        blk.axis_command = _AXIS_NON_MODAL
    if number in (4, 10, 28, 30, 53, 92):
        group = "non_modal"
        if number in (28, 30, 92):
            if mantissa not in (0, 10):
                raise _BlockError(ERR_GCODE_UNSUPPORTED_COMMAND)
            blk.non_modal = _NON_MODAL[number, mantissa]
            mantissa = 0
        else:
            blk.non_modal = _NON_MODAL[number, 0]
    elif number in (0, 1, 2, 3, 38, 80):
        if number != 80:
            if blk.axis_command != _AXIS_NONE:
                raise _BlockError(ERR_GCODE_AXIS_COMMAND_CONFLICT)
            blk.axis_command = _AXIS_MOTION
        group = "motion"
        if number == 38:
            if mantissa not in (20, 30, 40, 50):
                raise _BlockError(ERR_GCODE_UNSUPPORTED_COMMAND)
            blk.motion = _PROBE[mantissa]
            mantissa = 0
        else:
            blk.motion = _MOTION[number]
    elif number in (17, 18, 19):
        group = "plane"
        blk.plane = _PLANE[number]
    elif number in (90, 91):
        if mantissa == 0:
            group = "distance"
            blk.distance = _DISTANCE[number]
        else:
            # G91.1 (arc IJK incremental) is Grbl's only mode and does nothing; G90.1 is refused.
            group = "arc_distance"
            if mantissa != 10 or number == 90:
                raise _BlockError(ERR_GCODE_UNSUPPORTED_COMMAND)
            mantissa = 0
    elif number in (93, 94):
        group = "feed_mode"
        blk.feed_mode = _FEED_MODE[number]
    elif number in (20, 21):
        group = "units"
        blk.units = _UNITS[number]
    elif number == 40:
        group = "cutter_comp"  # accepted only so program headers pass; compensation never exists
    elif number in (43, 49):
        group = "tool_length"
        if blk.axis_command != _AXIS_NONE:
            raise _BlockError(ERR_GCODE_AXIS_COMMAND_CONFLICT)
        blk.axis_command = _AXIS_TLO
        if number == 49:
            blk.tool_length_mode = "G49"
        elif mantissa == 10:
            blk.tool_length_mode = "G43.1"
        else:
            raise _BlockError(ERR_GCODE_UNSUPPORTED_COMMAND)
        # Reading: the firmware clears the fraction here for G49 too, so G49.5 acts as G49.
        mantissa = 0
    elif 54 <= number <= 59:
        group = "wcs"
        blk.wcs_index = number - 54
    elif number == 61:
        group = "path_control"
        if mantissa != 0:
            raise _BlockError(ERR_GCODE_UNSUPPORTED_COMMAND)
    else:
        # Reading: the firmware holds the number in 8 bits, so G256 and up may alias to low
        # codes there; this model reports them all as unsupported.
        raise _BlockError(ERR_GCODE_UNSUPPORTED_COMMAND)
    # A negative fraction wraps to a large unsigned value in the firmware, so any fraction fails.
    if mantissa != 0:
        raise _BlockError(ERR_GCODE_COMMAND_VALUE_NOT_INTEGER)
    _claim_group(blk, group)


def _m_word(blk: _Block, number: int, mantissa: int, *, m7: bool) -> None:
    """Apply one M word (STEP 2, 'M' case)."""
    if mantissa != 0:
        raise _BlockError(ERR_GCODE_COMMAND_VALUE_NOT_INTEGER)
    group: str
    if number in (0, 1, 2, 30):
        group = "stopping"
        # M1 (optional stop) is accepted and ignored.
        blk.program_flow = _PROGRAM_FLOW.get(number)
    elif number in (3, 4, 5):
        group = "spindle"
        blk.spindle = _SPINDLE[number]
    elif number in (8, 9) or (number == 7 and m7):
        group = "coolant"
        if number == 7:
            blk.coolant_mist = True
        elif number == 8:
            blk.coolant_flood = True
        else:
            blk.coolant_flood = blk.coolant_mist = False
    else:
        raise _BlockError(ERR_GCODE_UNSUPPORTED_COMMAND)
    _claim_group(blk, "m_" + group)


def _value_word(blk: _Block, letter: str, value: float, axes: tuple[str, ...]) -> None:
    """Store one value word (STEP 2 default case): 20, 38, 25, then 4, in the firmware's order."""
    whole = math.trunc(value)
    if letter == "F":
        blk.f = value
    elif letter in "IJK":
        index = "IJK".index(letter)
        blk.ijk[index] = value
        blk.ijk_words.add(index)
    elif letter == "L":
        blk.l_word = whole
    elif letter == "N":
        blk.n = whole
    elif letter == "P":
        blk.p = value
    elif letter == "R":
        blk.r = value
    elif letter == "S":
        blk.s = value
    elif letter == "T":
        if value > MAX_TOOL_NUMBER:
            raise _BlockError(ERR_GCODE_MAX_VALUE_EXCEEDED)
        blk.t = whole
    elif letter in axes:
        index = axes.index(letter)
        blk.xyz[index] = value
        blk.axis_words.add(index)
    else:
        raise _BlockError(ERR_GCODE_UNSUPPORTED_COMMAND)
    if letter in blk.words:
        raise _BlockError(ERR_GCODE_WORD_REPEATED)
    if letter in "FNPST" and value < 0.0:
        raise _BlockError(ERR_NEGATIVE_VALUE)
    blk.words.add(letter)


def _parse_words(text: str, blk: _Block, axes: tuple[str, ...], *, m7: bool) -> None:
    """STEP 2: read letter/number pairs; errors come in the order the words appear."""
    i = 0
    while i < len(text):
        letter = text[i]
        if not "A" <= letter <= "Z":
            raise _BlockError(ERR_EXPECTED_COMMAND_LETTER)
        number = read_number(text, i + 1)
        if number is None:
            raise _BlockError(ERR_BAD_NUMBER_FORMAT)
        value, i = number
        whole = math.trunc(value)
        mantissa = _round_half_away(100.0 * (value - whole))
        if letter == "G":
            _g_word(blk, whole, mantissa)
        elif letter == "M":
            _m_word(blk, whole, mantissa, m7=m7)
        else:
            _value_word(blk, letter, value, axes)


def _plane_axes(plane: PlaneMode) -> tuple[int, int, int]:
    """(first, second, linear) axis indices of an arc plane."""
    if plane == "G17":
        return 0, 1, 2
    if plane == "G18":
        return 2, 0, 1
    return 1, 2, 0


@dataclass(frozen=True, slots=True)
class _Arc:
    """A checked arc: offsets from the start to the centre (mm) and the radius (mm)."""

    offset_mm: tuple[float, float]
    radius_mm: float
    clockwise: bool


def _check_arc(blk: _Block, st: ParserState) -> _Arc:
    """STEP 3 [20] for G2/G3: the arc error checks; returns the centre for execution."""
    a0, a1, _ = _plane_axes(blk.plane)
    if not blk.axis_words:
        raise _BlockError(ERR_GCODE_NO_AXIS_WORDS)
    if a0 not in blk.axis_words and a1 not in blk.axis_words:
        raise _BlockError(ERR_GCODE_NO_AXIS_WORDS_IN_PLANE)
    dx = blk.xyz[a0] - st.position_mm[a0]
    dy = blk.xyz[a1] - st.position_mm[a1]
    clockwise = blk.motion == "G2"
    if "R" in blk.words:
        blk.words.discard("R")
        if list(st.position_mm) == blk.xyz:
            raise _BlockError(ERR_GCODE_INVALID_TARGET)
        r = blk.r * MM_PER_INCH if blk.units == "G20" else blk.r
        under_root = 4.0 * r * r - dx * dx - dy * dy
        if under_root < 0:
            raise _BlockError(ERR_GCODE_ARC_RADIUS_ERROR)
        # Centre on the perpendicular bisector of the chord; the side follows direction and the
        # sign of R (negative R asks for the arc longer than half a circle).
        h = -math.sqrt(under_root) / math.hypot(dx, dy)
        if not clockwise:
            h = -h
        if r < 0:
            h = -h
            r = -r
        return _Arc((0.5 * (dx - dy * h), 0.5 * (dy + dx * h)), r, clockwise)
    if a0 not in blk.ijk_words and a1 not in blk.ijk_words:
        raise _BlockError(ERR_GCODE_NO_OFFSETS_IN_PLANE)
    blk.words -= {"I", "J", "K"}
    scale = MM_PER_INCH if blk.units == "G20" else 1.0
    # IJK are indexed X, Y, Z like the axes, so the plane picks two of them.
    off0 = blk.ijk[a0] * scale
    off1 = blk.ijk[a1] * scale
    target_r = math.hypot(dx - off0, dy - off1)
    radius = math.hypot(off0, off1)
    delta_r = abs(target_r - radius)
    if delta_r > _ARC_RADIUS_SLACK_MM and (
        delta_r > _ARC_RADIUS_MAX_DIFF_MM or delta_r > _ARC_RADIUS_REL * radius
    ):
        raise _BlockError(ERR_GCODE_INVALID_TARGET)
    return _Arc((off0, off1), radius, clockwise)


def _arc_points(
    start: Vec, target: Vec, arc: _Arc, plane: PlaneMode, tolerance_mm: float
) -> list[Vec]:
    """Chord end points of an arc (mc_arc's segment count; exact trigonometry per point)."""
    a0, a1, _ = _plane_axes(plane)
    c0 = start[a0] + arc.offset_mm[0]
    c1 = start[a1] + arc.offset_mm[1]
    r0, r1 = -arc.offset_mm[0], -arc.offset_mm[1]
    t0, t1 = target[a0] - c0, target[a1] - c1
    angle = math.atan2(r0 * t1 - r1 * t0, r0 * t0 + r1 * t1)
    if arc.clockwise:
        if angle >= -_ARC_ANGLE_EPSILON:
            angle -= 2 * math.pi
    elif angle <= _ARC_ANGLE_EPSILON:
        angle += 2 * math.pi
    chord_room = tolerance_mm * (2 * arc.radius_mm - tolerance_mm)
    segments = (
        math.floor(abs(0.5 * angle * arc.radius_mm) / math.sqrt(chord_room))
        if chord_room > 0
        else 0
    )
    points: list[Vec] = []
    for k in range(1, segments):
        frac = k / segments
        cos_a, sin_a = math.cos(angle * frac), math.sin(angle * frac)
        # Axes outside the plane (the linear axis, and any beyond Z) move in proportion: a helix.
        p = [s + (t - s) * frac for s, t in zip(start, target, strict=True)]
        p[a0] = c0 + r0 * cos_a - r1 * sin_a
        p[a1] = c1 + r0 * sin_a + r1 * cos_a
        points.append(tuple(p))
    points.append(target)
    return points


def _distance_mm(a: Vec, b: Vec) -> float:
    return math.sqrt(sum((y - x) ** 2 for x, y in zip(a, b, strict=True)))


def execute_block(
    text: str,
    state: ParserState,
    *,
    jog: bool,
    envelope: TravelBox | None = None,
    n_axes: int = 3,
    m7: bool = False,
    arc_tolerance_mm: float = DEFAULT_ARC_TOLERANCE_MM,
) -> ExecResult:
    """Run one preparsed line through the gc_execute_line model.

    For a jog, `text` is either the whole `$J=...` line or just what follows `$J=`; call
    `check_jog_dispatch` first. `envelope` is the soft-limit box when `$20=1` (None: off).
    `n_axes` picks the axis letters (X Y Z, then A B C U V W) and must match the state. `m7` is
    the ENABLE_M7 build option (off in default Grbl: M7 is then error 20). Arcs are executed as
    chords like mc_arc, with `arc_tolerance_mm` as `$12`.
    """
    if n_axes != state.n_axes:
        raise ValueError(f"execute_block: n_axes={n_axes} but the state has {state.n_axes} axes")
    if jog and text.startswith(_JOG_PREFIX):
        text = text[len(_JOG_PREFIX) :]
    try:
        return _execute(text, state, jog, envelope, ALL_AXES[:n_axes], m7, arc_tolerance_mm)
    except _BlockError as fail:
        return ExecResult(error=fail.code, state=state)


def _execute(
    text: str,
    st: ParserState,
    jog: bool,
    envelope: TravelBox | None,
    axes: tuple[str, ...],
    m7: bool,
    arc_tolerance_mm: float,
) -> ExecResult:
    n = st.n_axes
    blk = _Block.from_state(st)
    if jog:
        # STEP 1: a jog is G1 under G94 whatever the modal state says (firmware-facts §1.3).
        blk.motion = "G1"
        blk.feed_mode = "G94"
    _parse_words(text, blk, axes, m7=m7)

    # STEP 3 [0]: axis words without an explicit axis command mean "use the motion mode".
    if blk.axis_words and blk.axis_command == _AXIS_NONE:
        blk.axis_command = _AXIS_MOTION
    if "N" in blk.words and blk.n > MAX_LINE_NUMBER:
        raise _BlockError(ERR_GCODE_INVALID_LINE_NUMBER)

    # [2]/[3] Feed mode and feed rate.
    if jog:
        if "F" not in blk.words:
            raise _BlockError(ERR_GCODE_UNDEFINED_FEED_RATE)
        if blk.units == "G20":
            blk.f *= MM_PER_INCH
    elif blk.feed_mode == "G93":
        if (
            blk.axis_command == _AXIS_MOTION
            and blk.motion not in ("G80", "G0")
            and "F" not in blk.words
        ):
            raise _BlockError(ERR_GCODE_UNDEFINED_FEED_RATE)
        # Under G93 F is an inverse time for this block only; it is never carried over.
    elif st.feed_mode == "G94":
        if "F" in blk.words:
            if blk.units == "G20":
                blk.f *= MM_PER_INCH
        else:
            blk.f = st.feed_mm_min
    # Else: G93 -> G94 in this block; F is the given value or stays undefined (0).

    # [4] S is modal.
    if "S" not in blk.words:
        blk.s = st.spindle_speed_rpm

    # [10] Dwell needs P.
    if blk.non_modal == "G4":
        if "P" not in blk.words:
            raise _BlockError(ERR_GCODE_VALUE_WORD_MISSING)
        blk.words.discard("P")

    # [12] Axis values to mm.
    if blk.units == "G20":
        for i in blk.axis_words:
            blk.xyz[i] *= MM_PER_INCH

    # [14] G43.1 takes exactly one axis word, Z.
    if (
        blk.axis_command == _AXIS_TLO
        and blk.tool_length_mode == "G43.1"
        and blk.axis_words != {TLO_AXIS}
    ):
        raise _BlockError(ERR_GCODE_G43_DYNAMIC_AXIS_ERROR)

    # [15] The coordinate system this block works in.
    block_wcs = st.coord_systems_mm[blk.wcs_index]

    # [19] Non-modal commands and the target.
    g10_index: int | None = None
    g10_values: Vec | None = None
    g92_values: Vec | None = None
    home_target: Vec | None = None
    if blk.non_modal == "G10":
        if not blk.axis_words:
            raise _BlockError(ERR_GCODE_NO_AXIS_WORDS)
        # Reading: the firmware's test is "neither P nor L given"; one of them alone passes here
        # (a missing L then fails as unsupported, a missing P means P0, the active system).
        if "P" not in blk.words and "L" not in blk.words:
            raise _BlockError(ERR_GCODE_VALUE_WORD_MISSING)
        p_index = math.trunc(blk.p)
        if p_index > N_COORDINATE_SYSTEMS:
            raise _BlockError(ERR_GCODE_UNSUPPORTED_COORD_SYS)
        # Only L2 (without R) and L20 exist.
        if blk.l_word != 20 and (blk.l_word != 2 or "R" in blk.words):
            raise _BlockError(ERR_GCODE_UNSUPPORTED_COMMAND)
        blk.words -= {"L", "P"}
        g10_index = p_index - 1 if p_index > 0 else blk.wcs_index
        stored = list(st.coord_systems_mm[g10_index])
        for i in blk.axis_words:
            if blk.l_word == 20:
                # L20: choose the offset that makes the current position read as the value.
                stored[i] = st.position_mm[i] - st.g92_offset_mm[i] - blk.xyz[i]
                if i == TLO_AXIS:
                    stored[i] -= st.tool_length_offset_mm
            else:
                stored[i] = blk.xyz[i]
        g10_values = tuple(stored)
    elif blk.non_modal == "G92":
        if not blk.axis_words:
            raise _BlockError(ERR_GCODE_NO_AXIS_WORDS)
        offset = list(st.g92_offset_mm)
        for i in blk.axis_words:
            # Choose the G92 offset that makes the current position read as the value.
            offset[i] = st.position_mm[i] - block_wcs[i] - blk.xyz[i]
            if i == TLO_AXIS:
                offset[i] -= st.tool_length_offset_mm
        g92_values = tuple(offset)
    else:
        if blk.axis_command != _AXIS_TLO and blk.axis_words:
            # STEP 3 [19] default branch (firmware-facts §1.5). With no axis word at all nothing
            # here runs and the target stays at the zeroed initial value: machine 0 for a jog
            # (firmware-facts §1.3).
            for i in range(n):
                if i not in blk.axis_words:
                    blk.xyz[i] = st.position_mm[i]
                elif blk.non_modal == "G53":
                    continue
                elif blk.distance == "G90":
                    blk.xyz[i] += block_wcs[i] + st.g92_offset_mm[i]
                    if i == TLO_AXIS:
                        blk.xyz[i] += st.tool_length_offset_mm
                else:
                    blk.xyz[i] += st.position_mm[i]
        if blk.non_modal in ("G28", "G30"):
            stored_home = st.g28_mm if blk.non_modal == "G28" else st.g30_mm
            if blk.axis_words:
                # Only the named axes go home; the others stay where they are.
                home_target = tuple(
                    stored_home[i] if i in blk.axis_words else st.position_mm[i] for i in range(n)
                )
            else:
                home_target = stored_home
                blk.axis_command = _AXIS_NONE
        elif blk.non_modal == "G53" and blk.motion not in ("G0", "G1"):
            raise _BlockError(ERR_GCODE_G53_INVALID_MOTION_MODE)

    # [20] Motion mode checks.
    arc: _Arc | None = None
    if blk.motion == "G80":
        if blk.axis_words:
            raise _BlockError(ERR_GCODE_AXIS_WORDS_EXIST)
    elif blk.axis_command == _AXIS_MOTION:
        if blk.motion == "G0":
            if not blk.axis_words:
                blk.axis_command = _AXIS_NONE
        else:
            if blk.f == 0.0:
                raise _BlockError(ERR_GCODE_UNDEFINED_FEED_RATE)
            if blk.motion == "G1":
                if not blk.axis_words:
                    blk.axis_command = _AXIS_NONE
            elif blk.motion in ("G2", "G3"):
                arc = _check_arc(blk, st)
            else:  # G38.x
                if not blk.axis_words:
                    raise _BlockError(ERR_GCODE_NO_AXIS_WORDS)
                if list(st.position_mm) == blk.xyz:
                    raise _BlockError(ERR_GCODE_INVALID_TARGET)

    # Unused words: in a jog only N and F are "used" (so S and T give 36, firmware-facts §1.3).
    blk.words -= {"N", "F"} if jog else {"N", "F", "S", "T"}
    if blk.axis_command != _AXIS_NONE:
        blk.words -= set(axes)
    if blk.words:
        raise _BlockError(ERR_GCODE_UNUSED_WORDS)

    target: Vec = tuple(blk.xyz)
    if jog:
        # Jog filter (firmware-facts §1.3 step 6), then the travel check of jog_execute
        # (firmware-facts §2).
        if not blk.groups <= _JOG_ALLOWED_GROUPS:
            raise _BlockError(ERR_INVALID_JOG_COMMAND)
        if blk.non_modal not in (None, "G53"):
            raise _BlockError(ERR_INVALID_JOG_COMMAND)
        if envelope is not None and not envelope.contains(target):
            raise _BlockError(ERR_TRAVEL_EXCEEDED)
        # Only the parser position moves; every mode and the stored F stay as they were (§1.5).
        return ExecResult(
            error=STATUS_OK,
            state=replace(st, position_mm=target),
            motions=(Motion(target, blk.f, rapid=False, is_jog=True, line_number=blk.n),),
        )
    return _run(
        blk,
        st,
        target,
        arc,
        g10_index,
        g10_values,
        g92_values,
        home_target,
        envelope,
        arc_tolerance_mm,
    )


def _run(
    blk: _Block,
    st: ParserState,
    target: Vec,
    arc: _Arc | None,
    g10_index: int | None,
    g10_values: Vec | None,
    g92_values: Vec | None,
    home_target: Vec | None,
    envelope: TravelBox | None,
    arc_tolerance_mm: float,
) -> ExecResult:
    """STEP 4 for plain G-code: update the state in the firmware's order and list the actions."""
    wco_changed = False
    spindle_changed = (blk.spindle != st.spindle) or (
        st.spindle != "M5" and blk.s != st.spindle_speed_rpm
    )
    coolant_changed = (blk.coolant_flood, blk.coolant_mist) != (st.coolant_flood, st.coolant_mist)

    tlo_mm = st.tool_length_offset_mm
    tlo_mode = st.tool_length_mode
    if blk.axis_command == _AXIS_TLO:
        tlo_mode = blk.tool_length_mode
        new_tlo = 0.0 if tlo_mode == "G49" else blk.xyz[TLO_AXIS]
        if new_tlo != tlo_mm:
            tlo_mm = new_tlo
            wco_changed = True
    if blk.wcs_index != st.wcs_index:
        wco_changed = True

    coord_systems = st.coord_systems_mm
    g92 = st.g92_offset_mm
    g28, g30 = st.g28_mm, st.g30_mm
    position = st.position_mm
    moves: list[tuple[Vec, bool]] = []  # (target, rapid)
    if g10_index is not None and g10_values is not None:
        table = list(coord_systems)
        table[g10_index] = g10_values
        coord_systems = tuple(table)
        wco_changed = wco_changed or g10_index == blk.wcs_index
    elif blk.non_modal in ("G28", "G30") and home_target is not None:
        if blk.axis_command != _AXIS_NONE:
            moves.append((target, True))
        moves.append((home_target, True))
        position = home_target
    elif blk.non_modal == "G28.1":
        g28 = position
    elif blk.non_modal == "G30.1":
        g30 = position
    elif blk.non_modal == "G92" and g92_values is not None:
        g92 = g92_values
        wco_changed = True
    elif blk.non_modal == "G92.1":
        g92 = (0.0,) * st.n_axes
        wco_changed = True

    probe: MotionMode | None = None
    if blk.motion != "G80" and blk.axis_command == _AXIS_MOTION:
        if blk.motion in ("G0", "G1"):
            moves.append((target, blk.motion == "G0"))
        elif arc is not None:
            moves.extend(
                (p, False) for p in _arc_points(position, target, arc, blk.plane, arc_tolerance_mm)
            )
        else:
            # A probe stops at contact; the simulator decides where, and the parser position is
            # then synced to the machine (the firmware's "update from system" case).
            probe = blk.motion
            moves.append((target, False))
        position = target

    motions: list[Motion] = []
    soft_limit = False
    corners = [st.position_mm, *(m[0] for m in moves)]
    path_mm = sum(_distance_mm(a, b) for a, b in itertools.pairwise(corners))
    for move_target, rapid in moves:
        if envelope is not None and not envelope.contains(move_target):
            soft_limit = True
            break
        feed = blk.f
        if blk.feed_mode == "G93" and not rapid:
            # Inverse time: the whole block takes 1/F minutes (arcs: over the whole arc).
            feed = blk.f * path_mm
        motions.append(
            Motion(move_target, feed, rapid=rapid, is_jog=False, line_number=blk.n, probe=probe)
        )

    flow = blk.program_flow
    motion_mode = blk.motion
    plane, distance, feed_mode = blk.plane, blk.distance, blk.feed_mode
    wcs_index, spindle = blk.wcs_index, blk.spindle
    flood, mist = blk.coolant_flood, blk.coolant_mist
    if flow in ("M2", "M30"):
        # Program end resets only some groups (the firmware follows LinuxCNC): G1 G17 G90 G94 G54
        # M5 M9; units, TLO, G92, F, S and T stay.
        motion_mode, plane, distance, feed_mode = "G1", "G17", "G90", "G94"
        wcs_index, spindle, flood, mist = 0, "M5", False, False
        spindle_changed = spindle_changed or st.spindle != "M5"
        coolant_changed = coolant_changed or st.coolant_flood or st.coolant_mist
        wco_changed = True

    new_state = replace(
        st,
        motion=motion_mode,
        feed_mode=feed_mode,
        units=blk.units,
        distance=distance,
        plane=plane,
        wcs_index=wcs_index,
        coord_systems_mm=coord_systems,
        g92_offset_mm=g92,
        tool_length_mode=tlo_mode,
        tool_length_offset_mm=tlo_mm,
        feed_mm_min=blk.f,
        spindle=spindle,
        spindle_speed_rpm=blk.s,
        coolant_flood=flood,
        coolant_mist=mist,
        # Reading: the block's T starts at 0 and is always copied, so a line without T reports
        # T0 afterwards (Grbl 1.1h tracks T but never uses it).
        tool=blk.t,
        program_flow=None,  # reset once the pause or end has been acted on
        line_number=blk.n,
        position_mm=position,
        g28_mm=g28,
        g30_mm=g30,
    )
    return ExecResult(
        error=STATUS_OK,
        state=new_state,
        motions=tuple(motions),
        dwell_s=blk.p if blk.non_modal == "G4" else None,
        wco_changed=wco_changed,
        program_flow=flow,
        soft_limit_violation=soft_limit,
        spindle_changed=spindle_changed,
        coolant_changed=coolant_changed,
    )
