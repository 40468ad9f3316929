"""Ground-truth measurements: what the simulated machine really did, from its segment trace."""

from __future__ import annotations

import bisect
import itertools
import math
import operator
from collections.abc import Sequence

from smoothjog.sim.motion import TraceSegment

#: Normalised correlation below which a velocity is said not to follow a command at all.
FOLLOW_MATCH = 0.5
#: A segment slower than this is treated as standing still (mm/s): below one step per second.
REST_MM_S = 1e-3


def distance_after(trace: Sequence[TraceSegment], t_s: float) -> float:
    """Path length travelled after t_s (every restart included)."""
    total = 0.0
    for seg in trace:
        if seg.t1_s <= t_s:
            continue
        length = math.dist(seg.start_mm, seg.end_mm)
        span = seg.t1_s - seg.t0_s
        if seg.t0_s >= t_s or span <= 0:
            total += length
        else:
            total += length * (seg.t1_s - t_s) / span
    return total


def mean_speed(trace: Sequence[TraceSegment], t0_s: float, t1_s: float) -> float:
    """Path length travelled over [t0_s, t1_s] divided by its duration (mm/s)."""
    return (distance_after(trace, t0_s) - distance_after(trace, t1_s)) / (t1_s - t0_s)


def position_at(
    trace: Sequence[TraceSegment], t_s: float, starts_s: Sequence[float] | None = None
) -> tuple[float, ...]:
    """Where the machine really was at t_s; starts_s (every segment's t0_s) speeds up the search."""
    if not trace:
        return ()
    starts = starts_s if starts_s is not None else [seg.t0_s for seg in trace]
    i = bisect.bisect_right(starts, t_s) - 1
    if i < 0:
        return trace[0].start_mm
    seg = trace[i]
    if t_s >= seg.t1_s or seg.t1_s <= seg.t0_s:
        return seg.end_mm
    f = (t_s - seg.t0_s) / (seg.t1_s - seg.t0_s)
    return tuple(a + f * (b - a) for a, b in zip(seg.start_mm, seg.end_mm, strict=True))


def last_motion_end(trace: Sequence[TraceSegment]) -> float:
    """When the machine last stopped moving."""
    moving = [s.t1_s for s in trace if s.speed_mm_s > REST_MM_S]
    return max(moving) if moving else 0.0


def restarts_after(trace: Sequence[TraceSegment], t_s: float) -> int:
    """How many times the machine started again after coming to rest, after t_s."""
    count = 0
    prev_end: float | None = None
    for seg in trace:
        if seg.t1_s <= t_s or seg.speed_mm_s <= REST_MM_S:
            continue
        if prev_end is not None and seg.t0_s - prev_end > 1e-6:
            count += 1
        prev_end = seg.t1_s
    return count


def velocity_at(
    trace: Sequence[TraceSegment], t_s: float, start: int = 0
) -> tuple[tuple[float, ...], int]:
    """Velocity vector at t_s (zero between segments) and the index to resume a forward scan."""
    i = start
    while i < len(trace) and trace[i].t1_s <= t_s:
        i += 1
    if i < len(trace) and trace[i].t0_s <= t_s:
        seg = trace[i]
        dt = seg.t1_s - seg.t0_s
        if dt > 0:
            return tuple((e - s) / dt for s, e in zip(seg.start_mm, seg.end_mm, strict=True)), i
    n = len(trace[0].start_mm) if trace else 3
    return (0.0,) * n, i


def sample_velocity(
    trace: Sequence[TraceSegment], t0_s: float, t1_s: float, dt_s: float = 0.001
) -> list[tuple[float, tuple[float, ...]]]:
    """The velocity vector every dt_s over [t0_s, t1_s)."""
    out = []
    idx = 0
    steps = int((t1_s - t0_s) / dt_s)
    for k in range(steps):
        t = t0_s + k * dt_s
        v, idx = velocity_at(trace, t, idx)
        out.append((t, v))
    return out


def hold_quality(
    trace: Sequence[TraceSegment], t0_s: float, t1_s: float, speed_mm_s: float
) -> tuple[float, int]:
    """Share of [t0, t1] spent within 2 % of speed, and how many times it dipped below 98 %."""
    samples = sample_velocity(trace, t0_s, t1_s)
    inside = 0
    dips = 0
    below = False
    for _, v in samples:
        s = math.sqrt(sum(c * c for c in v))
        ok = abs(s - speed_mm_s) <= 0.02 * speed_mm_s
        inside += ok
        now_below = s < 0.98 * speed_mm_s
        if now_below and not below:
            dips += 1
        below = now_below
    return (inside / len(samples) if samples else 0.0), dips


def time_to_velocity(
    trace: Sequence[TraceSegment], t0_s: float, t_end_s: float, axis: int, target_mm_s: float
) -> float | None:
    """First time after t0 that the velocity along axis reaches 98 % of target (signed)."""
    for t, v in sample_velocity(trace, t0_s, t_end_s):
        if target_mm_s > 0 and v[axis] >= 0.98 * target_mm_s:
            return t - t0_s
        if target_mm_s < 0 and v[axis] <= 0.98 * target_mm_s:
            return t - t0_s
    return None


def settle_time(
    trace: Sequence[TraceSegment], t0_s: float, t_end_s: float, speed_mm_s: float
) -> float | None:
    """Time after t0 from which the speed stays within 2 % of speed_mm_s until t_end."""
    last_out: float | None = None
    for t, v in sample_velocity(trace, t0_s, t_end_s):
        s = math.sqrt(sum(c * c for c in v))
        if abs(s - speed_mm_s) > 0.02 * speed_mm_s:
            last_out = t
    if last_out is None:
        return 0.0
    if last_out >= t_end_s - 0.002:
        return None
    return last_out - t0_s + 0.001


def lag_and_match(
    commanded: Sequence[tuple[float, float]],
    actual: Sequence[tuple[float, float]],
    max_lag_s: float = 0.5,
    step_s: float = 0.001,
    min_match: float = FOLLOW_MATCH,
) -> tuple[float, float]:
    """The shift of actual behind commanded (both sampled every step_s) that matches them best,
    and how well they match there (normalised correlation, 1 = the same shape).

    The lag is infinite when the machine does not follow: it barely moved, the best shift is the
    end of the search window (no optimum inside it; the match is then 0), or even shifted the
    velocity matches the command less than min_match (it moved, but not like the stick).
    """
    cmd = [c for _, c in commanded]
    act = [a for _, a in actual]
    if max((abs(a) for a in act), default=0.0) < 0.05 * max((abs(c) for c in cmd), default=1.0):
        return math.inf, 0.0  # the machine hardly moved: it never followed
    # Running sums of squares, so each shift's normalisation costs O(1).
    cmd_sq = list(itertools.accumulate((c * c for c in cmd), initial=0.0))
    act_sq = list(itertools.accumulate((a * a for a in act), initial=0.0))
    best_k, best_match = 0, -math.inf
    last_k = 0
    for k in range(int(max_lag_s / step_s) + 1):
        n = min(len(cmd), len(act) - k)
        if n <= 10:
            break
        last_k = k
        # Normalised correlation over the overlap: the window shrinks as the shift grows, and
        # a plain mean product would then favour shifts that merely cut off part of a period.
        power = math.sqrt(cmd_sq[n] * (act_sq[k + n] - act_sq[k]))
        dot = sum(map(operator.mul, cmd[:n], act[k : k + n]))
        match = dot / power if power > 0 else 0.0
        if match > best_match:
            best_k, best_match = k, match
    if best_k == last_k:
        return math.inf, 0.0
    return (best_k * step_s if best_match >= min_match else math.inf), best_match
