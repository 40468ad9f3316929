"""Tests for core/responses.py: every form of firmware-facts §5.3, §5.4 and §7, and that it never
raises."""

from __future__ import annotations

from typing import get_args

import pytest
from hypothesis import given
from hypothesis import strategies as st

from smoothjog.core.responses import (
    OPTION_CODES,
    AlarmReply,
    Banner,
    BuildOptions,
    Empty,
    ErrorReply,
    Feedback,
    GcodeModes,
    HelpReply,
    Message,
    NamedSetting,
    Ok,
    Parameter,
    Response,
    SettingLine,
    StartupLineResult,
    StatusReport,
    Unparsed,
    VersionInfo,
    parse_response,
)

_HELP_WORDS = (
    "$$", "$#", "$G", "$I", "$N", "$x=val", "$Nx=line", "$J=line",
    "$SLP", "$C", "$X", "$H", "~", "!", "?", "ctrl-x",
)  # fmt: skip


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        (b"ok\r\n", Ok()),
        (b"ok\n", Ok()),
        (b"ok\r", Ok()),
        ("ok", Ok()),
        (b"error:22\r\n", ErrorReply(22)),
        (b"error:9", ErrorReply(9)),
        (b"ALARM:2\r\n", AlarmReply(2)),
        (b"ALARM:10", AlarmReply(10)),
        (b"\r\n", Empty()),
        (b"", Empty()),
        (b"[MSG:Reset to continue]\r\n", Message("Reset to continue")),
        (b"[MSG:'$H'|'$X' to unlock]", Message("'$H'|'$X' to unlock")),
        (b"[MSG:Caution: Unlocked]", Message("Caution: Unlocked")),
        (b"[echo:G1X0.540Y10.4F100]", Feedback("echo:G1X0.540Y10.4F100")),
        (b"[FIRMWARE:grblHAL]", Feedback("FIRMWARE:grblHAL")),
        (b"[no colon here]", Feedback("no colon here")),
        (b">G54G20:ok\r\n", StartupLineResult("G54G20", ok=True, error=None)),
        (b">G54G20:error:20", StartupLineResult("G54G20", ok=False, error=20)),
        (b">:ok", StartupLineResult("", ok=True, error=None)),
        (
            b"[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]",
            HelpReply(_HELP_WORDS),
        ),
    ],
)
def test_simple_forms(line: bytes | str, expected: Response) -> None:
    """Replies, alarms, messages, feedback and startup-line results parse to their types."""
    assert parse_response(line) == expected


@pytest.mark.parametrize(
    ("line", "firmware", "version"),
    [
        ("Grbl 1.1h ['$' for help]", "grbl", "1.1h"),
        ("Grbl 1.1f ['$' for help]", "grbl", "1.1f"),
        ("GrblHAL 1.1f ['$' or '$HELP' for help]", "grblhal", "1.1f"),
        ("Grbl 1.1f ['$' or '$HELP' for help]", "grblhal", "1.1f"),
        ("Grbl 3.7 [FluidNC v3.7.8 (esp32-wifi) '$' for help]", "fluidnc", "3.7.8"),
        ("Grbl 3.6 [FluidNC v3.6.5 (noradio) '$' for help]", "fluidnc", "3.6.5"),
    ],
)
def test_banners(line: str, firmware: str, version: str) -> None:
    """The three firmwares' welcome lines name the firmware and its own version (firmware-facts
    §5.3, §7)."""
    parsed = parse_response(line.encode() + b"\r\n")
    assert parsed == Banner(firmware, version, line)  # type: ignore[arg-type]


