"""Tests for core/machine.py: settings, mm positions, WCO, envelope, unhomed, resets, keep-outs."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from smoothjog.core.errors import ConfigError, CoreError
from smoothjog.core.gcode import TravelBox
from smoothjog.core.machine import KeepOut, MachineModel, Settings
from smoothjog.core.responses import parse_response

# The `$$` listing of a default Grbl 1.1h build (firmware-facts §0, §5.3).
DEFAULT_LISTING = """\
$0=10
$1=25
$2=0
$3=0
$4=0
$5=0
$6=0
$10=1
$11=0.010
$12=0.002
$13=0
$20=0
$21=0
$22=0
$23=0
$24=25.000
$25=500.000
$26=250
$27=1.000
$30=1000
$31=0
$32=0
$100=250.000
$101=250.000
$102=250.000
$110=500.000
$111=500.000
$112=500.000
$120=10.000
$121=10.000
$122=10.000
$130=200.000
$131=200.000
$132=200.000
"""


def feed(model: MachineModel, *lines: str) -> MachineModel:
    """Apply each line, parsed as the link would hand it over, and return the model."""
    for line in lines:
        model.apply(parse_response(line.encode() + b"\r\n"))
    return model


def soft_limited(*extra: str) -> MachineModel:
    """A model with homing and soft limits on and the given further lines applied."""
    return feed(MachineModel(), "$22=1", "$20=1", *extra)


def test_defaults_before_anything_is_known() -> None:
    """An empty model answers with Grbl 1.1h defaults (firmware-facts §0, §4.1, §5.1)."""
    model = MachineModel()
    assert model.n_axes == 3
    assert model.axis_letters == ("X", "Y", "Z")
    assert model.planner_blocks == 15
    assert model.planner_usable_blocks == 15
    assert model.rx_buffer_bytes == 128
    assert model.axis_max_rate_mm_min() == (500.0, 500.0, 500.0)
    assert model.axis_accel_mm_s2() == (10.0, 10.0, 10.0)
    assert model.steps_per_mm() == (250.0, 250.0, 250.0)
    assert model.soft_limit_envelope() is None


def test_settings_from_the_default_listing() -> None:
    """Every setting the host needs is typed from the facts' `$$` listing."""
    model = feed(MachineModel(), *DEFAULT_LISTING.splitlines())
    s = model.settings
    assert (s.status_mask, s.junction_deviation_mm, s.report_inches) == (1, 0.010, False)
    assert (s.soft_limits, s.hard_limits, s.homing, s.homing_dir_mask) == (False,) * 3 + (0,)
    assert s.pull_off_mm == 1.0
    assert s.raw_value(24) == "25.000"
    assert s.raw_value(99) is None
    assert len(s.raw) == 34


def test_settings_for_more_axes_and_extras() -> None:
    """A 5-axis grblHAL listing gives 5-axis tuples; non-numeric extras stay raw only."""
    groups = ((100, 80), (110, 3000), (120, 200))
    lines = [f"${base + i}={value + i}" for base, value in groups for i in range(5)]
    lines += ["$130=300", "$70=192.168.5.1", "$Config/Filename=mill.yaml"]
    model = feed(MachineModel(), *lines)
    assert model.n_axes == 5
    assert model.axis_letters == ("X", "Y", "Z", "A", "B")
    assert model.steps_per_mm() == (80.0, 81.0, 82.0, 83.0, 84.0)
    assert model.axis_max_rate_mm_min() == (3000.0, 3001.0, 3002.0, 3003.0, 3004.0)
    assert model.axis_accel_mm_s2() == (200.0, 201.0, 202.0, 203.0, 204.0)
    # Only $130 was given: the other axes keep the 200 mm default.
    assert model.settings.max_travel_mm == (300.0, 200.0, 200.0, 200.0, 200.0)
    assert model.settings.raw_value(70) == "192.168.5.1"
    assert model.settings.named == (("Config/Filename", "mill.yaml"),)


