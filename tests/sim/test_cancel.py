"""Jog cancel, feed hold, safety door and reset (firmware-facts §3), with Grbl 1.1h's flaws and the
grblHAL / FluidNC differences of firmware-facts §7."""

from __future__ import annotations

import itertools
import math

import pytest

from smoothjog.sim.firmware import EXEC_CYCLE_STOP
from tests.sim.rigtools import Host, field, mpos

JOG_LINE = "$J=G91X1F300\n"


def stream_jogs(host: Host, count: int, rx_size: int = 128, jog: str = JOG_LINE) -> int:
    """Stream count jogs with character counting (firmware-facts §5.1); returns the oks received."""
    outstanding: list[int] = []
    sent = acked = 0
    while sent < count:
        while sent < count and sum(outstanding) + len(jog) <= rx_size:
            host.send(jog)
            outstanding.append(len(jog))
            sent += 1
        for line in host.until(lambda x: x == "ok", 5.0):
            if line == "ok":
                outstanding.pop(0)
                acked += 1
    return acked


def finish(host: Host) -> int:
    """Run until everything settles; the oks that arrived meanwhile."""
    lines = host.until(lambda _x: False, 60.0)
    return lines.count("ok")


@pytest.mark.parametrize("cancel", [b"\x85", b"!"], ids=["0x85", "feed-hold"])
def test_ghost_jog_grbl_runs_the_whole_cancelled_distance(cancel: bytes) -> None:
    host = Host()
    assert host.reply("$10=3") == "ok"
    acked = stream_jogs(host, 25)
    report = host.status()
    # Planner full, one line blocked in mc_line, the rest waiting in RX (firmware-facts §3.1:
    # Bf:0,24).
    in_rx = 25 - acked - 1
    assert in_rx >= 5
    assert field(report, "Bf") == f"0,{128 - in_rx * len(JOG_LINE)}"
    host.send(cancel)
    acked += finish(host)
    assert acked == 25
    assert mpos(host.status()) == (25.0, 0.0, 0.0)  # firmware-facts §3.1: start + 25 mm


def test_grblhal_cancel_flushes_the_rx_buffer() -> None:
    host = Host("grblhal")
    # 100 planner blocks and a 1024-byte RX: stream enough to back lines up in RX.
    acked = stream_jogs(host, 150, rx_size=1024)
    host.send(b"\x85")
    acked += finish(host)
    final_x = mpos(host.status())[0]
    # The lines waiting in RX are gone: fewer oks and a shorter move than the 150 mm queued.
    assert acked < 110
    assert final_x < 110.0


def test_fluidnc_drops_the_blocked_jog_and_answers_ok() -> None:
    host = Host("fluidnc")
    acked = stream_jogs(host, 25)
    host.send(b"\x85")
    acked += finish(host)
    assert acked == 25  # the dropped jog is still answered ok
    assert mpos(host.status())[0] < 25.0


def test_cancel_in_jog_decelerates_in_jog_state_then_idle_without_output() -> None:
    host = Host()
    assert host.reply("$J=G91X50F500") == "ok"
    host.run(1.0)
    host.send(b"\x85")
    assert host.run(0.001) == []
    states = []
    for _ in range(200):
        states.append(host.state())
        if states[-1] == "Idle":
            break
        host.run(0.01)
    assert states[0] == "Jog"
    assert states[-1] == "Idle"
    assert "Hold:1" not in states
    assert [x for x in host.received if not x[1].startswith("<")][-1][1] == "ok"
    assert mpos(host.status())[0] < 10.0


@pytest.mark.parametrize("setup", ["idle", "run", "alarm"])
def test_cancel_outside_jog_is_ignored(setup: str) -> None:
    host = Host()
    if setup == "run":
        assert host.reply("G1X5F300") == "ok"
        host.run(0.2)
    elif setup == "alarm":
        host.send(b"\x18")
        assert host.reply("$J=G91X5F500") == "ok"
        host.run(0.05)
        host.send(b"\x18")
        host.until(lambda x: x.startswith("[MSG:'$H'"))
    before = host.state()
    host.send(b"\x85")
    assert host.run(0.05) == []
    assert host.state() == before
    if setup == "run":
        host.wait_state("Idle")
        assert mpos(host.status()) == (5.0, 0.0, 0.0)


def test_feed_hold_in_jog_never_shows_hold() -> None:
    host = Host()
    assert host.reply("$J=G91X50F500") == "ok"
    host.run(0.5)
    host.send(b"!")
    seen = {host.state() for _ in range(50) if host.run(0.02) is not None}
    assert not any(s.startswith("Hold") for s in seen)
    host.wait_state("Idle")


def test_feed_hold_in_idle_freezes_the_stream_until_resume() -> None:
    host = Host()
    host.send(b"!")
    assert host.state() == "Hold:0"
    host.send("$J=G91X1F300\n")
    assert [x for x in host.run(1.0) if not x.startswith("<")] == []  # no reply in Hold
    host.send(b"~")
    assert host.until(lambda x: x == "ok", 1.0)[-1] == "ok"
    host.wait_state("Idle")
    assert mpos(host.status()) == (1.0, 0.0, 0.0)


