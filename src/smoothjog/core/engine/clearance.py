"""Clearance: the soft-limit envelope and keep-out zones, and what may run into them.

Every increment is shortened to stop one step inside the envelope and one step short of a
keep-out, sliding along a boundary; a line that, run from anywhere an outside stop could leave
the machine, could sweep into a keep-out is held back (docs/jogging.md, "Safety").
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

from smoothjog.core import increments as inc
from smoothjog.core.engine.limits import EngineLimits
from smoothjog.core.engine.records import Notices
from smoothjog.core.engine.tracker import PathSeg, PathTracker
from smoothjog.core.jogline import MM_DECIMALS
from smoothjog.core.units import Vec

#: Steps (of the busiest axis) every block moves at least: Grbl plans a block under half a step
#: as nothing, so shorter blocks of a very slow jog would be all rounding.
MIN_BLOCK_STEPS = 1.5
#: The least speed a slide along an edge keeps, as a share of the stick's: below it (a stick
#: within 3° of square to the edge) the jog stops at the edge rather than crawl along it.
SLIDE_MIN_SHARE = 0.05

#: A report at rest inside a block not yet explained: when it was built at the latest, where
#: it put the machine, and the block (signs.py, "rest-inside-block").
Suspect = tuple[float, float, PathSeg]


class Clearance:
    """Room along a ray, clipped increments, and lines held back near keep-outs."""

    def __init__(self, limits: EngineLimits, track: PathTracker, notices: Notices) -> None:
        """Clearance for these limits along this path."""
        self.limits = limits
        self.track = track
        self.notices = notices
        #: What last stopped an increment short.
        self.blocked_by = "the soft limit"

    def inset_mm(self) -> float:
        """One step of margin: float rounding in the firmware must not tip a target over the
        edge (error:15 is inclusive at the edge, firmware-facts §2)."""
        return 1.0 / min(self.limits.steps_per_mm)

    def fits_envelope(self, end: Vec) -> bool:
        """True when end lies inside the soft-limit envelope (or there is none)."""
        env = self.limits.envelope
        return env is None or env.contains(end)

    def step_along_mm(self, unit_vec: Sequence[float]) -> float:
        """Distance along unit_vec in which the busiest axis makes one step."""
        return min(
            (
                1.0 / (spm * abs(u))
                for u, spm in zip(unit_vec, self.limits.steps_per_mm, strict=True)
                if u
            ),
            default=1.0 / max(self.limits.steps_per_mm),
        )

    def room_along(self, start: Vec, ray: Vec) -> tuple[float, str]:
        """How far from start along ray the machine stays inside the inset envelope and clear of
        every inset keep-out (inf if nothing stops it), and what stops it there."""
        inset = self.inset_mm()
        room_mm, by = math.inf, ""
        env = self.limits.envelope
        if env is not None:
            lo = tuple(v + inset for v in env.min_mm)
            hi = tuple(v - inset for v in env.max_mm)
            room_mm, by = inc.ray_box_exit(start, ray, lo, hi)[0], "the soft limit"
        for zone in self.limits.keepouts:
            t_in = max(inc.ray_box_entry(start, ray, zone.min_mm, zone.max_mm)[0] - inset, 0.0)
            if t_in < room_mm:
                room_mm, by = t_in, f"the keep-out zone {zone.name!r}"
        return room_mm, by

    def clip(
        self, start: Vec, move: inc.VectorMove, length_mm: float
    ) -> tuple[inc.VectorMove, float] | None:
        """Shorten (or slide) an increment so it stays in the envelope and out of keep-outs."""
        vel = list(move.velocity_mm_s)
        for attempt in range(len(vel) + 1):
            # The first try is the move itself (it is already capped as Grbl caps it).
            m = (
                move
                if attempt == 0
                else inc.vector_move(vel, self.limits.max_rate_mm_min, self.limits.accel_mm_s2)
            )
            if m is None:
                return None
            step_mm = self.step_along_mm(m.unit_vec)
            t = length_mm
            if m is not move:
                if m.speed_mm_s < SLIDE_MIN_SHARE * move.speed_mm_s:
                    # Pushed nearly square into the edge: what is left is a crawl, which would
                    # hold the planner for seconds. The jog stops there.
                    return None
                # A slide runs slower than the move it is cut from: keep the block's time (a
                # stick held nearly square to the edge would queue blocks of seconds), and at
                # least MIN_BLOCK_STEPS.
                t = max(length_mm * m.speed_mm_s / move.speed_mm_s, MIN_BLOCK_STEPS * step_mm)
            t, blocked = self._first_boundary(start, m.unit_vec, t)
            if t >= step_mm or blocked is None:
                return (m, t) if t >= step_mm else None
            # Blocked within a step: drop the blocked axis and slide along the boundary.
            vel[blocked] = 0.0
        return None

    def _first_boundary(self, start: Vec, ray: Vec, t: float) -> tuple[float, int | None]:
        """The distance along ray to the first boundary within t (else t) and the axis or face
        it blocks (else None)."""
        inset = self.inset_mm()
        blocked: int | None = None
        env = self.limits.envelope
        if env is not None:
            lo = tuple(v + inset for v in env.min_mm)
            hi = tuple(v - inset for v in env.max_mm)
            t_env, axis = inc.ray_box_exit(start, ray, lo, hi)
            if t_env < t:
                t = t_env
                blocked = axis
                self.blocked_by = "the soft limit"
        for zone in self.limits.keepouts:
            t_in, face = inc.ray_box_entry(start, ray, zone.min_mm, zone.max_mm)
            t_in = max(t_in - inset, 0.0)
            if t_in < t:
                t = t_in
                blocked = face
                self.blocked_by = f"the keep-out zone {zone.name!r}"
        return t, blocked

    def ghost_clear(self, deltas: Vec, suspect: Suspect | None) -> bool:
        """True when a G91 line of these deltas stays out of every keep-out however short of
        its start an outside stop leaves the machine.

        A hold or 0x85 from someone else leaves the lines not yet parsed in the controller's
        buffer, and each then runs its increment from the stopping point (firmware-facts §3.1,
        §3.7). The firmware checks its own soft limits; keep-outs are smoothjog's alone, so the
        region the line could sweep from there is checked here (zones grown by half the inset).
        """
        track = self.track
        # From where the machine may really be: the estimate runs ahead of it while it brakes
        # for a corner, so the last report's place counts when it is further back.
        reported = track.x_reported_mm
        x_mm = min(track.x_est_mm, reported if reported is not None else 0.0)
        grow = 0.5 * self.inset_mm()
        zones = [
            (tuple(v - grow for v in zone.min_mm), tuple(v + grow for v in zone.max_mm))
            for zone in self.limits.keepouts
        ]
        if not self._suspect_rest_clear(deltas, zones, suspect):
            return False
        # The lines sent and not yet answered may be among those left unparsed: they run first,
        # one after another from the stopping point, so this line then starts that much further
        # on (after a reversal, further back). Each count of them is an offset of that point.
        offsets: list[Vec] = [tuple(0.0 for _ in deltas)]
        for seg in reversed(track.path):
            if seg.acked:
                break
            offsets.append(
                tuple(
                    o + e - b for o, e, b in zip(offsets[-1], seg.end_mm, seg.start_mm, strict=True)
                )
            )
        # The path behind the machine (kept for late reports) is skipped by bisection.
        first = track.seg_index_at(x_mm) or 0
        for seg in itertools.islice(track.path, first, None):
            if seg.x0_mm + seg.length_mm <= x_mm:
                continue
            a0 = track.point_at(x_mm) if seg.x0_mm < x_mm else seg.start_mm
            if self._sweeps_enter(a0, seg.end_mm, offsets, deltas, zones):
                return False
        return True

    @staticmethod
    def _sweeps_enter(
        a0: Vec,
        b0: Vec,
        offsets: list[Vec],
        deltas: Vec,
        zones: Sequence[tuple[Vec, Vec]],
    ) -> bool:
        """True when deltas run from any point of a0->b0 (moved by any offset) enter a zone."""
        for offset in offsets:
            a = tuple(v + o for v, o in zip(a0, offset, strict=True))
            b = tuple(v + o for v, o in zip(b0, offset, strict=True))
            for lo, hi in zones:
                # Most pieces are nowhere near a zone: their sweep's bounding box tells.
                if any(
                    min(ai, bi) + min(di, 0.0) >= h or max(ai, bi) + max(di, 0.0) <= lw
                    for ai, bi, di, lw, h in zip(a, b, deltas, lo, hi, strict=False)
                ):
                    continue
                if inc.sweep_enters_box(a, b, deltas, lo, hi):
                    return True
        return False

    def _suspect_rest_clear(
        self, deltas: Vec, zones: Sequence[tuple[Vec, Vec]], suspect: Suspect | None
    ) -> bool:
        """False when a report at rest inside a block, not yet explained, may be someone
        else's stop there and this line could then enter a zone.

        Lines still in the RX buffer run one after another from the stopping point
        (firmware-facts §3.1), acknowledged by now or not: this line may start at that point
        plus any unbroken run of the lines after the block.
        """
        if suspect is None or not zones:
            return True
        _built_s, rest_mm, seg = suspect
        track = self.track
        index = track.seg_index_at(rest_mm)
        if index is None or track.path[index] is not seg:
            return True  # the path was begun afresh: the suspicion is moot
        after = [
            tuple(e - b for e, b in zip(piece.end_mm, piece.start_mm, strict=True))
            for piece in track.path[index + 1 :]
        ]
        rest = track.point_at(rest_mm)
        for first in range(len(after) + 1):
            point = rest
            for k in range(first, len(after) + 1):
                if k > first:
                    point = tuple(p + d for p, d in zip(point, after[k - 1], strict=True))
                if any(inc.sweep_enters_box(point, point, deltas, lo, hi) for lo, hi in zones):
                    return False
        return True

    def where_blocked(self, start: Vec) -> str:
        """Where the machine is, for a message about an edge."""
        return "at " + ", ".join(
            f"{a} {p:.3f}" for a, p in zip(self.limits.axes, start, strict=True)
        )

    def path_problem(self, start: Vec, end: Vec) -> str | None:
        """Why a straight jog from start to end is not allowed, or None."""
        env = self.limits.envelope
        if env is not None and not env.contains(end):
            return "the target lies outside the soft limits"
        for zone in self.limits.keepouts:
            if zone.crosses(start, end):
                return f"the path crosses the keep-out zone {zone.name!r}"
        return None

    def axis_room_mm(self, start: Vec, axis: int, sign: int) -> float:
        """How far a move may go from start along one axis (inf if nothing stops it)."""
        unit_vec = tuple(float(sign) if k == axis else 0.0 for k in range(len(start)))
        return self.room_along(start, unit_vec)[0]

    def step_room_mm(self, start: Vec, axis: int, dist_mm: float) -> float | None:
        """dist_mm, or shorter to stop at the inset soft limit or a keep-out (said in words);
        None (a fault in words) when there is no room at all that way."""
        unit_vec = tuple(
            (1.0 if dist_mm > 0 else -1.0) if k == axis else 0.0 for k in range(len(start))
        )
        room_mm, by = self.room_along(start, unit_vec)
        if room_mm >= abs(dist_mm):
            return dist_mm
        name = f"{self.limits.axes[axis]}{'+' if dist_mm > 0 else '-'}"
        # Toward zero on the 0.001 mm grid, so the shortened step stays inside.
        short_mm = math.floor(room_mm * 10**MM_DECIMALS) / 10**MM_DECIMALS
        if short_mm <= 0.0:
            self.notices.fault_now(
                self.track.est_s,
                f"step refused: no room to jog {name}, {by} is there ({self.where_blocked(start)})",
                "jog the other way",
                refusal=True,
            )
            return None
        self.notices.info(
            self.track.est_s,
            f"step {name} shortened to {short_mm:g} mm (asked {abs(dist_mm):g} mm): {by} is there",
        )
        return math.copysign(short_mm, dist_mm)
