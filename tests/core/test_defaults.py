"""Tests for core/defaults.py: Grbl's default settings as firmware-facts §0 lists them, used by the
model."""

from __future__ import annotations

from dataclasses import replace

import pytest

from smoothjog.core.defaults import DEFAULT_AXES, GRBL_DEFAULTS
from smoothjog.core.machine import MachineModel, Settings

# firmware-facts §0, written out again so a slip in the table shows.
FACTS_0 = {
    **dict.fromkeys((100, 101, 102), 250.0),
    **dict.fromkeys((110, 111, 112), 500.0),
    **dict.fromkeys((120, 121, 122), 10.0),
    **dict.fromkeys((130, 131, 132), 200.0),
    10: 1,
    11: 0.010,
    12: 0.002,
    13: 0,
    20: 0,
    21: 0,
    22: 0,
    23: 0,
    27: 1.000,
}


@pytest.mark.parametrize(("number", "value"), sorted(FACTS_0.items()))
def test_the_facts_defaults(number: int, value: float) -> None:
    assert GRBL_DEFAULTS[number] == value


def test_three_axes_and_every_group_filled() -> None:
    assert DEFAULT_AXES == 3
    per_axis = [n for n in GRBL_DEFAULTS if n >= 100]
    assert per_axis == [100, 101, 102, 110, 111, 112, 120, 121, 122, 130, 131, 132]


def test_the_model_falls_back_on_them() -> None:
    settings = Settings()
    assert settings.status_mask == GRBL_DEFAULTS[10]
    assert settings.junction_deviation_mm == GRBL_DEFAULTS[11]
    assert settings.pull_off_mm == GRBL_DEFAULTS[27]
    assert settings.steps_per_mm == (GRBL_DEFAULTS[100],) * 3
    assert settings.max_rate_mm_min == (GRBL_DEFAULTS[110],) * 3
    assert settings.accel_mm_s2 == (GRBL_DEFAULTS[120],) * 3
    assert settings.max_travel_mm == (GRBL_DEFAULTS[130],) * 3
    assert MachineModel().n_axes == DEFAULT_AXES


def test_a_full_default_listing_reads_back_as_the_defaults() -> None:
    raw = {number: f"{value:g}" for number, value in GRBL_DEFAULTS.items()}
    assert replace(Settings.from_raw(raw), raw=()) == Settings()