def test_feed_hold_in_run_holds_then_resumes() -> None:
    host = Host()
    assert host.reply("G1X10F300") == "ok"
    host.run(0.5)
    host.send(b"!")
    assert host.state() == "Hold:1"
    host.wait_state("Hold:0")
    held = mpos(host.status())
    host.run(0.5)
    assert mpos(host.status()) == held
    host.send(b"~")
    host.wait_state("Idle")
    assert mpos(host.status()) == (10.0, 0.0, 0.0)


def test_door_in_jog_reports_at_once_then_door_then_resume() -> None:
    host = Host()
    assert host.reply("$J=G91X50F500") == "ok"
    host.run(0.5)
    host.send(b"\x84")
    assert host.until(lambda x: x.startswith("[MSG"), 0.1)[-1] == "[MSG:Check Door]"
    assert host.state() == "Jog"
    host.wait_state("Door:0")
    host.send("$J=G91X1F300\n")
    assert [x for x in host.run(0.5) if not x.startswith("<")] == []  # no reply in Door
    stopped = mpos(host.status())
    host.send(b"~")
    assert host.until(lambda x: x == "ok", 1.0)[-1] == "ok"
    host.wait_state("Idle")
    assert mpos(host.status())[0] == pytest.approx(stopped[0] + 1.0)


def test_door_in_idle() -> None:
    host = Host()
    host.send(b"\x84")
    assert host.until(lambda x: x.startswith("[MSG"), 0.1)[-1] == "[MSG:Check Door]"
    assert host.state() == "Door:0"
    host.send(b"~")
    host.run(0.01)
    assert host.state() == "Idle"


def test_reset_while_jogging_alarm_pause_stray_ok_banner() -> None:
    host = Host()
    assert host.reply("$10=3") == "ok"
    stream_jogs(host, 25)
    host.send(b"\x18")
    t_reset = host.now_s
    lines = host.until(lambda x: x.startswith("[MSG:'$H'"), 2.0)
    times = {text: t for t, text in host.received if t >= t_reset}
    assert lines == [
        "ALARM:3",
        "ok",
        "",
        "Grbl 1.1h ['$' for help]",
        "[MSG:'$H'|'$X' to unlock]",
    ]
    assert times["ok"] - times["ALARM:3"] >= 0.49  # the 500 ms pause, less the byte times
    report = host.status()
    assert report.startswith("<Alarm")
    assert field(report, "Bf") == "15,128"  # RX flushed, planner empty
    assert host.run(1.0) == []  # the lines that were waiting in RX are lost
    true_x = host.rig.trace[-1].end_mm[0]
    assert mpos(report)[0] == pytest.approx(true_x, abs=0.005)  # MPos kept


def test_a_reset_during_a_cancels_step_idle_delay_runs_only_the_prepared_segments() -> None:
    # The planner full and a line held in mc_line; 0x85, and a reset while st_reset's $1 delay
    # ends the cancel. mc_line then plans and starts that line before its checkpoint sees the
    # reset; ALARM:3's 500 ms pause runs in the main program, which alone prepares segments, so
    # the steppers run the few already prepared (50 ms at most) and stop, not the whole pause.
    host = Host(machine="hobby-router")  # soft limits -800..0, at -1: jog toward minus
    stream_jogs(host, 25, jog="$J=G91X-2F600\n")
    host.send(b"\x85")
    while host.fw.motion.is_running():
        host.run(0.001)
    # The stepper ISR's st_go_idle delay first, then the cycle stop serviced, which ends the
    # cancel with st_reset and its own delay of $1 (25 ms): strike inside that second one.
    while host.fw._rt & EXEC_CYCLE_STOP:
        host.run(0.001)
    host.run(0.005)
    host.send(b"\x18")
    t_reset = host.now_s
    lines = host.until(lambda x: x.startswith("[MSG:'$H'"), 2.0)
    assert "ALARM:3" in lines
    after = [seg for seg in host.rig.trace if seg.t0_s >= t_reset]
    assert after, "the held line started after the reset (the race this test is about)"
    assert after[-1].t1_s - after[0].t0_s <= 0.051
    assert sum(math.dist(seg.start_mm, seg.end_mm) for seg in after) < 1.0


def test_reset_in_idle_prints_only_the_banner() -> None:
    host = Host()
    host.send(b"\x18")
    lines = host.until(lambda x: x.startswith("Grbl"), 1.0)
    assert lines == ["", "Grbl 1.1h ['$' for help]"]
    assert host.run(0.2) == []
    assert host.state() == "Idle"


def test_reset_restores_parser_defaults_and_keeps_mpos() -> None:
    host = Host()
    assert host.reply("G91G20") == "ok"
    assert host.reply("G92X1") == "ok"
    assert host.reply("$J=G21X5F500") == "ok"  # G91 from the modal state: relative
    host.wait_state("Idle")
    host.send(b"\x18")
    host.until(lambda x: x.startswith("Grbl"), 1.0)
    assert host.command("$G")[0] == "[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]"
    report = host.status()
    assert mpos(report) == (5.0, 0.0, 0.0)
    assert field(report, "WCO") == "0.000,0.000,0.000"  # G92 cleared


