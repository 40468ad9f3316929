"""The simulator computes lengths as Grbl 1.1h does: 32-bit floats and whole steps (firmware-facts
§1.5).

The expected values come from an oracle written here with ctypes' C float, independent of the
simulator's struct-based helper: AVR arithmetic rounds every operation to a single (avr-gcc's
`double` is a single too), read_float scales an integer by 0.01 and 0.1, the planner rounds with
lround, reports divide steps by steps/mm. Each test also checks that the result differs from a
float64 computation, so it fails on a simulator that adds in doubles.
"""

from __future__ import annotations

import ctypes
import math
from fractions import Fraction
from pathlib import Path

import pytest

from smoothjog.sim.f32 import lround, print_float, read_float, steps_to_mm
from tests.sim.rigtools import Host, field, is_reply, mpos


def single(x: float) -> float:
    """x stored in a C float."""
    return ctypes.c_float(x).value


def avr_read(text: str) -> float:
    """nuts_bolts.c:read_float on an AVR, for plain decimals such as '-0.3237' (the oracle)."""
    negative = text.startswith("-")
    digits = text.lstrip("+-")
    whole, _, frac = digits.partition(".")
    value = single(float(int(whole + frac)))
    exp = -len(frac)
    while exp <= -2:
        value = single(value * single(0.01))
        exp += 2
    if exp < 0:
        value = single(value * single(0.1))
    return -value if negative else value


def c_lround(x: float) -> int:
    """C lround: halves away from zero."""
    return int(math.copysign(math.floor(abs(x) + 0.5), x))


def stream(host: Host, lines: list[str]) -> list[str]:
    """Send lines with character counting (firmware-facts §5.1); the replies, in order."""
    outstanding: list[int] = []
    replies: list[str] = []
    sent = 0
    while len(replies) < len(lines):
        while sent < len(lines) and sum(outstanding) + len(lines[sent]) + 1 <= 128:
            host.send(lines[sent] + "\n")
            outstanding.append(len(lines[sent]) + 1)
            sent += 1
        got = [line for line in host.run(0.005) if is_reply(line)]
        replies += got
        del outstanding[: len(got)]
        assert host.now_s < 600.0, "the stream stalled"
    return replies


# ------------------------------------------------------------------ the helpers against the oracle
@pytest.mark.parametrize(
    "text", ["0.0123", "0.001", "0.0010", "-0.3237", "0.3021", "25.4", "1.005", "-799.768", "7"]
)
def test_read_float_scales_in_single_precision(text: str) -> None:
    value = read_float(text, 0)
    assert value is not None
    assert value == (avr_read(text), len(text))


def test_read_float_is_not_always_the_nearest_single() -> None:
    # "0.0010" is 10 x 0.01f x 0.01f, "0.001" is 1 x 0.01f x 0.1f: two different singles, and the
    # first is not the single nearest to 0.001.
    first, second = read_float("0.0010", 0), read_float("0.001", 0)
    assert first is not None
    assert second is not None
    assert first[0] != second[0]
    assert first[0] != single(0.001)


@pytest.mark.parametrize(("x", "n"), [(2.5, 3), (-2.5, -3), (0.49999997, 0), (-199941.83, -199942)])
def test_lround_rounds_halves_away_from_zero(x: float, n: int) -> None:
    assert lround(single(x)) == n == c_lround(single(x))


def test_print_float_rounds_in_single_precision() -> None:
    # Step -199991 at 80 steps/mm is -2499.8875 mm, stored as the single -2499.887451...;
    # printFloat scales it by 100 and 10 in singles (-> 2499887.5) and adds 0.5, so the chip
    # prints .888 where a correctly rounded decimal of that single would be .887.
    value = steps_to_mm(-199991, 80.0)
    assert value == single(single(-199991.0) / 80.0)
    assert print_float(value, 3) == "-2499.888"
    assert f"{value:.3f}" == "-2499.887"
    assert print_float(single(-0.0001), 3) == "-0.000"
    assert print_float(-0.0, 3) == "0.000"


# ------------------------------------------------------------------ (a) a long G91 stream
def test_thousands_of_small_g91_jogs_accumulate_as_singles() -> None:
    host = Host()
    n = 5000
    replies = stream(host, ["$J=G91X0.0123F500"] * n)
    assert replies == ["ok"] * n
    host.wait_state("Idle", timeout_s=60.0)
    step = avr_read("0.0123")
    x = 0.0
    for _ in range(n):
        x = single(x + step)  # gc_execute_line: target = position + value, a single
    fw = host.fw
    assert fw.parser.position_mm[0] == x
    assert fw.motion.position_steps()[0] == c_lround(single(x * 250.0))
    assert mpos(host.status())[0] == pytest.approx(c_lround(single(x * 250.0)) / 250.0)
    # In doubles the stream ends at 61.5 mm, step 15375; the chip ends at 61.49695, step 15374.
    assert x != n * 0.0123
    assert c_lround(single(x * 250.0)) == 15374 != round(n * 0.0123 * 250.0)


