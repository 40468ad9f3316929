"""Parse every line a Grbl-family controller sends into a typed, frozen response; never raises.

The forms follow firmware-facts §5.3 (replies and push messages) and §5.4 (status reports), with the
grblHAL and FluidNC variants of firmware-facts §7. Numbers stay in the units the controller reported
them in (mm, or inches when `$13=1`); converting them is the machine model's job, not the parser's.
Anything garbled, truncated or not UTF-8 becomes `Unparsed` so a noisy link can never crash a
caller.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Final

from smoothjog.core.errors import CoreError
from smoothjog.core.firmware import FirmwareName

#: Status-report states known to the three firmwares; an unknown word is still accepted.
KNOWN_STATES: frozenset[str] = frozenset(
    {"Idle", "Run", "Hold", "Jog", "Alarm", "Door", "Check", "Home", "Sleep", "Tool"}
)

# Grbl prints numbers as optional sign, digits, optional point and decimals (firmware-facts §1.3
# number format, report side in print.c). `float()` alone would also take "nan", "inf", "1e3" and
# "1_0", none of which a controller sends, so a stricter pattern keeps garbage out.
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)")
_INT = re.compile(r"[+-]?\d+")
#: A control byte (below 0x20, or DEL) anywhere in a line: line noise, never a controller's text.
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")
_MAX_AXES = 9  # X Y Z A B C U V W, FluidNC's maximum (firmware-facts §7)


@dataclass(frozen=True, slots=True)
class Ok:
    """`ok`: the oldest un-answered line was accepted."""


@dataclass(frozen=True, slots=True)
class ErrorReply:
    """`error:N`: the oldest un-answered line was rejected with Grbl error code N."""

    code: int


@dataclass(frozen=True, slots=True)
class AlarmReply:
    """`ALARM:N`: the controller entered alarm N (firmware-facts §5.6)."""

    code: int


@dataclass(frozen=True, slots=True)
class Banner:
    """The welcome line after power-up or reset: all buffers empty, parser at defaults."""

    firmware: FirmwareName
    version: str
    raw: str


@dataclass(frozen=True, slots=True)
class StatusReport:
    """A `<...>` status report; positions, WCO and feed are in the report units ($13)."""

    state: str
    substate: int | None
    mpos: tuple[float, ...] | None
    wpos: tuple[float, ...] | None
    buffer: tuple[int, int] | None  # (planner blocks free, RX bytes free), firmware-facts §4.4
    line_number: int | None
    feed: float | None  # mm/min, or in/min when $13=1
    spindle_speed: float | None  # rpm
    pins: str | None
    wco: tuple[float, ...] | None
    overrides: tuple[int, int, int] | None  # (feed %, rapid %, spindle %)
    accessories: str | None
    raw: str
    extras: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True, slots=True)
class GcodeModes:
    """`[GC:...]` from `$G`: the G/M mode words, and F, S and T when printed."""

    words: tuple[str, ...]
    feed: float | None  # mm/min, or in/min when $13=1
    spindle_speed: float | None
    tool: int | None
    raw: str


@dataclass(frozen=True, slots=True)
class Message:
    """`[MSG:...]` feedback text."""

    text: str


@dataclass(frozen=True, slots=True)
class VersionInfo:
    """`[VER:version.build:user]` from `$I`; build is "" when the line has none."""

    version: str
    build: str
    user: str


#: The `[OPT:]` letters Grbl 1.1h, grblHAL and FluidNC print, each with what it says about the
#: build (`report_build_info` in Grbl's and grblHAL's report.c, FluidNC's Report.cpp). Punctuation
#: and digits are letters too. Starred meanings are printed when a feature is compiled *out*.
OPTION_CODES: Final[Mapping[str, str]] = MappingProxyType(
    {
        "V": "variable spindle",
        "N": "line numbers",
        "M": "mist coolant (M7)",
        "C": "CoreXY kinematics",
        "P": "parking motion",
        "Z": "homing sets the origin at the switches (HOMING_FORCE_SET_ORIGIN, firmware-facts §2)",
        "H": "single-axis homing commands ($HX ...)",
        "T": "two limit switches on one pin",
        "A": "feed override allowed while probing",
        "D": "spindle direction pin used as the enable pin",
        "0": "spindle off at zero speed",
        "S": "software debounce of the limit pins",
        "R": "parking override control (M56)",
        "L": "no alarm lock at power-up (HOMING_INIT_LOCK off)",
        "+": "safety door input pin",
        "*": "*restore-all command ($RST=*)",
        "$": "*restore-settings command ($RST=$)",
        "#": "*restore-parameters command ($RST=#)",
        "I": "*build-info write command ($I=...)",
        "E": "*planner sync before a settings write",
        "W": "*planner sync before a work offset change",
        "2": "dual (ganged) axis motors",
        "B": "Bluetooth (FluidNC)",
    }
)


@dataclass(frozen=True, slots=True)
class BuildOptions:
    """`[OPT:codes,blocks,rx]` from `$I`; extra grblHAL fields are kept as text in extras."""

    codes: str
    planner_blocks: int | None
    rx_buffer_bytes: int | None
    extras: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class Parameter:
    """One `$#` line: a coordinate system, G28/G30/G92, TLO, or PRB with its success flag."""

    name: str
    values: tuple[float, ...]
    probe_ok: bool | None


@dataclass(frozen=True, slots=True)
class SettingLine:
    """A numbered `$N=value` line from `$$`; value is None when the text is not a number."""

    number: int
    value: float | None
    raw: str  # the value text exactly as printed after "="


@dataclass(frozen=True, slots=True)
class NamedSetting:
    """A `$Name=value` line with a non-numeric name (FluidNC `$Config/...`, Grbl `$N0=...`)."""

    name: str
    raw: str


@dataclass(frozen=True, slots=True)
class HelpReply:
    """`[HLP:...]` from `$`: the command words listed."""

    commands: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class StartupLineResult:
    """`>line:ok` or `>line:error:N`, printed when a `$N` startup line runs after reset."""

    line: str
    ok: bool
    error: int | None


@dataclass(frozen=True, slots=True)
class Feedback:
    """Any other `[...]` line (`[echo:...]`, `[FIRMWARE:...]`, unknown tags), brackets off."""

    text: str


@dataclass(frozen=True, slots=True)
class Empty:
    """A blank line (Grbl sends one before its banner)."""


@dataclass(frozen=True, slots=True)
class Unparsed:
    """A line that fits no known form; reason says why, for logs."""

    raw: bytes
    reason: str


Response = (
    Ok
    | ErrorReply
    | AlarmReply
    | Banner
    | StatusReport
    | GcodeModes
    | Message
    | VersionInfo
    | BuildOptions
    | Parameter
    | SettingLine
    | NamedSetting
    | HelpReply
    | StartupLineResult
    | Feedback
    | Empty
    | Unparsed
)


class _MalformedLineError(CoreError):
    """Internal: a line is malformed; carries the reason for Unparsed. Never escapes."""


def parse_response(line: bytes | str) -> Response:
    """Parse one line from the controller; any input at all yields a Response, never an error."""
    if line == b"ok":
        return _OK  # the reply to almost every line, framed without its line end
    raw = _as_bytes(line)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        return Unparsed(raw, f"not UTF-8 (byte {exc.start})")
    text = _strip_eol(text)
    try:
        return _parse_text(text)
    except _MalformedLineError as exc:
        return Unparsed(raw, str(exc))
    except Exception as exc:
        # The contract is "never raises": a parser bug must cost one log line, not a running jog.
        return Unparsed(raw, f"parser fault: {type(exc).__name__}")


_OK = Ok()


def _as_bytes(line: bytes | str) -> bytes:
    """The bytes of a line; str input is encoded so Unparsed always carries bytes."""
    if isinstance(line, str):
        # surrogatepass: a str with lone surrogates still encodes, and then fails to decode below.
        return line.encode("utf-8", "surrogatepass")
    return bytes(line)


def _strip_eol(text: str) -> str:
    """Remove one trailing line end: `\\r\\n`, `\\n` or `\\r`."""
    for eol in ("\r\n", "\n", "\r"):
        if text.endswith(eol):
            return text[: -len(eol)]
    return text


def _parse_text(text: str) -> Response:
    """Dispatch a decoded line without its line end on its first characters."""
    if text == "":
        return Empty()
    # One regex scan, not a Python loop over the characters: this runs for every line received.
    bad = _CONTROL.search(text)
    if bad is not None:
        # A controller never prints control bytes inside a line: this is line noise.
        raise _MalformedLineError(f"control byte 0x{ord(bad.group()):02x} inside the line")
    if text == "ok":
        return Ok()
    if text.startswith("error:"):
        return ErrorReply(_parse_int(text[6:], "error code"))
    if text.startswith("ALARM:"):
        return AlarmReply(_parse_int(text[6:], "alarm code"))
    if text.startswith("<"):
        return _parse_status(text)
    if text.startswith("["):
        return _parse_bracket(text)
    if text.startswith("$"):
        return _parse_setting(text)
    if text.startswith(">"):
        return _parse_startup(text)
    banner = _parse_banner(text)
    if banner is not None:
        return banner
    raise _MalformedLineError("unrecognised line")


def _parse_int(text: str, what: str) -> int:
    """A whole decimal number, or _MalformedLineError naming what it should have been."""
    if _INT.fullmatch(text) is None:
        raise _MalformedLineError(f"{what} {text!r} is not a whole number")
    return int(text)


def _parse_number(text: str, what: str) -> float:
    """A decimal number as Grbl prints it (no exponent), or _MalformedLineError naming the field."""
    if _NUMBER.fullmatch(text) is None:
        raise _MalformedLineError(f"{what} {text!r} is not a number")
    return float(text)


def _parse_numbers(text: str, what: str, lo: int, hi: int) -> tuple[float, ...]:
    """Between lo and hi comma-separated numbers."""
    parts = text.split(",")
    if not lo <= len(parts) <= hi:
        raise _MalformedLineError(f"{what} has {len(parts)} values, expected {lo} to {hi}")
    return tuple(_parse_number(p, what) for p in parts)


#: A coordinate as the firmware prints one: always with a decimal point and a fixed number of
#: decimals (3 in mm, 4 in inches: firmware-facts §5.4).
_COORD = re.compile(r"[+-]?\d+\.(\d+)")


def _parse_coords(text: str, what: str, decimals: list[int]) -> tuple[float, ...]:
    """MPos, WPos or WCO: 1 to _MAX_AXES coordinates, each with the decimals of every other
    coordinate of the report (decimals holds the count seen first, or is empty).

    The firmware prints every coordinate with the same decimals, so one without a decimal
    point, or with another count of decimals, is a line a byte was lost from or flipped in on
    the wire (`-406075` for `-406.075`): taken as read, it would put the machine 400 m away.
    """
    parts = text.split(",")
    if not 1 <= len(parts) <= _MAX_AXES:
        raise _MalformedLineError(f"{what} has {len(parts)} values, expected 1 to {_MAX_AXES}")
    values: list[float] = []
    for part in parts:
        match = _COORD.fullmatch(part)
        if match is None:
            raise _MalformedLineError(f"{what} {part!r} is not a coordinate with decimals")
        count = len(match.group(1))
        if not decimals:
            decimals.append(count)
        elif count != decimals[0]:
            raise _MalformedLineError(
                f"{what} {part!r} has {count} decimals where the report's others have"
                f" {decimals[0]} (a byte lost or changed on the wire?)"
            )
        values.append(float(part))
    return tuple(values)


def _parse_ints(text: str, what: str, count: int) -> tuple[int, ...]:
    """Exactly count comma-separated whole numbers."""
    parts = text.split(",")
    if len(parts) != count:
        raise _MalformedLineError(f"{what} has {len(parts)} values, expected {count}")
    return tuple(_parse_int(p, what) for p in parts)


# --- status reports (firmware-facts §5.4)
# ------------------------------------------------------------

_STATE = re.compile(r"([A-Za-z]+)(?::(\d+))?")
_VALUED_FIELDS = frozenset({"MPos", "WPos", "WCO", "Bf", "Ln", "FS", "F", "Pn", "Ov", "A"})


def _parse_status(text: str) -> StatusReport:
    """`<State|Field:value|...>` with the fields in any order (the docs say not to rely on it)."""
    if not text.endswith(">") or len(text) < 3:
        raise _MalformedLineError("status report not closed with '>' (truncated?)")
    fields = text[1:-1].split("|")
    state_match = _STATE.fullmatch(fields[0])
    if state_match is None:
        raise _MalformedLineError(f"status state {fields[0]!r} is not a word with an optional :N")
    state = state_match.group(1)
    substate = int(state_match.group(2)) if state_match.group(2) is not None else None
    mpos: tuple[float, ...] | None = None
    wpos: tuple[float, ...] | None = None
    wco: tuple[float, ...] | None = None
    buffer: tuple[int, int] | None = None
    line_number: int | None = None
    feed: float | None = None
    spindle: float | None = None
    pins: str | None = None
    overrides: tuple[int, int, int] | None = None
    accessories: str | None = None
    extras: list[tuple[str, str]] = []
    decimals: list[int] = []  # of the report's coordinates, all alike (see _parse_coords)
    for field in fields[1:]:
        name, sep, value = field.partition(":")
        if name == "" or (not sep and name in _VALUED_FIELDS):
            raise _MalformedLineError(f"status field {field!r} has no name or no value")
        if name == "MPos":
            mpos = _parse_coords(value, "MPos", decimals)
        elif name == "WPos":
            wpos = _parse_coords(value, "WPos", decimals)
        elif name == "WCO":
            wco = _parse_coords(value, "WCO", decimals)
        elif name == "Bf":
            planner_free, rx_free = _parse_ints(value, "Bf", 2)
            buffer = (planner_free, rx_free)
        elif name == "Ln":
            line_number = _parse_int(value, "Ln")
        elif name == "FS":
            # grblHAL may append a third value (actual spindle rpm): keep the first two.
            speeds = _parse_numbers(value, "FS", 2, 3)
            feed, spindle = speeds[0], speeds[1]
        elif name == "F":
            feed = _parse_number(value, "F")
        elif name == "Pn":
            pins = value
        elif name == "Ov":
            feed_pct, rapid_pct, spindle_pct = _parse_ints(value, "Ov", 3)
            overrides = (feed_pct, rapid_pct, spindle_pct)
        elif name == "A":
            accessories = value
        else:
            extras.append((name, value))
    return StatusReport(
        state=state,
        substate=substate,
        mpos=mpos,
        wpos=wpos,
        buffer=buffer,
        line_number=line_number,
        feed=feed,
        spindle_speed=spindle,
        pins=pins,
        wco=wco,
        overrides=overrides,
        accessories=accessories,
        raw=text,
        extras=tuple(extras),
    )


# --- bracketed push messages and query replies (firmware-facts §5.3)
# ----------------------------------

_PARAM_NAME = re.compile(r"G\d+(?:\.\d)?|TLO|PRB")


def _parse_bracket(text: str) -> Response:
    """`[TAG:body]` lines: MSG, GC, VER, OPT, HLP, the `$#` parameters, or other feedback."""
    if not text.endswith("]"):
        raise _MalformedLineError("bracketed line not closed with ']' (truncated?)")
    inner = text[1:-1]
    tag, sep, body = inner.partition(":")
    if not sep:
        return Feedback(inner)
    if tag == "MSG":
        return Message(body)
    if tag == "GC":
        return _parse_gc(body, text)
    if tag == "VER":
        return _parse_ver(body)
    if tag == "OPT":
        return _parse_opt(body)
    if tag == "HLP":
        return HelpReply(tuple(body.split()))
    if _PARAM_NAME.fullmatch(tag):
        return _parse_parameter(tag, body)
    return Feedback(inner)


def _parse_gc(body: str, raw: str) -> GcodeModes:
    """`G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0`: modes, then T, F and S pulled out."""
    words: list[str] = []
    feed: float | None = None
    spindle: float | None = None
    tool: int | None = None
    for word in body.split():
        letter, number = word[0], word[1:]
        if letter == "F":
            feed = _parse_number(number, "GC feed")
        elif letter == "S":
            spindle = _parse_number(number, "GC spindle speed")
        elif letter == "T":
            tool = _parse_int(number, "GC tool")
        elif letter in "GM" and _NUMBER.fullmatch(number):
            words.append(word)
        else:
            raise _MalformedLineError(f"GC word {word!r} is not a G, M, T, F or S word")
    return GcodeModes(tuple(words), feed, spindle, tool, raw)


_BUILD_DATE = re.compile(r"\d{8}")


def _parse_ver(body: str) -> VersionInfo:
    """`1.1h.20190830:user` -> version 1.1h, build 20190830, user (which may hold colons)."""
    version_build, _, user = body.partition(":")
    version, dot, build = version_build.rpartition(".")
    # Grbl and grblHAL builds are yyyymmdd dates; FluidNC prints "3.7 FluidNC v3.7.8" with none.
    if not dot or _BUILD_DATE.fullmatch(build) is None:
        return VersionInfo(version_build, "", user)
    return VersionInfo(version, build, user)


def _parse_opt(body: str) -> BuildOptions:
    """`V,15,128` -> letters, planner blocks, RX bytes; more fields (grblHAL) kept as text."""
    parts = body.split(",")
    codes = parts[0]
    # Any printable ASCII mark is a letter here, documented in OPTION_CODES or not: the sizes
    # after it must never be lost to a letter this table does not know yet. Spaces and non-ASCII
    # are noise, since no firmware prints them.
    bad = next((c for c in codes if not "!" <= c <= "~"), None)
    if bad is not None:
        raise _MalformedLineError(f"OPT codes {codes!r} hold {bad!r}, which no firmware prints")
    blocks = _parse_int(parts[1], "OPT planner blocks") if len(parts) > 1 else None
    rx_bytes = _parse_int(parts[2], "OPT RX buffer size") if len(parts) > 2 else None
    return BuildOptions(codes, blocks, rx_bytes, tuple(parts[3:]))


def _parse_parameter(name: str, body: str) -> Parameter:
    """`x,y,z` or, for PRB, `x,y,z:0|1`."""
    probe_ok: bool | None = None
    values_text = body
    if name == "PRB":
        values_text, sep, flag = body.rpartition(":")
        if not sep or flag not in ("0", "1"):
            raise _MalformedLineError(f"PRB line {body!r} lacks its ':0' or ':1' success flag")
        probe_ok = flag == "1"
    return Parameter(name, _parse_numbers(values_text, name, 1, _MAX_AXES), probe_ok)


# --- $$ settings, startup lines and banners ---------------------------------------------------

_BANNER = re.compile(r"(GrblHAL|grblHAL|Grbl) (\S+) \[(.*)\]")
_FLUIDNC_VERSION = re.compile(r"FluidNC v?(\d[^\s\])]*)")


def _parse_setting(text: str) -> SettingLine | NamedSetting:
    """`$110=5000.000`; a non-numeric value stays in raw with value None."""
    name, sep, value = text[1:].partition("=")
    if not sep or name == "":
        raise _MalformedLineError("'$' line without 'name=value'")
    if not name.isdigit():
        return NamedSetting(name, value)
    number = _NUMBER.fullmatch(value)
    return SettingLine(int(name), float(value) if number is not None else None, value)


def _parse_startup(text: str) -> StartupLineResult:
    """`>G54G20:ok` or `>G54G20:error:N`; the line itself may contain colons."""
    body = text[1:]
    if body.endswith(":ok"):
        return StartupLineResult(body[:-3], ok=True, error=None)
    line, sep, code = body.rpartition(":error:")
    if sep:
        return StartupLineResult(line, ok=False, error=_parse_int(code, "startup line error"))
    raise _MalformedLineError("startup line result without ':ok' or ':error:N'")


def _parse_banner(text: str) -> Banner | None:
    """The welcome line of Grbl, grblHAL or FluidNC (firmware-facts §5.3, §7), or None."""
    match = _BANNER.fullmatch(text)
    if match is None:
        return None
    name, version, note = match.groups()
    fluidnc = _FLUIDNC_VERSION.search(note)
    if fluidnc is not None:
        # FluidNC's "Grbl 3.7" is a compatibility number; its own version is inside the brackets.
        return Banner("fluidnc", fluidnc.group(1), text)
    # grblHAL's compatibility banner still names '$HELP'; a bare "Grbl 1.1f ['$' for help]" cannot
    # be told from classic Grbl here, so the handshake refines it from `$I` when it can.
    if name.lower() == "grblhal" or "$HELP" in note:
        return Banner("grblhal", version, text)
    return Banner("grbl", version, text)