def test_g4p0_after_cancel_answers_only_once_stopped() -> None:
    host = Host()
    assert host.reply("$J=G91X50F500") == "ok"
    host.run(1.0)
    host.send(b"\x85")
    host.send("G4P0\n")
    lines = host.until(lambda x: x in ("ok", "error:9"), 5.0)
    assert lines[-1] == "ok"
    assert host.fw.state == "Idle"
    assert not host.fw.motion.is_running()
    assert mpos(host.status()) == tuple(round(v, 3) for v in host.fw.mpos_mm())


def test_g4p0_reports_error_9_when_a_stale_jog_restarted() -> None:
    host = Host()
    stream_jogs(host, 25)
    host.send(b"\x85")
    host.send("G4P0\n")
    lines = host.until(lambda x: x.startswith("error"), 10.0)
    assert lines[-1] == "error:9"


@pytest.mark.parametrize(("idle_ms", "min_gap_s"), [(25, 0.050), (0, 0.0)])
def test_step_idle_delay_after_a_cancel(idle_ms: int, min_gap_s: float) -> None:
    host = Host()
    assert host.reply(f"$1={idle_ms}") == "ok"
    assert host.reply("$J=G91X50F500") == "ok"
    host.run(1.0)
    host.send(b"\x85")
    host.send("$J=G91X1F300\n")
    host.until(lambda x: x == "ok", 5.0)
    host.run(0.5)
    trace = host.rig.trace
    # The dead time is the largest pause between consecutive ground-truth segments.
    gap_s = max(b.t0_s - a.t1_s for a, b in itertools.pairwise(trace))
    assert gap_s >= min_gap_s
    if idle_ms == 0:
        assert gap_s < 0.010


def test_grblhal_ignores_feed_hold_in_jog() -> None:
    host = Host("grblhal")
    assert host.reply("$J=G91X2F300") == "ok"
    host.run(0.1)
    host.send(b"!")
    host.wait_state("Idle")
    assert mpos(host.status()) == (2.0, 0.0, 0.0)


@pytest.mark.parametrize(
    ("firmware", "setup", "line", "expected_reply", "expected_x"),
    [
        ("grbl", [], "$J=G91X-900F3000", "error:15", -1.0),
        ("grblhal", [], "$J=G91X-900F3000", "error:15", -1.0),
        ("grblhal", ["$40=1"], "$J=G91X-900F3000", "ok", -800.0),
        ("fluidnc", [], "$J=G91X-900F3000", "ok", -800.0),
    ],
)
def test_jog_soft_limit_clipping_by_firmware(
    firmware: str, setup: list[str], line: str, expected_reply: str, expected_x: float
) -> None:
    host = Host(firmware, machine="hobby-router")
    for cmd in setup:
        assert host.reply(cmd) == "ok"
    assert host.reply(line) == expected_reply
    host.wait_state("Idle", timeout_s=60)
    assert mpos(host.status())[0] == pytest.approx(expected_x)


def test_each_jog_cancel_records_what_it_threw_away() -> None:
    # The record is the benches' ground truth (the firmware keeps none): a cancel of a jog in
    # full flow leaves planned steps unrun; on grblHAL the lines in RX are dropped too.
    host = Host()
    stream_jogs(host, 25)
    host.send(b"\x85")
    finish(host)
    [(_t, unrun, dropped)] = host.fw.cancel_log
    assert unrun > 250  # over a millimetre of planned X left (250 steps/mm)
    assert dropped == 0  # Grbl 1.1h keeps its RX buffer (firmware-facts §3.1)
    hal = Host("grblhal")
    stream_jogs(hal, 150, rx_size=1024)
    hal.send(b"\x85")
    finish(hal)
    [(_t, unrun, dropped)] = hal.fw.cancel_log
    assert unrun > 0
    assert dropped > 5


def test_a_jog_cancel_that_strikes_the_last_braking_throws_nothing_away() -> None:
    # One jog braking into its end when the 0x85 comes: the cancel brakes no harder than the
    # planner already did, so it leaves nothing unrun (within a step).
    host = Host()
    assert host.reply("$J=G91X2F300") == "ok"
    # 2 mm at 5 mm/s with Grbl's default 10 mm/s² ($120): it brakes over the last 1.25 mm;
    # strike late in that braking.
    while mpos(host.status())[0] < 1.9:
        host.run(0.005)
    host.send(b"\x85")
    finish(host)
    [(rest_s, unrun, dropped)] = host.fw.cancel_log
    assert unrun <= 1
    assert dropped == 0
    # Stamped with the rest the motion trace shows, not with the end of the $1 delay (25 ms)
    # after it, when the firmware finishes the cancel: a bench matches the two.
    assert rest_s == host.fw.motion.trace[-1].t1_s