def test_grbl_settings_list_from_facts() -> None:
    """The whole `$$` list of a default 1.1h build parses, numbers as floats (firmware-facts §0,
    §5.3)."""
    listing = {
        0: "10", 1: "25", 2: "0", 3: "0", 4: "0", 5: "0", 6: "0", 10: "1", 11: "0.010",
        12: "0.002", 13: "0", 20: "0", 21: "0", 22: "0", 23: "0", 24: "25.000",
        25: "500.000", 26: "250", 27: "1.000", 30: "1000", 31: "0", 32: "0",
        100: "250.000", 101: "250.000", 102: "250.000", 110: "500.000", 111: "500.000",
        112: "500.000", 120: "10.000", 121: "10.000", 122: "10.000", 130: "200.000",
        131: "200.000", 132: "200.000",
    }  # fmt: skip
    for number, text in listing.items():
        parsed = parse_response(f"${number}={text}\r\n".encode())
        assert parsed == SettingLine(number, float(text), text)


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ("$110=5000.000", SettingLine(110, 5000.0, "5000.000")),
        ("$70=192.168.5.1", SettingLine(70, None, "192.168.5.1")),
        ("$340=", SettingLine(340, None, "")),
        ("$Config/Filename=config.yaml", NamedSetting("Config/Filename", "config.yaml")),
        ("$N0=G54G20", NamedSetting("N0", "G54G20")),
    ],
)
def test_settings_variants(line: str, expected: Response) -> None:
    """Non-numeric values keep their text; named settings (FluidNC, `$N`) are kept too."""
    assert parse_response(line) == expected


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ("[G54:0.000,0.000,306.351]", Parameter("G54", (0.0, 0.0, 306.351), None)),
        ("[G59:-1.000,2.500,0.000]", Parameter("G59", (-1.0, 2.5, 0.0), None)),
        ("[G28:0.000,-10.225,0.000]", Parameter("G28", (0.0, -10.225, 0.0), None)),
        ("[G30:1.000,2.000,3.000]", Parameter("G30", (1.0, 2.0, 3.0), None)),
        ("[G92:0.000,0.000,0.000]", Parameter("G92", (0.0, 0.0, 0.0), None)),
        ("[G59.3:1.000,2.000,3.000,4.000]", Parameter("G59.3", (1.0, 2.0, 3.0, 4.0), None)),
        ("[TLO:120.000]", Parameter("TLO", (120.0,), None)),
        ("[PRB:0.000,0.000,1.492:1]", Parameter("PRB", (0.0, 0.0, 1.492), True)),
        ("[PRB:0.000,0.000,0.000:0]", Parameter("PRB", (0.0, 0.0, 0.0), False)),
    ],
)
def test_ngc_parameters(line: str, expected: Parameter) -> None:
    """`$#` lines give the name, the values and, for PRB, the success flag."""
    assert parse_response(line + "\r\n") == expected


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ("[VER:1.1h.20190830:]", VersionInfo("1.1h", "20190830", "")),
        ("[VER:1.1h.20190830:my mill: left]", VersionInfo("1.1h", "20190830", "my mill: left")),
        (
            "[VER:1.1f(STM32F4xx).20220314:]",
            VersionInfo("1.1f(STM32F4xx)", "20220314", ""),
        ),
        ("[VER:3.7 FluidNC v3.7.8:]", VersionInfo("3.7 FluidNC v3.7.8", "", "")),
        ("[OPT:V,15,128]", BuildOptions("V", 15, 128, ())),
        ("[OPT:VZL,15,128]", BuildOptions("VZL", 15, 128, ())),
        ("[OPT:VNMSL,35,1024,3,0]", BuildOptions("VNMSL", 35, 1024, ("3", "0"))),
        ("[OPT:PH]", BuildOptions("PH", None, None, ())),
    ],
)
def test_build_info(line: str, expected: Response) -> None:
    """`$I` lines: version, build date, user string, option letters, planner and RX sizes."""
    assert parse_response(line) == expected


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        # Grbl 1.1h with a door pin and the EEPROM restore commands compiled out (report.c
        # report_build_info: `+` for ENABLE_SAFETY_DOOR_INPUT_PIN, `*`, `$`, `#` when disabled).
        ("[OPT:VZL+*$#,15,128]", BuildOptions("VZL+*$#", 15, 128, ())),
        # Every letter Grbl 1.1h can print, in its order, digits `0` and `2` included.
        ("[OPT:VNMCPZHTAD0SRL+*$#IEW2,15,128]",
         BuildOptions("VNMCPZHTAD0SRL+*$#IEW2", 15, 128, ())),
        # grblHAL: a 35-block planner behind punctuation, then N_AXIS and N_TOOLS.
        ("[OPT:VNMSL+*$#W2,35,1024,3,0]", BuildOptions("VNMSL+*$#W2", 35, 1024, ("3", "0"))),
        # FluidNC prints letters only, no sizes.
        ("[OPT:MPHABSREW]", BuildOptions("MPHABSREW", None, None, ())),
        # A letter nobody documents yet still leaves the sizes readable.
        ("[OPT:V%,35,1024]", BuildOptions("V%", 35, 1024, ())),
        ("[OPT:,15,128]", BuildOptions("", 15, 128, ())),
    ],
)  # fmt: skip
def test_option_punctuation_is_kept_and_the_sizes_still_read(
    line: str, expected: BuildOptions
) -> None:
    """`+ * $ #` and digits are option letters too; they never cost the planner size."""
    assert parse_response(line) == expected