def test_a_later_setting_line_replaces_the_earlier() -> None:
    """`$110=...` after a change overrides the old value."""
    model = feed(MachineModel(), "$110=500.000", "$110=4000.000")
    assert model.axis_max_rate_mm_min()[0] == 4000.0


def test_settings_from_raw_skips_non_numbers() -> None:
    """A non-numeric or non-finite value for a known setting keeps the default."""
    settings = Settings.from_raw({110: "fast", 111: "nan", 112: "700"})
    assert settings.max_rate_mm_min == (500.0, 500.0, 700.0)


@pytest.mark.parametrize(
    ("firmware_banner", "opt", "blocks", "usable", "rx"),
    [
        ("Grbl 1.1h ['$' for help]", None, 15, 15, 128),
        ("GrblHAL 1.1f ['$' or '$HELP' for help]", None, 15, 15, 1024),
        ("Grbl 3.7 [FluidNC v3.7.8 (esp32-wifi) '$' for help]", None, 16, 15, 256),
        ("Grbl 1.1h ['$' for help]", "[OPT:V,15,128]", 15, 15, 128),
        ("GrblHAL 1.1f ['$' or '$HELP' for help]", "[OPT:VNMSL,35,1024,3,0]", 35, 35, 1024),
        ("Grbl 3.7 [FluidNC v3.7.8 (esp32-wifi) '$' for help]", "[OPT:PH,32,256]", 32, 31, 256),
    ],
)
def test_planner_and_rx_sizes(
    firmware_banner: str, opt: str | None, blocks: int, usable: int, rx: int
) -> None:
    """[OPT:] wins; unknown, the smallest usable planner of any family (15) is assumed; FluidNC
    can fill blocks - 1 (firmware-facts §7)."""
    model = feed(MachineModel(), "", firmware_banner, *([opt] if opt else []))
    assert (model.planner_blocks, model.planner_usable_blocks, model.rx_buffer_bytes) == (
        blocks,
        usable,
        rx,
    )


def test_larger_bf_seen_raises_usable_blocks() -> None:
    """A report's Bf is ground truth for the usable planner depth."""
    model = feed(MachineModel(), "<Idle|MPos:0.000,0.000,0.000|Bf:20,128>")
    assert model.planner_usable_blocks == 20
    assert model.buffer == (20, 128)


GRBLHAL_BANNER = "GrblHAL 1.1f ['$' or '$HELP' for help]"


@pytest.mark.parametrize(
    ("opt", "blocks"),
    [
        ("[OPT:VNMSL+*$#W2,35,1024,3,0]", 35),
        ("[OPT:VNMZHL+,35,1024,3,0]", 35),
        ("[OPT:V0S2,50,1024,5,0]", 50),
    ],
)
def test_planner_size_comes_from_opt_whatever_the_letters(opt: str, blocks: int) -> None:
    """A grblHAL `[OPT:]` with `+ * $ #` or digits still sets the planner size (not 100)."""
    model = feed(MachineModel(), "", GRBLHAL_BANNER, "[VER:1.1f.20240101:]", opt)
    assert (model.planner_blocks, model.planner_usable_blocks) == (blocks, blocks)


@pytest.mark.parametrize(
    "banner",
    [
        None,
        "Grbl 1.1h ['$' for help]",
        GRBLHAL_BANNER,
        "Grbl 3.7 [FluidNC v3.7.8 (x) '$' for help]",
    ],
)
def test_unknown_planner_size_assumes_the_smallest(banner: str | None) -> None:
    """No `[OPT:]` size and no Bf: the smallest usable planner of the table, never the largest."""
    model = feed(MachineModel(), *(["", banner] if banner else []), "[OPT:MPHABSREW]")
    assert model.planner_usable_blocks == 15


