"""The link split: a cruise's status reports tell the way out from the way back."""

from __future__ import annotations

import random

import pytest

from smoothjog.core.engine.linksplit import MAX_GAP_S, MIN_SAMPLES, WINDOW, LinkSplit

V_MM_S = 80.0
WIRE_S = 0.004  # a report's own bytes at 115200 baud


def _cruise(
    split: LinkSplit,
    n: int,
    *,
    out_s: list[float],
    back_s: list[float],
    start_s: float = 1.0,
    key: object = "X-",
) -> list[float]:
    """Feed n reports asked every 50 ms of a machine at V_MM_S through x = V_MM_S * t; each
    `?` takes out_s[i] to be answered, the report back_s[i] (its wire time included) to
    arrive. Returns each report's true age on arrival."""
    ages = []
    for i in range(n):
        asked_s = start_s + 0.05 * i
        built_s = asked_s + out_s[i]
        now_s = built_s + back_s[i]
        split.add(key, asked_s, now_s, V_MM_S * built_s, V_MM_S, WIRE_S)
        ages.append(now_s - built_s)
    return ages


def test_nothing_is_told_before_enough_reports_of_one_cruise() -> None:
    split = LinkSplit()
    _cruise(split, MIN_SAMPLES - 1, out_s=[0.001] * 20, back_s=[0.010] * 20)
    assert not split.ready
    assert split.spread_s() is None
    assert split.newest_age_s() is None
    assert split.fastest_s() is None
    asked_s = 1.0 + 0.05 * (MIN_SAMPLES - 1)
    split.add("X-", asked_s, asked_s + 0.011, V_MM_S * (asked_s + 0.001), V_MM_S, WIRE_S)
    assert split.ready


def test_an_adapter_that_holds_replies_back_is_seen_as_a_slow_way_back() -> None:
    # FTDI-like: the way out within a 1 ms USB frame, the way back 4-20 ms (latency timer).
    rng = random.Random(1)
    out_s = [rng.uniform(0.0, 0.001) for _ in range(WINDOW)]
    back_s = [WIRE_S + rng.uniform(0.0, 0.016) for _ in range(WINDOW)]
    split = LinkSplit()
    ages = _cruise(split, WINDOW, out_s=out_s, back_s=back_s)
    spread = split.spread_s()
    assert spread is not None
    assert spread == pytest.approx(max(out_s) - min(out_s))
    assert spread < 0.001  # not the 16 ms the round trips vary by
    age = split.newest_age_s()
    assert age is not None
    # Never younger than it is (the estimate must not lag the machine), and too old by no
    # more than the fastest way out.
    assert ages[-1] <= age <= ages[-1] + min(out_s) + 1e-12
    fastest = split.fastest_s()
    assert fastest is not None
    assert fastest == pytest.approx(min(o + b - WIRE_S for o, b in zip(out_s, back_s, strict=True)))


def test_a_jittery_way_out_is_what_the_spread_shows() -> None:
    rng = random.Random(2)
    out_s = [0.0025 + rng.uniform(0.0, 0.0225) for _ in range(WINDOW)]
    back_s = [0.0025 + rng.uniform(0.0, 0.0225) for _ in range(WINDOW)]
    split = LinkSplit()
    ages = _cruise(split, WINDOW, out_s=out_s, back_s=back_s)
    assert split.spread_s() == pytest.approx(max(out_s) - min(out_s))
    age = split.newest_age_s()
    assert age is not None
    assert ages[-1] <= age <= ages[-1] + min(out_s) + 1e-12


@pytest.mark.parametrize("breaks", ["another move", "went backwards", "long gap", "no speed"])
def test_a_report_that_breaks_the_cruise_starts_the_window_afresh(breaks: str) -> None:
    split = LinkSplit()
    _cruise(split, WINDOW, out_s=[0.001] * WINDOW, back_s=[0.010] * WINDOW)
    assert split.ready
    last_s = 1.0 + 0.05 * (WINDOW - 1)
    asked_s = last_s + 0.05
    along_mm = V_MM_S * (asked_s + 0.001)
    key: object = "X-"
    speed = V_MM_S
    if breaks == "another move":
        key = "Y+"
    elif breaks == "went backwards":
        along_mm = 0.0
    elif breaks == "long gap":
        asked_s = last_s + MAX_GAP_S + 0.1
        along_mm = V_MM_S * (asked_s + 0.001)
    else:
        speed = 0.0
    split.add(key, asked_s, asked_s + 0.011, along_mm, speed, WIRE_S)
    assert not split.ready


def test_reset_forgets_the_cruise() -> None:
    split = LinkSplit()
    _cruise(split, WINDOW, out_s=[0.001] * WINDOW, back_s=[0.010] * WINDOW)
    split.reset()
    assert not split.ready