def test_every_documented_option_letter_parses() -> None:
    """One `[OPT:]` holding every letter of the table parses with the sizes intact."""
    codes = "".join(OPTION_CODES)
    assert set("+*$#02") <= set(codes)
    assert parse_response(f"[OPT:{codes},35,1024]") == BuildOptions(codes, 35, 1024, ())


@pytest.mark.parametrize("codes", ["V N", "V\u00e9", "V\u2603Z"])
def test_option_letters_that_no_firmware_prints_are_noise(codes: str) -> None:
    """Spaces or non-ASCII in the letters are line noise: Unparsed, never a guessed size."""
    assert isinstance(parse_response(f"[OPT:{codes},15,128]"), Unparsed)


def test_gcode_modes() -> None:
    """`[GC:...]` keeps the G/M words in order and pulls out T, F and S (firmware-facts §5.3)."""
    line = "[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]"
    assert parse_response(line) == GcodeModes(
        ("G0", "G54", "G17", "G21", "G90", "G94", "M5", "M9"), 0.0, 0.0, 0, line
    )
    inch = parse_response("[GC:G1 G55 G17 G20 G91 G94 M0 M3 M8 T4 F39.4 S12000]")
    assert isinstance(inch, GcodeModes)
    assert inch.words[-3:] == ("M0", "M3", "M8")
    assert (inch.feed, inch.spindle_speed, inch.tool) == (39.4, 12000.0, 4)


def _status(line: str) -> StatusReport:
    """Parse a line that must be a status report."""
    parsed = parse_response(line + "\r\n")
    assert isinstance(parsed, StatusReport), parsed
    return parsed


def test_full_status_report_in_grbl_order() -> None:
    """Every 1.1h field in its fixed order lands in its own attribute (firmware-facts §5.4)."""
    line = (
        "<Jog|MPos:-1.000,2.500,-0.000|Bf:14,128|Ln:7|FS:500,0|Pn:XZP"
        "|WCO:1.000,2.000,3.000|Ov:100,50,120|A:SF>"
    )
    report = _status(line)
    assert report == StatusReport(
        state="Jog",
        substate=None,
        mpos=(-1.0, 2.5, -0.0),
        wpos=None,
        buffer=(14, 128),
        line_number=7,
        feed=500.0,
        spindle_speed=0.0,
        pins="XZP",
        wco=(1.0, 2.0, 3.0),
        overrides=(100, 50, 120),
        accessories="SF",
        raw=line,
        extras=(),
    )


def test_status_fields_in_any_order() -> None:
    """Reordering the fields gives the same report apart from the raw text (the docs allow it)."""
    fields = [
        "MPos:1.000,2.000,3.000",
        "Bf:15,128",
        "FS:0,0",
        "WCO:0.000,0.000,0.000",
        "Ov:100,100,100",
    ]
    forward = _status("<Idle|" + "|".join(fields) + ">")
    backward = _status("<Idle|" + "|".join(reversed(fields)) + ">")
    assert forward.mpos == backward.mpos == (1.0, 2.0, 3.0)
    assert forward.buffer == backward.buffer == (15, 128)
    assert forward.wco == backward.wco
    assert forward.overrides == backward.overrides == (100, 100, 100)
    assert forward.feed == backward.feed == 0.0


