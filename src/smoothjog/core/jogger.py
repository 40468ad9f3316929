"""The sans-I/O jog engine: intents, controller replies and the time in; bytes to send out.

Continuous jogging streams short `$J=G21G91...` increments, keeping queued ahead of the machine
just the distance that holding the speed needs (the stopping distance v²/2a plus what the firmware
has committed and what the link needs), never filling the planner, so every `ok` comes back at
once and a stop never leaves a line in flight. A stop is a full handshake (facts §3.1, §3.6): wait
until every `$J` has its `ok`, send 0x85, then `G4P0` whose `ok` means "stopped, planner empty,
positions synced" (an `error:9` on it means motion restarted: cancel again), then read the
position. Every line names G21 and G91 (or G53), so the controller's modal state never changes.

The engine never reads a clock; every call takes `now_s`. It never writes to a link; `poll`
returns `Output`s for the driver to send.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from enum import Enum

from smoothjog.core import increments as inc
from smoothjog.core.codes import alarm_info, error_info
from smoothjog.core.errors import JogBuildError
from smoothjog.core.gcode import TravelBox
from smoothjog.core.jogline import MM_DECIMALS, build_jog_line, format_number
from smoothjog.core.machine import KeepOut, MachineModel
from smoothjog.core.responses import (
    AlarmReply,
    Banner,
    ErrorReply,
    Message,
    Ok,
    Response,
    StatusReport,
)
from smoothjog.core.units import (
    Vec,
    mm_min_to_mm_s,
    mm_s_to_mm_min,
    norm,
    unit,
)

JOG_CANCEL = b"\x85"
STATUS_QUERY = b"?"
SYNC_LINE = "G4P0"
#: Grbl's slowest feed (MINIMUM_FEED_RATE, 1 mm/min, facts §4.2), in mm/s.
MIN_FEED_MM_S = 1.0 / 60.0
#: Jog-line latencies the round-trip estimate looks at.
RTT_WINDOW = 32
#: Distance of finished path kept behind the estimate (a stop is judged against the path ahead).
PATH_KEEP_MM = 20.0
#: At most this many jogs are remembered (a slow jog makes many short ones); far more than
#: the planner can hold, so every jog not yet run is always kept.
PATH_KEEP_SEGMENTS = 96

#: Controller states in which a jog is accepted (facts §1.4).
JOG_STATES = frozenset({"Idle", "Jog"})

_STATE_REASONS = {
    "Alarm": "the controller is in Alarm: unlock with $X or home with $H first",
    "Hold": "the controller is in feed hold: resume (~) or reset before jogging",
    "Door": "the safety door is open: close it and resume (~) before jogging",
    "Check": "the controller is in check mode ($C): leave it before jogging",
    "Run": "the controller is running a program: jogging waits until it is idle",
    "Home": "the controller is homing: jogging waits until it is done",
    "Sleep": "the controller is asleep: reset it to wake it",
}


# ------------------------------------------------------------------------------------ intents
@dataclass(frozen=True)
class ContinuousIntent:
    """Hold a velocity: stick deflection per axis in [-1, 1] and a global speed in (0, 1]."""

    axes: Mapping[str, float]
    speed: float = 1.0

    def is_neutral(self) -> bool:
        """True when no axis is deflected."""
        return all(v == 0.0 for v in self.axes.values())


@dataclass(frozen=True)
class StepIntent:
    """Move exactly dist_mm along one axis (0.001 to 100 mm), after any steps already queued."""

    axis: str
    dist_mm: float
    speed: float = 0.5


@dataclass(frozen=True)
class GotoIntent:
    """Jog in a straight line to a machine position (G53), at speed (fraction of the max feed)."""

    target_mpos_mm: Mapping[str, float]
    speed: float = 0.5


@dataclass(frozen=True)
class StopIntent:
    """Stop now (full cancel handshake) and drop any steps not yet sent."""


Intent = ContinuousIntent | StepIntent | GotoIntent | StopIntent

STEP_MIN_MM = 0.001
STEP_MAX_MM = 100.0


# ------------------------------------------------------------------------------------ outputs
@dataclass(frozen=True)
class SendLine:
    """Send this line (the driver appends the single `\\n`)."""

    text: str


@dataclass(frozen=True)
class SendRealtime:
    """Send this realtime byte at once, ahead of any queued line."""

    byte: bytes


Output = SendLine | SendRealtime


@dataclass(frozen=True)
class EngineEvent:
    """Something worth telling the user or a log: what happened, in words, and its kind."""

    t_s: float
    kind: str  # "fault", "stop", "info", "choice"
    text: str
    hint: str = ""


# ------------------------------------------------------------------------------------ settings
@dataclass(frozen=True)
class JogTuning:
    """Engine parameters; every default is justified by a firmware fact or a measurement."""

    #: Per-axis speed ratios (the pendant post's 1 : 1 : 0.25); missing axes are 1.
    speed_ratios: Mapping[str, float] = field(default_factory=dict)
    #: Feed at speed 1.0; None means the fastest axis's max rate ($11x).
    max_feed_mm_min: float | None = None
    #: Segments the firmware has committed ahead of the step generator (facts §4.1: ~50 ms).
    committed_s: float = 0.050
    #: Shortest block duration: the jogging doc's conservative 10 ms for the parser to keep up,
    #: plus 0.5 ms so each block is one full 10 ms segment and a short one (increments.committed_s).
    dt_floor_s: float = 0.0105
    #: Extra queue time on top of the measured round trip, for jitter of the host's scheduling
    #: and of the link. Nothing jitters in virtual time, so the engine's default is 0; the
    #: real-time commands take it from the config ([jog] link_margin_s, 5 ms by default).
    link_margin_s: float = 0.0
    #: How often the engine wants to be polled while jogging (the top-up check).
    tick_s: float = 0.001
    #: Wire time of one byte from the controller (115200 8N1: 86.8 µs); a status report's position
    #: is as old as its bytes took to arrive (facts §6). Overstating it only makes the queue
    #: longer, never too short.
    byte_s: float = 10 / 115200
    #: Status polling while moving and while idle (Grbl's docs: 5-10 Hz is comfortable).
    poll_moving_s: float = 0.050
    poll_idle_s: float = 0.250
    #: Planner blocks the engine leaves free so an `ok` is never held back by a full planner.
    planner_reserve_blocks: int = 3
    #: Re-ask for a status report if none came within this time.
    status_timeout_s: float = 0.5


@dataclass(frozen=True)
class EngineLimits:
    """What the engine needs to know of the machine (from a MachineModel after the handshake)."""

    axes: tuple[str, ...]
    steps_per_mm: Vec
    max_rate_mm_min: Vec
    accel_mm_s2: Vec
    planner_blocks: int
    rx_buffer_bytes: int
    max_line_chars: int
    idle_delay_s: float
    envelope: TravelBox | None
    keepouts: tuple[KeepOut, ...]
    firmware: str
    junction_deviation_mm: float = 0.01

    @classmethod
    def from_model(cls, model: MachineModel, keepouts: Sequence[KeepOut] = ()) -> EngineLimits:
        """Limits from a machine model filled by the connect handshake."""
        n = model.n_axes
        s = model.settings.for_axes(n)
        idle_raw = s.raw_value(1)
        try:
            idle_ms = float(idle_raw) if idle_raw is not None else 25.0
        except ValueError:
            idle_ms = 25.0
        max_line = {"grbl": 79, "grblhal": 256, "fluidnc": 255}.get(model.firmware, 79)
        return cls(
            axes=model.axis_letters,
            steps_per_mm=s.steps_per_mm,
            max_rate_mm_min=s.max_rate_mm_min,
            accel_mm_s2=s.accel_mm_s2,
            planner_blocks=model.planner_usable_blocks,
            rx_buffer_bytes=model.rx_buffer_bytes,
            max_line_chars=max_line,
            idle_delay_s=idle_ms / 1000.0 if idle_ms < 255 else 0.0,
            envelope=model.soft_limit_envelope(),
            keepouts=tuple(keepouts) or model.keep_outs,
            firmware=model.firmware,
            junction_deviation_mm=s.junction_deviation_mm,
        )


# ------------------------------------------------------------------------------------ state
class Phase(Enum):
    """What the engine is doing."""

    IDLE = "idle"
    JOGGING = "jogging"  # streaming continuous increments
    STEPPING = "stepping"  # step or go-to jogs queued
    STOPPING = "stopping"  # cancel handshake under way
    SETTLING = "settling"  # waiting for the machine to report rest after the queue ran out


class _Stop(Enum):
    WAIT_ACKS = 1
    WAIT_SYNC = 2
    WAIT_STATUS = 3


@dataclass
class _PathSeg:
    """One jog sent: where it starts and ends in machine mm, and its speed."""

    start_mm: Vec
    end_mm: Vec
    length_mm: float
    speed_mm_s: float
    accel_mm_s2: float
    x0_mm: float  # distance along the engine's path where this jog starts
    acked: bool = False
    entry_cap_mm_s: float = 0.0  # fastest the planner lets the machine enter it (junction)


@dataclass
class _Pending:
    """A line sent and not yet answered."""

    text: str
    kind: str  # "jog", "sync"
    cost: int
    sent_s: float
    seg: _PathSeg | None = None


@dataclass
class StopRecord:
    """One completed stop: how it ended and how far the tracked position was from the real one."""

    t_s: float
    cancelled: bool
    recancels: int
    tracked_error_mm: float
    tracked_error_steps: float  # the worst axis, in its own steps
    mpos_mm: Vec


@dataclass
class EngineStats:
    """Counters the tests and the benchmark read."""

    lines_sent: int = 0
    jogs_sent: int = 0
    cancels: int = 0
    recancels: int = 0
    error_replies: int = 0
    soft_limit_errors: int = 0
    run_state_seen: int = 0
    turn_choices: list[tuple[float, str, float, float]] = field(default_factory=list)
    stops: list[StopRecord] = field(default_factory=list)


@dataclass(frozen=True)
class EngineView:
    """A snapshot for the pendant and logs."""

    t_s: float
    phase: str
    state: str | None
    substate: int | None
    can_jog: bool
    reason: str | None
    mpos_mm: Vec | None
    wpos_mm: Vec | None
    feed_mm_min: float
    commanded_speed_mm_s: float
    actual_speed_mm_s: float
    stop_point_mm: Vec | None
    queued_mm: float
    queued_blocks: int
    fault: tuple[str, str] | None


# ------------------------------------------------------------------------------------ engine
class Jogger:
    """The jog engine; drive it with set_intent, on_response and poll, always passing now_s."""

    def __init__(self, model: MachineModel, limits: EngineLimits, tuning: JogTuning | None = None):
        self.model = model
        self.limits = limits
        self.tuning = tuning or JogTuning()
        self.stats = EngineStats()
        self.events: list[EngineEvent] = []
        self.phase = Phase.IDLE
        self._intent: ContinuousIntent | None = None
        self._acted_intent: ContinuousIntent | None = None
        self._stop_requested = False
        self._cancel_owed = False
        self._pending_desync = False
        self._ratios = dict(self.tuning.speed_ratios)
        self._pending: deque[_Pending] = deque()
        self._pending_bytes = 0
        self._path: list[_PathSeg] = []
        self._steps: deque[StepIntent | GotoIntent] = deque()
        self._path_end_mm: Vec | None = None  # end of the last jog sent (machine mm)
        self._x_est_mm = 0.0  # estimated machine progress along the path
        self._v_est_mm_s = 0.0
        self._est_s = 0.0
        self._moving_since_ack = False
        self._stop_phase = _Stop.WAIT_ACKS
        self._stop_cancelled = False
        self._stop_recancels = 0
        self._restart_after_stop = False
        self._status_asked_s: float | None = None
        self._status_wanted_after_s: float | None = None
        self._last_status_sent_s = -math.inf
        self._rtt_s = 0.003  # time for a jog line to be planned: a low percentile of its ok latency
        self._rtts: deque[float] = deque(maxlen=RTT_WINDOW)
        self._fault: tuple[str, str] | None = None
        self._last_report: tuple[float, Vec] | None = None
        self._actual_speed_mm_s = 0.0
        self._commanded = inc.VectorMove((0.0,) * len(limits.axes), 0.0, 1.0)

    # ----------------------------------------------------------------- inputs
    def set_intent(self, intent: Intent, now_s: float) -> None:
        """Take the newest intent; the next poll acts on the latest one only."""
        if isinstance(intent, StepIntent | GotoIntent):
            if isinstance(intent, StepIntent):
                self._validate_step(intent)
            else:
                self._validate_goto(intent)
            self._steps.append(intent)  # steps queue in order; a held stick is released
            self._intent = None
            return
        if isinstance(intent, StopIntent) or intent.is_neutral():
            self._intent = None
            self._steps.clear()
            self._stop_requested = True
            return
        self._validate_continuous(intent)
        self._intent = intent

    def _act_on_intent(self, now_s: float) -> None:
        """Turn the newest intent into a phase change (called from poll)."""
        intent = self._intent
        if self._cancel_owed and self.model.state in JOG_STATES and self.phase is Phase.IDLE:
            # Lines left in the controller when a door or hold stopped us: cancel them now.
            self._cancel_owed = False
            self._begin_stop(now_s)
            self._stop_cancelled = True
        if self._stop_requested:
            self._stop_requested = False
            if intent is None and (
                self.phase in (Phase.STEPPING, Phase.SETTLING)
                or (self.phase is Phase.IDLE and self.model.state == "Jog")
            ):
                self._begin_stop(now_s)
        if self.phase is Phase.JOGGING:
            if intent is None:
                self._begin_stop(now_s)  # neutral, or a step waits for the stick to stop
            elif intent is not self._acted_intent:
                self._consider_turn(self._commanded, now_s)
        elif self.phase is Phase.STOPPING:
            self._restart_after_stop = isinstance(intent, ContinuousIntent)
        self._acted_intent = intent

    def busy(self) -> bool:
        """True while anything is queued, streaming or stopping, or an intent is held."""
        return self.phase is not Phase.IDLE or bool(self._steps) or self._intent is not None

    def set_speed_ratios(self, ratios: Mapping[str, float]) -> None:
        """Per-axis speed ratios in (0, 1]."""
        for axis, r in ratios.items():
            if axis not in self.limits.axes:
                raise JogBuildError(f"speed ratio for unknown axis {axis!r}")
            if not (0.0 < r <= 1.0):
                raise JogBuildError(f"speed ratio {r!r} for {axis} must be in (0, 1]")
        self._ratios.update(ratios)

    def on_response(self, resp: Response, now_s: float) -> None:
        """Feed one line the controller sent."""
        self.model.apply(resp)
        if isinstance(resp, Ok | ErrorReply):
            self._on_reply(resp, now_s)
        elif isinstance(resp, StatusReport):
            self._on_status(resp, now_s)
        elif isinstance(resp, AlarmReply):
            info = alarm_info(resp.code)
            self._fault_now(now_s, f"ALARM:{resp.code} {info.meaning}", info.hint)
            self._abandon_motion()
        elif isinstance(resp, Banner):
            self._fault_now(
                now_s,
                "the controller was reset (its banner arrived mid-session)",
                "check why it reset; smoothjog re-reads its settings before jogging again",
            )
            self._pending.clear()
            self._pending_bytes = 0
            self._abandon_motion()
        elif isinstance(resp, Message) and resp.text == "Check Door":
            self._fault_now(now_s, "the safety door opened", "close the door and resume (~)")
            # The door already cancels the jog; send nothing more (lines in the controller's
            # buffer would run after the resume) and cancel those still unanswered then.
            self._abandon_motion()

    def reset_machine(self, limits: EngineLimits) -> None:
        """Start over after a re-handshake (the controller was reset)."""
        self.limits = limits
        self._pending.clear()
        self._pending_bytes = 0
        self._abandon_motion()

    # ----------------------------------------------------------------- the driver's tick
    def poll(self, now_s: float) -> list[Output]:
        """Everything to send now; call on every reply and at least every next_deadline_s()."""
        out: list[Output] = []
        self._update_estimate(now_s)
        self._prune_path()
        self._act_on_intent(now_s)
        if self.phase is Phase.IDLE:
            if self._steps and self._may_jog():
                self.phase = Phase.STEPPING
            elif self._intent is not None and self._may_jog():
                self._start_jogging(now_s)
        try:
            if self.phase is Phase.JOGGING:
                if not self._may_jog():
                    self._begin_stop(now_s)
                else:
                    self._stream(now_s, out)
            if self.phase is Phase.STEPPING:
                self._stream_steps(now_s, out)
        except JogBuildError as exc:
            # A line that cannot be written (a value no axis can reach, say): never send it,
            # stop what runs, and say why; the driver keeps running.
            self._fault_now(now_s, f"jog not sent: {exc}", "check the intent that asked for it")
            self._intent = None
            self._steps.clear()
            self._begin_stop(now_s)
        if self.phase is Phase.STOPPING:
            self._advance_stop(now_s, out)
        self._poll_status(now_s, out)
        return out

    def next_deadline_s(self, now_s: float) -> float:
        """The latest time the driver should call poll again."""
        if self.phase is Phase.IDLE and self._intent is None and not self._steps:
            return now_s + self.tuning.poll_idle_s
        return now_s + self.tuning.tick_s

    # ----------------------------------------------------------------- continuous jogging
    def _velocity(self) -> inc.VectorMove | None:
        """The per-axis velocity the current intent asks for, capped as Grbl caps it."""
        intent = self._intent
        if not isinstance(intent, ContinuousIntent):
            return None
        base_mm_s = mm_min_to_mm_s(self._max_feed_mm_min()) * intent.speed
        vel = tuple(
            intent.axes.get(axis, 0.0) * self._ratios.get(axis, 1.0) * base_mm_s
            for axis in self.limits.axes
        )
        move = inc.vector_move(vel, self.limits.max_rate_mm_min, self.limits.accel_mm_s2)
        if move is None or move.speed_mm_s < MIN_FEED_MM_S:
            return None  # below Grbl's 1 mm/min floor the stick is as good as neutral
        return move

    def _max_feed_mm_min(self) -> float:
        return self.tuning.max_feed_mm_min or max(self.limits.max_rate_mm_min)

    def _start_jogging(self, now_s: float) -> None:
        mpos = self.model.mpos_mm
        if mpos is None:
            return  # no position yet: wait for the first status report
        self.phase = Phase.JOGGING
        self._path.clear()
        self._path_end_mm = self._on_step_grid(mpos)
        self._x_est_mm = 0.0
        self._v_est_mm_s = 0.0
        self._est_s = now_s
        self._moving_since_ack = False

    def _ahead_s(self, block_s: float) -> float:
        """Queue time beyond the stopping distance: committed segments, round trip, one tick.

        The firmware commits segments of the blocks already queued, so the longest of those
        (or of the next one) decides how much time five segments can hold.
        """
        longest_s = block_s
        for seg in reversed(self._path):  # the queued jogs are at the end of the path
            if seg.x0_mm + seg.length_mm <= self._x_est_mm:
                break
            if seg.speed_mm_s > 0.0:
                longest_s = max(longest_s, seg.length_mm / seg.speed_mm_s)
        committed = min(inc.committed_s(longest_s), self.tuning.committed_s)
        return committed + self._rtt_s + self.tuning.link_margin_s

    def _block_s(self, move: inc.VectorMove) -> float:
        """Duration of one increment at this speed: just over one 10 ms segment when possible.

        A block of 10-20 ms makes the firmware's five prepared segments cover ~31 ms instead of
        50 ms (see increments.committed_s), so less is committed when the stick is released. It
        must still satisfy the corrected bound dt >= v/(2a(N-1)) and let the planner hold the
        stopping distance within the blocks the engine allows itself.
        """
        usable = max(self.limits.planner_blocks - self.tuning.planner_reserve_blocks, 2)
        return max(
            self.tuning.dt_floor_s,
            inc.min_block_s(move.speed_mm_s, move.accel_mm_s2, self.limits.planner_blocks),
            inc.stop_distance_mm(move.speed_mm_s, move.accel_mm_s2)
            / (move.speed_mm_s * (usable - 1)),
            # A very slow jog still moves at least a step and a half per block: shorter blocks
            # are all rounding (Grbl plans a block under half a step as nothing).
            1.5 * self._step_along_mm(move.unit_vec) / move.speed_mm_s,
        )

    def _step_along_mm(self, unit_vec: Sequence[float]) -> float:
        """Distance along unit_vec in which the busiest axis makes one step."""
        return min(
            (
                1.0 / (spm * abs(u))
                for u, spm in zip(unit_vec, self.limits.steps_per_mm, strict=True)
                if u
            ),
            default=1.0 / max(self.limits.steps_per_mm),
        )

    def _stream(self, now_s: float, out: list[Output]) -> None:
        move = self._velocity()
        if move is None:
            return
        self._commanded = move
        n_blocks = self.limits.planner_blocks
        usable_blocks = max(n_blocks - self.tuning.planner_reserve_blocks, 1)
        block_s = self._block_s(move)
        ahead_s = self._ahead_s(block_s)
        blocks = self._blocks_in_planner()
        for _ in range(n_blocks):
            queued_mm = self._queued_mm()
            # While the machine is still faster than the new speed (a slowdown), size the queue
            # for the speed it has: the slower blocks must be queued before the faster ones run
            # out, or the planner brakes below the new speed.
            speed_mm_s = max(move.speed_mm_s, self._v_est_mm_s)
            target_mm = inc.queue_target_mm(speed_mm_s, move.accel_mm_s2, ahead_s)
            if queued_mm >= target_mm:
                return
            if blocks >= usable_blocks:
                return
            # Blocks of the planned duration, but never so short that the queue needs more of
            # them than the engine allows itself: while slowing from a higher speed the queue
            # is sized for that speed, and 10 ms blocks at the new one would fill the planner.
            length_mm = max(
                move.speed_mm_s * block_s,
                (target_mm - speed_mm_s * self.tuning.committed_s) / max(usable_blocks - 1, 1),
            )
            if not self._path:
                # The firmware commits ~50 ms of segments from the first block alone, planned
                # to stop at its end; make it long enough that this ramp never turns to braking
                # before the next lines arrive (else a fresh jog stutters at ~20 mm/s).
                ramp_s = self.tuning.committed_s + 2.0 * self._rtt_s + self.tuning.dt_floor_s
                length_mm = max(length_mm, min(move.accel_mm_s2 * ramp_s**2, target_mm))
            if not self._send_increment(move, length_mm, now_s, out):
                return
            blocks += 1

    def _send_increment(
        self, move: inc.VectorMove, length_mm: float, now_s: float, out: list[Output]
    ) -> bool:
        """Send one G91 increment along move (clipped to the envelope and keep-outs)."""
        assert self._path_end_mm is not None
        start = self._path_end_mm
        clipped = self._clip(start, move, length_mm)
        if clipped is None:
            return False
        move, length_mm = clipped
        deltas: dict[str, float] = {}
        for axis, u in zip(self.limits.axes, move.unit_vec, strict=True):
            d = float(format_number(u * length_mm, MM_DECIMALS))
            if d != 0.0:
                deltas[axis] = d
        if not deltas:
            return False
        end = tuple(
            s + deltas.get(axis, 0.0) for s, axis in zip(start, self.limits.axes, strict=True)
        )
        if not self._fits_envelope(end):
            return False
        line = build_jog_line(
            moves=deltas,
            feed_mm_min=round(mm_s_to_mm_min(move.speed_mm_s), 3),
            mode="G91",
            axes=self.limits.axes,
            max_line_chars=self.limits.max_line_chars,
        )
        if not self._fits_rx(line):
            return False
        seg_len = norm(tuple(e - s for e, s in zip(end, start, strict=True)))
        seg = _PathSeg(
            start, end, seg_len, move.speed_mm_s, move.accel_mm_s2, self._path_length_mm()
        )
        self._append_seg(seg)
        self._path_end_mm = end
        self._send(line, "jog", now_s, out, seg)
        return True

    def _clip(
        self, start: Vec, move: inc.VectorMove, length_mm: float
    ) -> tuple[inc.VectorMove, float] | None:
        """Shorten (or slide) an increment so it stays in the envelope and out of keep-outs."""
        vel = list(move.velocity_mm_s)
        inset = self._inset_mm()
        for _ in range(len(vel) + 1):
            m = inc.vector_move(vel, self.limits.max_rate_mm_min, self.limits.accel_mm_s2)
            if m is None:
                return None
            step_mm = self._step_along_mm(m.unit_vec)
            t = length_mm
            blocked: int | None = None
            env = self.limits.envelope
            if env is not None:
                lo = tuple(v + inset for v in env.min_mm)
                hi = tuple(v - inset for v in env.max_mm)
                t_env, axis = inc.ray_box_exit(start, m.unit_vec, lo, hi)
                if t_env < t:
                    t = t_env
                    blocked = axis
            for zone in self.limits.keepouts:
                t_in, face = inc.ray_box_entry(start, m.unit_vec, zone.min_mm, zone.max_mm)
                t_in = max(t_in - inset, 0.0)
                if t_in < t:
                    t = t_in
                    blocked = face
            if t >= step_mm or blocked is None:
                return (m, t) if t >= step_mm else None
            # Blocked within a step: drop the blocked axis and slide along the boundary.
            vel[blocked] = 0.0
        return None

    def _on_step_grid(self, mpos: Sequence[float]) -> Vec:
        """A reported position (3 decimals) put back on the step grid Grbl counts in.

        After a stop Grbl's parser position is the exact step count; the report rounds it.
        Starting a G91 chain from the rounded value would shift every target by up to
        0.0005 mm, enough to meet error:15 at the edge of the envelope.
        """
        return tuple(
            round(p * spm) / spm for p, spm in zip(mpos, self.limits.steps_per_mm, strict=True)
        )

    def _steps_from(self, a: Sequence[float], b: Sequence[float]) -> float:
        """Distance between two positions in steps of the worst axis."""
        return max(
            abs(x - y) * spm for x, y, spm in zip(a, b, self.limits.steps_per_mm, strict=True)
        )

    def _inset_mm(self) -> float:
        # One step of margin keeps float rounding in the firmware from tipping a target over
        # the edge (error:15 is inclusive at the edge, facts §2).
        return 1.0 / min(self.limits.steps_per_mm)

    def _fits_envelope(self, end: Vec) -> bool:
        env = self.limits.envelope
        return env is None or env.contains(end)

    def _consider_turn(self, previous: inc.VectorMove, now_s: float) -> None:
        """On a big change, pick let-the-queue-run or cancel-and-restart, whichever is faster."""
        new = self._velocity()
        if new is None or previous.speed_mm_s <= 0.0:
            return
        cos = sum(a * b for a, b in zip(previous.unit_vec, new.unit_vec, strict=True))
        slower = new.speed_mm_s < 0.8 * previous.speed_mm_s
        if cos > 0.5 and not slower:
            return
        reverse = cos <= 0.5
        accel = min(previous.accel_mm_s2, new.accel_mm_s2)
        let_run = inc.let_run_turn_s(
            self._queued_mm(), previous.speed_mm_s, new.speed_mm_s, accel, reverse=reverse
        )
        cancel = inc.cancel_restart_s(
            previous.speed_mm_s,
            new.speed_mm_s,
            accel,
            committed_s=self.tuning.committed_s,
            idle_delay_s=self.limits.idle_delay_s,
            round_trip_s=self._rtt_s,
        )
        choice = "cancel" if cancel < let_run else "let-run"
        self.stats.turn_choices.append((now_s, choice, let_run, cancel))
        if choice == "cancel":
            self._begin_stop(now_s)
            self._restart_after_stop = True

    # ----------------------------------------------------------------- steps and go-to
    def _validate_step(self, intent: StepIntent) -> None:
        if intent.axis not in self.limits.axes:
            raise JogBuildError(
                f"cannot step axis {intent.axis!r}: the machine has {self.limits.axes}"
            )
        if not (STEP_MIN_MM <= abs(intent.dist_mm) <= STEP_MAX_MM):
            raise JogBuildError(
                f"step of {intent.dist_mm!r} mm is outside {STEP_MIN_MM} to {STEP_MAX_MM} mm"
            )
        if not (0.0 < intent.speed <= 1.0):
            raise JogBuildError(f"step speed {intent.speed!r} must be in (0, 1]")
        self._check_feed(intent.speed)

    def _validate_goto(self, intent: GotoIntent) -> None:
        for axis, value in intent.target_mpos_mm.items():
            if axis not in self.limits.axes:
                raise JogBuildError(f"cannot go to {axis}: the machine has {self.limits.axes}")
            if not math.isfinite(value):
                raise JogBuildError(f"go-to target {axis}={value!r} is not a number")
        if not intent.target_mpos_mm:
            raise JogBuildError("a go-to needs at least one axis target")
        if not (0.0 < intent.speed <= 1.0):
            raise JogBuildError(f"go-to speed {intent.speed!r} must be in (0, 1]")
        self._check_feed(intent.speed)

    def _check_feed(self, speed: float) -> None:
        feed_mm_min = self._max_feed_mm_min() * speed
        if feed_mm_min < 1.0:
            raise JogBuildError(
                f"speed {speed!r} gives {feed_mm_min:.3g} mm/min, below Grbl's 1 mm/min minimum"
            )

    def _validate_continuous(self, intent: ContinuousIntent) -> None:
        for axis, value in intent.axes.items():
            if axis not in self.limits.axes:
                raise JogBuildError(f"cannot jog axis {axis!r}: the machine has {self.limits.axes}")
            if not (math.isfinite(value) and -1.0 <= value <= 1.0):
                raise JogBuildError(f"deflection {axis}={value!r} must be in [-1, 1]")
        if not (math.isfinite(intent.speed) and 0.0 < intent.speed <= 1.0):
            raise JogBuildError(f"speed {intent.speed!r} must be in (0, 1]")

    def _stream_steps(self, now_s: float, out: list[Output]) -> None:
        if not self._may_jog():
            self._steps.clear()
            self._begin_stop(now_s)
            return
        if self._path_end_mm is None:
            if self.model.mpos_mm is None:
                return
            self._path.clear()
            self._path_end_mm = self._on_step_grid(self.model.mpos_mm)
            self._x_est_mm = 0.0
            self._v_est_mm_s = 0.0
            self._est_s = now_s
        usable_blocks = max(self.limits.planner_blocks - self.tuning.planner_reserve_blocks, 1)
        while self._steps and self._blocks_in_planner() < usable_blocks:
            step = self._steps[0]
            line_seg = self._step_line(step)
            if line_seg is None:
                self._steps.popleft()
                continue
            line, seg = line_seg
            if not self._fits_rx(line):
                return
            self._steps.popleft()
            self._append_seg(seg)
            self._path_end_mm = seg.end_mm
            self._send(line, "jog", now_s, out, seg)
        if not self._steps and not self._pending:
            self._settle(now_s)

    def _step_line(self, step: StepIntent | GotoIntent) -> tuple[str, _PathSeg] | None:
        assert self._path_end_mm is not None
        start = self._path_end_mm
        axes = self.limits.axes
        if isinstance(step, StepIntent):
            i = axes.index(step.axis)
            d = float(format_number(step.dist_mm, MM_DECIMALS))
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
        problem = self._path_problem(start, end)
        if problem is not None:
            self._fault_now(self._est_s, f"jog refused: {problem}", "jog less far or elsewhere")
            return None
        delta = tuple(e - s for e, s in zip(end, start, strict=True))
        move = inc.vector_move(
            tuple(d * 1e6 for d in delta), self.limits.max_rate_mm_min, self.limits.accel_mm_s2
        )
        if move is None:
            return None
        speed_mm_s = min(mm_min_to_mm_s(self._max_feed_mm_min()) * step.speed, move.speed_mm_s)
        line = build_jog_line(
            moves=moves,
            feed_mm_min=round(mm_s_to_mm_min(speed_mm_s), 3),
            mode=mode,  # type: ignore[arg-type]
            axes=axes,
            max_line_chars=self.limits.max_line_chars,
        )
        seg = _PathSeg(
            start, end, norm(delta), speed_mm_s, move.accel_mm_s2, self._path_length_mm()
        )
        return line, seg

    def _path_problem(self, start: Vec, end: Vec) -> str | None:
        """Why a straight jog from start to end is not allowed, or None."""
        env = self.limits.envelope
        if env is not None and not env.contains(end):
            return "the target lies outside the soft limits"
        for zone in self.limits.keepouts:
            if zone.crosses(start, end):
                return f"the path crosses the keep-out zone {zone.name!r}"
        return None

    # ----------------------------------------------------------------- stopping
    def _begin_stop(self, now_s: float) -> None:
        if self.phase is Phase.STOPPING:
            return
        self.phase = Phase.STOPPING
        self._stop_phase = _Stop.WAIT_ACKS
        self._stop_cancelled = False
        self._stop_recancels = 0

    def _settle(self, now_s: float) -> None:
        """The queue was sent whole: wait for the machine to report rest."""
        self.phase = Phase.SETTLING
        self._status_wanted_after_s = now_s

    def _advance_stop(self, now_s: float, out: list[Output]) -> None:
        if self._stop_phase is _Stop.WAIT_ACKS:
            if any(p.kind == "jog" for p in self._pending):
                return  # a cancel now would let these lines run on (facts §3.1)
            if self._path or self._stop_cancelled or self.model.state == "Jog":
                out.append(SendRealtime(JOG_CANCEL))
                self._stop_cancelled = True
                self.stats.cancels += 1
            self._send(SYNC_LINE, "sync", now_s, out)
            self._stop_phase = _Stop.WAIT_SYNC

    def _on_sync_reply(self, resp: Ok | ErrorReply, now_s: float) -> None:
        if self.phase is not Phase.STOPPING:
            return
        if isinstance(resp, Ok):
            self._stop_phase = _Stop.WAIT_STATUS
            self._status_wanted_after_s = now_s
            self._status_asked_s = None
            return
        if resp.code == 9 and self.model.state != "Alarm" and self._stop_recancels < 5:
            # facts §3.6: the sync line met a jog that restarted: cancel again.
            self._stop_recancels += 1
            self.stats.recancels += 1
            self._stop_phase = _Stop.WAIT_ACKS
            return
        self._fault_now(now_s, f"stop sync failed: error:{resp.code}", error_info(resp.code).hint)
        self._stop_phase = _Stop.WAIT_STATUS
        self._status_wanted_after_s = now_s

    def _finish_stop(self, report: StatusReport, now_s: float) -> None:
        mpos = self.model.mpos_mm
        if mpos is not None:
            # The report rounds to 0.001 mm; the step counts behind it are exact (a step is
            # over 0.002 mm on any axis this is meant for), so compare on the step grid.
            err_mm, err_steps = self._tracking_error(
                self._on_step_grid(mpos), cancelled=self._stop_cancelled
            )
            self.stats.stops.append(
                StopRecord(
                    now_s,
                    self._stop_cancelled,
                    self._stop_recancels,
                    err_mm,
                    err_steps,
                    tuple(mpos),
                )
            )
            self.events.append(EngineEvent(now_s, "stop", f"stopped at {_fmt(mpos)}"))
        self._path.clear()
        self._path_end_mm = None
        self._x_est_mm = 0.0
        self._v_est_mm_s = 0.0
        self._commanded = inc.VectorMove((0.0,) * len(self.limits.axes), 0.0, 1.0)
        self.phase = Phase.IDLE
        self._restart_after_stop = False

    def _tracking_error(self, mpos: Vec, *, cancelled: bool) -> tuple[float, float]:
        """Tracked minus real, in mm and in steps of the worst axis.

        After a queue that ran out, it is the miss of the planned end; after a cancel, the miss
        of the nearest point of the queued path (the stop must lie on it, facts §3.1). Steps are
        counted per axis because the firmware rounds each axis to its own steps.
        """
        if not self._path:
            return 0.0, 0.0
        spm = self.limits.steps_per_mm
        if not cancelled:
            ref = self._path[-1].end_mm
            steps = max(abs(r - m) * k for r, m, k in zip(ref, mpos, spm, strict=True))
            return math.dist(ref, mpos), steps
        best_steps, best_ref = math.inf, mpos
        for seg in self._path:
            steps, ref = _nearest_in_steps(mpos, seg.start_mm, seg.end_mm, spm)
            if steps < best_steps:
                best_steps, best_ref = steps, ref
        return math.dist(best_ref, mpos), best_steps

    def _abandon_motion(self) -> None:
        """Forget the queued path (door, hold, alarm, reset): nothing more is sent.

        Jog lines still unanswered sit in the controller's buffer and run once it resumes
        (facts §3.1-§3.3): a cancel is owed, sent as soon as the state is Idle or Jog again.
        """
        self._cancel_owed = any(p.kind == "jog" for p in self._pending)
        self._path.clear()
        self._path_end_mm = None
        self._steps.clear()
        self._intent = None
        self._acted_intent = None
        self._restart_after_stop = False
        self.phase = Phase.IDLE

    # ----------------------------------------------------------------- replies and status
    def _on_reply(self, resp: Ok | ErrorReply, now_s: float) -> None:
        if not self._pending:
            self.events.append(
                EngineEvent(now_s, "info", "an ok/error arrived with no line waiting")
            )
            return
        pending = self._pending.popleft()
        self._pending_bytes -= pending.cost
        if isinstance(resp, ErrorReply):
            self.stats.error_replies += 1
            if resp.code == 15:
                self.stats.soft_limit_errors += 1
        if pending.kind == "sync":
            self._on_sync_reply(resp, now_s)
            return
        if pending.kind != "jog" or pending.seg is None:
            return
        if isinstance(resp, Ok):
            pending.seg.acked = True
            # The upper quartile of recent latencies: it follows a jittery link, yet one ok
            # delayed behind a status report on the way back does not move it.
            self._rtts.append(now_s - pending.sent_s)
            self._rtt_s = sorted(self._rtts)[(3 * len(self._rtts)) // 4]
            if not self._moving_since_ack:
                self._moving_since_ack = True
                self._est_s = now_s
            return
        # A rejected G91 jog leaves the parser where it was, so every later increment is off:
        # stop, re-sync, and say why.
        info = error_info(resp.code)
        self._fault_now(now_s, f"jog rejected: error:{resp.code} {info.meaning}", info.hint)
        if pending.seg in self._path:
            self._path.remove(pending.seg)
        self._steps.clear()
        self._intent = None
        if self.phase in (Phase.JOGGING, Phase.STEPPING, Phase.SETTLING):
            self._begin_stop(now_s)

    def _on_status(self, report: StatusReport, now_s: float) -> None:
        self._status_asked_s = None
        state = report.state
        mpos = self.model.mpos_mm
        if mpos is not None:
            if self._last_report is not None and now_s > self._last_report[0]:
                dt = now_s - self._last_report[0]
                self._actual_speed_mm_s = math.dist(mpos, self._last_report[1]) / dt
            self._last_report = (now_s, tuple(mpos))
            self._correct_estimate(mpos, (len(report.raw) + 2) * self.tuning.byte_s)
        if state == "Run" and self.phase in (Phase.JOGGING, Phase.STEPPING, Phase.STOPPING):
            # facts §9: a jog block can start in Run (a firmware race); it finishes by itself
            # within the queued path. Stop streaming and wait for Idle.
            self.stats.run_state_seen += 1
            self._fault_now(
                now_s,
                "the controller ran a jog block in Run state (a Grbl race)",
                "smoothjog stopped streaming; the machine stops at the end of what was queued",
            )
            self._intent = None
            self._steps.clear()
            self.phase = Phase.SETTLING
            self._status_wanted_after_s = now_s
            return
        if self._pending_desync:
            self._pending_desync = False
            if self.phase is Phase.JOGGING:
                self._fault_now(
                    now_s,
                    "the machine left the path smoothjog sent (stopped or moved from elsewhere)",
                    "release the stick and jog again",
                )
                self._intent = None
                self._acted_intent = None
                self._begin_stop(now_s)
                return
        if (
            report.pins
            and ("H" in report.pins or "D" in report.pins)
            and self.phase
            in (
                Phase.JOGGING,
                Phase.STEPPING,
                Phase.SETTLING,
            )
        ):
            # The hold button or the door switch is pressed: the controller is stopping the jog.
            self._fault_now(
                now_s,
                "the controller's feed-hold or door input is active",
                "release it, resume with ~, and jog again",
            )
            self._abandon_motion()
            return
        if (
            state == "Idle"
            and self.phase is Phase.JOGGING
            and self._moving_since_ack
            and self._path
            and mpos is not None
        ):
            at_end = self._steps_from(mpos, self._path[-1].end_mm) <= 2.0
            planned = [seg for seg in self._path if seg.acked]
            # Resting where the planned (acknowledged) jogs end is a queue that ran dry, not an
            # outside stop: the lines still on their way will start it again.
            at_planned_end = bool(planned) and self._steps_from(mpos, planned[-1].end_mm) <= 2.0
            if at_end and not any(p.kind == "jog" for p in self._pending):
                # Every jog was answered and the machine rests at the end: the queue has run
                # (at the edge of the envelope, or a host that could not keep up).
                self._x_est_mm = self._path_length_mm()
                self._v_est_mm_s = 0.0
            elif not at_end and not at_planned_end:
                # At rest short of the planned end while jogging: something else
                # stopped the jog (a feed hold or jog cancel from a button or another client).
                # Grbl re-synced its parser to where it stopped, so every further G91 increment
                # would be off: sync, forget the path, and wait for a fresh intent.
                self._fault_now(
                    now_s,
                    "the jog was stopped outside smoothjog (a feed hold or cancel)",
                    "release the stick and jog again",
                )
                self._intent = None
                self._acted_intent = None
                self._begin_stop(now_s)
        fresh = self._status_wanted_after_s is not None
        if state not in JOG_STATES and state != "Run":
            self._status_wanted_after_s = None
            if self.phase is not Phase.IDLE:
                self._fault_now(now_s, f"jogging stopped: {_STATE_REASONS.get(state, state)}", "")
                self._abandon_motion()
            return
        if state == "Idle" and fresh:
            if self.phase is Phase.STOPPING and self._stop_phase is _Stop.WAIT_STATUS:
                self._status_wanted_after_s = None
                self._finish_stop(report, now_s)
            elif self.phase is Phase.SETTLING and not self._pending:
                self._status_wanted_after_s = None
                self._stop_cancelled = False
                self._stop_recancels = 0
                self._finish_stop(report, now_s)

    def _poll_status(self, now_s: float, out: list[Output]) -> None:
        asked = self._status_asked_s
        if asked is not None and now_s - asked < self.tuning.status_timeout_s:
            return  # one `?` at a time: Grbl folds a second one into the first anyway (§5.2)
        settled = self._x_est_mm >= self._path_length_mm() - 1e-9 and self._v_est_mm_s == 0.0
        urgent = self._status_wanted_after_s is not None and (
            (self.phase is Phase.SETTLING and settled)
            or (self.phase is Phase.STOPPING and self._stop_phase is _Stop.WAIT_STATUS)
        )
        busy = self.phase is not Phase.IDLE or self.model.state not in (None, "Idle")
        interval = self.tuning.poll_moving_s if busy else self.tuning.poll_idle_s
        if urgent or now_s - self._last_status_sent_s >= interval:
            out.append(SendRealtime(STATUS_QUERY))
            self._status_asked_s = now_s
            self._last_status_sent_s = now_s

    # ----------------------------------------------------------------- bookkeeping
    def _send(
        self, line: str, kind: str, now_s: float, out: list[Output], seg: _PathSeg | None = None
    ) -> None:
        cost = len(line) + 1
        self._pending.append(_Pending(line, kind, cost, now_s, seg))
        self._pending_bytes += cost
        self.stats.lines_sent += 1
        if kind == "jog":
            self.stats.jogs_sent += 1
        out.append(SendLine(line))

    def _fits_rx(self, line: str) -> bool:
        return self._pending_bytes + len(line) + 1 <= self.limits.rx_buffer_bytes

    def _may_jog(self) -> bool:
        return self.can_jog()[0]

    def can_jog(self) -> tuple[bool, str | None]:
        """Whether a jog may be sent now, and why not in words."""
        state = self.model.state
        if state is None:
            return False, "waiting for the controller's first status report"
        if state not in JOG_STATES:
            return False, _STATE_REASONS.get(state, f"the controller is in state {state}")
        if self.limits.envelope is not None and self.model.looks_unhomed():
            return False, (
                "soft limits are on but the machine looks unhomed (MPos is 0,0,0, so every jog "
                "toward + would fail with error:15): home it with $H first"
            )
        return True, None

    def _path_length_mm(self) -> float:
        if not self._path:
            return 0.0
        last = self._path[-1]
        return last.x0_mm + last.length_mm

    def _queued_mm(self) -> float:
        return max(self._path_length_mm() - self._x_est_mm, 0.0)

    def _blocks_in_planner(self) -> int:
        """Jogs sent whose end the machine has not yet reached, less those already committed."""
        committed_end = self._x_est_mm + self._v_est_mm_s * self.tuning.committed_s
        count = 0
        for seg in reversed(self._path):  # queued jogs are at the end; stop at the first done
            if seg.x0_mm + seg.length_mm <= committed_end:
                break
            count += 1
        return count

    def _update_estimate(self, now_s: float) -> None:
        """Advance the estimated progress along the path with the firmware's own kinematics."""
        if not self._path or not self._moving_since_ack:
            self._est_s = now_s
            return
        dt = now_s - self._est_s
        if dt <= 0.0:
            return
        self._est_s = now_s
        # Integrate in small steps so braking at the end of the queue is followed closely.
        steps = max(1, math.ceil(dt / 0.002))
        h = dt / steps
        end_x = self._path_length_mm()
        for _ in range(steps):
            index = self._seg_index_at(self._x_est_mm)
            if index is None:
                self._v_est_mm_s = 0.0
                self._x_est_mm = end_x
                return
            a = self._path[index].accel_mm_s2
            v_cap = self._speed_cap_mm_s(index)
            if self._v_est_mm_s < v_cap:
                self._v_est_mm_s = min(v_cap, self._v_est_mm_s + a * h)
            else:
                self._v_est_mm_s = max(v_cap, self._v_est_mm_s - a * h)
            self._x_est_mm = min(self._x_est_mm + self._v_est_mm_s * h, end_x)

    def _append_seg(self, seg: _PathSeg) -> None:
        """Add a sent jog to the path, with the speed the planner allows at its start."""
        if self._path:
            prev = self._path[-1]
            seg.entry_cap_mm_s = min(
                seg.speed_mm_s, prev.speed_mm_s, self._junction_speed_mm_s(prev, seg)
            )
        self._path.append(seg)

    def _junction_speed_mm_s(self, prev: _PathSeg, seg: _PathSeg) -> float:
        """Grbl's junction-deviation speed limit between two jogs (facts §4.3)."""
        u0 = unit(tuple(e - s for s, e in zip(prev.start_mm, prev.end_mm, strict=True)))
        u1 = unit(tuple(e - s for s, e in zip(seg.start_mm, seg.end_mm, strict=True)))
        return math.sqrt(
            inc.junction_speed_sqr(
                u0, u1, self.limits.accel_mm_s2, self.limits.junction_deviation_mm
            )
        )

    def _speed_cap_mm_s(self, seg_index: int) -> float:
        """The fastest the machine can be at the estimate, braking for what lies ahead.

        Grbl plans so that every junction and slower block ahead is met at its allowed speed,
        and the end of the queue at rest; the machine cannot be faster than that.
        """
        x = self._x_est_mm
        path = self._path
        seg = path[seg_index]
        a = seg.accel_mm_s2
        cap = seg.speed_mm_s
        reach_mm = cap * cap / (2.0 * a)
        for nxt in path[seg_index + 1 :]:
            ahead = nxt.x0_mm - x
            if ahead > reach_mm:
                break
            cap = min(cap, math.sqrt(nxt.entry_cap_mm_s**2 + 2.0 * a * max(ahead, 0.0)))
        end_x = path[-1].x0_mm + path[-1].length_mm
        return min(cap, math.sqrt(2.0 * a * max(end_x - x, 0.0)))

    def _seg_index_at(self, x_mm: float) -> int | None:
        """Index of the path segment containing x_mm (bisect: the path is sorted by x0)."""
        path = self._path
        i = bisect.bisect_right(path, x_mm, key=lambda seg: seg.x0_mm) - 1
        if 0 <= i < len(path) and x_mm < path[i].x0_mm + path[i].length_mm:
            return i
        return None

    def _seg_at(self, x_mm: float) -> _PathSeg | None:
        i = self._seg_index_at(x_mm)
        return None if i is None else self._path[i]

    def _correct_estimate(self, mpos: Vec, age_s: float) -> None:
        """Pull the estimate onto the reported position (projected on the path).

        A path that doubles back passes the same point twice, so among the segments the report
        lies on, the one nearest the current estimate wins.
        """
        if not self._path or not self._moving_since_ack:
            return
        tolerance_mm = 2.0 / min(self.limits.steps_per_mm) + 1e-6
        best: float | None = None
        for seg in self._path:
            d, along = _project(mpos, seg.start_mm, seg.end_mm)
            if d > tolerance_mm:
                continue
            x = seg.x0_mm + along
            if best is None or abs(x - self._x_est_mm) < abs(best - self._x_est_mm):
                best = x
        if best is None:
            if self.phase is Phase.JOGGING and not self._pending_desync:
                # The machine is off every jog we sent: something moved or stopped it outside
                # smoothjog (a feed hold, a cancel, another sender), and Grbl re-synced its G91
                # origin. Further increments would land off the tracked path, so stop and sync.
                self._pending_desync = True
            return
        # The report was built before its bytes crossed the wire: move it forward by that age.
        ahead = self._v_est_mm_s * age_s
        self._x_est_mm = min(best + ahead, self._path_length_mm())

    def _prune_path(self) -> None:
        """Forget jogs the machine finished long ago (the path would grow without end)."""
        keep_from = self._x_est_mm - PATH_KEEP_MM
        # Never forget what the next status reports can still show: their position is a few
        # milliseconds old, so keep well over that much path behind the estimate.
        recent_from = self._x_est_mm - (1.0 + self._v_est_mm_s * 0.3)
        drop = 0
        while drop < len(self._path) - 1 and (
            self._path[drop].x0_mm + self._path[drop].length_mm < keep_from
            or (
                len(self._path) - drop > PATH_KEEP_SEGMENTS
                and self._path[drop].x0_mm + self._path[drop].length_mm < recent_from
            )
        ):
            drop += 1
        if drop:
            del self._path[:drop]

    def _fault_now(self, now_s: float, text: str, hint: str) -> None:
        self._fault = (text, hint)
        self.events.append(EngineEvent(now_s, "fault", text, hint))

    # ----------------------------------------------------------------- views
    def stop_point_mm(self) -> Vec | None:
        """Where the machine would come to rest if the jog were released now."""
        mpos = self.model.mpos_mm
        if mpos is None:
            return None
        if not self._path:
            return tuple(mpos)
        v = self._v_est_mm_s
        seg = self._seg_at(self._x_est_mm) or self._path[-1]
        brake = v * self.tuning.committed_s + v * v / (2.0 * seg.accel_mm_s2) if v > 0 else 0.0
        return self._point_at(min(self._x_est_mm + brake, self._path_length_mm()))

    def _point_at(self, x_mm: float) -> Vec:
        for seg in self._path:
            if x_mm <= seg.x0_mm + seg.length_mm or seg is self._path[-1]:
                f = (
                    0.0
                    if seg.length_mm == 0
                    else min(max((x_mm - seg.x0_mm) / seg.length_mm, 0), 1)
                )
                return tuple(s + (e - s) * f for s, e in zip(seg.start_mm, seg.end_mm, strict=True))
        return self._path_end_mm or ()

    def view(self, now_s: float) -> EngineView:
        """A snapshot for the pendant."""
        ok, reason = self.can_jog()
        return EngineView(
            t_s=now_s,
            phase=self.phase.value,
            state=self.model.state,
            substate=self.model.substate,
            can_jog=ok,
            reason=reason,
            mpos_mm=self.model.mpos_mm,
            wpos_mm=self.model.wpos_mm,
            feed_mm_min=self.model.feed_mm_min or 0.0,
            commanded_speed_mm_s=self._commanded.speed_mm_s if self.phase is Phase.JOGGING else 0.0,
            actual_speed_mm_s=self._actual_speed_mm_s if self.model.state != "Idle" else 0.0,
            stop_point_mm=self.stop_point_mm(),
            queued_mm=self._queued_mm(),
            queued_blocks=self._blocks_in_planner(),
            fault=self._fault,
        )

    def clear_fault(self) -> None:
        """Forget the last fault (the user saw it)."""
        self._fault = None


