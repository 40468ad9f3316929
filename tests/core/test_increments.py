"""Jog-increment math against hand-computed values (hobby router: v = 83.3 mm/s, a = 500)."""

from __future__ import annotations

import math

import pytest

from smoothjog.core import increments as inc

V = 5000 / 60
A = 500.0


@pytest.mark.parametrize(
    ("block_s", "expected_s"),
    [
        (0.0105, 0.031),  # 10, 0.5, 10, 0.5, 10
        (0.010, 0.050),  # whole segments
        (0.005, 0.025),  # one short segment per block
        (0.0155, 0.041),  # 10, 5.5, 10, 5.5, 10
        (0.1, 0.050),
        (2.0, 0.050),
    ],
)
def test_committed_time_follows_the_segment_pattern(block_s: float, expected_s: float) -> None:
    assert inc.committed_s(block_s) == pytest.approx(expected_s, abs=1e-9)


def test_corrected_block_bound_has_the_right_units() -> None:
    # dt >= v / (2 a (N-1)): 83.3 / (2 * 500 * 14) = 5.95 ms; the printed form would give 0.496 s.
    assert inc.min_block_s(V, A, 15) == pytest.approx(0.005952, rel=1e-3)
    assert inc.min_block_mm(V, A, 15) == pytest.approx(V * V / (2 * A * 14))
    assert inc.stop_distance_mm(V, A) == pytest.approx(6.944, rel=1e-3)


def test_vector_move_caps_the_diagonal_like_grbl() -> None:
    move = inc.vector_move((V, V, 0.0), (5000, 5000, 1500), (500, 500, 200))
    assert move is not None
    assert move.speed_mm_s == pytest.approx(V * math.sqrt(2))  # both axes at their own max
    move = inc.vector_move((2 * V, 0.0, 0.0), (5000, 5000, 1500), (500, 500, 200))
    assert move is not None
    assert move.speed_mm_s == pytest.approx(V)  # capped at $110
    assert inc.vector_move((0.0, 0.0, 0.0), (1, 1, 1), (1, 1, 1)) is None


def test_turn_predictions() -> None:
    # Reversal with exactly the stopping distance queued: v/a to stop, v/a back up.
    assert inc.let_run_turn_s(V * V / (2 * A), V, V, A, reverse=True) == pytest.approx(2 * V / A)
    cancel = inc.cancel_restart_s(
        V, V, A, committed_s=0.031, idle_delay_s=0.025, round_trip_s=0.004
    )
    assert cancel == pytest.approx(0.031 + 2 * V / A + 0.05 + 0.008)


def test_ray_box_helpers() -> None:
    t, axis = inc.ray_box_exit((0.0, 0.0), (1.0, 0.0), (-10.0, -10.0), (5.0, 10.0))
    assert (t, axis) == (5.0, 0)
    t, face = inc.ray_box_entry((0.0, 0.0), (1.0, 0.0), (3.0, -1.0), (4.0, 1.0))
    assert (t, face) == (3.0, 0)
    t, face = inc.ray_box_entry((0.0, 1.0), (1.0, 0.0), (3.0, -1.0), (4.0, 1.0))
    assert t == math.inf  # running along a face is not entering


@pytest.mark.parametrize("block_s", [0.0, -0.01, 1e-12], ids=["zero", "negative", "sub-ns"])
def test_committed_time_of_degenerate_blocks_is_the_full_window(block_s: float) -> None:
    """No usable block length: assume five full 10 ms segments, the most ever committed."""
    assert inc.committed_s(block_s) == pytest.approx(0.050)


@pytest.mark.parametrize(
    ("queued_mm", "speed", "new_speed", "reverse", "expected_s"),
    [
        pytest.param(0.0, 0.0, V, True, V / A, id="from-rest"),
        pytest.param(10.0, V / 2, V, False, (V / 2) / A, id="speeding-up"),
        pytest.param(
            50.0,
            V,
            V / 2,
            False,
            (50.0 - (V**2 - (V / 2) ** 2) / (2 * A) - (V / 2) ** 2 / (2 * A)) / V + (V / 2) / A,
            id="slowing-down",
        ),
    ],
)
def test_let_run_turn_times(
    queued_mm: float, speed: float, new_speed: float, reverse: bool, expected_s: float
) -> None:
    got = inc.let_run_turn_s(queued_mm, speed, new_speed, A, reverse=reverse)
    assert got == pytest.approx(expected_s)


@pytest.mark.parametrize(
    ("start", "unit_vec", "expected"),
    [
        pytest.param((5.0, 0.0), (-1.0, 0.0), (1.0, 0), id="from-the-far-side"),
        pytest.param((0.0, 5.0), (1.0, 0.0), (math.inf, None), id="passes-beside"),
        pytest.param((0.0, 0.0), (-1.0, 0.0), (math.inf, None), id="moving-away"),
        pytest.param((3.5, 0.0), (1.0, 0.0), (math.inf, None), id="already-inside"),
        pytest.param((0.0, -4.0), (0.6, 0.8), (5.0, 0), id="diagonal-through-a-side"),
        pytest.param((3.5, -3.0), (0.0, 1.0), (2.0, 1), id="through-the-bottom"),
    ],
)
def test_ray_box_entry_cases(
    start: tuple[float, float], unit_vec: tuple[float, float], expected: tuple[float, int | None]
) -> None:
    """A box from (3, -1) to (4, 1): where a ray enters its interior, if ever."""
    t, face = inc.ray_box_entry(start, unit_vec, (3.0, -1.0), (4.0, 1.0))
    assert t == pytest.approx(expected[0])
    assert face == expected[1]
