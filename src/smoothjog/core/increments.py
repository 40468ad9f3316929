"""Jog-increment math: feed along a vector, the corrected block bound, queue depth, turn times.

The jogging doc's rule `dt > v²/(2a(N−1))` mixes units: v²/(2a) is a *distance* (the stopping
distance), which must fit in the N−1 blocks queued behind the executing one. The correct rules are
`s = v·dt ≥ v²/(2a(N−1))` for the block length and `dt ≥ v/(2a(N−1))` for its duration
(firmware-facts §4.3).

Every function here is pure arithmetic in mm, mm/s, mm/s² and s.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from decimal import ROUND_HALF_UP, Decimal

from smoothjog.core.units import Vec, limit_by_axis_maximum, mm_min_to_mm_s, norm, unit


@dataclass(frozen=True)
class VectorMove:
    """A velocity as Grbl will run it: direction, speed along it, and the acceleration it gets."""

    unit_vec: Vec
    speed_mm_s: float
    accel_mm_s2: float

    @property
    def velocity_mm_s(self) -> Vec:
        """Per-axis velocity components."""
        return tuple(u * self.speed_mm_s for u in self.unit_vec)


def vector_move(
    velocity_mm_s: Sequence[float], max_rate_mm_min: Sequence[float], accel_mm_s2: Sequence[float]
) -> VectorMove | None:
    """The move Grbl makes for a requested per-axis velocity, or None for no motion.

    The speed is the vector length of the request, capped the way Grbl caps a block (firmware-facts
    §4.2: the smallest max_i/|u_i| over moving axes), so the direction is kept and a diagonal never
    runs faster than asked. The acceleration is Grbl's along that direction.
    """
    speed = norm(velocity_mm_s)
    if speed <= 0.0:
        return None
    u = unit(velocity_mm_s)
    cap_mm_s = mm_min_to_mm_s(limit_by_axis_maximum(max_rate_mm_min, u))
    return VectorMove(u, min(speed, cap_mm_s), limit_by_axis_maximum(accel_mm_s2, u))


def stop_distance_mm(speed_mm_s: float, accel_mm_s2: float) -> float:
    """Distance to brake from speed to rest: v²/(2a)."""
    return speed_mm_s * speed_mm_s / (2.0 * accel_mm_s2)


def nearest_step_mm(target_mm: Decimal, steps_per_mm: float) -> float:
    """The step nearest an exact target (machine mm), ties away from zero as Grbl's lround.

    Grbl rounds every absolute target to whole steps (firmware-facts §1.5), so a target chosen
    on that grid is where the machine ends, however its line's 4 decimals round the distance.
    """
    steps = (target_mm * Decimal(steps_per_mm)).to_integral_value(rounding=ROUND_HALF_UP)
    return float(steps) / steps_per_mm


def min_block_mm(speed_mm_s: float, accel_mm_s2: float, planner_blocks: int) -> float:
    """The shortest block letting N−1 queued blocks hold the stopping distance (corrected)."""
    return stop_distance_mm(speed_mm_s, accel_mm_s2) / max(planner_blocks - 1, 1)


def min_block_s(speed_mm_s: float, accel_mm_s2: float, planner_blocks: int) -> float:
    """The corrected time bound: dt ≥ v/(2a(N−1))."""
    return speed_mm_s / (2.0 * accel_mm_s2 * max(planner_blocks - 1, 1))


def queue_target_mm(speed_mm_s: float, accel_mm_s2: float, ahead_s: float) -> float:
    """Distance to keep queued ahead of the machine to hold speed: v²/(2a) + v·ahead_s.

    ahead_s covers what runs before the planner's own look-ahead counts: the segments the
    firmware has already committed (about 50 ms on Grbl 1.1h) and the time a new line needs to
    reach the planner (bytes on the wire plus parsing).
    """
    return stop_distance_mm(speed_mm_s, accel_mm_s2) + speed_mm_s * ahead_s


@functools.lru_cache(maxsize=256)  # a held jog asks for the same block length at every poll
def committed_s(block_s: float, *, segment_s: float = 0.010, segments: int = 5) -> float:
    """Longest time the firmware's prepared segments can cover when every block lasts block_s.

    Grbl cuts each block into segments of at most segment_s and ends a segment at the end of its
    block (firmware-facts §4.3, st_prep_buffer), and keeps `segments` of them prepared
    (firmware-facts §4.1). With blocks of 10.5 ms the pattern is 10, 0.5, 10, 0.5, ... so five
    segments hold at most 31 ms, not 50: short blocks shorten what a cancel cannot take back.
    """
    if block_s <= 0.0:
        return segments * segment_s
    full = int(block_s // segment_s)
    if full >= segments:
        return segments * segment_s  # every window of segments is full ones
    rest = block_s - full * segment_s
    pattern = [segment_s] * full + ([rest] if rest > 1e-9 else [])
    if not pattern:
        return segments * segment_s
    n = len(pattern)
    return max(sum(pattern[(start + k) % n] for k in range(segments)) for start in range(n))


def junction_speed_sqr(
    prev_unit: Sequence[float],
    unit_vec: Sequence[float],
    accel_mm_s2: Sequence[float],
    deviation_mm: float,
) -> float:
    """Grbl's junction-deviation limit (squared speed) between two moves (firmware-facts §4.3).

    0 for a full reversal, 1e38 (no limit) straight on; otherwise a·δ·s/(1−s) with s the sine
    of half the junction angle and a the per-axis-limited acceleration along u − u_prev.
    """
    cos_junction = -sum(p * u for p, u in zip(prev_unit, unit_vec, strict=True))
    if cos_junction > 0.999999:
        return 0.0  # a full reversal: stop at the junction
    if cos_junction < -0.999999:
        return 1e38  # straight on: no junction limit
    diff = tuple(u - p for u, p in zip(unit_vec, prev_unit, strict=True))
    diff_len = math.sqrt(sum(c * c for c in diff))
    junction_unit = tuple(c / diff_len for c in diff)
    junction_accel = limit_by_axis_maximum(accel_mm_s2, junction_unit)
    sin_half = math.sqrt(0.5 * (1.0 - cos_junction))
    return max(0.0, junction_accel * deviation_mm * sin_half / (1.0 - sin_half))


def braking_lead_mm(speed_mm_s: float, accel_mm_s2: float, lead_s: float) -> float:
    """How far the machine runs in the last lead_s before it comes to rest from speed_mm_s.

    It cruises, then brakes to rest over v/a: the last lead_s hold ½·a·t² of the braking, and
    the cruise before it when lead_s is longer than the braking.
    """
    if speed_mm_s <= 0.0 or lead_s <= 0.0:
        return 0.0
    brake_s = speed_mm_s / accel_mm_s2
    if lead_s <= brake_s:
        return 0.5 * accel_mm_s2 * lead_s**2
    return speed_mm_s**2 / (2.0 * accel_mm_s2) + speed_mm_s * (lead_s - brake_s)


def let_run_turn_s(
    queued_mm: float, speed_mm_s: float, new_speed_mm_s: float, accel_mm_s2: float, *, reverse: bool
) -> float:
    """Predicted time to reach the new velocity if the queue already sent is left to run.

    For a reversal the machine cruises until it must brake, stops at the end of the queue, then
    accelerates the other way. For a slowdown it brakes just in time to enter the slower blocks.
    For a speed-up it runs the queued blocks at their own feed (the planner never goes faster
    than a block's feed within it), then accelerates in the first faster block.
    """
    if speed_mm_s <= 0.0:
        return new_speed_mm_s / accel_mm_s2
    if reverse:
        cruise_mm = max(queued_mm - stop_distance_mm(speed_mm_s, accel_mm_s2), 0.0)
        return cruise_mm / speed_mm_s + (speed_mm_s + new_speed_mm_s) / accel_mm_s2
    dv = abs(speed_mm_s - new_speed_mm_s)
    brake_mm = abs(speed_mm_s**2 - new_speed_mm_s**2) / (2.0 * accel_mm_s2)
    if new_speed_mm_s >= speed_mm_s:
        return queued_mm / speed_mm_s + dv / accel_mm_s2
    cruise_mm = max(queued_mm - brake_mm - stop_distance_mm(new_speed_mm_s, accel_mm_s2), 0.0)
    return cruise_mm / speed_mm_s + dv / accel_mm_s2


def cancel_restart_s(
    speed_mm_s: float,
    new_speed_mm_s: float,
    accel_mm_s2: float,
    *,
    committed_s: float,
    idle_delay_s: float,
    round_trip_s: float,
) -> float:
    """Predicted time to reach the new velocity by cancelling and starting again from rest.

    The committed segments run out first, the machine brakes, Grbl idles `$1` twice after a
    cancel, the sync and the first new line make a round trip, then the machine accelerates.
    """
    return (
        committed_s
        + speed_mm_s / accel_mm_s2
        + 2.0 * idle_delay_s
        + 2.0 * round_trip_s
        + new_speed_mm_s / accel_mm_s2
    )


def _box_over(n_axes: int, lo_mm: Sequence[float], hi_mm: Sequence[float]) -> tuple[Vec, Vec]:
    """A box's corners over n_axes: axes it does not name (the last ones) are unbounded."""
    if len(lo_mm) != len(hi_mm):
        raise ValueError(f"box corners have {len(lo_mm)} and {len(hi_mm)} axes; give both alike")
    if len(lo_mm) > n_axes:
        raise ValueError(f"a box with {len(lo_mm)} axes cannot bound a ray of {n_axes} axes")
    free = n_axes - len(lo_mm)
    return tuple(lo_mm) + (-math.inf,) * free, tuple(hi_mm) + (math.inf,) * free


def ray_box_exit(
    start_mm: Sequence[float],
    unit_vec: Sequence[float],
    lo_mm: Sequence[float],
    hi_mm: Sequence[float],
) -> tuple[float, int | None]:
    """How far a ray from inside a box can go before leaving it, and the axis that stops it.

    The box may name fewer axes than the ray (the rest are unbounded) and have infinite bounds;
    no face in the way gives (inf, None). Positions must be finite.
    """
    best = math.inf
    axis: int | None = None
    lo_all, hi_all = _box_over(len(start_mm), lo_mm, hi_mm)
    for i, (p, u, lo, hi) in enumerate(zip(start_mm, unit_vec, lo_all, hi_all, strict=True)):
        # Zero components are skipped (no division by zero); an infinite bound gives t = ±inf,
        # never NaN, since p is finite.
        if u > 0.0:
            t = (hi - p) / u
        elif u < 0.0:
            t = (lo - p) / u
        else:
            continue
        if t < best:
            best, axis = t, i
    return max(best, 0.0), axis


def ray_box_entry(
    start_mm: Sequence[float],
    unit_vec: Sequence[float],
    lo_mm: Sequence[float],
    hi_mm: Sequence[float],
) -> tuple[float, int | None]:
    """Where a ray from outside enters a box's open interior (inf if never), and the face axis.

    Slab method; touching a face or running along it is not entering. As for ray_box_exit, axes
    the box does not name are unbounded (a keep-out given in X and Y blocks every Z) and bounds
    may be infinite: an unbounded slab is entered at t = -inf, so it never names the face.
    """
    t_enter = -math.inf
    t_exit = math.inf
    face: int | None = None
    lo_all, hi_all = _box_over(len(start_mm), lo_mm, hi_mm)
    for i, (p, u, lo, hi) in enumerate(zip(start_mm, unit_vec, lo_all, hi_all, strict=True)):
        if u == 0.0:
            if not lo < p < hi:
                return math.inf, None
            continue
        t0 = (lo - p) / u
        t1 = (hi - p) / u
        if t0 > t1:
            t0, t1 = t1, t0
        if t0 > t_enter:
            t_enter, face = t0, i
        t_exit = min(t_exit, t1)
    if t_enter >= t_exit or t_exit <= 0.0:
        return math.inf, None
    if t_enter < 0.0:
        # Already inside (moved there by other means): let the user drive out rather than trap them.
        return math.inf, None
    return t_enter, face


def sweep_enters_box(
    a_mm: Sequence[float],
    b_mm: Sequence[float],
    d_mm: Sequence[float],
    lo_mm: Sequence[float],
    hi_mm: Sequence[float],
) -> bool:
    """True when a move d_mm, started from any point between a_mm and b_mm, passes through the
    box's open interior.

    The region swept is the parallelogram {a + s(b - a) + t d : s, t in [0, 1]}. Each slab of the
    box bounds s and t linearly, so the unit square of (s, t) is clipped by two half-planes per
    bounded axis; anything left over is a start point and a time at which the move is inside.
    Axes the box does not name are unbounded (as in ray_box_entry).
    """
    lo_all, hi_all = _box_over(len(a_mm), lo_mm, hi_mm)
    poly = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
    for a, b, d, lo, hi in zip(a_mm, b_mm, d_mm, lo_all, hi_all, strict=True):
        e = b - a
        # lo < a + s e + t d < hi, as two constraints of the form k_s s + k_t t < c.
        for k_s, k_t, c in ((e, d, hi - a), (-e, -d, a - lo)):
            if math.isinf(c):
                continue
            poly = _clip_half_plane(poly, k_s, k_t, c)
            if not poly:
                return False
    return True


def _clip_half_plane(
    poly: list[tuple[float, float]], k_s: float, k_t: float, c: float
) -> list[tuple[float, float]]:
    """The part of a convex polygon where k_s s + k_t t < c (Sutherland-Hodgman, one edge)."""

    def inside(p: tuple[float, float]) -> bool:
        return k_s * p[0] + k_t * p[1] < c

    out: list[tuple[float, float]] = []
    for i, p in enumerate(poly):
        q = poly[(i + 1) % len(poly)]
        p_in, q_in = inside(p), inside(q)
        if p_in:
            out.append(p)
        if p_in != q_in:
            fp = k_s * p[0] + k_t * p[1] - c
            fq = k_s * q[0] + k_t * q[1] - c
            u = fp / (fp - fq)
            out.append((p[0] + u * (q[0] - p[0]), p[1] + u * (q[1] - p[1])))
    return out