@pytest.mark.parametrize(
    ("state_text", "state", "substate"),
    [
        ("Idle", "Idle", None),
        ("Run", "Run", None),
        ("Jog", "Jog", None),
        ("Home", "Home", None),
        ("Alarm", "Alarm", None),
        ("Check", "Check", None),
        ("Sleep", "Sleep", None),
        ("Hold:0", "Hold", 0),
        ("Hold:1", "Hold", 1),
        ("Door:0", "Door", 0),
        ("Door:1", "Door", 1),
        ("Door:2", "Door", 2),
        ("Door:3", "Door", 3),
        ("Tool", "Tool", None),
    ],
)
def test_status_states(state_text: str, state: str, substate: int | None) -> None:
    """The state word and its substate number are split (firmware-facts §5.4)."""
    report = _status(f"<{state_text}|MPos:0.000,0.000,0.000|FS:0,0>")
    assert (report.state, report.substate) == (state, substate)


@pytest.mark.parametrize(
    ("line", "mpos", "wpos", "feed", "spindle"),
    [
        ("<Idle|WPos:-0.000,1.000,2.000|FS:0,0>", None, (-0.0, 1.0, 2.0), 0.0, 0.0),
        ("<Idle|MPos:0.0394,-1.0000,0.0001|FS:39.4,0>", (0.0394, -1.0, 0.0001), None, 39.4, 0.0),
        ("<Jog|MPos:1.000,2.000,3.000|F:300>", (1.0, 2.0, 3.0), None, 300.0, None),
        (
            "<Idle|MPos:1.000,2.000,3.000,4.000|FS:0,0>",
            (1.0, 2.0, 3.0, 4.0),
            None,
            0.0,
            0.0,
        ),
        (
            "<Idle|MPos:1.000,2.000,3.000,4.000,5.000|FS:0,0>",
            (1.0, 2.0, 3.0, 4.0, 5.0),
            None,
            0.0,
            0.0,
        ),
        (
            "<Idle|MPos:1.000,2.000,3.000,4.000,5.000,6.000|FS:0,0>",
            (1.0, 2.0, 3.0, 4.0, 5.0, 6.0),
            None,
            0.0,
            0.0,
        ),
        ("<Run|MPos:0.000,0.000,0.000|FS:1200,8000,7990>", (0.0, 0.0, 0.0), None, 1200.0, 8000.0),
    ],
)
def test_status_positions_and_feed(
    line: str,
    mpos: tuple[float, ...] | None,
    wpos: tuple[float, ...] | None,
    feed: float,
    spindle: float | None,
) -> None:
    """WPos or MPos, `-0.000`, 4-decimal inch values, F or FS, and 3 to 6 axes."""
    report = _status(line)
    assert report.mpos == mpos
    assert report.wpos == wpos
    assert report.feed == feed
    assert report.spindle_speed == spindle


def test_negative_zero_keeps_its_sign_but_equals_zero() -> None:
    """`-0.000` is a zero (rounding keeps the sign, firmware-facts §5.4)."""
    report = _status("<Idle|MPos:-0.000,0.000,0.000>")
    assert report.mpos is not None
    assert report.mpos[0] == 0.0


def test_status_unknown_fields_survive() -> None:
    """grblHAL and FluidNC extras (`H:`, `MPG:`, `T:`, bare words) are kept as pairs."""
    report = _status("<Idle|MPos:0.000,0.000,0.000|H:1,7|MPG:0|T:3|SD:4.5,file.nc|Sync>")
    assert report.extras == (
        ("H", "1,7"),
        ("MPG", "0"),
        ("T", "3"),
        ("SD", "4.5,file.nc"),
        ("Sync", ""),
    )


