"""Steps, go-tos and handwheel runs: one ordered queue of exact moves.

Position-mode handwheel runs on one axis merge into longer lines and keep a running target on
the step grid, so the machine moves exactly the counts turned; velocity-mode counts beyond the
stopping distance are dropped, and a wheel silent for wheel_timeout_s ends its run.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from decimal import Decimal

from smoothjog.core import increments as inc
from smoothjog.core.engine.limits import EngineLimits
from smoothjog.core.engine.parts import MotionParts
from smoothjog.core.engine.records import Output
from smoothjog.core.engine.tracker import PathSeg
from smoothjog.core.intents import GotoIntent, HandwheelIntent, StepIntent
from smoothjog.core.jogline import MM_DECIMALS, build_jog_line, format_number
from smoothjog.core.units import mm_min_to_mm_s, mm_s_to_mm_min, norm


@dataclass
class WheelRun:
    """Handwheel detents not yet sent: one axis, one direction, one feed, one mode.

    Reports that agree on all four merge into one run, and so into one line (its distance
    is exact: a decimal sum of count x step).
    """

    axis: int  # index into the machine's axes
    sign: int  # +1 or -1
    dist_mm: Decimal  # > 0: the detents' distance, exactly as the user's step sizes add up
    counts: int
    speed: float
    mode: str  # "position", "velocity"
    last_s: float  # when its newest detent arrived (velocity mode's timeout runs from it)


@dataclass(frozen=True)
class WheelChain:
    """The running target of one axis's handwheel moves, so that rounding never accumulates.

    Every line goes to the step nearest anchor + total (firmware-facts §1.5), never to the
    previous target plus this report's distance. The chain holds while the axis's path end is
    still end_mm (no other move, stop or clip came between).
    """

    anchor_mm: float  # the axis's parser position where the chain began
    total_mm: Decimal  # signed detent distance since the anchor
    end_mm: float  # the axis's path end after the chain's last line


@dataclass(frozen=True)
class WheelPlan:
    """The next line of a run (None when it moves no step) and the chain once it is sent."""

    axis: int
    chain: WheelChain
    line: str | None
    seg: PathSeg | None
    clipped: bool


Queued = StepIntent | GotoIntent | WheelRun


class StepQueue:
    """Steps, go-tos and handwheel runs waiting to be sent, in order."""

    def __init__(self, parts: MotionParts, limits: EngineLimits) -> None:
        """An empty queue."""
        self.parts = parts
        self.limits = limits
        self.queue: deque[Queued] = deque()
        #: Per axis index: the running target of its handwheel moves.
        self._chains: dict[int, WheelChain] = {}
        #: (axis index, sign) of the newest velocity-mode detents taken: a report the other
        #: way on that axis is a reversal.
        self.wheel_dir: tuple[int, int] | None = None

    def wheel_next(self) -> bool:
        """True when a handwheel run is next in the queue."""
        return bool(self.queue) and isinstance(self.queue[0], WheelRun)

    def abandon(self) -> None:
        """Forget everything queued (a door, hold, alarm or reset)."""
        self.queue.clear()
        self.wheel_dir = None

    def keep_steps(self, queued: list[Queued]) -> None:
        """Queue again the steps and go-tos of queued (a handwheel run's moment has passed)."""
        self.queue.extend(step for step in queued if not isinstance(step, WheelRun))

    def after_stop(self, now_s: float) -> None:
        """A stop ended: detents queued behind it waited for the engine, not for a still wheel,
        so their timeout runs from now."""
        wheel_runs = [r for r in self.queue if isinstance(r, WheelRun)]
        if not wheel_runs:
            self.wheel_dir = None
        for run in wheel_runs:
            run.last_s = max(run.last_s, now_s)

    def wheel_feed(self, axis: int, speed: float) -> tuple[float, float]:
        """A handwheel's speed (mm/s: speed x the axis's max rate) and acceleration on axis."""
        feed_mm_min = round(self.limits.max_rate_mm_min[axis] * speed, 3)
        return mm_min_to_mm_s(feed_mm_min), self.limits.accel_mm_s2[axis]

    def take_wheel(
        self, wheel: HandwheelIntent, now_s: float, *, stop_requested: bool, stopping: bool
    ) -> bool:
        """Queue a report's detents; in velocity mode drop what runs past the stopping distance.
        Returns whether a stop is requested now (a velocity reversal cancels what was sent).

        Velocity mode (LinuxCNC's MPG velocity mode): the path ahead of the machine, with what
        waits unsent, never exceeds v²/2a + v·committed_s at the wheel's feed along the axis.
        A report the other way on the same axis cancels everything queued, then goes that way.
        Position mode keeps every count.
        """
        track = self.parts.track
        axis = self.limits.axes.index(wheel.axis)
        sign = 1 if wheel.counts > 0 else -1
        counts = abs(wheel.counts)
        if wheel.mode == "velocity":
            if self.wheel_dir == (axis, -sign):
                self.queue.clear()
                # Only what was sent needs the handshake; detents still unsent just go.
                stop_requested = stop_requested or bool(track.path)
            self.wheel_dir = (axis, sign)
            speed_mm_s, accel_mm_s2 = self.wheel_feed(axis, wheel.speed)
            limit_mm = inc.queue_target_mm(speed_mm_s, accel_mm_s2, self.parts.tuning.committed_s)
            track.update_estimate(now_s)
            # A path being cancelled (or about to be) is not ahead: the reversal starts after it.
            ahead_mm = 0.0 if (stop_requested or stopping) else track.queued_mm()
            ahead_mm += sum(float(r.dist_mm) for r in self.queue if isinstance(r, WheelRun))
            # A line goes to the step nearest its running target: up to half a step further.
            ahead_mm += 0.5 / self.limits.steps_per_mm[axis]
            fit = min(counts, int(max(limit_mm - ahead_mm, 0.0) / wheel.step_mm + 1e-9))
            self.parts.stats.wheel_counts_dropped += counts - fit
            counts = fit
            if not counts:
                return stop_requested
        # The shortest decimal that reads back as step_mm: 0.01, not the binary value near it.
        dist_mm = Decimal(str(float(wheel.step_mm))) * counts
        last = self.queue[-1] if self.queue else None
        if isinstance(last, WheelRun) and (last.axis, last.sign, last.speed, last.mode) == (
            axis,
            sign,
            wheel.speed,
            wheel.mode,
        ):
            last.dist_mm += dist_mm
            last.counts += counts
            last.last_s = now_s
            return stop_requested
        self.queue.append(WheelRun(axis, sign, dist_mm, counts, wheel.speed, wheel.mode, now_s))
        return stop_requested

    def stream(self, now_s: float, out: list[Output]) -> bool:
        """Send what the planner and the RX buffer take; True when all is sent and answered
        (the queue then settles)."""
        p = self.parts
        track = p.track
        if track.end_mm is None:
            if p.model.mpos_mm is None:
                return False
            # moving_since_ack is kept as it was: a step queue after a jog starts estimating
            # from now, not from its first ok.
            track.begin(track.on_step_grid(p.model.mpos_mm), now_s)
        usable_blocks = max(self.limits.planner_blocks - p.tuning.planner_reserve_blocks, 1)
        while self.queue and track.blocks_in_planner() < usable_blocks:
            step = self.queue[0]
            plan: WheelPlan | None = None
            if isinstance(step, WheelRun):
                if step.mode == "velocity" and now_s - step.last_s > p.tuning.wheel_timeout_s:
                    # The wheel stopped while these waited for room: the machine rests at the
                    # end of what was sent instead of running on after it.
                    p.stats.wheel_counts_dropped += step.counts
                    self.queue.popleft()
                    continue
                if step.mode == "position" and self._wheel_waits(step):
                    break  # merge further reports into this run while the queue holds speed
                plan = self._plan_wheel(step)
                line_seg = None if plan.line is None or plan.seg is None else (plan.line, plan.seg)
            else:
                line_seg = self._step_line(step)
            if line_seg is None:
                if plan is not None:
                    self._commit_wheel(plan, now_s)
                self.queue.popleft()
                continue
            line, seg = line_seg
            if not p.lines.fits(line):
                p.lines.rx_blocked = True
                return False
            self.queue.popleft()
            if plan is not None:
                self._commit_wheel(plan, now_s)
            track.append(seg)
            p.lines.send(line, "jog", now_s, out, seg)
        return not self.queue and not p.lines.unanswered()

    def _wheel_waits(self, run: WheelRun) -> bool:
        """True while the path queued already keeps the machine at the run's speed: later
        reports then merge into it, so a wheel spun faster than the machine sends long lines."""
        p = self.parts
        if not p.track.path:
            return False
        speed_mm_s, accel_mm_s2 = self.wheel_feed(run.axis, run.speed)
        ahead_s = (
            p.tuning.committed_s + p.clock.rtt_s + p.tuning.link_margin_s + p.tuning.settle_tick_s
        )
        return p.track.queued_mm() >= inc.queue_target_mm(speed_mm_s, accel_mm_s2, ahead_s)

    def _plan_wheel(self, run: WheelRun) -> WheelPlan:
        """The G91 line taking the run's axis to the step nearest its running target.

        The target is clipped at the soft limits (one step inside) and one step short of a
        keep-out zone: the counts past it are dropped, and the chain starts again at the edge.
        """
        track = self.parts.track
        start = track.end_mm
        assert start is not None
        i = run.axis
        spm = self.limits.steps_per_mm[i]
        chain = self._chains.get(i)
        # Compared in whole steps: a machine that came to rest between reports reads back its
        # position on the step grid, a float an ulp away from the chain's own sum.
        if chain is None or round(chain.end_mm * spm) != round(start[i] * spm):
            chain = WheelChain(start[i], Decimal(0), start[i])
        total_mm = chain.total_mm + run.sign * run.dist_mm
        target = inc.nearest_step_mm(Decimal(chain.anchor_mm) + total_mm, spm)
        chain = WheelChain(chain.anchor_mm, total_mm, start[i])
        room_mm = self.parts.clearance.axis_room_mm(start, i, run.sign)
        clipped = (target - start[i]) * run.sign > room_mm
        if clipped:
            # Round toward the start so the edge's one step of margin is kept.
            edge = (start[i] + run.sign * room_mm) * spm
            target = (math.floor(edge + 1e-9) if run.sign > 0 else math.ceil(edge - 1e-9)) / spm
            chain = WheelChain(target, Decimal(0), start[i])
        d = float(format_number(target - start[i], MM_DECIMALS))
        end = tuple(s + (d if k == i else 0.0) for k, s in enumerate(start))
        if d * run.sign <= 0.0 or not self.parts.clearance.fits_envelope(end):
            return WheelPlan(i, chain, None, None, clipped)
        feed_mm_min = round(self.limits.max_rate_mm_min[i] * run.speed, 3)
        speed_mm_s, accel_mm_s2 = self.wheel_feed(i, run.speed)
        line = build_jog_line(
            moves={self.limits.axes[i]: d},
            feed_mm_min=feed_mm_min,
            mode="G91",
            axes=self.limits.axes,
            max_line_chars=self.limits.max_line_chars,
        )
        seg = PathSeg(start, end, abs(d), speed_mm_s, accel_mm_s2, track.length_mm())
        return WheelPlan(i, WheelChain(chain.anchor_mm, chain.total_mm, end[i]), line, seg, clipped)

    def _commit_wheel(self, plan: WheelPlan, now_s: float) -> None:
        """The run's line was sent (or moved no step): keep its chain, and say if it was cut
        (once, with the line that reaches the limit)."""
        self._chains[plan.axis] = plan.chain
        if plan.clipped:
            self.parts.stats.wheel_clips += 1
        if plan.clipped and plan.line is not None:
            axis = self.limits.axes[plan.axis]
            self.parts.notices.info(
                now_s,
                f"handwheel {axis} stopped at the soft limit or a keep-out zone "
                f"({axis}={plan.chain.anchor_mm:.4f}); the detents past it were dropped",
            )

    def _step_line(self, step: StepIntent | GotoIntent) -> tuple[str, PathSeg] | None:
        """The line of a step or go-to, shortened at an edge; None (said in words) if refused."""
        p = self.parts
        start = p.track.end_mm
        assert start is not None
        axes = self.limits.axes
        if isinstance(step, StepIntent):
            i = axes.index(step.axis)
            dist_mm = float(format_number(step.dist_mm, MM_DECIMALS))
            d = p.clearance.step_room_mm(start, i, dist_mm)
            if d is None:
                return None
            end = tuple(s + (d if k == i else 0.0) for k, s in enumerate(start))
            moves = {step.axis: d}
            mode = "G91"
        else:
            end = tuple(
                float(format_number(step.target_mpos_mm.get(a, s), MM_DECIMALS))
                for a, s in zip(axes, start, strict=True)
            )
            moves = {a: end[k] for k, a in enumerate(axes) if a in step.target_mpos_mm}
            mode = "G53"
        problem = p.clearance.path_problem(start, end)
        if problem is not None:
            p.notices.fault_now(
                p.track.est_s, f"jog refused: {problem}", "jog less far or elsewhere", refusal=True
            )
            return None
        delta = tuple(e - s for e, s in zip(end, start, strict=True))
        move = inc.vector_move(
            tuple(d * 1e6 for d in delta), self.limits.max_rate_mm_min, self.limits.accel_mm_s2
        )
        if move is None:
            return None
        # A fraction of the fastest this direction allows, each axis within its own $11x.
        top_mm_s = move.speed_mm_s
        if p.tuning.max_feed_mm_min:
            top_mm_s = min(top_mm_s, mm_min_to_mm_s(p.tuning.max_feed_mm_min))
        speed_mm_s = top_mm_s * step.speed
        line = build_jog_line(
            moves=moves,
            feed_mm_min=round(mm_s_to_mm_min(speed_mm_s), 3),
            mode=mode,  # type: ignore[arg-type]
            axes=axes,
            max_line_chars=self.limits.max_line_chars,
        )
        seg = PathSeg(start, end, norm(delta), speed_mm_s, move.accel_mm_s2, p.track.length_mm())
        return line, seg
