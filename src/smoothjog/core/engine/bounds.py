"""The planner's bounds the outside-event signs compare reports with.

Where the acknowledged jogs end, how fast a planned block must still run at a place, which
junctions the planner passes at no speed, and where a queue runs out at a boundary: a report
outside these bounds is someone else's doing (signs.py).
"""

from __future__ import annotations

import math

from smoothjog.core import increments as inc
from smoothjog.core.engine.clearance import Clearance
from smoothjog.core.engine.limits import JogTuning
from smoothjog.core.engine.tracker import PathSeg, PathTracker
from smoothjog.core.units import Vec, mm_min_to_mm_s, mm_s_to_mm_min

#: The estimate follows the firmware's planner to well under this at every stop (bench tables).
OUTSIDE_LAG_MM = 0.05
#: A feed below this share of the slowest the planned blocks allow (less SLOWED_FLOOR_MM_S) is
#: a machine someone else brakes: room for FS's rounding and an acceleration a fifth lower.
SLOWED_SHARE = 0.8
SLOWED_FLOOR_MM_S = 1.0


def acked_end_mm(track: PathTracker) -> float | None:
    """Where along the path the acknowledged jogs end (replies come in order, so they are a
    prefix of the path), or None before the first ok."""
    for seg in reversed(track.path):
        if seg.acked:
            return seg.x0_mm + seg.length_mm
    return None


def at_path_ends(track: PathTracker, mpos: Vec) -> tuple[bool, bool]:
    """Whether mpos rests (within two steps) at the path's end, and at the acknowledged jogs'."""
    path = track.path
    at_end = track.steps_from(mpos, path[-1].end_mm) <= 2.0
    planned = [seg for seg in path if seg.acked]
    at_planned_end = bool(planned) and track.steps_from(mpos, planned[-1].end_mm) <= 2.0
    return at_end, at_planned_end


def fs_lead_mm(tuning: JogTuning, speed_mm_s: float, step_mm: float) -> float:
    """How far ahead of the reported position FS may apply at this speed: the committed
    segments (a lead of up to twice committed_s) and the report's rounding."""
    return speed_mm_s * 2.0 * tuning.committed_s + max(OUTSIDE_LAG_MM, 3.0 * step_mm)


def rest_ahead_mm(
    track: PathTracker, acked_end: float, step_mm: float, *, cruised: bool
) -> float | None:
    """How much path the planner surely held ahead of a machine reported at rest in Jog; None
    when a rest there says nothing.

    Once the run was seen at speed the planner holds every acknowledged jog. Before that, the
    lines planned so far may have run out, and only the rest of the block it is on counts (a
    queue run dry rests at a block's end); a report at the run's start is a jog not yet moving.
    """
    if cruised:
        return acked_end - track.x_est_mm
    x_mm = track.x_reported_mm
    if x_mm is None or x_mm <= max(OUTSIDE_LAG_MM, 3.0 * step_mm):
        return None
    here = track.seg_at(x_mm)
    if here is None or not here.acked:
        return None
    return here.x1_mm - x_mm


def running_out_at_a_boundary(track: PathTracker, clearance: Clearance, within_mm: float) -> bool:
    """True when everything sent ends at the envelope or a keep-out, within_mm ahead of the
    estimate: the queue runs out there, and a slow jog's committed segments still run at its
    speed when FS reads 0 (allowed only at such an end: mid-path it hides a real 0x85)."""
    path = track.path
    if not path or track.length_mm() - track.x_est_mm > within_mm:
        return False
    last = path[-1]
    if last.length_mm <= 0.0:
        return False
    ray = last.unit_vec or tuple(
        (e - s) / last.length_mm for e, s in zip(last.end_mm, last.start_mm, strict=True)
    )
    room_mm = clearance.room_along(last.end_mm, ray)[0]
    # The last increments stop short of the edge by what rounding leaves (2 steps seen).
    return room_mm <= 4.0 / min(track.steps_per_mm)


def slowed_inside_a_block(
    track: PathTracker, tuning: JogTuning, feed_mm_min: float, step_mm: float
) -> str | None:
    """A sentence when the reported feed is below the slowest that the block the machine is in
    can run at the reported place, whatever the link did; else None.

    A planned block speeds the machine up from wherever it entered and brakes it only for its
    end, and FS applies at most the committed lead ahead: x into a block of speed v, length L
    and acceleration a, FS is at least min(v, √(2a·x), √(2a·(L − x − lead))).
    """
    x_mm = track.x_reported_mm
    if x_mm is None:
        return None
    seg = track.seg_at(x_mm)
    if seg is None or not seg.acked or seg.speed_mm_s <= 0.0:
        return None
    a = seg.accel_mm_s2
    lead_mm = fs_lead_mm(tuning, seg.speed_mm_s, step_mm)
    into_mm = x_mm - seg.x0_mm
    left_mm = seg.x1_mm - x_mm - lead_mm
    if into_mm <= 0.0 or left_mm <= 0.0:
        return None
    low_mm_s = min(seg.speed_mm_s, math.sqrt(2.0 * a * into_mm), math.sqrt(2.0 * a * left_mm))
    if mm_min_to_mm_s(feed_mm_min) >= SLOWED_SHARE * low_mm_s - SLOWED_FLOOR_MM_S:
        return None
    return (
        f"it ran at {feed_mm_min:.0f} mm/min {into_mm:.2f} mm into a jog that runs at least"
        f" {mm_s_to_mm_min(low_mm_s):.0f} mm/min there"
    )


