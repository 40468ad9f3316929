"""Conformance of the simulated Grbl 1.1h's line protocol with firmware-facts §1, §2 and §5."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.sim.rigtools import Host, field, mpos

# (line, reply) pairs from firmware-facts §1.1-§1.3, sent through the simulated serial port in Idle.
JOG_REPLIES = [
    ("$J=X1F100", "ok"),
    ("$j=x1f100", "ok"),
    ("$ J = X 1 F 1 0 0", "ok"),
    ("$J=X1F100(comment)", "ok"),
    ("$J=X.5F100", "ok"),
    ("$J=X1.F100", "ok"),
    ("$J=X+1F100", "ok"),
    ("$J=G21G91X1F100", "ok"),
    ("$J=G53X1F100", "ok"),
    ("$J=N5X1F100", "ok"),
    ("$J=F1000", "ok"),
    ("$J=X1", "error:22"),
    ("$J=X1F0", "error:22"),
    ("$J=X1F-5", "error:4"),
    ("$J=G90G91X1F100", "error:21"),
    ("$J=G1X1F1000", "error:16"),
    ("$J=G0X1F1000", "error:16"),
    ("$J=G94X1F100", "error:16"),
    ("$J=G93X1F100", "error:16"),
    ("$J=G54X1F100", "error:16"),
    ("$J=G17X1F100", "error:16"),
    ("$J=G4P1F100", "error:16"),
    ("$J=M3X1F100", "error:16"),
    ("$J=G2X1F100", "error:35"),
    ("$J=G80X1F100", "error:31"),
    ("$J=G92F100", "error:26"),
    ("$J=G1.5X1F100", "error:23"),
    ("$J=X1S100F100", "error:36"),
    ("$J=X1T3F100", "error:36"),
    ("$J=X1T300F100", "error:38"),
    ("$J=X1I1F100", "error:36"),
    ("$J=X1Q1F100", "error:20"),
    ("$J=X1e3F100", "error:20"),
    ("$J=X1X2F100", "error:25"),
    ("$J=X1F100F200", "error:25"),
    ("$J=X1.2.3F100", "error:1"),
    ("$J=XF100", "error:2"),
    ("$J=N-1X1F100", "error:4"),
    ("$J=N20000000X1F100", "error:27"),
    ("$JX1F100", "error:3"),
    ("$J", "error:3"),
    ("%", "error:1"),
    ("", "ok"),
    ("(only a comment)", "ok"),
]


@pytest.mark.parametrize(("line", "expected"), JOG_REPLIES)
def test_jog_line_replies_in_idle(line: str, expected: str) -> None:
    assert Host().reply(line) == expected


@pytest.mark.parametrize(
    ("stored_chars", "expected"), [(79, "ok"), (80, "error:11")], ids=["79", "80"]
)
def test_line_length_limit_counts_stored_chars(stored_chars: int, expected: str) -> None:
    # "$J=G91X0." + zeros + "F100": digits past the 8th add nothing, so X stays 0 (empty jog).
    line = "$J=G91X0." + "0" * (stored_chars - 13) + "F100"
    assert len(line) == stored_chars
    host = Host()
    assert host.reply(line + " (a long comment does not count)") == expected


def test_banner_at_power_up() -> None:
    assert Host().banner == ["", "Grbl 1.1h ['$' for help]"]


@pytest.mark.parametrize(
    ("firmware", "banner"),
    [
        ("grblhal", "GrblHAL 1.1f ['$' or '$HELP' for help]"),
        ("fluidnc", "Grbl 3.9 [FluidNC v3.9.1 (sim-uart) '$' for help]"),
    ],
)
def test_other_firmware_banners(firmware: str, banner: str) -> None:
    assert Host(firmware).banner[-1] == banner


def test_crlf_gives_two_oks() -> None:
    host = Host()
    host.send("$J=G91X0.1F100\r\n")
    host.run(0.5)
    assert [x for _t, x in host.received].count("ok") == 2


def test_realtime_byte_inside_a_line_acts_and_the_line_still_runs() -> None:
    host = Host()
    host.send("$J=G91X1(why?)F100\n")
    lines = host.until(lambda x: x == "ok")
    assert lines[0].startswith("<Idle")
    assert lines[-1] == "ok"
    host.wait_state("Idle")
    assert mpos(host.status()) == (1.0, 0.0, 0.0)


def test_unknown_extended_bytes_are_discarded() -> None:
    host = Host()
    host.send(b"$J=G91\x98\x9f\xffX1F100\n")
    assert host.until(lambda x: x == "ok")[-1] == "ok"


def test_jog_without_axis_words_goes_to_machine_zero() -> None:
    host = Host()
    assert host.reply("$J=G53X-5Y-3Z-1F1000") == "ok"
    host.wait_state("Idle")
    assert host.reply("G10L20P1X0Y0Z0") == "ok"  # WCO -5,-3,-1: WPos 0 is not MPos 0
    assert host.reply("$J=G91F500") == "ok"
    host.wait_state("Idle")
    assert mpos(host.status()) == (0.0, 0.0, 0.0)


def _long_jog(host: Host) -> None:
    assert host.reply("$J=G91X50F500") == "ok"
    assert host.state() == "Jog"


JOG_STATE_COMMANDS = [
    ("G4P0", "error:9"),
    ("G0X1", "error:9"),
    ("$G", "ok"),
    ("$$", "ok"),
    ("$", "ok"),
    ("$X", "ok"),
    ("$#", "error:8"),
    ("$I", "error:8"),
    ("$N", "error:8"),
    ("$C", "error:8"),
    ("$H", "error:8"),
    ("$SLP", "error:8"),
    ("$RST=$", "error:8"),
    ("$10=2", "error:8"),
    ("$J=G91X1F100", "ok"),
]


@pytest.mark.parametrize(("line", "expected"), JOG_STATE_COMMANDS)
def test_other_commands_while_jogging(line: str, expected: str) -> None:
    host = Host()
    _long_jog(host)
    assert host.reply(line) == expected


def test_alarm_state_rules(homing_machine: str) -> None:
    host = Host(machine=homing_machine)
    assert host.state() == "Alarm"
    assert host.reply("$J=X-1F100") == "error:8"
    assert host.reply("G0X-1") == "error:9"
    assert host.reply("$G") == "ok"
    assert host.command("$X")[-2:] == ["[MSG:Caution: Unlocked]", "ok"]
    assert host.state() == "Idle"
    # Nothing is homed: MPos is 0 and every + jog leaves the box (firmware-facts §2).
    assert host.reply("$J=G91X1F100") == "error:15"


def test_power_up_with_homing_enabled_enters_alarm(homing_machine: str) -> None:
    host = Host(machine=homing_machine)
    assert host.banner == ["", "Grbl 1.1h ['$' for help]"]
    assert host.run(0.1) == ["[MSG:'$H'|'$X' to unlock]"]


def test_homing_sets_mpos_to_the_pull_off_and_unlocks(homing_machine: str) -> None:
    host = Host(machine=homing_machine)
    assert host.reply("$H", timeout_s=30.0) == "ok"
    report = host.status()
    assert report.startswith("<Idle")
    assert mpos(report) == (-1.0, -1.0, -1.0)


def test_homing_disabled_is_error_5() -> None:
    assert Host().reply("$H") == "error:5"


def test_check_mode_rules() -> None:
    host = Host()
    assert host.command("$C")[-2:] == ["[MSG:Enabled]", "ok"]
    assert host.state() == "Check"
    assert host.reply("$J=X1F100") == "error:8"
    assert host.reply("G0X5") == "ok"
    host.run(0.5)
    assert mpos(host.status()) == (0.0, 0.0, 0.0)
    lines = host.command("$C")
    assert lines[:2] == ["[MSG:Disabled]", "ok"]
    host.until(lambda x: x.startswith("Grbl"))
    assert host.state() == "Idle"


def test_jog_in_run_state_is_error_8() -> None:
    host = Host()
    assert host.reply("G1X20F300") == "ok"
    host.run(0.1)
    assert host.state() == "Run"
    assert host.reply("$J=X1F100") == "error:8"


# ------------------------------------------------------------------ soft limits (firmware-facts §2)
@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ("$J=G53X-800F1000", "ok"),
        ("$J=G53X-800.001F1000", "error:15"),
        ("$J=G53X0F1000", "ok"),
        ("$J=G53X0.001F1000", "error:15"),
        ("$J=G53Z-100F500", "ok"),
        ("$J=G53Z-100.01F500", "error:15"),
    ],
)
def test_soft_limit_box_is_inclusive_for_jogs(line: str, expected: str) -> None:
    assert Host(machine="hobby-router").reply(line) == expected


def test_rejected_jog_leaves_the_others_running() -> None:
    host = Host(machine="hobby-router")
    replies = [host.reply(x) for x in ("$J=G91X-10F3000", "$J=G91X-900F3000", "$J=G91X-10F3000")]
    assert replies == ["ok", "error:15", "ok"]
    host.wait_state("Idle")
    assert mpos(host.status())[0] == pytest.approx(-21.0)


def test_gcode_soft_limit_alarm_blocks_until_reset() -> None:
    host = Host(machine="hobby-router")
    host.send("G0X10\n")
    lines = host.until(lambda x: x.startswith("[MSG:Reset"))
    assert lines[-2:] == ["ALARM:2", "[MSG:Reset to continue]"]
    host.send(b"?")
    host.send("G4P0\n")
    assert host.run(1.0) == []  # no status report, no reply: everything blocked
    host.send(b"\x18")
    lines = host.until(lambda x: x.startswith("[MSG:'$H'"))
    assert lines == ["ok", "", "Grbl 1.1h ['$' for help]", "[MSG:'$H'|'$X' to unlock]"]
    assert host.state() == "Alarm"


@pytest.mark.parametrize(
    ("commands", "expected"),
    [
        (["$20=1"], "error:10"),
        (["$22=1", "$20=1"], "ok"),
        (["$10=-1"], "error:4"),
        (["$99=1"], "error:3"),
        (["$256=1"], "error:3"),
        (["$10=x"], "error:2"),
        (["$10=2x"], "error:3"),
        (["$1=30"], "ok"),
    ],
)
def test_setting_store_rules(commands: list[str], expected: str) -> None:
    host = Host()
    replies = [host.reply(c) for c in commands]
    assert replies[-1] == expected


def test_homing_off_turns_soft_limits_off() -> None:
    host = Host()
    for line in ("$22=1", "$20=1", "$22=0"):
        assert host.reply(line) == "ok"
    assert "$20=0" in host.command("$$")


def test_dollar_dollar_format_and_order() -> None:
    lines = Host().command("$$")
    assert lines == [
        "$0=10", "$1=25", "$2=0", "$3=0", "$4=0", "$5=0", "$6=0",
        "$10=1", "$11=0.010", "$12=0.002", "$13=0",
        "$20=0", "$21=0", "$22=0", "$23=0", "$24=25.000", "$25=500.000", "$26=250", "$27=1.000",
        "$30=1000", "$31=0", "$32=0",
        "$100=250.000", "$101=250.000", "$102=250.000",
        "$110=500.000", "$111=500.000", "$112=500.000",
        "$120=10.000", "$121=10.000", "$122=10.000",
        "$130=200.000", "$131=200.000", "$132=200.000",
        "ok",
    ]  # fmt: skip


@pytest.mark.parametrize(
    ("firmware", "expected"),
    [
        ("grbl", ["[VER:1.1h.20190830:]", "[OPT:V,15,128]", "ok"]),
        ("grblhal", ["[VER:1.1f.20260817:]", "[OPT:V,100,1024]", "ok"]),
        ("fluidnc", ["[VER:3.9 FluidNC v3.9.1:]", "[OPT:V,15,256]", "ok"]),
    ],
)
def test_build_info(firmware: str, expected: list[str]) -> None:
    assert Host(firmware).command("$I") == expected


def test_gcode_modes_help_and_parameters() -> None:
    host = Host()
    assert host.command("$G") == ["[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]", "ok"]
    assert host.command("$") == [
        "[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]",
        "ok",
    ]
    assert host.reply("G10L2P2X1Y2Z3") == "ok"
    params = host.command("$#")
    assert params[1] == "[G55:1.000,2.000,3.000]"
    assert params[-3:] == ["[TLO:0.000]", "[PRB:0.000,0.000,0.000:0]", "ok"]


def test_startup_lines_are_stored_and_run_at_reset() -> None:
    host = Host()
    assert host.reply("$N0=G20") == "ok"
    assert host.command("$N") == ["$N0=G20", "$N1=", "ok"]
    host.send(b"\x18")
    assert host.until(lambda x: x.startswith(">"))[-1] == ">G20:ok"


def test_sleep_blocks_lines_until_reset() -> None:
    host = Host()
    assert host.command("$SLP")[-1] == "ok"
    assert host.until(lambda x: x == "[MSG:Sleeping]", 1.0)[-1] == "[MSG:Sleeping]"
    assert host.state() == "Sleep"
    host.send("$I\n")
    assert host.run(0.5) == []


# ------------------------------------------------------------------ status reports (firmware-facts
# §5.4)
def test_wco_and_ov_counters_while_idle() -> None:
    host = Host()
    reports = [host.status() for _ in range(22)]
    with_wco = [i + 1 for i, r in enumerate(reports) if field(r, "WCO") is not None]
    with_ov = [i + 1 for i, r in enumerate(reports) if field(r, "Ov") is not None]
    assert with_wco == [1, 11, 21]
    assert with_ov == [2, 12, 22]


def test_wco_every_30th_report_while_busy() -> None:
    host = Host(machine="slow-machine")
    host.status()  # the boot report with WCO
    assert host.reply("$J=G91X200F600") == "ok"
    reports = [host.status() for _ in range(40)]
    assert all(r.startswith("<Jog") for r in reports)
    with_wco = [i for i, r in enumerate(reports) if field(r, "WCO") is not None]
    # The report after boot's set the idle period (10); then the busy period of 30 applies.
    assert with_wco[1] - with_wco[0] == 30


def test_wco_forced_after_an_offset_change() -> None:
    host = Host()
    host.status()
    host.status()
    assert field(host.status(), "WCO") is None
    assert host.reply("G10L20P1X5") == "ok"
    report = host.status()
    assert field(report, "WCO") == "-5.000,0.000,0.000"
    assert host.reply("$10=0") == "ok"
    assert field(host.status(), "WPos") == "5.000,0.000,0.000"


def test_status_mask_and_inches() -> None:
    host = Host()
    assert host.reply("$10=3") == "ok"
    report = host.status()
    assert field(report, "MPos") == "0.000,0.000,0.000"
    assert field(report, "Bf") == "15,128"
    assert host.reply("$J=G91X25.4F100") == "ok"
    assert field(host.status(), "Bf") == "14,128"
    host.wait_state("Idle", timeout_s=60)
    assert host.reply("$13=1") == "ok"
    report = host.status()
    assert field(report, "MPos") == "1.0000,0.0000,0.0000"
    assert field(report, "WCO") == "0.0000,0.0000,0.0000"  # $13 change forces WCO


def test_fs_shows_the_capped_feed_and_zero_when_idle() -> None:
    host = Host()
    assert host.reply("$J=G91X100F10000") == "ok"
    host.run(2.0)
    assert field(host.status(), "FS") == "500,0"  # capped at $110 (firmware-facts §4.2)
    host.send(b"\x85")
    host.wait_state("Idle")
    assert field(host.status(), "FS") == "0,0"


@pytest.fixture
def homing_machine(tmp_path: Path) -> str:
    """A machine with homing and soft limits that powers up un-homed (HOMING_INIT_LOCK)."""
    path = tmp_path / "homing.toml"
    path.write_text('start = "power-up"\n[settings]\n20 = 1\n22 = 1\n', encoding="utf-8")
    return str(path)


def test_door_during_homing_is_alarm_7_then_a_reset(homing_machine: str) -> None:
    host = Host(machine=homing_machine)
    host.send("$H\n")
    host.run(0.5)
    host.send(b"\x84")
    lines = host.until(lambda x: x.startswith("Grbl"), 3.0)
    assert "ALARM:7" in lines
    assert "ALARM:6" not in lines
    assert lines.index("ALARM:7") < lines.index("Grbl 1.1h ['$' for help]")
    assert host.state() == "Alarm"


# ------------------------------------------------------------------ overrides (firmware-facts §4.2,
# §5.2)
def _ov(host: Host) -> str | None:
    """Ov of the next report that is not the boot report carrying WCO (which defers Ov)."""
    report = host.status()
    if field(report, "WCO") is not None and field(report, "Ov") is None:
        report = host.status()
    return field(report, "Ov")


def _feed_of(report: str) -> float:
    value = field(report, "FS")
    assert value is not None, report
    return float(value.split(",")[0])


def test_feed_override_slows_g1_but_not_a_jog() -> None:
    host = Host(machine="fast")
    host.send(b"\x92" * 1)  # -10 %: 90 %
    host.run(0.05)
    for _ in range(4):  # one flag at a time, each serviced before the next: 50 %
        host.send(b"\x92")
        host.run(0.05)
    assert _ov(host) == "50,100,100"
    assert host.reply("G1X-100F3000") == "ok"
    host.run(1.0)
    assert _feed_of(host.status()) == pytest.approx(1500, abs=2)
    host.wait_state("Idle")
    assert host.reply("$J=G91X50F3000") == "ok"
    host.run(0.5)
    report = host.status()
    assert report.startswith("<Jog")
    assert _feed_of(report) == pytest.approx(3000, abs=2)


def test_feed_override_mid_move_replans_the_queue() -> None:
    host = Host(machine="fast")
    assert host.reply("G1X-200F3000") == "ok"
    host.run(0.5)
    assert _feed_of(host.status()) == pytest.approx(3000, abs=2)
    host.send(b"\x92")  # 90 %
    host.run(0.5)
    assert _feed_of(host.status()) == pytest.approx(2700, abs=2)
    host.send(b"\x90")  # back to 100 %
    host.run(0.5)
    assert _feed_of(host.status()) == pytest.approx(3000, abs=2)


def test_rapid_override_slows_g0() -> None:
    host = Host(machine="fast")
    host.send(b"\x97")  # 25 %
    host.run(0.05)
    assert _ov(host) == "100,25,100"
    assert host.reply("G0X-200") == "ok"
    host.run(1.0)
    rapid = float(host.fw.settings[110])
    assert _feed_of(host.status()) == pytest.approx(0.25 * rapid, abs=2)


def test_override_flags_raised_twice_count_once() -> None:
    host = Host()
    # Five +10 % bytes land while the main loop parses the line before them: one flag.
    host.send(b"G4P0\n" + b"\x91" * 5)
    host.run(0.05)
    assert _ov(host) == "110,100,100"


def test_ov_is_forced_only_by_a_real_change() -> None:
    host = Host()
    host.status()
    host.status()  # the boot reports with WCO and Ov are out of the way
    host.send(b"\x90")  # feed override reset while already at 100 %: nothing changes
    host.run(0.05)
    assert field(host.status(), "Ov") is None
    host.send(b"\x91")
    host.run(0.05)
    assert field(host.status(), "Ov") == "110,100,100"


# ------------------------------------------------------------------ dwell (delay_sec)
def test_a_status_request_during_a_dwell_waits_for_the_next_50_ms_step() -> None:
    host = Host()
    host.send("G4P1\n")
    host.run(0.02)  # the dwell has started; its first step's checkpoint is behind us
    asked = host.now_s
    host.send(b"?")
    host.until(lambda x: x.startswith("<"), 1.0)
    answered = next(t for t, line in host.received if line.startswith("<"))
    # Answered at the next step boundary, not after the byte and report times (about 6 ms).
    assert 0.015 < answered - asked < 0.060
    assert host.until(lambda x: x == "ok", 2.0)[-1] == "ok"


def test_a_hold_during_a_dwell_suspends_it_until_resumed() -> None:
    host = Host()
    host.send("G4P0.5\n")
    host.run(0.1)
    host.send(b"!")
    assert "ok" not in host.run(1.0)  # the dwell waits while held
    assert host.state().startswith("Hold")
    resumed = host.now_s
    host.send(b"~")
    host.until(lambda x: x == "ok", 2.0)
    done = next(t for t, line in host.received if line == "ok" and t > resumed)
    # Some 0.4 s of the 0.5 s dwell were left when it was suspended.
    assert 0.3 < done - resumed < 0.5


def test_on_off_settings_are_stored_as_bits() -> None:
    host = Host()
    assert host.reply("$13=5") == "ok"
    assert "$13=1" in host.command("$$")
    assert host.reply("$13=0") == "ok"
    assert "$13=0" in host.command("$$")
    assert host.reply("$10=3") == "ok"  # a mask keeps its value
    assert "$10=3" in host.command("$$")


def test_long_output_stalls_the_main_loop_until_the_tx_ring_has_room() -> None:
    host = Host()
    t0 = host.now_s
    host.send("$J=G91X-1F300\n")
    host.run(2.0)  # the whole jog (10 mm/s² here), and the $1 delay after it
    alone = host.fw.trace[0].t0_s - t0
    t1 = host.now_s
    host.send("$$\n$J=G91X-1F300\n")
    lines = host.run(0.5)
    started = next(seg.t0_s for seg in host.fw.trace if seg.t0_s >= t1) - t1
    sent = sum(len(line) + 2 for line in lines[: lines.index("ok") + 1])
    byte_s = 10 / 115200
    # The jog line is read only once all but 104 bytes of the `$$` text are on their way.
    assert sent > 300
    assert started >= (sent - 104) * byte_s
    assert alone < 0.006  # a short reply never fills the ring


def test_reset_while_jogging_waits_the_step_idle_delay_before_alarm_and_banner() -> None:
    host = Host(machine="hobby-router")
    assert host.reply("$J=G91X-50F3000") == "ok"
    host.run(0.3)
    t = host.now_s
    host.send(b"\x18")
    host.run(1.0)
    seen = {line: when - t for when, line in host.received if when >= t}
    lock_s = host.fw.settings[1] / 1000  # $1 = 25 ms
    # mc_reset's st_go_idle (in the ISR) holds ALARM:3 back by $1 ms; after the 500 ms pause the
    # re-initialisation's st_reset waits $1 ms more before the banner.
    assert seen["ALARM:3"] == pytest.approx(lock_s, abs=0.003)
    assert seen["Grbl 1.1h ['$' for help]"] == pytest.approx(lock_s + 0.5 + lock_s, abs=0.005)


def test_a_reset_puts_the_overrides_back_to_100_percent() -> None:
    host = Host(machine="fast")
    host.send(b"G4P0\n" + b"\x92")  # 90 %
    host.run(0.05)
    assert _ov(host) == "90,100,100"
    host.send(b"\x18")
    host.until(lambda x: x.startswith("Grbl"), 2.0)
    assert host.reply("G1X-200F3000") == "ok"
    host.run(1.0)
    assert _feed_of(host.status()) == pytest.approx(3000, abs=2)


def test_a_reset_during_a_dwell_aborts_after_the_current_50_ms_step() -> None:
    host = Host()
    host.send("G4P1\n")
    host.run(0.02)
    t = host.now_s
    host.send(b"\x18")
    host.until(lambda x: x.startswith("Grbl"), 1.0)
    seen = {line: when - t for when, line in host.received if when >= t}
    # The reset is seen at the next step's checkpoint (about 30 ms on), which only marks the
    # abort; that step's 50 ms sleep runs, then the dwell returns its ok and Grbl restarts.
    assert 0.070 < seen["ok"] < 0.090
    assert seen["Grbl 1.1h ['$' for help]"] > seen["ok"]


def test_feed_override_wraps_as_a_byte_before_the_clamp() -> None:
    host = Host()
    for _ in range(9):  # 100 % -> 10 %, one flag at a time
        host.send(b"\x92")
        host.run(0.01)
    assert _ov(host) == "10,100,100"
    host.send(b"G4P0\n" + b"\x92\x94")  # -10 and -1 in one pass: 10 - 11 wraps to 255 -> 200 %
    host.run(0.05)
    assert _ov(host) == "200,100,100"
