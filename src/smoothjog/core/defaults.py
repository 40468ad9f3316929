"""Grbl 1.1h's default `$` settings (`defaults.h` DEFAULTS_GENERIC), held once for every layer.

The machine model falls back on them for any setting a controller has not reported, and the
simulator starts from them (firmware-facts §0). The values are those of the default 3-axis build; a
machine with more axes repeats each per-axis default (`$100+i`, `$110+i`, `$120+i`, `$130+i`).
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Final

#: Axes of the default build (`N_AXIS`).
DEFAULT_AXES: Final = 3

# The first setting number of each per-axis group; axis i adds i (firmware-facts §0).
STEPS_PER_MM_SETTING: Final = 100
MAX_RATE_SETTING: Final = 110
ACCEL_SETTING: Final = 120
MAX_TRAVEL_SETTING: Final = 130
AXIS_GROUP_SETTINGS: Final = (
    STEPS_PER_MM_SETTING,
    MAX_RATE_SETTING,
    ACCEL_SETTING,
    MAX_TRAVEL_SETTING,
)

DEFAULT_STEP_IDLE_DELAY_MS: Final = 25.0  # $1 (255 keeps the motors enabled)
DEFAULT_STATUS_MASK: Final = 1  # $10: MPos in reports, no Bf
DEFAULT_JUNCTION_DEVIATION_MM: Final = 0.010  # $11
DEFAULT_ARC_TOLERANCE_MM: Final = 0.002  # $12
DEFAULT_PULL_OFF_MM: Final = 1.0  # $27
DEFAULT_STEPS_PER_MM: Final = 250.0  # $100..
DEFAULT_MAX_RATE_MM_MIN: Final = 500.0  # $110..
DEFAULT_ACCEL_MM_S2: Final = 10.0  # $120.. (Grbl stores it x3600 as mm/min²)
DEFAULT_MAX_TRAVEL_MM: Final = 200.0  # $130..

#: Per-axis group -> its default, for filling any number of axes.
AXIS_GROUP_DEFAULTS: Final = MappingProxyType(
    {
        STEPS_PER_MM_SETTING: DEFAULT_STEPS_PER_MM,
        MAX_RATE_SETTING: DEFAULT_MAX_RATE_MM_MIN,
        ACCEL_SETTING: DEFAULT_ACCEL_MM_S2,
        MAX_TRAVEL_SETTING: DEFAULT_MAX_TRAVEL_MM,
    }
)

#: Every setting of the default 3-axis build, by `$` number, as `$$` would list it.
GRBL_DEFAULTS: Final[MappingProxyType[int, float]] = MappingProxyType(
    {
        0: 10,  # step pulse, µs
        1: DEFAULT_STEP_IDLE_DELAY_MS,
        2: 0,  # step port invert mask
        3: 0,  # direction port invert mask
        4: 0,  # step enable invert
        5: 0,  # limit pins invert
        6: 0,  # probe pin invert
        10: DEFAULT_STATUS_MASK,
        11: DEFAULT_JUNCTION_DEVIATION_MM,
        12: DEFAULT_ARC_TOLERANCE_MM,
        13: 0,  # report in mm
        20: 0,  # soft limits off
        21: 0,  # hard limits off
        22: 0,  # homing off
        23: 0,  # every axis homes toward +
        24: 25.0,  # homing feed, mm/min
        25: 500.0,  # homing seek, mm/min
        26: 250,  # homing debounce, ms
        27: DEFAULT_PULL_OFF_MM,
        30: 1000,  # max spindle speed, rpm
        31: 0,  # min spindle speed, rpm
        32: 0,  # laser mode off
        **{
            group + axis: default
            for group, default in AXIS_GROUP_DEFAULTS.items()
            for axis in range(DEFAULT_AXES)
        },
    }
)
