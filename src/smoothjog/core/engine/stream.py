"""Streaming: a held stick's velocity, the queue kept ahead of the machine, and its increments.

The queue is v²/2a plus v times the committed segments, the time a new line needs to reach the
planner, the host's lateness and the configured margin; each increment lasts just over one 10 ms
segment unless the link or the planner asks for longer (docs/jogging.md, "Continuous jogging").
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from smoothjog.core import increments as inc
from smoothjog.core.engine.clearance import MIN_BLOCK_STEPS, Suspect
from smoothjog.core.engine.limits import EngineLimits
from smoothjog.core.engine.parts import MotionParts
from smoothjog.core.engine.records import Output
from smoothjog.core.engine.tracker import PathSeg
from smoothjog.core.errors import JogBuildError
from smoothjog.core.intents import ContinuousIntent, Intent
from smoothjog.core.jogline import MM_DECIMALS, build_jog_line, format_number
from smoothjog.core.units import Vec, g91_end, mm_min_to_mm_s, mm_s_to_mm_min, norm

#: Grbl's slowest feed (MINIMUM_FEED_RATE, 1 mm/min, firmware-facts §4.2), in mm/s.
MIN_FEED_MM_S = 1.0 / 60.0
#: A queue within this of its target is topped up: the wake-up computed for the instant the
#: queue reaches its target must send then, not find a rounding error's worth still queued.
QUEUE_TOLERANCE_MM = 1e-6
#: Queue kept beyond the stopping distance and the committed segments however slow the jog:
#: with less, an outside stop would run it all and rest where a queue run dry rests.
QUEUE_FLOOR_MM = 0.3
#: Repeats of one increment before its run is worked out afresh from where the firmware put
#: the last target: 16 lines drift at most 8 ulps off the ray, 0.001 mm within 2048 mm.
CRUISE_LINES = 16
#: Share of the wire's throughput the engine's own lines may take (the rest: `?`, other owners).
LINE_SHARE = 0.6
#: The longest wait a release may expect, on average, for the `ok` of a jog line still on the
#: wire: at 9600 baud (25 ms per line) blocks of 78 ms; at 38400 and faster it never binds.
RELEASE_WAIT_S = 0.004
#: How much sooner (s) a cancel-and-restart must reach a faster speed than letting the queued
#: slower blocks run out before the engine cancels for a speed-up alone.
SPEEDUP_CANCEL_MARGIN_S = 0.15


@dataclass(eq=False)
class Cruise:
    """One increment repeated while a held jog cruises, and how far its ray is clear."""

    move: inc.VectorMove
    limits: EngineLimits
    length_mm: float
    line: str
    deltas_mm: Vec
    seg_len_mm: float
    unit_vec: Vec
    clear_mm: float  # along unit_vec from where the run began
    run_mm: float  # path of the run sent so far
    next_start_mm: Vec  # where the next repeat must start (the end of the last one sent)
    lines: int = 0  # repeats sent (the run is worked out afresh after CRUISE_LINES)


def still(axes: int) -> inc.VectorMove:
    """The commanded move of an engine at rest."""
    return inc.VectorMove((0.0,) * axes, 0.0, 1.0)


class Streamer:
    """Continuous jogging: the velocity a stick asks for, the queue's size and its lines."""

    def __init__(self, parts: MotionParts, limits: EngineLimits) -> None:
        """Nothing streamed yet."""
        self.parts = parts
        self.limits = limits
        self.ratios = dict(parts.tuning.speed_ratios)
        self._ratios_version = 0
        #: The increment a cruising jog repeats (None: work the next one out afresh).
        self.cruise: Cruise | None = None
        #: The stick already told why it moves nothing.
        self._edge_told: Intent | None = None
        self._block_cache: tuple[inc.VectorMove, EngineLimits, tuple[float, int], float] | None = (
            None
        )
        self._velocity_cache: (
            tuple[ContinuousIntent, int, EngineLimits, inc.VectorMove | None] | None
        ) = None
        #: The move the stick asks for now (zero at rest).
        self.commanded = still(len(limits.axes))
        #: When the streaming queue needs its next top-up (None: a reply will say).
        self.wake_at_s: float | None = None

    def set_speed_ratios(self, ratios: Mapping[str, float]) -> None:
        """Per-axis speed ratios in (0, 1]."""
        for axis, r in ratios.items():
            if axis not in self.limits.axes:
                raise JogBuildError(f"speed ratio for unknown axis {axis!r}")
            if not (0.0 < r <= 1.0):
                raise JogBuildError(f"speed ratio {r!r} for {axis} must be in (0, 1]")
        self.ratios.update(ratios)
        self._ratios_version += 1

    def velocity(self, intent: Intent | None) -> inc.VectorMove | None:
        """The per-axis velocity the intent asks for, capped as Grbl caps it."""
        if not isinstance(intent, ContinuousIntent):
            return None
        # A held stick asks the same at every poll (about a hundred a second): computed once.
        cache = self._velocity_cache
        if (
            cache is not None
            and cache[0] is intent
            and cache[1] == self._ratios_version
            and cache[2] is self.limits
        ):
            return cache[3]
        move = self._velocity_of(intent)
        self._velocity_cache = (intent, self._ratios_version, self.limits, move)
        return move

    def _velocity_of(self, intent: ContinuousIntent) -> inc.VectorMove | None:
        # Speed, deflection and ratio are fractions of each axis's own maximum ($11x): Z at
        # 25 % runs at a quarter of $112, not at a quarter of the fastest axis.
        vel = tuple(
            intent.axes.get(axis, 0.0)
            * self.ratios.get(axis, 1.0)
            * intent.speed
            * mm_min_to_mm_s(self._axis_feed_mm_min(rate_mm_min))
            for axis, rate_mm_min in zip(self.limits.axes, self.limits.max_rate_mm_min, strict=True)
        )
        move = inc.vector_move(vel, self.limits.max_rate_mm_min, self.limits.accel_mm_s2)
        if move is None or move.speed_mm_s < MIN_FEED_MM_S:
            return None  # below Grbl's 1 mm/min floor the stick is as good as neutral
        return move

    def _axis_feed_mm_min(self, rate_mm_min: float) -> float:
        """An axis's full jog speed: its $11x, or the configured top feed if that is lower."""
        cap = self.parts.tuning.max_feed_mm_min
        return min(rate_mm_min, cap) if cap else rate_mm_min

    def ahead_s(self, block_s: float, now_s: float) -> float:
        """Queue time beyond the stopping distance: committed segments, the time a line needs
        to reach the planner, how late the host wakes, the configured margin.

        The firmware commits segments of the blocks already queued, so the longest of those
        (or of the next one) decides how much time five segments can hold.
        """
        p = self.parts
        longest_s = p.track.longest_queued_s(block_s)
        committed = min(inc.committed_s(longest_s), p.tuning.committed_s)
        return committed + p.clock.queue_rtt_s(now_s) + p.clock.lateness_s + p.tuning.link_margin_s

    def block_s(self, move: inc.VectorMove) -> float:
        """Duration of one increment at this speed: just over one 10 ms segment when possible.

        It must still satisfy dt >= v/(2a(N-1)), let the planner hold the stopping distance
        within the blocks the engine allows itself, let each line cross the wire in time and
        let the lines the RX buffer holds span a round trip.
        """
        clock = self.parts.clock
        tuning = self.parts.tuning
        cache = self._block_cache
        if (
            cache is not None
            and cache[0] is move
            and cache[1] is self.limits
            and cache[2] == (clock.rtt_hi_s, clock.line_bytes)
        ):
            return cache[3]  # a held jog asks for the same move at every poll
        usable = max(self.limits.planner_blocks - tuning.planner_reserve_blocks, 2)
        rx_lines = max(self.limits.rx_buffer_bytes // clock.line_bytes - 1, 1)
        line_s = clock.line_bytes * clock.byte_s
        block_s = max(
            line_s / LINE_SHARE,
            # A release waits for the `ok` of a line still crossing the wire before its cancel
            # (firmware-facts §3.1): long blocks keep that expected wait short.
            line_s * line_s / (2.0 * RELEASE_WAIT_S),
            clock.rtt_hi_s / rx_lines,
            tuning.dt_floor_s,
            inc.min_block_s(move.speed_mm_s, move.accel_mm_s2, self.limits.planner_blocks),
            inc.stop_distance_mm(move.speed_mm_s, move.accel_mm_s2)
            / (move.speed_mm_s * (usable - 1)),
            # A very slow jog still moves at least a step and a half per block.
            MIN_BLOCK_STEPS * self.parts.clearance.step_along_mm(move.unit_vec) / move.speed_mm_s,
        )
        self._block_cache = (move, self.limits, (clock.rtt_hi_s, clock.line_bytes), block_s)
        return block_s

    def stream(
        self, now_s: float, out: list[Output], intent: Intent | None, suspect: Suspect | None
    ) -> None:
        """Top the queue up to its target for the intent's velocity."""
        move = self.velocity(intent)
        if move is None:
            return
        p = self.parts
        track, tuning = p.track, p.tuning
        self.commanded = move
        if not track.path:
            self._start_from_newest_report(now_s)
        n_blocks = self.limits.planner_blocks
        usable_blocks = max(n_blocks - tuning.planner_reserve_blocks, 1)
        block_s = self.block_s(move)
        ahead_s = self.ahead_s(block_s, now_s)
        committed_s = (
            ahead_s - p.clock.queue_rtt_s(now_s) - p.clock.lateness_s - tuning.link_margin_s
        )
        blocks = track.blocks_in_planner()
        for _ in range(n_blocks):
            queued_mm = track.queued_mm()
            # While the machine is still faster than the new speed (a slowdown), size the queue
            # for the speed it has, or the planner brakes below the new speed.
            speed_mm_s = max(move.speed_mm_s, track.v_est_mm_s)
            target_mm = max(
                inc.queue_target_mm(speed_mm_s, move.accel_mm_s2, ahead_s),
                inc.queue_target_mm(speed_mm_s, move.accel_mm_s2, committed_s) + QUEUE_FLOOR_MM,
            )
            if queued_mm >= target_mm + QUEUE_TOLERANCE_MM:
                # Nothing to send until the queue has drained to its target.
                self.wake_at_s = self._run_time_s(now_s, queued_mm - target_mm, move)
                return
            if blocks >= usable_blocks:
                # The planner is as full as the engine lets it be until a block is committed.
                lead_mm = track.uncommitted_lead_mm()
                if lead_mm is not None:
                    self.wake_at_s = self._run_time_s(now_s, lead_mm, move)
                return
            # Blocks of the planned duration, but never so short that the queue needs more of
            # them than the engine allows itself.
            length_mm = max(
                move.speed_mm_s * block_s,
                (target_mm - speed_mm_s * tuning.committed_s) / max(usable_blocks - 1, 1),
            )
            if not track.path:
                # The first block must be long enough that the firmware's committed ramp never
                # turns to braking before the next lines arrive (a fresh jog would stutter).
                ramp_s = tuning.committed_s + 2.0 * p.clock.rtt_s + tuning.dt_floor_s
                length_mm = max(length_mm, min(move.accel_mm_s2 * ramp_s**2, target_mm))
            if not self._send_increment(move, length_mm, now_s, out, intent, suspect):
                return
            blocks += 1

    def _start_from_newest_report(self, now_s: float) -> None:
        """Nothing is sent yet in this run: start its path where the newest report puts the
        machine (a report damaged in a way its format cannot show is put right by the next)."""
        track = self.parts.track
        mpos = self.parts.model.mpos_mm
        if mpos is None or len(mpos) != len(self.limits.axes):
            return
        start = track.on_step_grid(mpos)
        if start != track.end_mm:
            track.begin(start, now_s)
            self.cruise = None

    def _run_time_s(self, now_s: float, dist_mm: float, move: inc.VectorMove) -> float | None:
        """When the machine will have run dist_mm further, at the faster of its estimated and
        commanded speed (so an accelerating machine is never woken for too late); None at rest.
        """
        track = self.parts.track
        speed_mm_s = max(track.v_est_mm_s, move.speed_mm_s)
        if not track.moving_since_ack or speed_mm_s <= 0.0:
            return None  # nothing drains before the first ok: that reply wakes the engine
        return now_s + dist_mm / speed_mm_s

    def _repeat(self, start: Vec, move: inc.VectorMove, length_mm: float) -> Vec | None:
        """Where the cruise's increment ends when repeated from start, if it may be."""
        cruise = self.cruise
        if (
            cruise is not None
            and cruise.move is move
            and cruise.length_mm == length_mm
            and cruise.limits is self.limits
            and start == cruise.next_start_mm
            and cruise.clear_mm >= cruise.run_mm + cruise.seg_len_mm
            and cruise.lines < CRUISE_LINES
        ):
            # The firmware's single-precision sums leave each start up to half an ulp per line
            # off the ray, so the run is worked out afresh every CRUISE_LINES lines.
            end = g91_end(start, cruise.deltas_mm)
            return end if self.parts.clearance.fits_envelope(end) else None
        return None

    def _send_increment(
        self,
        move: inc.VectorMove,
        length_mm: float,
        now_s: float,
        out: list[Output],
        intent: Intent | None,
        suspect: Suspect | None,
    ) -> bool:
        """Send one G91 increment along move (clipped to the envelope and keep-outs)."""
        p = self.parts
        track, clearance = p.track, p.clearance
        start = track.end_mm
        assert start is not None
        cruise = self.cruise
        end = self._repeat(start, move, length_mm)
        if end is not None:
            assert cruise is not None
            line, deltas, seg_len = cruise.line, cruise.deltas_mm, cruise.seg_len_mm
            run_mm = cruise.run_mm + seg_len
            seg_move = move
        else:
            made = self._make_increment(start, move, length_mm, intent)
            if made is None:
                return False
            line, deltas, seg_len, cruise, seg_move = made
            run_mm = seg_len
            # Where the firmware's parser will put the target, not the sum in doubles.
            end = g91_end(start, deltas)
            if not clearance.fits_envelope(end):
                if not track.path and not clearance.fits_envelope(start):
                    # Outside the soft-limit travel (or a report damaged on the wire).
                    self._tell_once_per_stick(
                        intent,
                        "no jog fits from where the controller reports the machine"
                        f" ({clearance.where_blocked(start)}): that is outside the soft limits",
                        "if the report was right, move back inside with soft limits off"
                        " ($20=0) or home",
                    )
                return False
        if self.limits.keepouts and not clearance.ghost_clear(deltas, suspect):
            # Sent now, this line could run from where an outside stop left the machine and cut
            # into a keep-out: wait until the machine has come far enough along the path.
            self.wake_at_s = now_s + p.tuning.settle_tick_s
            return False
        if not p.lines.fits(line):
            p.lines.rx_blocked = True
            return False
        if cruise is not None:
            cruise.run_mm = run_mm
            cruise.next_start_mm = end
            cruise.lines += 1
        self.cruise = cruise
        seg = PathSeg(
            start,
            end,
            # The length between the float positions the path keeps (not the exact increment).
            norm(tuple(e - s for e, s in zip(end, start, strict=True))),
            # The speed and acceleration of the line as written (a slide has the axes left).
            seg_move.speed_mm_s,
            seg_move.accel_mm_s2,
            track.length_mm(),
            unit_vec=cruise.unit_vec if cruise is not None else None,
        )
        track.append(seg)
        p.lines.send(line, "jog", now_s, out, seg)
        return True

    def _make_increment(
        self, start: Vec, move: inc.VectorMove, length_mm: float, intent: Intent | None
    ) -> tuple[str, Vec, float, Cruise | None, inc.VectorMove] | None:
        """Clip, round and write one increment; the cruise to repeat it, when it may be."""
        clearance = self.parts.clearance
        clipped = clearance.clip(start, move, length_mm)
        if clipped is None:
            # The stick is still held but there is no room left that way: say why.
            self._tell_once_per_stick(
                intent,
                f"the jog stops at {clearance.blocked_by} ({clearance.where_blocked(start)})",
                "jog another way, or change the limits if they are wrong",
            )
            return None
        clipped_move, clipped_mm = clipped
        deltas: dict[str, float] = {}
        for axis, u in zip(self.limits.axes, clipped_move.unit_vec, strict=True):
            d = float(format_number(u * clipped_mm, MM_DECIMALS))
            if d != 0.0:
                deltas[axis] = d
        if not deltas:
            return None
        line = build_jog_line(
            moves=deltas,
            feed_mm_min=round(mm_s_to_mm_min(clipped_move.speed_mm_s), 3),
            mode="G91",
            axes=self.limits.axes,
            max_line_chars=self.limits.max_line_chars,
        )
        clock = self.parts.clock
        clock.line_bytes = max(clock.line_bytes, len(line) + 1)  # sizes blocks for the link
        delta_vec = tuple(deltas.get(axis, 0.0) for axis in self.limits.axes)
        seg_len = norm(delta_vec)
        if clipped_move is not move or clipped_mm != length_mm or seg_len <= 0.0:
            # Near an edge: worked out afresh each time; a slide runs at its own speed.
            return line, delta_vec, seg_len, None, clipped_move
        # The rounded increment's own direction: start + k * delta stays exactly on this ray,
        # so its clear distance holds for every repeat.
        ray = tuple(d / seg_len for d in delta_vec)
        cruise = Cruise(
            move=move,
            limits=self.limits,
            length_mm=length_mm,
            line=line,
            deltas_mm=delta_vec,
            seg_len_mm=seg_len,
            unit_vec=ray,
            clear_mm=clearance.room_along(start, ray)[0],
            run_mm=0.0,
            next_start_mm=start,
        )
        return line, delta_vec, seg_len, cruise, move

    def _tell_once_per_stick(self, intent: Intent | None, text: str, hint: str) -> None:
        """Say why a held stick moves nothing, once for this stick position."""
        if intent is None or self._edge_told is intent:
            return
        self._edge_told = intent
        self.parts.notices.info(self.parts.track.est_s, text, hint)

    def turn_wants_cancel(self, intent: Intent | None, now_s: float) -> bool:
        """On a big change of the stick, True when cancel-and-restart beats letting the queue
        run (the choice is recorded in the stats)."""
        previous = self.commanded
        new = self.velocity(intent)
        if new is None or previous.speed_mm_s <= 0.0:
            return False
        cos = sum(a * b for a, b in zip(previous.unit_vec, new.unit_vec, strict=True))
        slower = new.speed_mm_s < 0.8 * previous.speed_mm_s
        # A speed-up from a crawl: the slow blocks queued must run out at their own feed first,
        # which at a few mm/s can take longer than stopping and starting again.
        faster = new.speed_mm_s > 1.25 * previous.speed_mm_s
        if cos > 0.5 and not slower and not faster:
            return False
        reverse = cos <= 0.5
        accel = min(previous.accel_mm_s2, new.accel_mm_s2)
        p = self.parts
        let_run = inc.let_run_turn_s(
            p.track.queued_mm(), previous.speed_mm_s, new.speed_mm_s, accel, reverse=reverse
        )
        cancel = inc.cancel_restart_s(
            previous.speed_mm_s,
            new.speed_mm_s,
            accel,
            committed_s=p.tuning.committed_s,
            idle_delay_s=self.limits.idle_delay_s,
            round_trip_s=p.clock.rtt_s,
        )
        # A cancel also stops the machine for the handshake: for a speed-up alone it must win
        # clearly, or a stick sweeping smoothly up from a reversal would stutter for nothing.
        margin_s = SPEEDUP_CANCEL_MARGIN_S if (cos > 0.5 and not slower) else 0.0
        choice = "cancel" if cancel + margin_s < let_run else "let-run"
        p.stats.turn_choices.append((now_s, choice, let_run, cancel))
        return choice == "cancel"
