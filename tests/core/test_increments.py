"""Jog-increment math against hand-computed values (hobby router: v = 83.3 mm/s, a = 500)."""

from __future__ import annotations

import math
from collections.abc import Callable

import pytest
from hypothesis import given
from hypothesis import strategies as st

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
        # The 10 mm queued at V/2 run at V/2 first: a block is never run above its own feed.
        pytest.param(10.0, V / 2, V, False, 10.0 / (V / 2) + (V / 2) / A, id="speeding-up"),
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


INF = math.inf
# A keep-out naming X and Y only on a 3-axis machine, as the jog engine hands it over: bounds
# shorter than the ray, or (the same zone written out) infinite along Z.
XY_LO, XY_HI = (3.0, -1.0), (4.0, 1.0)
XY_LO_INF, XY_HI_INF = (3.0, -1.0, -INF), (4.0, 1.0, INF)


@pytest.mark.parametrize(
    ("lo", "hi"), [(XY_LO, XY_HI), (XY_LO_INF, XY_HI_INF)], ids=["short", "inf"]
)
@pytest.mark.parametrize(
    ("start", "unit_vec", "expected"),
    [
        pytest.param((0.0, 0.0, 50.0), (1.0, 0.0, 0.0), (3.0, 0), id="level-at-any-height"),
        pytest.param((0.0, 0.0, -9e9), (0.6, 0.0, 0.8), (5.0, 0), id="climbing-into-the-side"),
        pytest.param((3.5, -3.0, 7.0), (0.0, 1.0, 0.0), (2.0, 1), id="through-the-bottom"),
        pytest.param((0.0, 5.0, 0.0), (1.0, 0.0, 0.0), (INF, None), id="passes-beside"),
        pytest.param((3.5, 0.0, 10.0), (0.0, 0.0, -1.0), (INF, None), id="inside-going-down"),
        pytest.param((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (INF, None), id="beside-going-up"),
        pytest.param((3.0, 0.0, 0.0), (0.0, 0.0, 1.0), (INF, None), id="on-a-face-going-up"),
    ],
)
def test_ray_box_entry_with_axes_the_zone_leaves_out(
    lo: tuple[float, ...],
    hi: tuple[float, ...],
    start: tuple[float, ...],
    unit_vec: tuple[float, ...],
    expected: tuple[float, int | None],
) -> None:
    """An axis the zone does not name is unbounded: the zone blocks every height of its X/Y area."""
    t, face = inc.ray_box_entry(start, unit_vec, lo, hi)
    assert not math.isnan(t)
    assert t == pytest.approx(expected[0])
    assert face == expected[1]


@pytest.mark.parametrize(
    ("start", "unit_vec", "lo", "hi", "expected"),
    [
        pytest.param((0.0, 0.0), (0.0, 1.0), (-INF, -INF), (INF, INF), (INF, None), id="no-bounds"),
        pytest.param((0.0, 0.0), (1.0, 0.0), (-INF, -5.0), (INF, 5.0), (INF, None), id="open-x"),
        pytest.param((0.0, 0.0), (0.6, -0.8), (-INF, -4.0), (INF, 4.0), (5.0, 1), id="to-a-face"),
        pytest.param((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), (-1.0,), (1.0,), (INF, None), id="short"),
        pytest.param((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (-1.0, -1.0), (1.0, 1.0), (INF, None),
                     id="short-along-the-free-axis"),
        pytest.param((0.0, 0.0, 0.0), (0.0, 0.6, 0.8), (-1.0, -3.0), (1.0, 3.0), (5.0, 1),
                     id="short-to-a-face"),
    ],
)  # fmt: skip
def test_ray_box_exit_with_infinite_or_missing_bounds(
    start: tuple[float, ...],
    unit_vec: tuple[float, ...],
    lo: tuple[float, ...],
    hi: tuple[float, ...],
    expected: tuple[float, int | None],
) -> None:
    """No face in the way gives (inf, None), never NaN; missing axes are unbounded."""
    t, axis = inc.ray_box_exit(start, unit_vec, lo, hi)
    assert not math.isnan(t)
    assert t == pytest.approx(expected[0])
    assert axis == expected[1]


@pytest.mark.parametrize("function", [inc.ray_box_entry, inc.ray_box_exit])
def test_ray_boxes_refuse_bounds_for_axes_the_ray_lacks(function: Callable[..., object]) -> None:
    """A box with more axes than the position is a caller's mistake, said in words."""
    with pytest.raises(ValueError, match=r"3 axes .* 2"):
        function((0.0, 0.0), (1.0, 0.0), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0))


_COORD = st.one_of(
    st.floats(min_value=-1e6, max_value=1e6, allow_nan=False), st.sampled_from([0.0, -0.0])
)
_BOUND = st.one_of(_COORD, st.sampled_from([INF, -INF]))


@given(
    st.lists(st.tuples(_COORD, st.sampled_from([-1.0, -0.5, 0.0, 0.5, 1.0]), _BOUND, _BOUND),
             min_size=1, max_size=6),
    st.integers(min_value=0, max_value=6),
)  # fmt: skip
def test_ray_boxes_never_give_nan_or_divide_by_zero(
    axes: list[tuple[float, float, float, float]], named: int
) -> None:
    """Any finite position, any direction with zero components, any ±inf bounds: a number."""
    start = tuple(a[0] for a in axes)
    direction = tuple(a[1] for a in axes)
    lo = tuple(min(a[2], a[3]) for a in axes)[:named]
    hi = tuple(max(a[2], a[3]) for a in axes)[:named]
    for function in (inc.ray_box_entry, inc.ray_box_exit):
        t, axis = function(start, direction, lo, hi)
        assert not math.isnan(t)
        assert t >= 0.0
        assert axis is None or 0 <= axis < len(lo)