@pytest.mark.parametrize(
    ("reports", "usable"),
    [
        # Idle with an empty planner shows every usable block: it lowers [OPT:]'s 35 ...
        (["<Idle|MPos:0.000,0.000,0.000|Bf:34,1024>"], 34),
        # ... and raises it.
        (["<Idle|MPos:0.000,0.000,0.000|Bf:40,1024>"], 40),
        # The largest Idle value wins: a momentary lower one does not undo it.
        (
            [
                "<Idle|MPos:0.000,0.000,0.000|Bf:34,1024>",
                "<Idle|MPos:0.000,0.000,0.000|Bf:30,1024>",
            ],
            34,
        ),
        (
            [
                "<Idle|MPos:0.000,0.000,0.000|Bf:30,1024>",
                "<Idle|MPos:0.000,0.000,0.000|Bf:34,1024>",
            ],
            34,
        ),
        # Outside Idle the planner may hold blocks: such a Bf says nothing about its size.
        (
            [
                "<Jog|MPos:0.000,0.000,0.000|Bf:10,1024>",
                "<Hold:0|MPos:0.000,0.000,0.000|Bf:2,1024>",
            ],
            35,
        ),
        (["<Run|MPos:0.000,0.000,0.000|Bf:36,1024>"], 35),
    ],
)
def test_idle_bf_sets_the_usable_blocks(reports: list[str], usable: int) -> None:
    """The largest Bf free-block count seen in Idle is the usable planner (firmware-facts §4.4)."""
    model = feed(MachineModel(), "", GRBLHAL_BANNER, "[OPT:VNMSL+,35,1024,3,0]", *reports)
    assert model.planner_usable_blocks == usable


def test_a_reboot_forgets_the_idle_bf() -> None:
    """After a banner the planner may have been resized ($398 takes effect on reboot, §7)."""
    model = feed(MachineModel(), "", GRBLHAL_BANNER, "[OPT:VNMSL,35,1024]", "ok")
    feed(model, "<Idle|MPos:0.000,0.000,0.000|Bf:40,1024>")
    assert model.planner_usable_blocks == 40
    feed(model, "", GRBLHAL_BANNER)
    assert model.planner_usable_blocks == 35
    feed(model, "<Idle|MPos:0.000,0.000,0.000|Bf:30,1024>")
    assert model.planner_usable_blocks == 30


@pytest.mark.parametrize("opt", ["[OPT:VZL+,15,128]", "[OPT:VNMZL+*$#W2,35,1024,3,0]"])
def test_force_origin_with_punctuation_letters(opt: str) -> None:
    """`Z` among `+ * $ #`: the envelope is 0..+travel on $23 axes and a homed machine at MPos 0
    is not taken for an unhomed one (firmware-facts §2)."""
    model = soft_limited("$23=7", "$130=200", "$131=300", "$132=100", opt)
    assert model.homing_force_set_origin
    assert model.soft_limit_envelope() == TravelBox((0.0, 0.0, 0.0), (200.0, 300.0, 100.0))
    feed(model, "<Idle|MPos:0.000,0.000,0.000|FS:0,0>")
    assert not model.looks_unhomed()


def test_firmware_version_and_options_from_banner_and_i() -> None:
    """Banner, `$I` and the force-origin option letter are recorded."""
    model = feed(
        MachineModel(),
        "",
        "Grbl 1.1h ['$' for help]",
        "[VER:1.1h.20190830:shop]",
        "[OPT:VZL,15,128]",
    )
    assert (model.firmware, model.version, model.build) == ("grbl", "1.1h", "20190830")
    assert model.option_codes == "VZL"
    assert model.homing_force_set_origin
    assert not feed(MachineModel(), "[OPT:V,15,128]").homing_force_set_origin


def test_grblhal_compat_banner_is_refined_by_firmware_line() -> None:
    """grblHAL's `[FIRMWARE:grblHAL]` corrects a plain "Grbl 1.1f" banner."""
    model = feed(MachineModel(), "Grbl 1.1f ['$' for help]")
    before = model.firmware
    feed(model, "[VER:1.1f.20220314:]", "[FIRMWARE:grblHAL]")
    assert (before, model.firmware) == ("grbl", "grblhal")
    assert model.rx_buffer_bytes == 1024


