"""The CPU benchmark plans holds within travel, reads the CLI's output and produces its table."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest
from bench import cpu

#: `smoothjog info --port PTY` against `smoothjog sim --machine hobby-router`, as printed.
INFO = """\
Link          /tmp/x/pty at 115200 baud
Controller    grbl 1.1h, build 20190830, options V
Planner       15 blocks, RX buffer 128 bytes
Axis                max rate    acceleration      travel
  X              5000 mm/min       500 mm/s²      800 mm
  Y              5000 mm/min       500 mm/s²      800 mm
  Z              1500 mm/min       200 mm/s²      100 mm
Soft limits   on (X -800..0, Y -800..0, Z -100..0 mm, machine coordinates)
Homing        on; hard limits off
Reports       MPos, mm
State         Idle: ready
MPos          X -1.000  Y -2.500  Z -1.000 mm
"""

#: `smoothjog jog --port PTY --replay FILE`, as printed.
JOG = """\
replay finished on /tmp/x/pty at 115200 baud
  duration        0.553 s
  stops           1
  tracked - real  0.00 µm, 0.00 steps (worst axis, worst stop)
  final state     Idle at MPos -10.238, -1.000, -1.500
  faults          none
"""


def test_info_gives_limits_position_and_firmware() -> None:
    c = cpu.parse_info(INFO, "Y")
    assert c.firmware == "grbl 1.1h, build 20190830, options V"
    assert c.limits == cpu.AxisLimits("Y", 5000.0, 500.0, -800.0, 0.0, True)
    assert c.pos_mm == -2.5


def test_info_without_the_axis_is_a_sentence() -> None:
    with pytest.raises(cpu.BenchError, match="X axis"):
        cpu.parse_info("Controller    grbl 1.1h\n", "X")


@pytest.mark.parametrize(("axis", "pos_mm"), [("X", -10.238), ("Y", -1.0), ("Z", -1.5)])
def test_jog_output_gives_final_position_and_link(axis: str, pos_mm: float) -> None:
    assert cpu.parse_jog(JOG, axis) == (pos_mm, None, "/tmp/x/pty at 115200 baud")


@pytest.mark.parametrize(
    ("hold_s", "speed_mm_s", "span_mm", "legs"),
    [
        (0.1, 83.3, 776.0, 1),  # the short hold
        (5.0, 83.3, 776.0, 1),  # 417 mm fits
        (20.0, 41.7, 776.0, 3),  # 833 mm: two legs would fit, but an odd count proves motion
        (20.0, 83.3, 776.0, 3),  # 1667 mm
        (20.0, 83.3, 300.0, 7),  # ceil(5.6) = 6, made odd
    ],
)
def test_legs_keep_the_hold_within_travel_and_odd(
    hold_s: float, speed_mm_s: float, span_mm: float, legs: int
) -> None:
    got = cpu.legs_for(hold_s, speed_mm_s, span_mm)
    assert got == legs
    assert hold_s * speed_mm_s / got <= span_mm


def test_replay_presses_reverses_and_releases() -> None:
    plan = cpu.Plan("X", 0.5, 3.0, 3, -1)
    lines = [json.loads(line) for line in plan.replay_lines()]
    lead = cpu.LEAD_S
    assert lines == [
        {"t": lead, "axes": {"x": -1.0}, "speed": 0.5},
        {"t": lead + 1.0, "axes": {"x": 1.0}, "speed": 0.5},
        {"t": lead + 2.0, "axes": {"x": -1.0}, "speed": 0.5},
        {"t": lead + 3.0, "axes": {"x": 0}},
    ]
    limits = cpu.AxisLimits("X", 5000.0, 500.0, -800.0, 0.0, True)
    # Three legs of 1 s at 41.7 mm/s: the first and second cancel, the third is left.
    assert plan.expected_move_mm(limits) == pytest.approx(-5000 / 60 / 2)


def test_cpu_bench_runs_the_real_commands_and_writes_its_table(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["--hold-s", "0.3", "--repeat", "1", "--speeds", "1.0", "--quiet", "--out"]
    code = cpu.main([*argv, str(tmp_path)])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    text = (tmp_path / "cpu.md").read_text(encoding="utf-8")
    assert text.strip() == printed.out.strip()
    assert "machine hobby-router" in text
    assert "115200 baud" in text
    rows = [line for line in text.splitlines() if line.startswith("| ")]
    assert len(rows) == 2  # the header and one row for the one speed
    cells = [c.strip() for c in rows[1].strip("|").split("|")]
    assert cells[:2] == ["100 %", "83.3 mm/s"]
    # One repeat: single figures. The sign of the difference is left to noise (0.2 s of held jog
    # costs less CPU than start-up varies by), so only its form is checked, not a threshold.
    host, sim = (re.fullmatch(r"(-?\d+\.\d) %", c) for c in cells[2:4])
    assert host is not None
    assert sim is not None
    assert math.isfinite(float(host.group(1)))
    short_cpu = re.fullmatch(r"(\d+\.\d+) s", cells[5])
    assert short_cpu is not None
    assert float(short_cpu.group(1)) > 0
    moved = re.fullmatch(r"X (\d+) mm", cells[6])
    assert moved is not None
    assert float(moved.group(1)) > 0
