"""Tracks the jogs sent as one path in machine mm, and where along it the machine should be now.

The estimate runs the firmware's own kinematics along the path (accelerate to each jog's speed,
brake for junctions, slower jogs and the end of the queue) and is pulled onto each status
report. Distances along the path are `x_mm`, from the start of the first jog sent.
"""

from __future__ import annotations

import bisect
import itertools
import math
import operator
from collections.abc import Sequence
from dataclasses import dataclass, field

from smoothjog.core import increments as inc
from smoothjog.core.units import Vec, norm, unit

#: Distance of finished path kept behind the estimate (a stop is judged against the path ahead).
PATH_KEEP_MM = 20.0
#: At most this many jogs are remembered (a slow jog makes many short ones); far more than
#: the planner can hold, so every jog not yet run is always kept.
PATH_KEEP_SEGMENTS = 96


#: The key seg_index_at bisects the path by (a C getter: it runs several times every poll).
_X0 = operator.attrgetter("x0_mm")


@dataclass
class PathSeg:
    """One jog sent: where it starts and ends in machine mm, and its speed."""

    start_mm: Vec
    end_mm: Vec
    length_mm: float
    speed_mm_s: float
    accel_mm_s2: float
    x0_mm: float  # distance along the path where this jog starts
    acked: bool = False
    entry_cap_mm_s: float = 0.0  # fastest the planner lets the machine enter it (junction)
    #: Its direction, when the sender already knows it (else worked out from start and end).
    unit_vec: Vec | None = None
    #: Where it ends along the path (x0_mm + length_mm), and how long it runs at its speed (0
    #: without one): worked out once, since the queue is scanned several times every poll.
    x1_mm: float = field(init=False, repr=False, compare=False)
    run_s: float = field(init=False, repr=False, compare=False)
    #: How many jogs in a row, ending with this one, enter at their own speed with the same
    #: speed and acceleration as this one (0 if this one enters slower): see _streak.
    streak: int = field(default=0, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        """Work out x1_mm and run_s (the fields above are never changed after this)."""
        self.x1_mm = self.x0_mm + self.length_mm
        self.run_s = self.length_mm / self.speed_mm_s if self.speed_mm_s > 0.0 else 0.0


class PathTracker:
    """The planned path and the estimated progress (x_est_mm, v_est_mm_s) along it."""

    def __init__(
        self,
        steps_per_mm: Vec,
        accel_mm_s2: Vec,
        junction_deviation_mm: float,
        committed_s: float,
    ) -> None:
        """committed_s: time of segments the firmware has committed ahead of the steppers."""
        self.steps_per_mm = steps_per_mm
        self.accel_mm_s2 = accel_mm_s2
        self.junction_deviation_mm = junction_deviation_mm
        self.committed_s = committed_s
        self.path: list[PathSeg] = []
        self.end_mm: Vec | None = None  # end of the last jog sent (machine mm)
        self.x_est_mm = 0.0  # estimated machine progress along the path
        #: Where the last status report placed the machine along the path (before moving it
        #: on by the report's age); None until a report of this path came.
        self.x_reported_mm: float | None = None
        self.v_est_mm_s = 0.0
        self.est_s = 0.0  # when the estimate was last advanced
        self.moving_since_ack = False  # the estimate runs only once a jog has its ok

    def use_machine(
        self, steps_per_mm: Vec, accel_mm_s2: Vec, junction_deviation_mm: float
    ) -> None:
        """Take new machine limits (after a re-handshake)."""
        self.steps_per_mm = steps_per_mm
        self.accel_mm_s2 = accel_mm_s2
        self.junction_deviation_mm = junction_deviation_mm

    # ----------------------------------------------------------------- the path
    def begin(self, start_mm: Vec, now_s: float) -> None:
        """Start a new path at start_mm with the machine at rest there."""
        self.path.clear()
        self.end_mm = start_mm
        self.x_est_mm = 0.0
        self.x_reported_mm = None
        self.v_est_mm_s = 0.0
        self.est_s = now_s

    def drop(self) -> None:
        """Forget the path; nothing more follows it (the estimate is left as it was)."""
        self.path.clear()
        self.end_mm = None

    def reset(self) -> None:
        """Forget the path and the estimate (a stop is complete)."""
        self.drop()
        self.x_est_mm = 0.0
        self.x_reported_mm = None
        self.v_est_mm_s = 0.0

    def append(self, seg: PathSeg) -> None:
        """Add a sent jog to the path, with the speed the planner allows at its start."""
        if self.path:
            prev = self.path[-1]
            if seg.unit_vec is not None and seg.unit_vec is prev.unit_vec:
                # A repeat of the same increment: straight on, no junction limit.
                seg.entry_cap_mm_s = min(seg.speed_mm_s, prev.speed_mm_s)
            else:
                seg.entry_cap_mm_s = min(
                    seg.speed_mm_s, prev.speed_mm_s, self.junction_speed_mm_s(prev, seg)
                )
        seg.streak = _streak(self.path[-1] if self.path else None, seg)
        self.path.append(seg)
        self.end_mm = seg.end_mm

    def remove(self, seg: PathSeg) -> None:
        """Take out a jog the controller rejected."""
        if seg in self.path:
            self.path.remove(seg)
            # The streaks after it counted it: count them again along what is left.
            prev: PathSeg | None = None
            for kept in self.path:
                kept.streak = _streak(prev, kept)
                prev = kept

    def ack(self, seg: PathSeg, now_s: float) -> None:
        """The controller planned this jog; the first ok starts the estimate."""
        seg.acked = True
        if not self.moving_since_ack:
            self.moving_since_ack = True
            self.est_s = now_s

    def length_mm(self) -> float:
        """Distance along the path to the end of the last jog sent."""
        if not self.path:
            return 0.0
        return self.path[-1].x1_mm

    def queued_mm(self) -> float:
        """Path still ahead of the estimate."""
        return max(self.length_mm() - self.x_est_mm, 0.0)

    def blocks_in_planner(self) -> int:
        """Jogs sent whose end the machine has not yet reached, less those already committed."""
        committed_end = self.x_est_mm + self.v_est_mm_s * self.committed_s
        count = 0
        for seg in reversed(self.path):  # queued jogs are at the end; stop at the first done
            if seg.x1_mm <= committed_end:
                break
            count += 1
        return count

    def uncommitted_lead_mm(self) -> float | None:
        """How far the machine runs until the oldest block not yet committed becomes committed.

        blocks_in_planner() counts one block fewer from then on; None when none is counted.
        """
        committed_end = self.x_est_mm + self.v_est_mm_s * self.committed_s
        oldest_end: float | None = None
        for seg in reversed(self.path):
            end = seg.x1_mm
            if end <= committed_end:
                break
            oldest_end = end
        return None if oldest_end is None else oldest_end - committed_end

    def longest_queued_s(self, block_s: float) -> float:
        """Duration of the longest jog not yet finished, or block_s if that is longer."""
        longest_s = block_s
        x_est_mm = self.x_est_mm
        for seg in reversed(self.path):  # the queued jogs are at the end of the path
            if seg.x1_mm <= x_est_mm:
                break
            # A comparison, not max(): this runs over the queue at every poll.
            if seg.speed_mm_s > 0.0 and seg.run_s > longest_s:
                longest_s = seg.run_s
        return longest_s

    def prune(self, report_age_s: float = 0.3) -> None:
        """Forget jogs the machine finished long ago (the path would grow without end).

        Never forget what a status report can still show: one may be report_age_s old when it
        arrives (a stalled link delivers reports late), so that much path behind the estimate
        is kept, at least PATH_KEEP_MM.
        """
        # At the speed jogged, not the estimate's: an estimate braking at the end of what was
        # acknowledged (replies held up by the same stall) says nothing of how far back a
        # late report can be.
        speed_mm_s = max(self.v_est_mm_s, self.path[-1].speed_mm_s) if self.path else 0.0
        recent_from = self.x_est_mm - (1.0 + speed_mm_s * report_age_s)
        keep_from = min(self.x_est_mm - PATH_KEEP_MM, recent_from)
        path = self.path
        n_segs = len(path)
        drop = 0
        while drop < n_segs - 1:
            seg = path[drop]
            end_mm = seg.x1_mm
            if not (
                end_mm < keep_from or (n_segs - drop > PATH_KEEP_SEGMENTS and end_mm < recent_from)
            ):
                break
            drop += 1
        if drop:
            del path[:drop]

    def seg_index_at(self, x_mm: float) -> int | None:
        """Index of the path segment containing x_mm (bisect: the path is sorted by x0)."""
        path = self.path
        i = bisect.bisect_right(path, x_mm, key=_X0) - 1
        if 0 <= i < len(path) and x_mm < path[i].x1_mm:
            return i
        return None

    def seg_at(self, x_mm: float) -> PathSeg | None:
        """The path segment containing x_mm, if any."""
        i = self.seg_index_at(x_mm)
        return None if i is None else self.path[i]

    def point_at(self, x_mm: float) -> Vec:
        """The machine position x_mm along the path (clamped to its ends)."""
        for seg in self.path:
            if x_mm <= seg.x0_mm + seg.length_mm or seg is self.path[-1]:
                f = (
                    0.0
                    if seg.length_mm == 0
                    else min(max((x_mm - seg.x0_mm) / seg.length_mm, 0), 1)
                )
                return tuple(s + (e - s) * f for s, e in zip(seg.start_mm, seg.end_mm, strict=True))
        return self.end_mm or ()

    # ----------------------------------------------------------------- the planner's limits
    def junction_speed_mm_s(self, prev: PathSeg, seg: PathSeg) -> float:
        """Grbl's junction-deviation speed limit between two jogs (firmware-facts §4.3)."""
        u0 = unit(tuple(e - s for s, e in zip(prev.start_mm, prev.end_mm, strict=True)))
        u1 = unit(tuple(e - s for s, e in zip(seg.start_mm, seg.end_mm, strict=True)))
        return math.sqrt(
            inc.junction_speed_sqr(u0, u1, self.accel_mm_s2, self.junction_deviation_mm)
        )

    def speed_cap_mm_s(self, seg_index: int) -> float:
        """The fastest the machine can be at the estimate, braking for what lies ahead.

        Grbl plans so that every junction and slower block ahead is met at its allowed speed,
        and the end of the queue at rest; the machine cannot be faster than that.
        """
        x = self.x_est_mm
        path = self.path
        seg = path[seg_index]
        a = seg.accel_mm_s2
        cap = seg.speed_mm_s
        reach_mm = cap * cap / (2.0 * a)
        for nxt in path[seg_index + 1 :]:
            ahead = nxt.x0_mm - x
            if ahead > reach_mm:
                break
            cap = min(cap, math.sqrt(nxt.entry_cap_mm_s**2 + 2.0 * a * max(ahead, 0.0)))
        end_x = path[-1].x1_mm
        return min(cap, math.sqrt(2.0 * a * max(end_x - x, 0.0)))

    # ----------------------------------------------------------------- the estimate
    def update_estimate(self, now_s: float) -> None:
        """Advance the estimated progress along the path with the firmware's own kinematics."""
        if not self.path or not self.moving_since_ack:
            self.est_s = now_s
            return
        dt = now_s - self.est_s
        if dt <= 0.0:
            return
        self.est_s = now_s
        # Integrate in small steps so braking at the end of the queue is followed closely.
        steps = max(1, math.ceil(dt / 0.002))
        h = dt / steps
        end_x = self.length_mm()
        index = self.seg_index_at(self.x_est_mm)
        if index is not None and self._cruises(index, self.v_est_mm_s * dt, end_x):
            # Hot path (every poll of a held jog): at full speed with nothing to brake for in
            # this window, each step below would keep v and add v*h; do just that.
            step_mm = self.v_est_mm_s * h
            x_mm = self.x_est_mm
            for _ in range(steps):
                x_mm += step_mm  # the same sums, one by one, as the loop below would make
            self.x_est_mm = x_mm
            return
        for _ in range(steps):
            index = self.seg_index_at(self.x_est_mm)
            if index is None:
                self.v_est_mm_s = 0.0
                self.x_est_mm = end_x
                return
            a = self.path[index].accel_mm_s2
            v_cap = self.speed_cap_mm_s(index)
            if self.v_est_mm_s < v_cap:
                self.v_est_mm_s = min(v_cap, self.v_est_mm_s + a * h)
            else:
                self.v_est_mm_s = max(v_cap, self.v_est_mm_s - a * h)
            self.x_est_mm = min(self.x_est_mm + self.v_est_mm_s * h, end_x)

    def _cruises(self, index: int, dist_mm: float, end_x: float) -> bool:
        """True when the estimate runs dist_mm on at its current speed, which is its block's.

        That holds when the speed is the block's own, every block the window enters has the same
        speed and acceleration, and no junction or the end of the queue needs braking before
        the window ends: then speed_cap_mm_s() would return that speed at every step.
        """
        path = self.path
        seg = path[index]
        v = self.v_est_mm_s
        a = seg.accel_mm_s2
        if v <= 0.0 or v != seg.speed_mm_s:
            return False
        x_end = self.x_est_mm + dist_mm
        v_sq = v * v
        if 2.0 * a * (end_x - x_end) < v_sq:
            return False  # braking for the end of the queue may start inside the window
        two_a = 2.0 * a
        last = path[-1]
        if (
            a > 0.0
            and last.streak >= len(path) - index - 1
            and last.speed_mm_s == v
            and last.accel_mm_s2 == a
            and v**2 >= v_sq
        ):
            # Hot path: every jog after this one enters at v with acceleration a (a held jog's
            # repeated increments), so each passes the loop's checks below: the same accel and
            # speed, and entry_cap**2 (which is v**2) + 2a * ahead never below v * v.
            return True
        reach_mm = v_sq / two_a
        # islice, not a slice: the loop mostly ends at the first block beyond reach (every
        # poll of a held jog comes here), so copying the rest of the path would be wasted.
        for nxt in itertools.islice(path, index + 1, None):
            ahead = nxt.x0_mm - x_end
            if ahead > reach_mm:
                break
            if nxt.accel_mm_s2 != a:
                return False
            if nxt.x0_mm <= x_end and nxt.speed_mm_s != v:
                return False  # the window enters a block of another speed
            ahead = max(ahead, 0.0)
            if nxt.entry_cap_mm_s**2 + two_a * ahead < v_sq:
                return False  # a junction ahead needs braking inside the window
        return True

    def correct_estimate(self, mpos: Vec, age_s: float) -> bool:
        """Pull the estimate onto the reported position (projected on the path).

        A path that doubles back passes the same point twice, so among the segments the report
        lies on, the one nearest the current estimate wins. Returns True when the report lies
        off every jog sent (the estimate is then left alone); False otherwise, also when
        there is nothing to correct yet.
        """
        if not self.path or not self.moving_since_ack:
            return False
        tolerance_mm = 2.0 / min(self.steps_per_mm) + 1e-6
        path = self.path
        x_est = self.x_est_mm
        best: float | None = None
        best_gap = math.inf

        def on(seg: PathSeg) -> float | None:
            """Where along the path the report lies on seg, or None if it lies off it."""
            if _outside_box(mpos, seg.start_mm, seg.end_mm, tolerance_mm):
                return None  # farther than the tolerance from the segment's box, so from it too
            d, along = project(mpos, seg.start_mm, seg.end_mm)
            return None if d > tolerance_mm else seg.x0_mm + along

        # Outward from the estimate's segment, each way only as far as a nearer answer could
        # lie: a report normally sits beside the estimate, so a few segments are tried, not all.
        # The earliest segment wins a tie, as in a scan in path order.
        first = min(max(bisect.bisect_right(path, x_est, key=_X0) - 1, 0), len(path) - 1)
        for seg in itertools.islice(path, first, None):
            if seg.x0_mm - x_est > best_gap:
                break
            x = on(seg)
            if x is not None and abs(x - x_est) < best_gap:
                best, best_gap = x, abs(x - x_est)
        for i in range(first - 1, -1, -1):
            seg = path[i]
            if x_est - seg.x1_mm > best_gap:
                break
            x = on(seg)
            if x is not None and abs(x - x_est) <= best_gap:
                best, best_gap = x, abs(x - x_est)
        if best is None:
            return True
        # The report was built before its bytes crossed the wire: move it forward by that age.
        ahead = self.v_est_mm_s * age_s
        self.x_reported_mm = best
        self.x_est_mm = min(best + ahead, self.length_mm())
        return False

    def arrive_at_end(self) -> None:
        """The machine is known to rest at the end of the path."""
        self.x_est_mm = self.length_mm()
        self.x_reported_mm = self.x_est_mm
        self.v_est_mm_s = 0.0

    def at_rest_at_end(self) -> bool:
        """True when the estimate has reached the end of the path and stopped."""
        return self.x_est_mm >= self.length_mm() - 1e-9 and self.v_est_mm_s == 0.0

    def stop_point_mm(self) -> Vec:
        """Where the machine would come to rest if the jog were released now (path not empty)."""
        v = self.v_est_mm_s
        seg = self.seg_at(self.x_est_mm) or self.path[-1]
        # The segments the firmware has committed are cut at block ends: with the engine's
        # short blocks they hold ~31 ms, not the 50 ms of five full segments (committed_s is
        # the worst case the queue is sized for; this is where the machine will really stop).
        committed = min(inc.committed_s(self.longest_queued_s(0.0)), self.committed_s)
        brake = v * committed + v * v / (2.0 * seg.accel_mm_s2) if v > 0 else 0.0
        return self.point_at(min(self.x_est_mm + brake, self.length_mm()))

    def tracking_error(self, mpos: Vec, *, cancelled: bool) -> tuple[float, float]:
        """Tracked minus real, in mm and in steps of the worst axis.

        After a queue that ran out, it is the miss of the planned end; after a cancel, the miss
        of the nearest point of the queued path (the stop must lie on it, firmware-facts §3.1).
        Steps are counted per axis because the firmware rounds each axis to its own steps.
        """
        if not self.path:
            return 0.0, 0.0
        spm = self.steps_per_mm
        if not cancelled:
            ref = self.path[-1].end_mm
            steps = max(abs(r - m) * k for r, m, k in zip(ref, mpos, spm, strict=True))
            return math.dist(ref, mpos), steps
        best_steps, best_ref = math.inf, mpos
        for seg in self.path:
            # No point of a segment is nearer than its bounding box: most are skipped unsolved.
            if _box_steps(mpos, seg.start_mm, seg.end_mm, spm) >= best_steps:
                continue
            steps, ref = nearest_in_steps(mpos, seg.start_mm, seg.end_mm, spm)
            if steps < best_steps:
                best_steps, best_ref = steps, ref
        return math.dist(best_ref, mpos), best_steps

    # ----------------------------------------------------------------- the step grid
    def on_step_grid(self, mpos: Sequence[float]) -> Vec:
        """A reported position (3 decimals) put back on the step grid Grbl counts in.

        After a stop Grbl's parser position is the exact step count; the report rounds it.
        Starting a G91 chain from the rounded value would shift every target by up to
        0.0005 mm, enough to meet error:15 at the edge of the envelope.
        """
        return tuple(round(p * spm) / spm for p, spm in zip(mpos, self.steps_per_mm, strict=True))

    def steps_from(self, a: Sequence[float], b: Sequence[float]) -> float:
        """Distance between two positions in steps of the worst axis."""
        return max(abs(x - y) * spm for x, y, spm in zip(a, b, self.steps_per_mm, strict=True))


def _streak(prev: PathSeg | None, seg: PathSeg) -> int:
    """seg's streak after prev: 0 if it enters slower than its speed, one more than prev's if
    prev is of the streak and of the same speed and acceleration, else 1."""
    if seg.entry_cap_mm_s != seg.speed_mm_s:
        return 0
    if (
        prev is not None
        and prev.streak
        and prev.speed_mm_s == seg.speed_mm_s
        and prev.accel_mm_s2 == seg.accel_mm_s2
    ):
        return prev.streak + 1
    return 1


def _outside_box(p: Vec, a: Vec, b: Vec, margin_mm: float) -> bool:
    """True when p lies more than margin_mm outside the axis-aligned box around segment ab.

    A cheap test that skips most segments of the kept path before the exact projection (a
    status report is checked against every one, 20 times a second).
    """
    for pi, ai, bi in zip(p, a, b, strict=True):
        if ai <= bi:
            if pi < ai - margin_mm or pi > bi + margin_mm:
                return True
        elif pi < bi - margin_mm or pi > ai + margin_mm:
            return True
    return False


def _box_steps(p: Vec, a: Vec, b: Vec, steps_per_mm: Vec) -> float:
    """How far p lies outside the axis-aligned box around segment ab, in steps of the worst
    axis: a lower bound of nearest_in_steps."""
    out = 0.0
    for pi, ai, bi, k in zip(p, a, b, steps_per_mm, strict=True):
        lo, hi = (ai, bi) if ai <= bi else (bi, ai)
        gap = lo - pi if pi < lo else pi - hi if pi > hi else 0.0
        out = max(out, gap * k)
    return out


def project(p: Vec, a: Vec, b: Vec) -> tuple[float, float]:
    """Distance from p to segment ab, and how far along ab the closest point lies."""
    ab = tuple(y - x for x, y in zip(a, b, strict=True))
    length = norm(ab)
    if length == 0.0:
        return math.dist(p, a), 0.0
    t = sum((pi - ai) * d for pi, ai, d in zip(p, a, ab, strict=True)) / (length * length)
    t = min(max(t, 0.0), 1.0)
    closest = tuple(ai + d * t for ai, d in zip(a, ab, strict=True))
    return math.dist(p, closest), t * length


def nearest_in_steps(p: Vec, a: Vec, b: Vec, steps_per_mm: Vec) -> tuple[float, Vec]:
    """The point of segment ab nearest to p when distance is the worst axis counted in steps.

    The firmware rounds each axis to its own step grid, so "within one step" is per axis. Along
    the segment (q = a + (b - a)·t) the distance is max_i k_i·|a_i - p_i + (b_i - a_i)·t|, the
    upper envelope of 2n lines in t: convex and piecewise linear, so its minimum on [0, 1] lies
    at an end or where two of those lines cross. Trying every crossing is exact and costs a few
    dozen multiplications for three axes (a status at a stop is checked against the whole path).
    """
    lines = []  # (slope, value at t = 0) of +-k_i·(a_i - p_i + d_i·t)
    for pi, ai, bi, k in zip(p, a, b, steps_per_mm, strict=True):
        slope, icpt = k * (bi - ai), k * (ai - pi)
        lines.append((slope, icpt))
        lines.append((-slope, -icpt))

    def err_at(t: float) -> float:
        return max(m * t + c for m, c in lines)

    best_t, best = 0.0, err_at(0.0)
    end = err_at(1.0)
    if end < best:
        best_t, best = 1.0, end
    for i, (m1, c1) in enumerate(lines):
        for m2, c2 in lines[i + 1 :]:
            if m1 != m2:
                t = (c2 - c1) / (m1 - m2)
                if 0.0 < t < 1.0:
                    e = err_at(t)
                    if e < best:
                        best_t, best = t, e
    q = tuple(ai + (bi - ai) * best_t for ai, bi in zip(a, b, strict=True))
    return best, q