@pytest.mark.parametrize(
    ("line", "reason_part"),
    [
        (b"<Idle|MPos:0.000,0.0", "truncated"),
        (b"<Idle|MPos:0.000,abc,0.000>", "MPos"),
        (b"<Idle|MPos:1e3,0,0>", "MPos"),
        (b"<Idle|MPos:nan,0,0>", "MPos"),
        (b"<Idle|Bf:15>", "Bf"),
        (b"<Idle|Ov:100,100>", "Ov"),
        (b"<Idle|Ln:x>", "Ln"),
        (b"<Idle|MPos>", "no value"),
        (b"<Id#le|MPos:0,0,0>", "state"),
        (b"<>", "truncated"),
        (b"<Idle|MPos:1,2,3,4,5,6,7,8,9,10>", "MPos"),
        # A byte lost or flipped on the wire: the firmware prints every coordinate with its
        # decimal point and the same decimals (the noise fuzz's `-406075` for `-406.075`).
        (b"<Idle|MPos:-406075,-364.900,-14.750|FS:0,0>", "decimals"),
        (b"<Idle|MPos:-406.075,-364.900,-14.75|FS:0,0>", "decimals"),
        (b"<Idle|MPos:-406.075,-364.900,-14.750|FS:0,0|WCO:0.000,0.00,0.000>", "decimals"),
        (b"<Idle|WPos:1.000,2.000,3>", "decimals"),
        (b"[MSG:Reset to cont", "truncated"),
        (b"[GC:G0 G54 X1]", "GC"),
        (b"[PRB:0.000,0.000,1.492]", "PRB"),
        (b"[OPT:V,fifteen,128]", "OPT"),
        (b"error:", "error code"),
        (b"error:Bad number format", "error code"),
        (b"ALARM:x", "alarm code"),
        (b">G54G20", "startup"),
        (b"$", "name=value"),
        (b"o\x00k", "control byte"),
        (b"ok\r\n\r\n", "control byte"),
        (b"\xffGrbl 1.1h ['$' for help]", "UTF-8"),
        (b"ok\xc3", "UTF-8"),
        (b"Grbl 1.1h ['$' for he", "unrecognised"),
        (b"hello", "unrecognised"),
    ],
)
def test_garbled_lines_are_unparsed(line: bytes, reason_part: str) -> None:
    """Truncated, garbled and non-UTF-8 lines give Unparsed with the raw bytes and a reason."""
    parsed = parse_response(line)
    assert isinstance(parsed, Unparsed), parsed
    assert parsed.raw == line
    assert reason_part in parsed.reason


def test_str_input_is_kept_as_bytes_in_unparsed() -> None:
    """A str line that fails still reports its bytes, UTF-8 encoded."""
    assert parse_response("hé") == Unparsed("hé".encode(), "unrecognised line")


@given(st.binary(max_size=200))
def test_never_raises_on_bytes(data: bytes) -> None:
    """Any bytes at all give a Response (the contract the links rely on)."""
    parsed = parse_response(data)
    assert isinstance(parsed, get_args(Response))
    # The catch-all in parse_response is a belt; the parser itself must not have needed it.
    assert not (isinstance(parsed, Unparsed) and parsed.reason.startswith("parser fault"))


_FRAGMENTS = st.sampled_from(
    ["<", ">", "[", "]", "|", ":", ",", "$", "=", "ok", "error:", "ALARM:", "MPos", "WCO",
     "FS", "Bf", "Ov", "Hold", "PRB", "GC", "VER", "OPT", "Grbl ", "1.1h", "-0.000", "12", "\r\n"]
)  # fmt: skip


@given(st.lists(_FRAGMENTS, max_size=20).map("".join))
def test_never_raises_on_near_miss_text(text: str) -> None:
    """Text built from protocol fragments (the likely garbles) never raises either."""
    parsed = parse_response(text)
    assert not (isinstance(parsed, Unparsed) and parsed.reason.startswith("parser fault"))
    assert parse_response(text.encode()) == parsed