def slowed_since(
    track: PathTracker,
    tuning: JogTuning,
    prev: tuple[float, float, float, PathSeg],
    x_mm: float,
    feed_mm_min: float,
    step_mm: float,
) -> str | None:
    """A sentence when the feed is below the slowest the jogs acknowledged by the last report
    (prev: its place, FS, where those jogs ended, its jog) allow at x_mm; else None.

    Every jog answered before a report was built was in the planner then (Grbl writes a line's
    reply before any report it builds after it), so from that report's place and feed on, FS
    stays at least that feed, each jog's speed, what each junction allows, and what braking
    for the end of those jogs allows.
    """
    x0_mm, fs0_mm_s, end_mm, seg0 = prev
    feed_mm_s = mm_min_to_mm_s(feed_mm_min)
    if feed_mm_s >= SLOWED_SHARE * fs0_mm_s - SLOWED_FLOOR_MM_S:
        return None  # the bound below never exceeds the last feed: a steady feed passes
    path = track.path
    if x_mm < x0_mm or not any(seg is seg0 for seg in path):
        return None  # a new path, or a report that went back
    held = [seg for seg in path if seg.x1_mm > x0_mm and seg.x0_mm < end_mm]
    if not held or not all(seg.acked for seg in held):
        return None
    v_top = max(seg.speed_mm_s for seg in held)
    # FS is the speed somewhere in [x_mm, at_mm].
    at_mm = x_mm + fs_lead_mm(tuning, v_top, step_mm)
    if at_mm >= end_mm:
        return None
    a = min(seg.accel_mm_s2 for seg in held)
    low = min(fs0_mm_s, math.sqrt(2.0 * a * (end_mm - at_mm)))
    for seg in held:
        if seg.x1_mm > x_mm and seg.x0_mm < at_mm:
            low = min(low, seg.speed_mm_s)
        xj = seg.x0_mm
        if xj <= x0_mm:
            continue  # a junction behind the last report's place: in its feed already
        cap = min(seg.entry_cap_mm_s, seg.speed_mm_s)
        if xj >= at_mm:
            low = min(low, math.sqrt(cap * cap + 2.0 * a * (xj - at_mm)))
        elif xj > x_mm:
            low = min(low, cap)
        else:
            low = min(low, math.sqrt(cap * cap + 2.0 * a * (x_mm - xj)))
    if feed_mm_s >= SLOWED_SHARE * low - SLOWED_FLOOR_MM_S:
        return None
    return (
        f"it slowed to {feed_mm_min:.0f} mm/min where the jogs it already held let it run"
        f" at least {mm_s_to_mm_min(low):.0f} mm/min"
    )


def near_a_junction_at_rest(track: PathTracker, x: float, tuning: JogTuning) -> bool:
    """True while x is within braking reach of a junction the planner passes at (nearly) no
    speed: a reversal the engine let the queue run through rests there.

    The path's first segment starts from rest, which is no junction. The machine brakes into a
    junction from the block before it, and FS (the speed at the end of the prepared segments)
    reads 0 up to the committed lead before it.
    """
    prev = None
    for seg in track.path:
        before, prev = prev, seg
        if before is None or seg.entry_cap_mm_s >= 0.1 * seg.speed_mm_s:
            continue
        reach_mm = seg.speed_mm_s**2 / seg.accel_mm_s2 + OUTSIDE_LAG_MM
        lead_mm = inc.braking_lead_mm(before.speed_mm_s, before.accel_mm_s2, tuning.committed_s)
        reach_in_mm = max(
            reach_mm,
            before.speed_mm_s**2 / before.accel_mm_s2,
            lead_mm + OUTSIDE_LAG_MM,
        )
        if seg.x0_mm - reach_in_mm <= x <= seg.x0_mm + reach_mm:
            return True
    return False


def near_a_slow_junction(track: PathTracker, move: inc.VectorMove) -> bool:
    """True while the estimate is within a speed-up's reach past a junction the planner slows
    for (or just before one it brakes for)."""
    x = track.x_est_mm
    longest_mm = 2.0 * inc.stop_distance_mm(move.speed_mm_s, move.accel_mm_s2)
    for seg in reversed(track.path):
        # Twice the distance to reach the block's speed at its own acceleration: a slide along
        # an edge leaves the axes with the lowest acceleration.
        reach_mm = seg.speed_mm_s**2 / seg.accel_mm_s2
        longest_mm = max(longest_mm, reach_mm)
        if seg.x0_mm + longest_mm < x:
            break
        if (
            seg.x0_mm - reach_mm <= x <= seg.x0_mm + reach_mm
            and seg.entry_cap_mm_s < 0.95 * seg.speed_mm_s
        ):
            return True
    return False