def test_status_with_mpos_and_wco_derives_wpos() -> None:
    """WPos = MPos - WCO (firmware-facts §5.4)."""
    model = feed(
        MachineModel(), "<Idle|MPos:-10.000,-20.000,-5.000|FS:0,0|WCO:-1.000,-2.000,-3.000>"
    )
    assert model.mpos_mm == (-10.0, -20.0, -5.0)
    assert model.wco_mm == (-1.0, -2.0, -3.0)
    assert model.wpos_mm == (-9.0, -18.0, -2.0)


def test_wco_is_kept_across_reports() -> None:
    """Reports without WCO still get WPos from the last WCO received."""
    model = feed(
        MachineModel(),
        "<Idle|MPos:0.000,0.000,0.000|FS:0,0|WCO:5.000,6.000,7.000>",
        "<Jog|MPos:1.000,1.000,1.000|FS:300,0>",
        "<Jog|MPos:2.000,2.000,2.000|FS:300,0|Ov:100,100,100>",
    )
    assert model.state == "Jog"
    assert model.wpos_mm == (-3.0, -4.0, -5.0)


def test_wpos_report_derives_mpos() -> None:
    """With $10=0 the report carries WPos; MPos = WPos + WCO."""
    model = feed(
        MachineModel(),
        "$10=0",
        "<Idle|WPos:1.000,2.000,3.000|FS:0,0|WCO:10.000,10.000,10.000>",
        "<Idle|WPos:0.500,2.000,3.000|FS:0,0>",
    )
    assert model.wpos_mm == (0.5, 2.0, 3.0)
    assert model.mpos_mm == (10.5, 12.0, 13.0)


def test_without_wco_the_other_frame_is_unknown() -> None:
    """No WCO yet: the frame not reported stays None rather than guessed."""
    model = feed(MachineModel(), "<Idle|MPos:1.000,2.000,3.000|FS:0,0>")
    assert model.mpos_mm == (1.0, 2.0, 3.0)
    assert model.wpos_mm is None
    model = feed(MachineModel(), "<Idle|WPos:1.000,2.000,3.000|FS:0,0>")
    assert model.mpos_mm is None


def test_inch_reports_are_held_in_mm() -> None:
    """$13=1 reports inches with 4 decimals; the model converts positions, WCO and feed (§5.5)."""
    model = feed(
        MachineModel(),
        "$13=1",
        "<Jog|MPos:1.0000,-0.5000,-0.0000|FS:39.4,0|WCO:0.1000,0.0000,0.0000>",
    )
    assert model.mpos_mm == pytest.approx((25.4, -12.7, 0.0))
    assert model.wco_mm == pytest.approx((2.54, 0.0, 0.0))
    assert model.wpos_mm == pytest.approx((22.86, -12.7, 0.0))
    assert model.feed_mm_min == pytest.approx(1000.76)
    feed(model, "[GC:G0 G54 G17 G20 G91 G94 M5 M9 T2 F10.0 S0]", "[G54:1.0000,0.0000,0.0000]")
    assert model.modal.feed_mm_min == pytest.approx(254.0)
    assert model.modal.units == "G20"
    assert model.offsets_mm["G54"] == pytest.approx((25.4, 0.0, 0.0))


def test_negative_zero_becomes_plain_zero() -> None:
    """`-0.000` is stored as 0.0 so printing it never shows a minus sign."""
    model = feed(MachineModel(), "<Idle|MPos:-0.000,0.000,-0.000|FS:0,0>")
    assert model.mpos_mm is not None
    assert [str(c) for c in model.mpos_mm] == ["0.0", "0.0", "0.0"]


@pytest.mark.parametrize("n_axes", [4, 5, 6])
def test_more_axes_in_reports(n_axes: int) -> None:
    """A 4-6 axis report sets the axis count and letters."""
    values = ",".join(f"{i}.000" for i in range(n_axes))
    model = feed(MachineModel(), f"<Idle|MPos:{values}|FS:0,0|WCO:{values}>")
    assert model.n_axes == n_axes
    assert model.axis_letters == ("X", "Y", "Z", "A", "B", "C")[:n_axes]
    assert model.wpos_mm == (0.0,) * n_axes
    assert len(model.axis_max_rate_mm_min()) == n_axes


