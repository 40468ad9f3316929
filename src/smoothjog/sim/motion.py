"""Grbl's planner and step-segment generator as a pure, time-driven model with a ground truth.

What it reproduces (firmware-facts §4): a ring of `planner_blocks` linear blocks; per-axis max rate
and acceleration limited along the move vector; junction deviation between blocks; every plan ends
at rest (the newest block exits at speed 0); a block added to an empty planner starts from rest; the
step preparer cuts the tail block into segments of at most `segment_s`, keeps `segment_buffer` of
them (the executing one included) committed ahead, and discards a block from the planner once the
last of it is cut; a hold decelerates from the speed at the end of the committed segments, at each
block's own acceleration, along the queued path.

Units: distances in mm, speeds in mm/s, accelerations in mm/s², times in s (the caller's clock).
Grbl stores mm/min and mm/min²; the ratios are the same, so the profiles are too.

Steps are the firmware's: a target becomes whole steps as plan_buffer_line rounds it (lround of
the single-precision product target x steps/mm, f32.py); the firmware converts step counts back
to mm in singles itself (firmware.py). The velocity planning and the segment profiles are computed
in doubles, where Grbl uses singles: that moves times by parts in ten million, never a step.

Deliberate simplifications (documented so no one mistakes them for the firmware):
- Steps are counted by rounding the exact position along the block, not by a Bresenham DDA; the end
  of every block lands exactly on its target step count, as on the chip.
- Grbl stretches a segment until it holds at least one step; at jog speeds every 10 ms segment holds
  many steps, so segments here are never stretched.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import islice

from smoothjog.core.increments import junction_speed_sqr
from smoothjog.core.units import limit_by_axis_maximum, mm_min_to_mm_s, mm_s_to_mm_min
from smoothjog.sim.f32 import f32, mm_to_steps

# Speed: the comments marked "hot path" here and in firmware.py / rig.py are optimisations that
# keep every result bit for bit (ground-truth traces and the bytes on the wire were compared
# before and after). Measured on `python -m bench sim` (the 60 s jog stream): under callgrind,
# which machine load does not disturb, 1768 M instructions before them and 1325 M after
# (x1.33) for sim/ as a whole; CPU time about 200 ms -> 175 ms; the bench's wall-clock figure,
# runs interleaved with the old code on the 2-core development machine, 169-187x -> 195-314x
# under heavy load (load average 3) and about 300x -> 340x under light load.

#: Event name reported by `Motion.advance` when the steppers run out of work.
CYCLE_STOP = "cycle_stop"

_EPS_MM = 1e-9
_EPS_S = 1e-12


@dataclass(frozen=True)
class AxisLimits:
    """One axis as the firmware sees it: `$10x`, `$11x` and `$12x`."""

    steps_per_mm: float
    max_rate_mm_min: float
    accel_mm_s2: float


@dataclass(frozen=True)
class TraceSegment:
    """Ground truth: the machine went from start_mm to end_mm at constant speed in [t0_s, t1_s]."""

    t0_s: float
    t1_s: float
    start_mm: tuple[float, ...]
    end_mm: tuple[float, ...]

    @property
    def speed_mm_s(self) -> float:
        """The constant speed of this segment."""
        dt_s = self.t1_s - self.t0_s
        if dt_s <= 0.0:
            return 0.0
        return math.dist(self.start_mm, self.end_mm) / dt_s


@dataclass(slots=True)
class _Block:
    """One planner block (Grbl's plan_block_t, in mm and mm/s)."""

    start_steps: tuple[int, ...]
    target_steps: tuple[int, ...]
    start_mm: tuple[float, ...]
    unit_vec: tuple[float, ...]
    length_mm: float
    nominal_mm_s: float
    accel_mm_s2: float
    max_entry_sqr: float
    entry_sqr: float = 0.0
    #: The rate the line asked for (mm/s), the axes' rapid rate along it, whether it is a rapid,
    #: whether feed override applies (not to jogs or homing), and its junction limit, so that an
    #: override change can recompute nominal_mm_s and max_entry_sqr (firmware-facts §4.2, §4.3).
    programmed_mm_s: float = 0.0
    rapid_mm_s: float = 0.0
    rapid: bool = False
    feed_override: bool = True
    junction_sqr: float = 0.0
    #: target_steps - start_steps per axis, kept so step counts need no subtraction each time.
    delta_steps: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        """Derive delta_steps (integers: the same values whenever they are computed)."""
        self.delta_steps = tuple(
            [t - s for s, t in zip(self.start_steps, self.target_steps, strict=True)]
        )


@dataclass(slots=True)
class _Segment:
    """A prepared segment: a piece of one block executed at constant speed over dt_s."""

    block: _Block
    d0_mm: float
    d1_mm: float
    dt_s: float
    end_speed_mm_s: float
    ends_block: bool


class Motion:
    """The planner plus the step-segment generator; call `advance` to let time pass."""

    def __init__(
        self,
        axes: Sequence[AxisLimits],
        *,
        junction_deviation_mm: float = 0.01,
        planner_blocks: int = 15,
        segment_s: float = 0.010,
        segment_buffer: int = 5,
        min_feed_mm_min: float = 1.0,
    ) -> None:
        if not axes:
            raise ValueError("a machine needs at least one axis")
        self.planner_blocks = planner_blocks
        self.segment_s = segment_s
        self.segment_buffer = segment_buffer
        self.min_feed_mm_min = min_feed_mm_min
        self._axes: tuple[AxisLimits, ...] = ()
        self._junction_deviation_mm = junction_deviation_mm
        self.reconfigure(axes, junction_deviation_mm)
        n = len(self._axes)
        self._machine_steps: tuple[int, ...] = (0,) * n
        self._planner_steps: tuple[int, ...] = (0,) * n
        self._prev_unit: tuple[float, ...] = (0.0,) * n
        self._prev_nominal_mm_s = 0.0
        # Feed and rapid override as fractions (firmware-facts §5.2); jog blocks ignore both.
        self._feed_ovr = 1.0
        self._rapid_ovr = 1.0
        self._blocks: deque[_Block] = deque()
        self._segments: deque[_Segment] = deque()
        # Step preparer state: how far into the tail block it has cut, and its speed there.
        self._prep_d_mm = 0.0
        self._prep_speed_mm_s = 0.0
        self._hold = False
        self._hold_done = False
        self._running = False
        # The main program blocks in a delay and prepares no segment (see starve).
        self._starved = False
        # The executing segment started at this time; _now_s is the last time advanced to.
        self._exec_start_s = 0.0
        self._now_s = 0.0
        #: Every segment executed, in order: the ground truth, while keep_trace is True. The
        #: embedded default machine turns it off (a day of jogging would fill memory with it).
        self.trace: list[TraceSegment] = []
        self.keep_trace = True

    # ----------------------------------------------------------------- configuration
    def reconfigure(self, axes: Sequence[AxisLimits], junction_deviation_mm: float) -> None:
        """Take new axis settings (`$x=val`); only meaningful while idle."""
        if self._axes and len(axes) != len(self._axes):
            raise ValueError("the number of axes cannot change")
        self._axes = tuple(axes)
        self._junction_deviation_mm = junction_deviation_mm
        # settings.steps_per_mm is a float on the chip: every conversion uses that single.
        self._steps_per_mm = tuple(f32(a.steps_per_mm) for a in self._axes)
        self._accel = tuple(a.accel_mm_s2 for a in self._axes)
        self._max_rate_mm_s = tuple(mm_min_to_mm_s(a.max_rate_mm_min) for a in self._axes)

    @property
    def steps_per_mm(self) -> tuple[float, ...]:
        """Each axis's steps/mm as the firmware holds it (a single)."""
        return self._steps_per_mm

    # ----------------------------------------------------------------- planner
    def planner_free(self) -> int:
        """Free planner blocks (the first value of `Bf:`)."""
        return self.planner_blocks - len(self._blocks)

    def planner_count(self) -> int:
        """Blocks waiting in the planner (the tail block being cut included)."""
        return len(self._blocks)

    def planner_empty(self) -> bool:
        """True when no block is waiting in the planner."""
        return not self._blocks

    def plan_line(
        self,
        target_mm: Sequence[float],
        feed_mm_min: float,
        *,
        rapid: bool = False,
        feed_override: bool = True,
    ) -> bool:
        """Queue one linear block to target_mm (machine mm); False if it rounds to no step.

        feed_override=False for jogs and homing moves: feed override leaves them alone, and a
        jog is not a rapid, so rapid override does not touch it either (firmware-facts §4.2).
        """
        if len(self._blocks) >= self.planner_blocks:
            raise RuntimeError("plan_line called with the planner full")
        target_steps = tuple(
            [mm_to_steps(t, spm) for t, spm in zip(target_mm, self._steps_per_mm, strict=True)]
        )
        delta_mm = tuple(
            (t - s) / spm
            for t, s, spm in zip(target_steps, self._planner_steps, self._steps_per_mm, strict=True)
        )
        length_mm = math.sqrt(sum(d * d for d in delta_mm))
        if all(t == s for t, s in zip(target_steps, self._planner_steps, strict=True)):
            return False
        unit_vec = tuple(d / length_mm for d in delta_mm)
        accel = limit_by_axis_maximum(self._accel, unit_vec)
        rapid_mm_s = limit_by_axis_maximum(self._max_rate_mm_s, unit_vec)
        # firmware-facts §4.3: a block added to an empty planner starts from rest.
        junction_sqr = self._junction_speed_sqr(unit_vec) if self._blocks else 0.0
        start_mm = tuple(
            s / spm for s, spm in zip(self._planner_steps, self._steps_per_mm, strict=True)
        )
        block = _Block(
            start_steps=self._planner_steps,
            target_steps=target_steps,
            start_mm=start_mm,
            unit_vec=unit_vec,
            length_mm=length_mm,
            nominal_mm_s=0.0,
            accel_mm_s2=accel,
            max_entry_sqr=0.0,
            programmed_mm_s=rapid_mm_s if rapid else mm_min_to_mm_s(feed_mm_min),
            rapid_mm_s=rapid_mm_s,
            rapid=rapid,
            feed_override=feed_override and not rapid,
            junction_sqr=junction_sqr,
        )
        self._set_speed_limits(block, self._prev_nominal_mm_s)
        was_empty = not self._blocks
        self._blocks.append(block)
        self._planner_steps = target_steps
        self._prev_unit = unit_vec
        self._prev_nominal_mm_s = block.nominal_mm_s
        if was_empty:
            # The preparer starts this block fresh, from whatever speed it has reached (zero here).
            self._prep_d_mm = 0.0
        self._recalculate()
        if self._running and not self._hold:
            self._fill_segments()
        return True

    def _set_speed_limits(self, block: _Block, prev_nominal_mm_s: float) -> None:
        """plan_compute_profile_parameters: nominal speed and the entry limit of one block."""
        block.nominal_mm_s = nominal = self._nominal_mm_s(block)
        block.max_entry_sqr = min(block.junction_sqr, nominal * nominal, prev_nominal_mm_s**2)

    def _nominal_mm_s(self, block: _Block) -> float:
        """plan_compute_profile_nominal_speed: the programmed rate under the overrides."""
        if block.rapid:
            nominal = block.rapid_mm_s * self._rapid_ovr
        else:
            nominal = block.programmed_mm_s
            if block.feed_override:
                nominal *= self._feed_ovr
            nominal = min(nominal, block.rapid_mm_s)
        return max(nominal, mm_min_to_mm_s(self.min_feed_mm_min))

    def set_overrides(self, feed_pct: int, rapid_pct: int, now_s: float) -> None:
        """A feed or rapid override changed: re-plan every queued block (firmware-facts §4.3).

        As plan_update_velocity_profile_parameters plus plan_cycle_reinitialize: new nominal
        speeds and entry limits for every block, then a re-plan from where the step preparer
        has got to. Segments already prepared run as they are.
        """
        self.advance(now_s)
        self._feed_ovr = feed_pct / 100.0
        self._rapid_ovr = rapid_pct / 100.0
        prev_nominal = math.inf  # the tail block's entry is not limited by a previous block
        for b in self._blocks:
            self._set_speed_limits(b, prev_nominal)
            prev_nominal = b.nominal_mm_s
        if self._blocks:
            self._prev_nominal_mm_s = prev_nominal
        self._recalculate()

    def _junction_speed_sqr(self, unit_vec: tuple[float, ...]) -> float:
        """Grbl's junction-deviation limit between the previous block and this one (firmware-facts
        §4.3)."""
        return junction_speed_sqr(
            self._prev_unit, unit_vec, self._accel, self._junction_deviation_mm
        )

    def _recalculate(self) -> None:
        """Reverse then forward pass: every plan ends at rest; no entry beyond what accel allows."""
        blocks = self._blocks
        if not blocks:
            return
        # Hot path (every planned block, over the whole planner): iterators instead of deque
        # indexing; the reverse pass writes min(cap, x) as `x if x < cap else cap` (the same
        # value, NaN included).
        # Reverse pass from the newest block (exit speed 0) back to the block after the tail.
        next_entry_sqr = 0.0
        for b in islice(reversed(blocks), len(blocks) - 1):
            cap = b.max_entry_sqr
            reach = next_entry_sqr + 2.0 * b.accel_mm_s2 * b.length_mm
            next_entry_sqr = b.entry_sqr = reach if reach < cap else cap
        # Forward pass starting at the tail, whose entry is where the preparer has got to.
        tail = blocks[0]
        tail.entry_sqr = self._prep_speed_mm_s**2 if self._prep_d_mm > 0.0 else tail.entry_sqr
        prev_v_sqr = tail.entry_sqr
        prev_remaining = tail.length_mm - self._prep_d_mm
        prev_accel = tail.accel_mm_s2
        for b in islice(blocks, 1, None):
            reachable = prev_v_sqr + 2.0 * prev_accel * prev_remaining
            b.entry_sqr = min(b.entry_sqr, reachable)
            prev_v_sqr, prev_remaining, prev_accel = b.entry_sqr, b.length_mm, b.accel_mm_s2

    # ----------------------------------------------------------------- execution
    def is_running(self) -> bool:
        """True while the steppers have segments to run."""
        return self._running

    def hold_active(self) -> bool:
        """True from `hold()` until `clear_after_stop()` or `resume()`."""
        return self._hold

    def hold_complete(self) -> bool:
        """True once a hold has brought the machine to rest."""
        return self._hold and not self._running

    def start_cycle(self, now_s: float) -> None:
        """Begin executing the queued blocks (Grbl's cycle start); no-op while running or held."""
        if self._running or self._hold or not self._blocks:
            return
        self._starved = False
        self._now_s = max(self._now_s, now_s)
        self._exec_start_s = self._now_s
        self._running = True
        self._fill_segments()
        if not self._segments:
            self._running = False

    def hold(self, now_s: float) -> None:
        """Start a forced deceleration after the segments already prepared (hold, jog cancel)."""
        if self._hold:
            return
        self.advance(now_s)
        self._hold = True
        self._hold_done = False

    def resume(self, now_s: float) -> None:
        """Continue after a completed hold (Run-state feed hold): re-plan from rest."""
        if not self.hold_complete():
            return
        self._hold = False
        self._prep_speed_mm_s = 0.0
        if self._blocks:
            self._blocks[0].entry_sqr = 0.0
            self._recalculate()
        self.start_cycle(now_s)

    def clear_after_stop(self) -> None:
        """Drop every block and segment; sync the planner to the machine (end of a jog cancel)."""
        self._starved = False
        self._blocks.clear()
        self._segments.clear()
        self._prep_d_mm = 0.0
        self._prep_speed_mm_s = 0.0
        self._hold = False
        self._running = False
        self._planner_steps = self._machine_steps
        self._prev_nominal_mm_s = 0.0

    def unrun_steps(self) -> int:
        """Steps between the machine and the end of what is planned, on the busiest axis."""
        return max(
            (abs(p - m) for p, m in zip(self._planner_steps, self.position_steps(), strict=True)),
            default=0,
        )

    def kill(self) -> None:
        """Stop at once (soft reset): everything queued is lost; the position is kept, and the
        part of the executing segment already run goes into the trace."""
        self._trace_partial_segment()
        self._machine_steps = self.position_steps()
        self.clear_after_stop()

    def _trace_partial_segment(self) -> None:
        """The executing segment up to now, as the trace's last segment (a reset cut it)."""
        if not (self.keep_trace and self._running and self._segments):
            return
        seg = self._segments[0]
        if self._now_s <= self._exec_start_s or seg.dt_s <= 0:
            return
        frac = min((self._now_s - self._exec_start_s) / seg.dt_s, 1.0)
        block = seg.block
        start, unit = block.start_mm, block.unit_vec
        d1 = seg.d0_mm + (seg.d1_mm - seg.d0_mm) * frac
        start_mm = tuple([s + u * seg.d0_mm for s, u in zip(start, unit, strict=True)])
        end_mm = tuple([s + u * d1 for s, u in zip(start, unit, strict=True)])
        self.trace.append(TraceSegment(self._exec_start_s, self._now_s, start_mm, end_mm))

    def set_position_steps(self, steps: Sequence[int]) -> None:
        """Set machine and planner step counters (homing sets sys_position); only while idle."""
        if len(steps) != len(self._axes):
            raise ValueError(f"position needs {len(self._axes)} axes, got {len(steps)}")
        self._machine_steps = tuple(steps)
        self._planner_steps = tuple(steps)

    def next_event_s(self) -> float | None:
        """When the executing segment ends (something changes then), or None when idle."""
        if not self._running or not self._segments:
            return None
        return self._exec_start_s + self._segments[0].dt_s

    def advance(self, to_s: float) -> list[tuple[float, str]]:
        """Let time pass up to to_s; returns events with their times (e.g. cycle stop)."""
        events: list[tuple[float, str]] = []
        if to_s < self._now_s:
            return events
        # Hot path (called at every firmware event): locals instead of repeated attribute look-ups.
        segments = self._segments
        limit_s = to_s + _EPS_S
        while self._running and segments:
            seg = segments[0]
            end_s = self._exec_start_s + seg.dt_s
            if end_s > limit_s:
                break
            self._complete_segment(seg, end_s)
            segments.popleft()
            self._exec_start_s = end_s
            self._fill_segments()
            if not segments:
                self._running = False
                if self._hold:
                    self._hold_done = True
                events.append((end_s, CYCLE_STOP))
        self._now_s = to_s
        return events

    def _complete_segment(self, seg: _Segment, end_s: float) -> None:
        # Hot path (once per 10 ms segment): list comprehensions over zip, the same arithmetic.
        block = seg.block
        start, unit = block.start_mm, block.unit_vec
        d0 = seg.d0_mm
        start_mm = tuple([s + u * d0 for s, u in zip(start, unit, strict=True)])
        if seg.ends_block:
            self._machine_steps = block.target_steps
            end_mm = tuple(
                [s / spm for s, spm in zip(block.target_steps, self._steps_per_mm, strict=True)]
            )
        else:
            d1 = seg.d1_mm
            self._machine_steps = self._steps_in_block(block, d1)
            end_mm = tuple([s + u * d1 for s, u in zip(start, unit, strict=True)])
        if self.keep_trace:
            self.trace.append(TraceSegment(self._exec_start_s, end_s, start_mm, end_mm))

    # ----------------------------------------------------------------- step preparer
    def starve(self) -> None:
        """The main program stops refilling the segment buffer (it blocks in a delay): the
        steppers run the segments already prepared, then stop. Until the next cycle start."""
        self._starved = True

    def _fill_segments(self) -> None:
        if self._starved:
            return
        segments = self._segments
        while len(segments) < self.segment_buffer:
            seg = self._prep_segment()
            if seg is None:
                return
            segments.append(seg)

    def _prep_segment(self) -> _Segment | None:
        """Cut the next segment off the tail block, as st_prep_buffer does; None if nothing."""
        if not self._blocks:
            return None
        if self._hold and self._prep_speed_mm_s <= 0.0 and self._prep_d_mm > 0.0:
            return None  # the hold has reached rest: prepare nothing more
        block = self._blocks[0]
        exit_sqr = 0.0 if self._hold or len(self._blocks) < 2 else self._blocks[1].entry_sqr
        d0 = self._prep_d_mm
        v = self._prep_speed_mm_s if d0 > 0.0 else math.sqrt(block.entry_sqr)
        if self._hold and d0 == 0.0:
            v = self._prep_speed_mm_s  # a hold carries its speed across block boundaries
        d, v, dt_used = _run_profile(
            d0,
            v,
            block.length_mm,
            block.nominal_mm_s,
            math.sqrt(exit_sqr),
            block.accel_mm_s2,
            self.segment_s,
            forced_decel=self._hold,
        )
        ends_block = block.length_mm - d <= _EPS_MM
        if dt_used <= _EPS_S and not ends_block:
            # Nothing left to move (a hold ended exactly at the start of this segment).
            self._prep_speed_mm_s = 0.0
            self._prep_d_mm = max(d0, _EPS_MM)
            return None
        seg = _Segment(block, d0, block.length_mm if ends_block else d, dt_used, v, ends_block)
        self._prep_speed_mm_s = v
        if ends_block:
            self._blocks.popleft()
            self._prep_d_mm = 0.0
            if self._blocks:
                nxt = self._blocks[0]
                if not self._hold:
                    # The next block starts at the speed this one exits with.
                    nxt.entry_sqr = v * v
        else:
            self._prep_d_mm = d
            if self._hold and v <= 0.0:
                self._prep_d_mm = max(d, _EPS_MM)
        return seg

    # ----------------------------------------------------------------- observation
    def _steps_in_block(self, block: _Block, d_mm: float) -> tuple[int, ...]:
        # Hot path (every segment and status report): precomputed integer deltas, no generator.
        frac = d_mm / block.length_mm
        return tuple(
            [s + round(n * frac) for s, n in zip(block.start_steps, block.delta_steps, strict=True)]
        )

    def position_steps(self) -> tuple[int, ...]:
        """The step counters at the last time advanced to (mid-segment positions interpolated)."""
        if not self._running or not self._segments:
            return self._machine_steps
        seg = self._segments[0]
        frac = (self._now_s - self._exec_start_s) / seg.dt_s if seg.dt_s > 0 else 1.0
        frac = min(max(frac, 0.0), 1.0)
        return self._steps_in_block(seg.block, seg.d0_mm + (seg.d1_mm - seg.d0_mm) * frac)

    def position_mm(self) -> tuple[float, ...]:
        """Machine position in mm: step counts over steps/mm, in double (ground truth)."""
        return tuple(
            s / spm for s, spm in zip(self.position_steps(), self._steps_per_mm, strict=True)
        )

    def planner_position_mm(self) -> tuple[float, ...]:
        """The end of the last planned block in machine mm (in double)."""
        return tuple(
            s / spm for s, spm in zip(self._planner_steps, self._steps_per_mm, strict=True)
        )

    def speed_mm_s(self) -> float:
        """The true speed now: the executing segment's constant speed (0 when stopped)."""
        if not self._running or not self._segments:
            return 0.0
        seg = self._segments[0]
        return (seg.d1_mm - seg.d0_mm) / seg.dt_s if seg.dt_s > 0 else 0.0

    def realtime_rate_mm_min(self) -> float:
        """The speed at the end of the most recently prepared segment: Grbl's `FS` feed value."""
        if not self._running:
            return 0.0
        return mm_s_to_mm_min(self._prep_speed_mm_s)

    def queued_segments(self) -> int:
        """Prepared segments waiting, the executing one included."""
        return len(self._segments)


def _run_profile(
    d_mm: float,
    v_mm_s: float,
    length_mm: float,
    nominal_mm_s: float,
    exit_mm_s: float,
    accel_mm_s2: float,
    dt_s: float,
    *,
    forced_decel: bool,
) -> tuple[float, float, float]:
    """Follow a block's trapezoid for up to dt_s from (d, v); returns (d, v, time used).

    Stops early at the end of the block, or (forced deceleration) when the speed reaches zero.
    """
    a = accel_mm_s2
    t_left = dt_s
    d, v = d_mm, v_mm_s
    for _ in range(64):  # a handful of phase changes per segment at most; the cap guards rounding
        rem = length_mm - d
        if t_left <= _EPS_S or rem <= _EPS_MM:
            break
        if forced_decel:
            t_stop = v / a
            disc = v * v - 2.0 * a * rem
            t_end = (v - math.sqrt(disc)) / a if disc > 0.0 else math.inf
            t = min(t_left, t_stop, t_end)
            d = min(d + v * t - 0.5 * a * t * t, length_mm)
            v = max(v - a * t, 0.0)
            t_left -= t
            if t == t_end:
                d, v = length_mm, math.sqrt(disc)
            if t in (t_end, t_stop):
                break
            continue
        decel_dist = (v * v - exit_mm_s * exit_mm_s) / (2.0 * a)
        if rem <= decel_dist + 1e-9 * (1.0 + decel_dist):
            # Decelerate so as to arrive at the block end exactly at the exit speed.
            a_eff = max((v * v - exit_mm_s * exit_mm_s) / (2.0 * rem), 1e-12)
            if a_eff > a * (1.0 + 1e-6):
                # Only after an override cut (the planner never asks for more): Grbl's
                # deceleration override decelerates at the block's own rate and leaves the
                # block faster than planned; the next block starts from that speed.
                exit_mm_s = math.sqrt(max(v * v - 2.0 * a * rem, 0.0))
                a_eff = a
            t_end = (v - exit_mm_s) / a_eff if v > exit_mm_s else rem / max(v, 1e-12)
            t = min(t_left, t_end)
            if t == t_end:
                d, v = length_mm, exit_mm_s
                t_left -= t
                break
            d += v * t - 0.5 * a_eff * t * t
            v -= a_eff * t
            t_left -= t
            continue
        if v < nominal_mm_s - 1e-9:
            # Accelerate towards nominal, or to where acceleration meets the final deceleration.
            peak = math.sqrt((v * v + exit_mm_s * exit_mm_s + 2.0 * a * rem) / 2.0)
            target = min(nominal_mm_s, peak)
            t_acc = (target - v) / a
            if t_acc <= _EPS_S:
                v = target
                continue
            t = min(t_left, t_acc)
            d += v * t + 0.5 * a * t * t
            v = target if t == t_acc else v + a * t
            t_left -= t
            continue
        if v > nominal_mm_s + 1e-9:
            # Faster than this block allows (it follows a faster one): come down to nominal.
            t = min(t_left, (v - nominal_mm_s) / a)
            d += v * t - 0.5 * a * t * t
            v = max(v - a * t, nominal_mm_s)
            t_left -= t
            continue
        # Cruise at nominal up to the deceleration point.
        v = nominal_mm_s
        cruise_mm = rem - (v * v - exit_mm_s * exit_mm_s) / (2.0 * a)
        t = min(t_left, cruise_mm / v)
        d += v * t
        t_left -= t
    return min(d, length_mm), v, dt_s - t_left