def _project(p: Vec, a: Vec, b: Vec) -> tuple[float, float]:
    """Distance from p to segment ab, and how far along ab the closest point lies."""
    ab = tuple(y - x for x, y in zip(a, b, strict=True))
    length = norm(ab)
    if length == 0.0:
        return math.dist(p, a), 0.0
    t = sum((pi - ai) * d for pi, ai, d in zip(p, a, ab, strict=True)) / (length * length)
    t = min(max(t, 0.0), 1.0)
    closest = tuple(ai + d * t for ai, d in zip(a, ab, strict=True))
    return math.dist(p, closest), t * length


def _nearest_in_steps(p: Vec, a: Vec, b: Vec, steps_per_mm: Vec) -> tuple[float, Vec]:
    """The point of segment ab nearest to p when distance is the worst axis counted in steps.

    The firmware rounds each axis to its own step grid, so "within one step" is per axis. The
    distance along the segment is convex in t; a ternary search finds its minimum.
    """

    def at(t: float) -> tuple[float, Vec]:
        q = tuple(ai + (bi - ai) * t for ai, bi in zip(a, b, strict=True))
        err = max(abs(qi - pi) * k for qi, pi, k in zip(q, p, steps_per_mm, strict=True))
        return err, q

    lo, hi = 0.0, 1.0
    for _ in range(60):
        m1 = lo + (hi - lo) / 3
        m2 = hi - (hi - lo) / 3
        if at(m1)[0] <= at(m2)[0]:
            hi = m2
        else:
            lo = m1
    return at((lo + hi) / 2)


def _fmt(v: Sequence[float]) -> str:
    return ", ".join(f"{x:.3f}" for x in v)