def test_status_fields_update_the_model() -> None:
    """State, substate, feed, Bf, Ln, pins, overrides and accessories are kept."""
    model = feed(
        MachineModel(),
        "<Hold:1|MPos:0.000,0.000,0.000|Bf:3,100|Ln:12|FS:800,1000|Pn:XP|Ov:120,50,90|A:SM>",
    )
    assert (model.state, model.substate) == ("Hold", 1)
    assert (model.feed_mm_min, model.spindle_rpm, model.buffer) == (800.0, 1000.0, (3, 100))
    assert (model.line_number, model.pins) == (12, "XP")
    assert (model.overrides, model.accessories) == ((120, 50, 90), "SM")
    feed(model, "<Door:2|MPos:0.000,0.000,0.000|FS:0,0>")
    assert (model.state, model.substate, model.pins) == ("Door", 2, "")
    assert (model.overrides, model.accessories) == ((120, 50, 90), "SM")
    feed(model, "<Idle|MPos:0.000,0.000,0.000|FS:0,0|Ov:100,100,100>")
    assert (model.overrides, model.accessories) == ((100, 100, 100), "")


def test_modal_state_from_gc() -> None:
    """Units, distance, WCS, feed and tool come from `[GC:]`."""
    model = feed(MachineModel(), "[GC:G1 G56 G17 G21 G91 G94 M3 M9 T4 F1500 S9000]")
    m = model.modal
    assert (m.units, m.distance, m.wcs, m.feed_mm_min, m.tool) == ("G21", "G91", "G56", 1500.0, 4)


def test_ngc_parameters_and_probe() -> None:
    """`$#` lines are stored by name; PRB records success."""
    model = feed(
        MachineModel(),
        "[G54:1.000,2.000,3.000]",
        "[G92:0.500,0.000,0.000]",
        "[TLO:12.000]",
        "[PRB:1.000,2.000,-3.000:1]",
    )
    assert model.offsets_mm["G54"] == (1.0, 2.0, 3.0)
    assert model.offsets_mm["TLO"] == (12.0,)
    assert model.offsets_mm["PRB"] == (1.0, 2.0, -3.0)
    assert model.probe_ok is True


def test_alarm_error_and_message_are_remembered() -> None:
    """ALARM:N also sets the state to Alarm; error and message are kept for the user."""
    model = feed(MachineModel(), "<Jog|MPos:0.000,0.000,0.000|FS:100,0>", "error:15", "ALARM:3")
    assert (model.last_error, model.last_alarm, model.state) == (15, 3, "Alarm")
    feed(model, "[MSG:Reset to continue]")
    assert model.last_message == "Reset to continue"


def test_power_up_banner_is_not_a_reset() -> None:
    """The blank line, boot chatter and the first banner are a power-up, not a reset."""
    model = feed(MachineModel(), "", "[MSG:INFO: booting]", "Grbl 1.1h ['$' for help]")
    assert model.reset_count == 0


