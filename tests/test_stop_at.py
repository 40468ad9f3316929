"""The pendant's "Stop at" against the simulator's ground truth, at full speed.

`Jogger.stop_point_mm()` is what the page shows while a jog is held. Here a full-speed X jog on
the built-in machine (Grbl 1.1h simulator, hobby router, the ideal in-process wire, virtual time)
is released at eight phases spread over 90 ms, and the prediction read at the moment of release
is compared with where the machine came to rest. `python -m bench stopat` prints the same for
every machine profile and speed.
"""

from __future__ import annotations

import pytest
from bench.stopat import release_miss_mm


@pytest.mark.parametrize("phase", range(8))
def test_stop_at_is_within_half_a_millimetre_at_full_speed(phase: int) -> None:
    miss_mm = release_miss_mm("hobby-router", 1.0, 2.5 + phase * 0.09 / 8)
    assert abs(miss_mm) <= 0.5
