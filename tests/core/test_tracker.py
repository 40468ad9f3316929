"""The path tracker's math: estimate, projection, step-grid error, junction cap and pruning."""

from __future__ import annotations

import math

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from smoothjog.core.engine.tracker import (
    PATH_KEEP_MM,
    PATH_KEEP_SEGMENTS,
    PathSeg,
    PathTracker,
    nearest_in_steps,
    project,
)
from smoothjog.core.units import Vec

SPM = (250.0, 250.0, 250.0)  # one step is 0.004 mm
ACCEL = (500.0, 500.0, 200.0)
COMMITTED_S = 0.05


def tracker() -> PathTracker:
    """A tracker for a three-axis machine starting at the origin."""
    track = PathTracker(SPM, ACCEL, 0.01, COMMITTED_S)
    track.begin((0.0, 0.0, 0.0), 0.0)
    return track


def add(
    track: PathTracker, end: Vec, speed_mm_s: float = 50.0, accel_mm_s2: float = 500.0
) -> PathSeg:
    """Append a jog from the path's end to end, as the engine does."""
    start = track.end_mm
    assert start is not None
    seg = PathSeg(start, end, math.dist(start, end), speed_mm_s, accel_mm_s2, track.length_mm())
    track.append(seg)
    return seg


def test_estimate_follows_a_straight_path_with_the_firmware_kinematics() -> None:
    track = tracker()
    seg = add(track, (10.0, 0.0, 0.0))
    track.update_estimate(0.5)
    assert track.x_est_mm == 0.0  # nothing moves before the first ok
    track.ack(seg, 0.5)
    track.update_estimate(0.6)  # 0.1 s at 500 mm/s²: 50 mm/s after 2.5 mm
    assert track.v_est_mm_s == pytest.approx(50.0)
    assert track.x_est_mm == pytest.approx(2.5, abs=0.1)
    track.update_estimate(0.65)  # cruising
    assert track.x_est_mm == pytest.approx(5.0, abs=0.1)
    assert track.queued_mm() == pytest.approx(5.0, abs=0.1)
    track.update_estimate(2.0)  # braked to rest at the end of the queue
    assert track.x_est_mm == 10.0
    assert track.v_est_mm_s == 0.0
    assert track.at_rest_at_end()