def test_mid_session_banner_bumps_reset_count_and_wipes_state() -> None:
    """A banner after replies is a reset: state unknown, parser defaults, G92/TLO cleared (§3.4)."""
    model = feed(
        MachineModel(),
        "",
        "Grbl 1.1h ['$' for help]",
        "[GC:G0 G55 G17 G20 G91 G94 M5 M9 T0 F0 S0]",
        "[G92:1.000,0.000,0.000]",
        "[TLO:5.000]",
        "ok",
        "<Jog|MPos:-3.000,-2.000,-1.000|FS:500,0|WCO:1.000,0.000,5.000|Ov:150,100,100>",
        "ALARM:3",
        "ok",
        "",
        "Grbl 1.1h ['$' for help]",
    )
    assert model.reset_count == 1
    assert model.state is None
    assert model.mpos_mm == (-3.0, -2.0, -1.0)  # MPos survives a reset
    assert model.wco_mm is None
    assert model.wpos_mm is None
    assert model.overrides == (100, 100, 100)
    assert (model.modal.units, model.modal.distance, model.modal.wcs) == ("G21", "G90", "G54")
    assert model.offsets_mm["G92"] == (0.0, 0.0, 0.0)
    assert model.offsets_mm["TLO"] == (0.0,)
    assert model.last_alarm == 3
    # A second reset counts again; the banner alone does not count twice.
    feed(model, "<Alarm|MPos:-3.000,-2.000,-1.000|FS:0,0>", "Grbl 1.1h ['$' for help]")
    assert model.reset_count == 2


# Envelope: (option letters, $23 mask, expected (min, max) per axis), $130..$132 = 200, 300, 100.
@pytest.mark.parametrize(
    ("opt_codes", "dir_mask", "expected"),
    [
        ("V", 0, ((-200.0, -300.0, -100.0), (0.0, 0.0, 0.0))),
        ("V", 0b111, ((-200.0, -300.0, -100.0), (0.0, 0.0, 0.0))),
        ("VZ", 0, ((-200.0, -300.0, -100.0), (0.0, 0.0, 0.0))),
        ("VZ", 0b011, ((0.0, 0.0, -100.0), (200.0, 300.0, 0.0))),
        ("VZ", 0b100, ((-200.0, -300.0, 0.0), (0.0, 0.0, 100.0))),
        ("VZ", 0b111, ((0.0, 0.0, 0.0), (200.0, 300.0, 100.0))),
    ],
)
def test_soft_limit_envelope(
    opt_codes: str, dir_mask: int, expected: tuple[tuple[float, ...], tuple[float, ...]]
) -> None:
    """Default build: -$13x..0 whatever $23; force-origin build flips axes with $23 set (§2)."""
    model = soft_limited(
        f"$23={dir_mask}", "$130=200", "$131=300", "$132=100", f"[OPT:{opt_codes},15,128]"
    )
    assert model.soft_limit_envelope() == TravelBox(*expected)


def test_envelope_is_none_without_soft_limits_and_ends_are_inclusive() -> None:
    """$20=0 gives no envelope; both faces of the box count as inside (firmware-facts §2)."""
    assert feed(MachineModel(), "$22=1", "$20=0").soft_limit_envelope() is None
    box = soft_limited().soft_limit_envelope()
    assert box is not None
    assert box.contains((-200.0, 0.0, -100.0))
    assert not box.contains((0.001, 0.0, 0.0))
    assert not box.contains((-200.001, 0.0, 0.0))


@pytest.mark.parametrize(
    ("lines", "unhomed"),
    [
        (["<Idle|MPos:0.000,0.000,0.000|FS:0,0>"], True),
        (["<Idle|MPos:-0.000,0.000,-0.000|FS:0,0>"], True),
        (["<Idle|MPos:-1.000,-1.000,-1.000|FS:0,0>"], False),
        (["<Idle|MPos:0.000,0.000,-0.004|FS:0,0>"], False),
        ([], False),
        (["[OPT:VZ,15,128]", "<Idle|MPos:0.000,0.000,0.000|FS:0,0>"], False),
    ],
)
def test_looks_unhomed_with_soft_limits(lines: list[str], unhomed: bool) -> None:
    """All-zero MPos with soft limits on in a default build looks unhomed (firmware-facts §2)."""
    assert soft_limited(*lines).looks_unhomed() is unhomed


def test_not_unhomed_without_soft_limits() -> None:
    """Without soft limits, MPos 0 is no cause for warning."""
    assert not feed(MachineModel(), "<Idle|MPos:0.000,0.000,0.000|FS:0,0>").looks_unhomed()