def test_a_mix_of_axes_units_and_increments_accumulates_as_singles() -> None:
    host = Host()
    # (line, {axis: increment text}, inches)
    cycle = [
        ("$J=G21G91X0.0123F500", {0: "0.0123"}, False),
        ("$J=G91Y-0.0071Z0.0033F500", {1: "-0.0071", 2: "0.0033"}, False),
        ("$J=G20G91X0.0005F20", {0: "0.0005"}, True),
        ("$J=G91X-0.0042Y0.0333F500", {0: "-0.0042", 1: "0.0333"}, False),
        ("$J=G91Z0.0001F500", {2: "0.0001"}, False),
    ]
    repeats = 800
    lines = [line for line, _, _ in cycle] * repeats
    assert stream(host, lines) == ["ok"] * len(lines)
    host.wait_state("Idle", timeout_s=60.0)
    pos = [0.0, 0.0, 0.0]
    doubles = [0.0, 0.0, 0.0]  # what a simulator adding in float64 would hold
    for _ in range(repeats):
        for _line, words, inches in cycle:
            for axis, text in words.items():
                value = avr_read(text)
                if inches:
                    value = single(value * single(25.4))
                pos[axis] = single(value + pos[axis])
                doubles[axis] += float(text) * (25.4 if inches else 1.0)
    fw = host.fw
    assert list(fw.parser.position_mm) == pos
    steps = [c_lround(single(p * 250.0)) for p in pos]
    assert list(fw.motion.position_steps()) == steps
    report_mpos = mpos(host.status())
    assert report_mpos == pytest.approx(tuple(s / 250.0 for s in steps), abs=1e-9)
    # Each axis has drifted from the float64 sum, by up to half a micrometre here (the steps hide
    # it; the X-only stream above drifts by a whole step).
    assert all(p != d for p, d in zip(pos, doubles, strict=True))
    assert max(abs(p - d) for p, d in zip(pos, doubles, strict=True)) > 2e-4


# ------------------------------------------------------------------ (b) the soft limit
@pytest.fixture
def router_250(tmp_path: Path) -> str:
    """An 800 mm router at 250 steps/mm with homing and soft limits, powered up un-homed."""
    path = tmp_path / "router250.toml"
    path.write_text(
        'start = "power-up"\n[settings]\n20 = 1\n22 = 1\n24 = 100.0\n27 = 1.0\n'
        "100 = 250.0\n110 = 5000.0\n120 = 500.0\n130 = 800.0\n",
        encoding="utf-8",
    )
    return str(path)


def edge_stream(increment: str) -> list[str]:
    """X- increments from MPos -1 whose exact (and float64) sum ends one step inside -800 mm.

    As a host that keeps each end one step inside the edge would write them: full increments
    while they fit, then one shortened to land on -799.996 mm.
    """
    inside = Fraction("-799.996")
    pos = Fraction(-1)
    mags: list[str] = []
    while pos - Fraction(increment) >= inside:
        mags.append(increment)
        pos -= Fraction(increment)
    last = pos - inside
    assert 0 < last < Fraction(increment)
    mags.append(f"{float(last):.4f}")
    assert Fraction(-1) - sum(Fraction(m) for m in mags) == inside
    return [f"$J=G21G91X-{m}F1850" for m in mags]


@pytest.mark.parametrize(
    ("increment", "end_mpos"),
    [
        # 37 % of 5000 mm/min for 10.5 ms blocks: 0.3237 mm a line.
        pytest.param("0.3237", "-799.920", id="37pct-10.5ms"),
        # One of the increments whose stream ends where a real Grbl 1.1h was measured to stop.
        pytest.param("0.3021", "-799.768", id="measured-end"),
    ],
)
def test_a_stream_one_step_inside_the_edge_meets_error_15(
    router_250: str, increment: str, end_mpos: str
) -> None:
    host = Host(machine=router_250)
    assert host.reply("$H", timeout_s=60.0) == "ok"
    assert mpos(host.status()) == (-1.0, -1.0, -1.0)
    lines = edge_stream(increment)
    # The oracle: the chip adds singles and refuses a target below the single -800.
    x = single(-1.0)
    expected: list[str] = []
    for line in lines:
        target = single(avr_read(line.split("X")[1].split("F")[0]) + x)
        if target < -800.0:
            expected.append("error:15")
        else:
            expected.append("ok")
            x = target
    # Only the shortened last line crosses the edge; every float64 target stays inside.
    assert expected == ["ok"] * (len(lines) - 1) + ["error:15"]
    assert stream(host, lines) == expected
    host.wait_state("Idle", timeout_s=120.0)
    fw = host.fw
    assert fw.parser.position_mm[0] == x
    assert fw.motion.position_steps()[0] == c_lround(single(x * 250.0))
    report = host.status()
    assert field(report, "MPos") == f"{end_mpos},-1.000,-1.000"