@pytest.mark.parametrize(
    ("p", "a", "b", "dist_mm", "along_mm"),
    [
        ((5.0, 0.0, 0.0), (0.0, 0.0, 0.0), (10.0, 0.0, 0.0), 0.0, 5.0),  # on the segment
        ((5.0, 3.0, 0.0), (0.0, 0.0, 0.0), (10.0, 0.0, 0.0), 3.0, 5.0),  # beside it
        ((12.0, 0.0, 0.0), (0.0, 0.0, 0.0), (10.0, 0.0, 0.0), 2.0, 10.0),  # past the end
        ((-3.0, 4.0, 0.0), (0.0, 0.0, 0.0), (10.0, 0.0, 0.0), 5.0, 0.0),  # before the start
        ((3.0, 4.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 5.0, 0.0),  # a point segment
        ((1.0, 1.0, 0.0), (0.0, 0.0, 0.0), (2.0, 2.0, 0.0), 0.0, math.sqrt(2.0)),  # diagonal
    ],
)
def test_projection_on_a_segment(p: Vec, a: Vec, b: Vec, dist_mm: float, along_mm: float) -> None:
    d, along = project(p, a, b)
    assert d == pytest.approx(dist_mm)
    assert along == pytest.approx(along_mm)


def test_a_report_on_the_path_pulls_the_estimate_and_one_off_it_is_flagged() -> None:
    track = tracker()
    seg = add(track, (10.0, 0.0, 0.0))
    assert not track.correct_estimate((4.0, 0.0, 0.0), 0.0)  # not moving yet: nothing to do
    assert track.x_est_mm == 0.0
    track.ack(seg, 0.0)
    track.v_est_mm_s = 50.0
    assert not track.correct_estimate((4.0, 0.0, 0.0), 0.002)  # moved on by its age
    assert track.x_est_mm == pytest.approx(4.1)
    assert track.correct_estimate((4.0, 1.0, 0.0), 0.0)  # off every jog
    assert track.x_est_mm == pytest.approx(4.1)


def test_a_path_that_doubles_back_takes_the_pass_nearest_the_estimate() -> None:
    track = tracker()
    out = add(track, (10.0, 0.0, 0.0))
    add(track, (0.0, 0.0, 0.0))
    track.ack(out, 0.0)
    track.x_est_mm = 15.0
    track.correct_estimate((4.0, 0.0, 0.0), 0.0)
    assert track.x_est_mm == pytest.approx(16.0)  # on the way back, not at 4 on the way out


@pytest.mark.parametrize(
    ("mpos", "cancelled", "err_mm", "err_steps"),
    [
        ((10.0, 0.0, 0.0), False, 0.0, 0.0),  # the queue ran out at its end
        ((10.004, 0.0, 0.0), False, 0.004, 1.0),  # one step past the end
        ((5.0, 0.0, 0.0), False, 5.0, 1250.0),  # short of the end without a cancel
        ((5.0, 0.0, 0.0), True, 0.0, 0.0),  # a cancel may stop anywhere on the path
        ((10.008, 0.0, 0.0), True, 0.008, 2.0),  # two steps past the end after a cancel
    ],
)
def test_tracking_error_counts_steps_of_the_worst_axis(
    mpos: Vec, cancelled: bool, err_mm: float, err_steps: float
) -> None:
    track = tracker()
    add(track, (10.0, 0.0, 0.0))
    got_mm, got_steps = track.tracking_error(mpos, cancelled=cancelled)
    assert got_mm == pytest.approx(err_mm, abs=1e-9)
    assert got_steps == pytest.approx(err_steps, abs=1e-6)


def test_nearest_in_steps_weighs_each_axis_by_its_own_steps() -> None:
    # X counts 10 steps/mm, Y 1000: along (10t, 0.01t) the X miss is 100|t - 0.5| steps and the
    # Y miss 10|t - 0.1|; the worst of the two is least where they meet, at t = 51/110.
    steps, q = nearest_in_steps(
        (5.0, 0.001, 0.0), (0.0, 0.0, 0.0), (10.0, 0.01, 0.0), (10, 1000, 1)
    )
    t = 51 / 110
    assert steps == pytest.approx(100 * (0.5 - t), abs=1e-6)
    assert q == pytest.approx((10 * t, 0.01 * t, 0.0), abs=1e-6)


@settings(max_examples=200, deadline=None)
@given(
    ends=st.lists(st.integers(0, 12), min_size=2, max_size=30),
    report_mm=st.integers(0, 48).map(lambda q: q / 4),
    est_frac=st.floats(0.0, 1.0),
)
def test_a_report_on_a_path_of_many_passes_takes_the_pass_nearest_the_estimate(
    ends: list[int], report_mm: float, est_frac: float
) -> None:
    # Back and forth along X between whole millimetres: most reports lie on several passes.
    track = tracker()
    for end in ends:
        if end != track.end_mm[0]:  # type: ignore[index]
            add(track, (float(end), 0.0, 0.0))
    if not track.path:
        return
    track.ack(track.path[0], 0.0)
    track.x_est_mm = est_frac * track.length_mm()
    mpos = (report_mm, 0.0, 0.0)
    # The answer of a plain scan of every segment in path order, the earliest winning a tie.
    want: float | None = None
    for seg in track.path:
        d, along = project(mpos, seg.start_mm, seg.end_mm)
        x = seg.x0_mm + along
        if d <= 0.008 and (want is None or abs(x - track.x_est_mm) < abs(want - track.x_est_mm)):
            want = x
    off = track.correct_estimate(mpos, 0.0)
    assert off == (want is None)
    if want is not None:
        assert track.x_est_mm == pytest.approx(want, abs=1e-9)


_COORD = st.floats(-50.0, 50.0, allow_nan=False)
_POINT = st.tuples(_COORD, _COORD, _COORD)
_SPM = st.tuples(*[st.sampled_from([10.0, 80.0, 250.0, 1000.0])] * 3)


@settings(max_examples=300, deadline=None)
@given(p=_POINT, a=_POINT, b=_POINT, spm=_SPM)
# Y moves by a rounding error only: once broke how the test read q's place off the segment.
@example(
    p=(0.0, 0.0, 0.0), a=(0.0, -50.0, 0.0), b=(7.0, -49.99999999999999, 0.0), spm=(80.0, 10.0, 10.0)
)
def test_nearest_in_steps_is_the_minimum_over_the_segment(p: Vec, a: Vec, b: Vec, spm: Vec) -> None:
    steps, q = nearest_in_steps(p, a, b, spm)

    def err(t: float) -> float:
        return max(
            abs(ai + (bi - ai) * t - pi) * k for ai, bi, pi, k in zip(a, b, p, spm, strict=True)
        )

    # q is on the segment and its error is the one returned ...
    # Where q lies along the segment, read off the axis that moves most (an axis that moves
    # by a rounding error, 1e-14 mm, would give any value).
    span = [abs(bi - ai) for ai, bi in zip(a, b, strict=True)]
    axis = span.index(max(span))
    t_q = (q[axis] - a[axis]) / (b[axis] - a[axis]) if span[axis] > 0.0 else 0.0
    assert 0.0 <= t_q <= 1.0 + 1e-12
    assert err(t_q) == pytest.approx(steps, rel=1e-9, abs=1e-9)
    # ... and no point of a fine sweep along it does better.
    assert all(err(i / 2000) >= steps - 1e-9 for i in range(2001))


def test_tracking_error_after_a_cancel_finds_the_nearest_segment_of_a_long_path() -> None:
    # A zigzag of 40 segments; the machine stopped near the 23rd, the others are skipped by
    # their bounding boxes or lose to it.
    track = tracker()
    for k in range(40):
        add(track, (float(k + 1), 2.0 * (k % 2), 0.0))
    stop = (22.5, 0.999, 0.0)
    want = min(nearest_in_steps(stop, seg.start_mm, seg.end_mm, SPM)[0] for seg in track.path)
    got_mm, got_steps = track.tracking_error(stop, cancelled=True)
    assert got_steps == pytest.approx(want)
    # 0.001 mm off the line in Y, which falls 2 mm per mm of X: best shared as 1/3 of it.
    assert got_steps == pytest.approx(0.001 * 250 / 3, abs=1e-6)
    assert got_mm < 0.001


@pytest.mark.parametrize(
    ("mpos", "on_grid"),
    [
        ((1.0011, 0.0, -2.0), (1.0, 0.0, -2.0)),
        ((1.0029, 0.0021, -2.0019), (1.004, 0.004, -2.0)),
    ],
)
def test_reports_go_back_on_the_step_grid(mpos: Vec, on_grid: Vec) -> None:
    track = tracker()
    assert track.on_step_grid(mpos) == pytest.approx(on_grid)
    assert track.steps_from(mpos, mpos) == 0.0
    assert track.steps_from((0.0, 0.0, 0.0), (0.0, 0.008, 0.004)) == pytest.approx(2.0)


@pytest.mark.parametrize(
    ("second_end", "entry_cap_mm_s"),
    [
        ((20.0, 0.0, 0.0), 40.0),  # straight on: the slower of the two speeds
        ((10.0, 10.0, 0.0), math.sqrt(500 * math.sqrt(2) * 0.01 * 0.5**0.5 / (1 - 0.5**0.5))),
        ((0.0, 0.0, 0.0), 0.0),  # a reversal stops at the junction
    ],
)
def test_junction_caps_the_entry_speed(second_end: Vec, entry_cap_mm_s: float) -> None:
    track = tracker()
    first = add(track, (10.0, 0.0, 0.0), speed_mm_s=50.0)
    second = add(track, second_end, speed_mm_s=40.0)
    assert first.entry_cap_mm_s == 0.0  # the first jog starts from rest
    assert second.entry_cap_mm_s == pytest.approx(entry_cap_mm_s)
    assert track.end_mm == second_end


def test_speed_cap_brakes_for_the_junction_ahead() -> None:
    track = tracker()
    add(track, (10.0, 0.0, 0.0))
    add(track, (10.0, 10.0, 0.0))  # a right angle: about 4.1 mm/s at the corner
    track.x_est_mm = 9.9
    corner = track.path[1].entry_cap_mm_s
    assert track.speed_cap_mm_s(0) == pytest.approx(math.sqrt(corner**2 + 2 * 500 * 0.1))


@pytest.mark.parametrize(
    ("n_segs", "seg_mm", "speed_mm_s", "kept"),
    [
        (200, 0.5, 50.0, 41),  # 20 mm kept behind the estimate at the end of 100 mm
        (200, 0.05, 1.0, PATH_KEEP_SEGMENTS),  # many short, slow jogs: capped in number
        # ... but never within what a report 0.3 s late can show at the speed jogged
        # (1 mm + 50 mm/s x 0.3 s = 16 mm: 320 jogs, and the one ending right there), however
        # the estimate has braked.
        (1000, 0.05, 50.0, 321),
        (200, 0.005, 1.0, 200),  # never drop the last millimetre, however many jogs it holds
    ],
)
def test_pruning_keeps_the_recent_path(
    n_segs: int, seg_mm: float, speed_mm_s: float, kept: int
) -> None:
    track = tracker()
    for i in range(n_segs):
        add(track, ((i + 1) * seg_mm, 0.0, 0.0), speed_mm_s)
    track.x_est_mm = track.length_mm()
    track.prune()
    assert len(track.path) == kept
    assert track.path[-1].end_mm[0] == pytest.approx(n_segs * seg_mm)  # the end is kept
    first = track.path[0]
    assert first.x0_mm + first.length_mm >= track.x_est_mm - PATH_KEEP_MM - 1e-9


def test_pruning_keeps_everything_ahead() -> None:
    track = tracker()
    for i in range(200):
        add(track, ((i + 1) * 0.5, 0.0, 0.0))
    track.prune()
    assert len(track.path) == 200


def test_stop_point_is_committed_time_plus_braking_ahead() -> None:
    track = tracker()
    add(track, (20.0, 0.0, 0.0))
    track.x_est_mm = 2.0
    track.v_est_mm_s = 50.0
    # 50 mm/s x 50 ms committed + 50² / (2 x 500) braking = 5 mm beyond the estimate.
    assert track.stop_point_mm() == pytest.approx((7.0, 0.0, 0.0))
    track.v_est_mm_s = 0.0
    assert track.stop_point_mm() == pytest.approx((2.0, 0.0, 0.0))


def test_queued_blocks_and_the_longest_one() -> None:
    track = tracker()
    add(track, (1.0, 0.0, 0.0), speed_mm_s=50.0)  # 20 ms
    add(track, (2.0, 0.0, 0.0), speed_mm_s=10.0)  # 100 ms
    add(track, (3.0, 0.0, 0.0), speed_mm_s=50.0)  # 20 ms
    assert track.blocks_in_planner() == 3
    assert track.longest_queued_s(0.01) == pytest.approx(0.1)
    track.x_est_mm = 2.0  # the first two are done
    assert track.blocks_in_planner() == 1
    assert track.longest_queued_s(0.01) == pytest.approx(0.02)
    track.v_est_mm_s = 20.0  # 1 mm committed: the last one is in the firmware's hands
    assert track.blocks_in_planner() == 0


def test_drop_and_reset_forget_the_path() -> None:
    track = tracker()
    seg = add(track, (10.0, 0.0, 0.0))
    track.remove(seg)
    assert track.path == []
    add(track, (20.0, 0.0, 0.0))
    track.x_est_mm, track.v_est_mm_s = 3.0, 10.0
    track.drop()
    assert (track.path, track.end_mm, track.x_est_mm) == ([], None, 3.0)
    track.reset()
    assert (track.x_est_mm, track.v_est_mm_s) == (0.0, 0.0)


def test_point_at_on_an_empty_path_is_its_end() -> None:
    """With every jog removed the position along the path is where the path ended."""
    track = tracker()
    assert track.point_at(5.0) == (0.0, 0.0, 0.0)
    track.drop()
    assert track.point_at(5.0) == ()


def test_stop_point_counts_only_what_short_blocks_let_the_firmware_commit() -> None:
    # Blocks of 10.5 ms are cut into 10 + 0.5 ms segments, so five prepared segments hold at
    # most 31 ms (increments.committed_s), not the 50 ms the queue is sized for.
    track = tracker()
    for i in range(40):
        add(track, ((i + 1) * 0.525, 0.0, 0.0))  # 0.525 mm at 50 mm/s: 10.5 ms each
    track.x_est_mm = 2.0
    track.v_est_mm_s = 50.0
    committed_s = 0.031
    assert track.stop_point_mm() == pytest.approx((2.0 + 50.0 * committed_s + 2.5, 0.0, 0.0))