def test_keep_out_zones() -> None:
    """Zones report containment, crossing moves, and the first zone at a point."""
    vise = KeepOut("vise", (-50.0, -50.0, -80.0), (-10.0, -10.0, -20.0))
    model = MachineModel()
    model.set_keep_outs([vise])
    assert model.keep_out_at((-30.0, -30.0, -50.0)) == vise
    assert model.keep_out_at((0.0, 0.0, 0.0)) is None
    assert vise.crosses((0.0, -30.0, -50.0), (-100.0, -30.0, -50.0))
    assert vise.crosses((-30.0, -30.0, 0.0), (-30.0, -30.0, -20.0))  # ends on the top face
    assert not vise.crosses((0.0, -30.0, -10.0), (-100.0, -30.0, -10.0))  # passes above
    assert not vise.crosses((0.0, 0.0, -50.0), (-5.0, -5.0, -50.0))  # stops short
    assert vise.box == TravelBox(vise.min_mm, vise.max_mm)


@pytest.mark.parametrize(
    ("low", "high", "message_part"),
    [((0.0, 0.0), (1.0,), "same number"), ((1.0, 0.0), (0.0, 1.0), "'clamp'.*axis X")],
)
def test_bad_boxes_are_refused(
    low: tuple[float, ...], high: tuple[float, ...], message_part: str
) -> None:
    """Inside-out or mismatched corners raise CoreError naming the zone and the fix."""
    with pytest.raises(CoreError, match=message_part):
        KeepOut("clamp", low, high)


INF = float("inf")
# A vise given in X and Y only: it blocks every Z height above that area.
XY_VISE = KeepOut("vise", (-50.0, -50.0), (-10.0, -10.0))


@pytest.mark.parametrize(
    ("start", "end", "crosses"),
    [
        ((0.0, -30.0, -50.0), (-100.0, -30.0, -50.0), True),  # straight through
        ((0.0, -30.0, 0.0), (-100.0, -30.0, 0.0), True),  # at the very top of Z: still blocked
        ((0.0, -30.0, -5e5), (-100.0, -30.0, -5e5), True),  # and far below
        ((-30.0, -30.0, 0.0), (-30.0, -30.0, -80.0), True),  # down Z inside the area
        ((0.0, 0.0, 0.0), (0.0, 0.0, -80.0), False),  # down Z beside it
        ((0.0, 0.0, -50.0), (-5.0, -5.0, -50.0), False),  # stops short
        ((-5.0, 0.0, -50.0), (-5.0, -100.0, -50.0), False),  # passes beside in X
    ],
)
def test_a_zone_with_fewer_axes_is_unbounded_along_the_others(
    start: tuple[float, ...], end: tuple[float, ...], crosses: bool
) -> None:
    """Axes the zone leaves out do not limit it (docs/config.md): contains and crosses agree."""
    assert XY_VISE.crosses(start, end) is crosses
    assert XY_VISE.contains((-30.0, -30.0, 123.0))
    assert not XY_VISE.contains((0.0, -30.0, -50.0))


@pytest.mark.parametrize(
    ("zone", "start", "end", "crosses"),
    [
        (KeepOut("slab", (-INF, -1.0), (INF, 1.0)), (5.0, -5.0), (5.0, 5.0), True),
        (KeepOut("slab", (-INF, -1.0), (INF, 1.0)), (5.0, 5.0), (-5.0, 5.0), False),
        (KeepOut("all", (-INF, -INF), (INF, INF)), (5.0, 5.0), (5.0, 5.0), True),
        (KeepOut("half", (0.0, -INF), (INF, INF)), (-1.0, 3.0), (-1.0, 9.0), False),
        (KeepOut("half", (0.0, -INF), (INF, INF)), (-1.0, 3.0), (1.0, 3.0), True),
    ],
)
def test_crosses_with_infinite_bounds_and_zero_components(
    zone: KeepOut, start: tuple[float, ...], end: tuple[float, ...], crosses: bool
) -> None:
    """±inf bounds and moves that do not change an axis give a plain answer, never NaN."""
    assert zone.crosses(start, end) is crosses


def test_set_keep_outs_checks_the_axes_against_the_machine() -> None:
    """Fewer axes than the machine are fine; an axis it lacks is refused, naming where and why."""
    model = feed(MachineModel(), "<Idle|MPos:0.000,0.000,0.000|FS:0,0>")
    model.set_keep_outs([XY_VISE])
    assert model.keep_outs == (XY_VISE,)
    four = KeepOut("rotary", (0.0, 0.0, 0.0, 0.0), (1.0, 1.0, 1.0, 1.0), source="mill.toml")
    with pytest.raises(ConfigError, match=r"^mill\.toml: \[keepout 'rotary'\] min_mm") as info:
        model.set_keep_outs([XY_VISE, four])
    assert "axis A" in str(info.value)
    assert "X Y Z" in str(info.value)
    assert model.keep_outs == (XY_VISE,)  # unchanged by the refusal
    feed(model, "Grbl 1.1h ['$' for help]", "<Idle|MPos:0.000,0.000,0.000,0.000|FS:0,0>")
    model.set_keep_outs([four])
    assert model.keep_outs == (four,)


def test_axis_letters_setter() -> None:
    """A grblHAL UVW build can name its axes; bad names are refused."""
    model = MachineModel()
    model.set_axis_letters(["x", "y", "z", "u"])
    assert model.axis_letters == ("X", "Y", "Z", "U")
    assert model.n_axes == 4
    with pytest.raises(CoreError, match="distinct"):
        model.set_axis_letters(["X", "X", "Q"])


def test_unparsed_and_empty_change_nothing() -> None:
    """Noise leaves the model as it was."""
    model = feed(MachineModel(), "<Idle|MPos:1.000,2.000,3.000|FS:0,0>")
    before = repr(model)
    feed(model, "", "garbage", "<Idle|MPos:1.0")
    assert repr(model) == before


_LINES = st.sampled_from(
    ["ok", "error:15", "ALARM:2", "", "Grbl 1.1h ['$' for help]", "$13=1", "$13=0", "$20=1",
     "$22=1", "$23=7", "$103=80", "$130=-5", "$110=1e400", "[OPT:VZ,15,128]", "[TLO:1.0]",
     "[GC:G20 G91 G59 F12.5]", "[PRB:1,2,3:0]", "<Idle|MPos:0.000,0.000,0.000|WCO:1,2,3>",
     "<Jog|WPos:1,2,3,4|FS:5,0>", "<Hold:0|MPos:1,2|Bf:0,0>", "<Door:3|WPos:9,9,9,9,9,9>"]
)  # fmt: skip


@given(st.lists(_LINES | st.binary(max_size=40).map(lambda b: b.decode("latin-1")), max_size=25))
def test_any_sequence_of_lines_is_absorbed(lines: list[str]) -> None:
    """apply() never raises on anything the parser returns, and derived queries still answer."""
    model = feed(MachineModel(), *lines)
    assert len(model.axis_max_rate_mm_min()) == model.n_axes
    envelope = model.soft_limit_envelope()
    assert envelope is None or len(envelope.min_mm) == model.n_axes
    assert isinstance(model.looks_unhomed(), bool)


def test_a_report_with_another_axis_count_is_damaged_and_keeps_the_last_position() -> None:
    """A lost comma or digit on a noisy wire changes the coordinate count: not a new machine."""
    from smoothjog.core.machine import MachineModel
    from smoothjog.core.responses import parse_response

    model = MachineModel()
    model.apply(parse_response("<Jog|MPos:-1.000,-2.000,-3.000|FS:500,0>"))
    model.apply(parse_response("<Jog|MPos:-1.100,-2.000|FS:500,0>"))
    assert model.mpos_mm == (-1.0, -2.0, -3.0)
    assert model.damaged_reports == 1
    model.apply(parse_response("<Jog|MPos:-1.200,-2.000,-3.000|FS:500,0>"))
    assert model.mpos_mm == (-1.2, -2.0, -3.0)
