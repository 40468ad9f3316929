"""The sans-I/O jog engine: intents, controller replies and the time in; bytes to send out.

Continuous jogging streams short `$J=G21G91...` increments, keeping queued ahead of the machine
just the distance that holding the speed needs (the stopping distance v²/2a plus what the firmware
has committed and what the link needs), never filling the planner, so every `ok` comes back at
once and a stop never leaves a line in flight. A stop is a full handshake (firmware-facts §3.1,
§3.6): wait until every `$J` has its `ok`, send 0x85, then `G4P0` whose `ok` means "stopped, planner
empty, positions synced" (an `error:9` on it means motion restarted: cancel again), then read the
position. Every line names G21 and G91 (or G53), so the controller's modal state never changes.

The engine never reads a clock; every call takes `now_s`. It never writes to a link; `poll`
returns `Output`s for the driver to send. This file is the phase machine; the intents and their
checks are in intents.py, the path and the position estimate in tracker.py, and the stop
handshake's state in stopper.py.
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from decimal import Decimal
from enum import Enum

from smoothjog.core import increments as inc
from smoothjog.core.codes import ERR_SYSTEM_GC_LOCK, ERR_TRAVEL_EXCEEDED, alarm_info, error_info
from smoothjog.core.defaults import DEFAULT_STEP_IDLE_DELAY_MS
from smoothjog.core.errors import JogBuildError
from smoothjog.core.firmware import BITS_PER_BYTE_8N1, DEFAULT_BAUD, firmware_facts, for_model
from smoothjog.core.gcode import TravelBox
from smoothjog.core.intents import (
    ContinuousIntent,
    GotoIntent,
    HandwheelIntent,
    Intent,
    StepIntent,
    StopIntent,
    validate_intent,
)
from smoothjog.core.jogline import MM_DECIMALS, build_jog_line, format_number
from smoothjog.core.ledger import ENGINE, Entry, Ledger, line_cost_bytes
from smoothjog.core.linksplit import LinkSplit
from smoothjog.core.machine import KeepOut, MachineModel
from smoothjog.core.realtime import CYCLE_START, JOG_CANCEL, STATUS_QUERY
from smoothjog.core.responses import (
    KNOWN_STATES,
    AlarmReply,
    Banner,
    ErrorReply,
    Message,
    Ok,
    Response,
    StatusReport,
)
from smoothjog.core.states import SLEEP_TEXT
from smoothjog.core.stopper import StopHandshake, StopPhase
from smoothjog.core.tracker import PathSeg, PathTracker
from smoothjog.core.units import (
    Vec,
    g91_end,
    mm_min_to_mm_s,
    mm_s_to_mm_min,
    norm,
)

#: The engine's public names; the intent vocabulary lives in core/intents.py.
__all__ = [
    "EngineEvent",
    "EngineLimits",
    "EngineStats",
    "EngineView",
    "JogTuning",
    "Jogger",
    "Output",
    "Phase",
    "SendLine",
    "SendRealtime",
    "StopRecord",
]

SYNC_LINE = "G4P0"
#: The control inputs a status report's Pn field names (firmware-facts §5.4).
_PIN_NAMES = {"H": "feed-hold", "D": "door"}
#: Grbl's slowest feed (MINIMUM_FEED_RATE, 1 mm/min, firmware-facts §4.2), in mm/s.
MIN_FEED_MM_S = 1.0 / 60.0
#: A queue within this of its target is topped up: the wake-up computed for the instant the
#: queue reaches its target must send then, not find a rounding error's worth still queued.
QUEUE_TOLERANCE_MM = 1e-6
#: A report that puts the machine at most this far ahead of the estimate needs no poll of its
#: own: at full speed it is well under a millisecond of queue (the link margin covers more).
ROUTINE_LEAD_MM = 0.05
#: A report that puts the machine this much further behind the estimate than its age can
#: explain means it is not running what was sent (an outside feed hold or cancel): the
#: estimate follows the firmware's planner to well under this at every stop (bench tables).
OUTSIDE_LAG_MM = 0.05
#: ... or this long at the commanded speed, if more. The fuzz's turns, slowdowns and queue
#: ends at 20-25 mm/s showed up to 0.7 mm of estimate lag with no outside stop; an outside
#: stop pauses a jog at least 50 ms (two $1 delays, firmware-facts §3.7).
OUTSIDE_LAG_S = 0.03
#: ... but never more than this: a hold at full speed must be seen within its deceleration.
OUTSIDE_LAG_CAP_MM = 1.0
#: Queue kept beyond the stopping distance and the committed segments however slow the jog.
QUEUE_FLOOR_MM = 0.3
#: The least distance a `FS:0` report may still leave to the end of the queue with nothing
#: outside at work (see _lags_outside).
FS_LEAD_FLOOR_MM = 0.1
#: A reported feed below this share of the slowest a block can run at the reported place
#: (less SLOWED_FLOOR_MM_S) is a machine someone else is braking (see _slowed_inside_a_block):
#: room for FS's integer rounding and an acceleration a fifth lower than the engine's.
SLOWED_SHARE = 0.8
SLOWED_FLOOR_MM_S = 1.0
#: A stop this many steps (of the worst axis) off the path sent was not smoothjog's doing: the
#: fuzz's worst tracked-minus-real without outside events is under one step.
OFF_PATH_STOP_STEPS = 5.0
#: Reports, each asked for after the one before arrived, that find the controller not reading
#: a jog line it holds before the engine calls it an outside stop (see _lines_unread).
UNREAD_REPORTS = 2
#: Status polling while an owed cancel waits for the stale lines to show themselves.
OWED_POLL_S = 0.010
#: Steps (of the busiest axis) every block moves at least: Grbl plans a block under half a step
#: as nothing, so shorter blocks of a very slow jog would be all rounding.
MIN_BLOCK_STEPS = 1.5
#: The least speed a slide along an edge keeps, as a share of the stick's: below it (a stick
#: within 3° of square to the edge) the jog stops at the edge rather than crawl along it.
SLIDE_MIN_SHARE = 0.05
#: Repeats of one increment before its run is worked out afresh from where the firmware put
#: the last target: 16 lines drift at most 8 ulps off the ray, 0.001 mm within 2048 mm.
CRUISE_LINES = 16
#: A report's FS is the feed rounded to whole mm/min (Grbl prints it with no decimals).
FEED_PRINT_MM_MIN = 0.5
#: Jog-line latencies the round-trip estimate looks at.
RTT_WINDOW = 64
#: How long a round trip far above the usual (a stall) keeps the queue long.
RTT_MEMORY_S = 30.0
#: A round trip over twice the window's slow one plus this is a stall, to be remembered.
STALL_MIN_S = 0.020
#: A round trip longer than this is a link that stopped, not one to size a queue for.
RTT_CAP_S = 0.5
#: Share of the wire's throughput the engine's own lines may take (the rest: `?`, other owners).
LINE_SHARE = 0.6
#: The longest wait a release may expect, on average, for the `ok` of a jog line still on the
#: wire: at 9600 baud (25 ms per line) blocks of 78 ms; at 38400 and faster it never binds.
RELEASE_WAIT_S = 0.004
#: Share of the return wire the status reports may take (the rest: replies, messages).
REPORT_SHARE = 0.3
#: Bytes of a typical jog line with its newline, for sizing before the first one is written.
JOG_LINE_BYTES = 24

#: Controller states in which a jog is accepted (firmware-facts §1.4).
JOG_STATES = frozenset({"Idle", "Jog"})

_STATE_REASONS = {
    "Alarm": "the controller is in Alarm: unlock with $X or home with $H first",
    "Hold": "the controller is in feed hold: resume (~) or reset before jogging",
    "Door": "the safety door is open: close it and resume (~) before jogging",
    "Check": "the controller is in check mode ($C): leave it before jogging",
    "Run": "the controller is running a program: jogging waits until it is idle",
    "Home": "the controller is homing: jogging waits until it is done",
    "Sleep": SLEEP_TEXT,
}


def _state_reason(state: str) -> str:
    """Why no jog goes in this state, in words."""
    reason = _STATE_REASONS.get(state)
    if reason is not None:
        return reason
    if state not in KNOWN_STATES:
        # A state no firmware has is most often a report damaged on the wire (`Joc`, `Idne`
        # in the noise fuzz); stopping is still right, since the report says nothing else.
        return (
            f"the controller reported the state {state!r}, which no firmware has"
            " (a report damaged on the wire?)"
        )
    return f"the controller is in state {state}"


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
    #: Segments the firmware has committed ahead of the step generator (firmware-facts §4.1: ~50
    #: ms).
    committed_s: float = 0.050
    #: Shortest block duration: the jogging doc's conservative 10 ms for the parser to keep up,
    #: plus 0.5 ms so each block is one full 10 ms segment and a short one (increments.committed_s).
    dt_floor_s: float = 0.0105
    #: Extra queue time on top of what the engine measures (the slow end of the round trips,
    #: remembered stalls, and how late the host wakes it for a top-up). 0 by default; the
    #: real-time commands take it from the config ([jog] link_margin_s).
    link_margin_s: float = 0.0
    #: The shortest wait between two polls the engine asks for (it plans its own wake-ups).
    tick_s: float = 0.001
    #: How often the engine looks while a queue runs out or steps wait for planner room.
    settle_tick_s: float = 0.005
    #: Wire time of one byte (115200 8N1: 86.8 µs); None: the link's own (the host asks it), or
    #: 115200 baud's if the link does not know. A status report's position is as old as its
    #: bytes took to arrive (firmware-facts §6), and lines, replies and reports must fit the
    #: wire's throughput. Overstating it only makes blocks longer and polls rarer.
    byte_s: float | None = None
    #: Status polling while moving and while idle (Grbl's docs: 5-10 Hz is comfortable).
    poll_moving_s: float = 0.050
    poll_idle_s: float = 0.250
    #: Planner blocks the engine leaves free so an `ok` is never held back by a full planner.
    planner_reserve_blocks: int = 3
    #: Re-ask for a status report if none came within this time.
    status_timeout_s: float = 0.5
    #: A stop that has heard no reply for this long (or ten measured round trips, if longer)
    #: presumes the replies it waits for were lost on the link (a garbled or dropped `ok`:
    #: Grbl answers every line), cancels and re-syncs instead of waiting for ever. Well over a
    #: Wi-Fi stall of 200 ms, so a late reply is not taken for a lost one.
    reply_timeout_s: float = 0.5
    #: A velocity-mode handwheel that sent no detent for this long has stopped: counts still
    #: waiting for planner or RX room are dropped, so the machine rests at the end of what was
    #: sent. Pendants report every 20-50 ms while the wheel turns, so 100 ms is two to five
    #: reports missed (a stopped wheel, not a late report), and at 5000 mm/min no more than
    #: 8 mm, about the stopping distance, is ever sent after the wheel stopped.
    wheel_timeout_s: float = 0.100


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
            idle_ms = float(idle_raw) if idle_raw is not None else DEFAULT_STEP_IDLE_DELAY_MS
        except ValueError:
            idle_ms = DEFAULT_STEP_IDLE_DELAY_MS
        return cls(
            axes=model.axis_letters,
            steps_per_mm=s.steps_per_mm,
            max_rate_mm_min=s.max_rate_mm_min,
            accel_mm_s2=s.accel_mm_s2,
            planner_blocks=model.planner_usable_blocks,
            rx_buffer_bytes=model.rx_buffer_bytes,
            max_line_chars=for_model(model).max_line_chars,
            idle_delay_s=idle_ms / 1000.0 if idle_ms < 255 else 0.0,
            envelope=model.soft_limit_envelope(),
            keepouts=tuple(keepouts) or model.keep_outs,
            firmware=model.firmware,
            junction_deviation_mm=s.junction_deviation_mm,
        )


# ------------------------------------------------------------------------------------ state
#: How much sooner (s) a cancel-and-restart must reach a faster speed than letting the queued
#: slower blocks run out before the engine cancels for a speed-up alone.
SPEEDUP_CANCEL_MARGIN_S = 0.15


class Phase(Enum):
    """What the engine is doing."""

    IDLE = "idle"
    JOGGING = "jogging"  # streaming continuous increments
    STEPPING = "stepping"  # step or go-to jogs queued
    STOPPING = "stopping"  # cancel handshake under way
    SETTLING = "settling"  # waiting for the machine to report rest after the queue ran out


class _Window:
    """The last `size` values, also kept in order so a percentile is one index away.

    Every reply and every late wake-up takes a percentile of such a window: keeping it sorted as
    values come and go costs less than sorting it again each time.
    """

    __slots__ = ("_recent", "ranked")

    def __init__(self, size: int) -> None:
        self._recent: deque[float] = deque(maxlen=size)
        #: The same values as the window, in increasing order.
        self.ranked: list[float] = []

    def add(self, value: float) -> None:
        """Take value in, dropping the oldest once the window is full."""
        recent = self._recent
        ranked = self.ranked
        if len(recent) == recent.maxlen:
            del ranked[bisect.bisect_left(ranked, recent[0])]
        recent.append(value)
        bisect.insort(ranked, value)


@dataclass(eq=False)
class _Cruise:
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


@dataclass
class _WheelRun:
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
class _WheelChain:
    """The running target of one axis's handwheel moves, so that rounding never accumulates.

    Every line goes to the step nearest anchor + total (firmware-facts §1.5), never to the
    previous target plus this report's distance. The chain holds while the axis's path end is
    still end_mm (no other move, stop or clip came between).
    """

    anchor_mm: float  # the axis's parser position where the chain began
    total_mm: Decimal  # signed detent distance since the anchor
    end_mm: float  # the axis's path end after the chain's last line


@dataclass(frozen=True)
class _WheelPlan:
    """The next line of a run (None when it moves no step) and the chain once it is sent."""

    axis: int
    chain: _WheelChain
    line: str | None
    seg: PathSeg | None
    clipped: bool


@dataclass(frozen=True)
class _LineTag:
    """What the engine keeps with each of its lines in the ledger."""

    kind: str  # "jog", "sync"
    seg: PathSeg | None = None
    #: By when its last byte has surely left the host: every byte counted in flight before it
    #: (its own included) at the controller's baud rate (the link's queue drains no slower).
    written_by_s: float = 0.0


@dataclass
class StopRecord:
    """One completed stop: how it ended and how far the tracked position was from the real one."""

    t_s: float
    cancelled: bool
    recancels: int
    tracked_error_mm: float
    tracked_error_steps: float  # the worst axis, in its own steps
    mpos_mm: Vec
    #: Something else stopped the machine first (an outside stop, a door, hold or reset): the
    #: lines it left ran from wherever that stop ended, off the path the engine tracked, so
    #: the tracked error measures that stop, not the engine's estimate.
    after_outside_stop: bool = False


@dataclass
class EngineStats:
    """Counters the tests and the benchmark read."""

    lines_sent: int = 0
    jogs_sent: int = 0
    #: `~` sent to a Grbl that reported Idle but answered nothing (firmware-facts §3.8).
    suspend_releases: int = 0
    cancels: int = 0
    recancels: int = 0
    #: Replies to the engine's lines that never came and were presumed lost on the link.
    replies_presumed_lost: int = 0
    error_replies: int = 0
    soft_limit_errors: int = 0
    run_state_seen: int = 0
    #: Velocity-mode detents dropped: beyond the stopping distance, or left when the wheel stopped.
    wheel_counts_dropped: int = 0
    #: Handwheel moves shortened at the soft limits or a keep-out zone (the counts past it dropped).
    wheel_clips: int = 0
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

    def __init__(
        self,
        model: MachineModel,
        limits: EngineLimits,
        tuning: JogTuning | None = None,
        ledger: Ledger | None = None,
    ):
        """An idle engine; ledger is the host's (a private one sized from limits by default)."""
        self.model = model
        #: Every line on the wire to this controller, whoever sent it (the host's).
        self.ledger = ledger if ledger is not None else Ledger(limits.rx_buffer_bytes)
        self.tuning = tuning or JogTuning()
        self._track = PathTracker(
            limits.steps_per_mm,
            limits.accel_mm_s2,
            limits.junction_deviation_mm,
            self.tuning.committed_s,
        )
        self._limits = limits
        self.stats = EngineStats()
        self.events: list[EngineEvent] = []
        #: Set by the host just before a banner that follows a Ctrl-X it sent for the user:
        #: that reset is told as news ("info"), not as a fault.
        self.reset_expected = False
        self.phase = Phase.IDLE
        self._intent: ContinuousIntent | None = None
        self._acted_intent: ContinuousIntent | None = None
        self._stop_requested = False
        self._cancel_owed = False
        self._pending_desync = False
        #: Stopped from outside: continuous intents are ignored until the stick is released.
        self._await_press = False
        #: A neutral or stop came since the last press (the next press clears the fault shown).
        self._released = True
        #: When the stop began its current wait, and when the last reply to the engine came.
        self._stop_wait_s = -math.inf
        self._last_reply_s = -math.inf
        #: `~` was sent for a silent Idle since the last reply (see _release_suspend).
        self._suspend_released = False
        self._prev_sent_s = -math.inf
        #: How late the host woke the engine for its planned top-ups (90th percentile).
        self._late_s = _Window(RTT_WINDOW)
        self._lateness_s = 0.0
        self._services = _Window(RTT_WINDOW)
        #: The commanded move a Jog report last showed running at its speed.
        self._seen_at_speed: inc.VectorMove | None = None
        #: A report of this run showed the machine at its commanded speed, with no stall since.
        self._cruised = False
        #: A Jog report at FS:0 inside a block: when it was built at the latest, where it put
        #: the machine, and the block (see _rested_inside_a_block).
        self._rest_inside: tuple[float, float, PathSeg] | None = None
        #: The last Jog report's place and FS (mm/s), where the acknowledged jogs then ended,
        #: and the jog it was on (see _slowed_since_last_report).
        self._prev_jog_report: tuple[float, float, float, PathSeg] | None = None
        #: The oldest line watched for being left unread, and when the last report that asked
        #: after it reached smoothjog, and how many did (see _lines_unread).
        self._unread_entry: Entry | None = None
        self._unread_seen_s = -math.inf
        self._unread_reports = 0
        #: Pn letters seen while the machine rested (an input that reads active while Idle).
        self._rest_pins = ""
        self._pins_warned = ""
        self._ratios = dict(self.tuning.speed_ratios)
        self._ratios_version = 0
        #: The increment a cruising jog repeats (None: work the next one out afresh).
        self._cruise: _Cruise | None = None
        #: What last stopped an increment short, and the stick already told of an edge.
        self._blocked_by = "the soft limit"
        self._edge_told: Intent | None = None
        self._block_cache: tuple[inc.VectorMove, EngineLimits, tuple[float, int], float] | None = (
            None
        )
        self._velocity_cache: (
            tuple[ContinuousIntent, int, EngineLimits, inc.VectorMove | None] | None
        ) = None
        #: The engine's own lines in the ledger, oldest first.
        self._pending: deque[Entry] = deque()
        self._steps: deque[StepIntent | GotoIntent | _WheelRun] = deque()
        #: Per axis index: the running target of its handwheel moves.
        self._wheel_chains: dict[int, _WheelChain] = {}
        #: (axis index, sign) of the newest velocity-mode detents taken: a report the other
        #: way on that axis is a reversal.
        self._wheel_dir: tuple[int, int] | None = None
        #: A settle may go back to streaming when handwheel moves arrive (not after a Run race).
        self._settle_resumable = False
        self._stop = StopHandshake()
        self._status_asked_s: float | None = None
        #: An Idle report is awaited to end a stop or a settle (the next one counts as fresh).
        self._fresh_status_wanted = False
        self._last_status_sent_s = -math.inf
        self._rtt_s = 0.003  # time for a jog line to be planned: a low percentile of its ok latency
        self._rtts = _Window(RTT_WINDOW)
        self._rtt_hi_s = self._rtt_s  # what the queue and the lines in flight are sized for
        #: Decreasing latencies of the last RTT_MEMORY_S (a sliding maximum), oldest first.
        self._rtt_peaks: deque[tuple[float, float]] = deque()
        #: A stall of the last RTT_MEMORY_S sizes the queue (_rtt_hi_s is that peak).
        self._stall_sized = False
        #: The way out and the way back, told apart by the reports of a cruise.
        self._split = LinkSplit()
        #: When the engine's bytes written so far have all left the host, at the wire's rate.
        self._wire_free_s = -math.inf
        #: How long the last `?` waited behind the engine's own lines (see _poll_status).
        self._status_backlog_s = 0.0
        self._byte_s = self.tuning.byte_s or BITS_PER_BYTE_8N1 / DEFAULT_BAUD
        self._line_bytes = JOG_LINE_BYTES
        self._last_report_bytes = 50  # a Grbl 1.1 report with MPos, FS and Pn
        self._last_report_s = -math.inf
        #: The last report showed a jog running and not braking (Jog, a speed above 0 and no
        #: lower than the report before): an owed cancel may act on it (see _owed_cancel_now).
        self._jog_unbraked = False
        self._prev_feed_mm_min: float | None = None  # FS of the last report, None if not Jog
        #: A jog cancel (smoothjog's or an outside one) may still be ending: no report since
        #: showed a state other than Jog or a jog running unbraked.
        self._cancel_ending = False
        #: A banner came with jog lines unanswered: one 0x85 goes out at once (reset_outputs).
        self._reset_cancel = False
        #: When that banner came; until reset_machine, the host reads no settings while
        #: restart_settled() is False, and the engine watches those lines (restart_outputs).
        self._restart_s: float | None = None
        #: Replies still due to lines the ledger dropped at that banner (any owner's), the
        #: ledger's counts of lines dropped at resets and of replies to nobody's line when last
        #: looked at, and when the last such reply came (restart_outputs).
        self._restart_replies_due = 0
        self._restart_lost = self.ledger.stats.lost_to_reset
        self._restart_unowned = 0
        self._restart_reply_s = -math.inf
        self._idle_since_s: float | None = None  # the first of the Idle reports in a row
        #: When the `?` of each Idle report in a row was written (None: not known).
        self._idle_asked_s: list[float | None] = []
        self._fault: tuple[str, str] | None = None
        #: The fault an ALARM:N showed: it goes once a report shows the controller out of Alarm.
        self._alarm_fault: tuple[str, str] | None = None
        #: A fault other than a refusal came since the last stop (see _finish_stop).
        self._path_faulted = False
        self._last_report: tuple[float, Vec] | None = None
        self._actual_speed_mm_s = 0.0
        #: When the streaming queue needs its next top-up (None: a reply will say).
        self._wake_at_s: float | None = None
        #: Something reached the engine (an intent, a line, new limits) since its last poll.
        self._changed = True
        #: The last poll held a line back for want of room in the controller's RX buffer.
        self._rx_blocked = False
        self._commanded = inc.VectorMove((0.0,) * len(limits.axes), 0.0, 1.0)

    @property
    def limits(self) -> EngineLimits:
        """What the engine knows of the machine; setting it hands the new limits on."""
        return self._limits

    @limits.setter
    def limits(self, limits: EngineLimits) -> None:
        self._limits = limits
        self._changed = True
        self._track.use_machine(
            limits.steps_per_mm, limits.accel_mm_s2, limits.junction_deviation_mm
        )

    # ----------------------------------------------------------------- inputs
    def set_intent(self, intent: Intent, now_s: float) -> None:
        """Take the newest intent; the next poll acts on the latest one only.

        Steps, go-tos and handwheel detents queue in order behind each other.
        """
        self._changed = True
        if isinstance(intent, StepIntent | GotoIntent):
            self._validate(intent)
            self._steps.append(intent)  # steps queue in order; a held stick is released
            self._intent = None
            self._await_press = False  # a step is a press of its own
            self._fault = None  # and the user has seen what went wrong before it
            self._path_faulted = False
            return
        if isinstance(intent, HandwheelIntent):
            self._validate(intent)
            if intent.counts:  # a report of no detents (a button) is no motion, nor a sign of life
                self._take_wheel(intent, now_s)
                self._intent = None
            return
        if isinstance(intent, StopIntent) or intent.is_neutral():
            self._intent = None
            self._steps.clear()
            self._stop_requested = True
            self._await_press = False
            self._released = True
            return
        # A neutral stick is a stop and is not checked further (an unknown axis at 0 is fine).
        self._validate(intent)
        if self._released:
            # A new press after a release: the fault shown since was seen; clear the banner.
            # (A held stick re-sent by its input is no new press and keeps it.)
            self._released = False
            self._fault = None
            self._path_faulted = False
        if self._await_press:
            # Someone else stopped this jog: the stick still held (or re-sent by its input) is
            # not a new press, so the machine stays where it was stopped.
            return
        self._intent = intent

    def _take_wheel(self, wheel: HandwheelIntent, now_s: float) -> None:
        """Queue a report's detents; in velocity mode drop what runs past the stopping distance.

        Velocity mode (LinuxCNC's MPG velocity mode): the path ahead of the machine, with what
        waits unsent, never exceeds v²/2a + v·committed_s at the wheel's feed along the axis,
        so the machine stops within that of the moment the wheel stops; counts that would go
        further are dropped. A report the other way on the same axis cancels everything queued
        (the full stop handshake) and then goes the other way. Position mode keeps every count.
        """
        axis = self.limits.axes.index(wheel.axis)
        sign = 1 if wheel.counts > 0 else -1
        counts = abs(wheel.counts)
        if wheel.mode == "velocity":
            if self._wheel_dir == (axis, -sign):
                self._steps.clear()
                # Only what was sent needs the handshake; detents still unsent just go.
                self._stop_requested = self._stop_requested or bool(self._track.path)
            self._wheel_dir = (axis, sign)
            speed_mm_s, accel_mm_s2 = self._wheel_feed(axis, wheel.speed)
            limit_mm = inc.queue_target_mm(speed_mm_s, accel_mm_s2, self.tuning.committed_s)
            self._track.update_estimate(now_s)
            # A path being cancelled (or about to be) is not ahead: the reversal starts after it.
            stopping = self._stop_requested or self.phase is Phase.STOPPING
            ahead_mm = 0.0 if stopping else self._track.queued_mm()
            ahead_mm += sum(float(r.dist_mm) for r in self._steps if isinstance(r, _WheelRun))
            # A line goes to the step nearest its running target: up to half a step further.
            ahead_mm += 0.5 / self.limits.steps_per_mm[axis]
            fit = min(counts, int(max(limit_mm - ahead_mm, 0.0) / wheel.step_mm + 1e-9))
            self.stats.wheel_counts_dropped += counts - fit
            counts = fit
            if not counts:
                return
        # The shortest decimal that reads back as step_mm: 0.01, not the binary value near it.
        dist_mm = Decimal(str(float(wheel.step_mm))) * counts
        last = self._steps[-1] if self._steps else None
        if isinstance(last, _WheelRun) and (last.axis, last.sign, last.speed, last.mode) == (
            axis,
            sign,
            wheel.speed,
            wheel.mode,
        ):
            last.dist_mm += dist_mm
            last.counts += counts
            last.last_s = now_s
            return
        self._steps.append(_WheelRun(axis, sign, dist_mm, counts, wheel.speed, wheel.mode, now_s))

    def _wheel_feed(self, axis: int, speed: float) -> tuple[float, float]:
        """A handwheel's speed (mm/s: speed x the axis's max rate) and acceleration on axis."""
        feed_mm_min = round(self.limits.max_rate_mm_min[axis] * speed, 3)
        return mm_min_to_mm_s(feed_mm_min), self.limits.accel_mm_s2[axis]

    def _validate(self, intent: Intent) -> None:
        """Refuse, in words, an intent this machine cannot run."""
        # max_feed_mm_min is computed up front, so default=0.0 keeps limits with no axis rates
        # (never built by from_model) from raising anything but JogBuildError here.
        max_feed_mm_min = self.tuning.max_feed_mm_min or max(
            self.limits.max_rate_mm_min, default=0.0
        )
        validate_intent(intent, self.limits.axes, max_feed_mm_min)

    def _act_on_intent(self, now_s: float) -> None:
        """Turn the newest intent into a phase change (called from poll)."""
        intent = self._intent
        if self._cancel_owed and self.model.state in JOG_STATES and self.phase is Phase.IDLE:
            # Lines left in the controller when a door or hold stopped us: cancel them now.
            self._cancel_owed = False
            self._begin_stop(now_s)
            self._stop.owe_cancel()
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
        self._acted_intent = intent

    @property
    def planned_end_mm(self) -> Vec | None:
        """Where the last jog sent ends (machine mm): the machine never goes beyond it."""
        return self._track.end_mm

    def busy(self) -> bool:
        """True while anything is queued, streaming or stopping, or an intent is held, or lines
        sent before a reset may still start the restarted controller (restart_settled)."""
        return (
            self.phase is not Phase.IDLE
            or bool(self._steps)
            or self._intent is not None
            or not self.restart_settled()
        )

    def set_speed_ratios(self, ratios: Mapping[str, float]) -> None:
        """Per-axis speed ratios in (0, 1]."""
        self._changed = True
        for axis, r in ratios.items():
            if axis not in self.limits.axes:
                raise JogBuildError(f"speed ratio for unknown axis {axis!r}")
            if not (0.0 < r <= 1.0):
                raise JogBuildError(f"speed ratio {r!r} for {axis} must be in (0, 1]")
        self._ratios.update(ratios)
        self._ratios_version += 1

    def on_reply(self, entry: Entry, resp: Ok | ErrorReply, now_s: float) -> bool:
        """The reply to one of the engine's own lines (the ledger matched it to entry).

        Returns whether the engine has anything to do at once. The `ok` of a jog while the
        stream runs normally changes nothing a poll would act on (the queue is sized in
        distance, not in lines), so the host need not poll for it: half the wake-ups of a
        held jog (about 95 a second at full speed) are saved that way.
        """
        self._changed = True
        if not self._pending or self._pending[0] is not entry:
            # Grbl answers in order, so the engine's oldest line is the one answered; anything
            # else means the ledger was reset under us. Never act on a reply we cannot place.
            self.events.append(
                EngineEvent(now_s, "info", f"a reply to {entry.text!r} came out of order")
            )
            if entry in self._pending:
                self._pending.remove(entry)
            return True
        self._pending.popleft()
        self._last_reply_s = now_s
        self._suspend_released = False
        first_ack = not self._track.moving_since_ack
        self._on_reply(entry, resp, now_s)
        routine = (
            self.phase is Phase.JOGGING
            and isinstance(resp, Ok)
            and _kind(entry) == "jog"
            and not first_ack  # the estimate starts moving: the wake-up time changes
            and not self._rx_blocked  # the RX buffer held a line back: there is room now
        )
        return not routine

    def on_response(self, resp: Response, now_s: float) -> bool:
        """Any other line the controller sent (the host has folded it into the model).

        Returns whether the engine has anything to do at once. A status report that finds a
        held jog running where the estimate expected it (or behind it, which only makes the
        queue longer than assumed) changes nothing the next planned poll would not see.
        """
        self._changed = True
        if isinstance(resp, StatusReport):
            if self._alarm_fault is not None and resp.state != "Alarm":
                self._alarm_over()
            fault = self._fault
            lead_mm = self._on_status(resp, now_s)
            wake_s = self._wake_at_s
            return not (
                self.phase is Phase.JOGGING
                # A planned top-up polls before the next status query is due (a long block's
                # top-up can be far off: the report must not leave the next `?` waiting on it).
                and wake_s is not None
                and wake_s <= self._status_due_s()
                and resp.state == "Jog"
                and lead_mm <= ROUTINE_LEAD_MM
                and not self._pending_desync
                and self._fault is fault
            )
        if isinstance(resp, AlarmReply):
            info = alarm_info(resp.code)
            self._fault_now(now_s, f"ALARM:{resp.code} {info.meaning}", info.hint)
            self._alarm_fault = self._fault
            self._abandon_motion()
        elif isinstance(resp, Banner):
            jogs = sum(1 for e in self._pending if _kind(e) == "jog")
            lost = (
                f"; {jogs} jog line{'s' if jogs != 1 else ''} had no reply yet: any that reach"
                " the restarted controller are cancelled once a report shows them running"
                if jogs
                else ""
            )
            if self.reset_expected:
                # The user's own reset: news, and no fault that would hide why jogs wait now.
                self.reset_expected = False
                self._path_faulted = True
                self.events.append(
                    EngineEvent(
                        now_s,
                        "info",
                        f"the controller was reset{lost}",
                        "smoothjog reads its settings again before jogging",
                    )
                )
            else:
                self._fault_now(
                    now_s,
                    f"the controller was reset (its banner arrived mid-session){lost}",
                    "check why it reset; smoothjog re-reads its settings before jogging again",
                )
            # Lines still on the wire when it restarted run as new jogs: owe them a cancel
            # (computed before the replies they will never get are forgotten), and send one at
            # once (reset_outputs).
            watching = self._restart_s is not None
            owed = self._cancel_owed
            self._reset_cancel = jogs > 0 or watching
            self._abandon_motion()
            self._forget_pending()
            lost_total = self.ledger.stats.lost_to_reset
            dropped, self._restart_lost = lost_total - self._restart_lost, lost_total
            if jogs or watching:
                # Another reset while the lines of the last one may still be on their way:
                # they can start this restarted controller as well (the cancel stays owed).
                self._cancel_owed = self._cancel_owed or owed
                self._restart_s = now_s
                # Each line the ledger dropped may still be answered, whoever wrote it: its
                # reply then goes to nobody's line.
                self._restart_replies_due = (self._restart_replies_due if watching else 0) + dropped
                self._restart_unowned = self.ledger.stats.unowned_replies
                self._restart_reply_s = now_s
                # Reports from before the restart say nothing of what runs now, and the first
                # Jog report after it may show a jog braking under reset_outputs' 0x85 rather
                # than one just started: only a speed that rises counts as running then.
                self._jog_unbraked = False
                self._prev_feed_mm_min = math.inf
                self._idle_since_s = None
                self._idle_asked_s.clear()
                # A reset drops a `?` still pending: ask again at once.
                self._status_asked_s = None
                self._last_status_sent_s = -math.inf
        elif isinstance(resp, Message) and resp.text == "Check Door":
            self._fault_now(now_s, "the safety door opened", "close the door and resume (~)")
            # The door already cancels the jog; send nothing more (lines in the controller's
            # buffer would run after the resume) and cancel those still unanswered then.
            self._abandon_motion()
        return True

    def reset_outputs(self) -> list[Output]:
        """What to send the moment a banner shows the controller reset, before anything else.

        Jog lines sent before the banner was seen may still be on their way: each starts a jog
        on the restarted controller as it arrives. The link keeps the order of bytes, so a
        0x85 sent now arrives right behind the last of them, while it is still speeding up,
        and cancels what they started. No cancel is under way after a restart for it to
        land in the end of (firmware-facts §3.8); with nothing running it is dropped.
        """
        if not self._reset_cancel:
            return []
        self._reset_cancel = False
        self._cancel_ending = True
        self.stats.cancels += 1
        return [SendRealtime(JOG_CANCEL)]

    def restart_outputs(self, now_s: float) -> list[Output]:
        """What to send while the host waits to re-read a restarted controller's settings:
        realtime bytes only. One `?` at a time, at most every OWED_POLL_S, and 0x85 for each
        jog a report shows running: the jog lines that were on the wire when it restarted
        start it one after another (those behind a cancel wait for its end, firmware-facts
        §3.1). No line goes out: the settings are read next, and a sync's reply must not mix
        with theirs.

        Before, nothing cancelled such a jog until the settings had been read: a press made
        just after someone else's reset of a machine at rest ran 5.7 mm of its first lines.
        """
        out: list[Output] = []
        if self._restart_s is None:
            return out
        # Their replies go to nobody's line (the ledger forgot them at the banner). While some
        # may still come, more of them may follow the jog that runs within milliseconds: one
        # 0x85 after the last throws them all away together, where one sent at once would hold
        # the rest back to start one by one after it, 1.25 mm each on the hobby router (as
        # during a stop, see _advance_stop). Those the reset threw away never answer: after a
        # quiet spell of a poll and the round trips' spread, the jog is cancelled anyway. Where
        # 0x85 empties the RX buffer (grblHAL) there is nothing to wait for.
        unowned = self.ledger.stats.unowned_replies
        if unowned != self._restart_unowned:
            self._restart_replies_due -= unowned - self._restart_unowned
            self._restart_unowned = unowned
            self._restart_reply_s = now_s
        if (
            self._jog_unbraked
            and self.model.state == "Jog"
            and (
                self._restart_replies_due <= 0
                or now_s - self._restart_reply_s >= self._restart_quiet_s()
                or firmware_facts(self.limits.firmware).jog_cancel.flushes_rx
            )
        ):
            self._send_owed_cancel(out)
        self._poll_status(now_s, out)
        return out

    def _restart_quiet_s(self) -> float:
        """How long no reply of a line from before a reset must come before the rest count as
        thrown away by it: a poll and the spread of the round trips (an FTDI adapter's timer
        holds replies back in batches)."""
        return OWED_POLL_S + max(self._rtt_hi_s - self._rtt_s, 0.0)

    def restart_wire_clear(self, now_s: float) -> None:
        """Every line written before the reset has left the host now: the link's own queue
        still held some at the banner (a stalled wire), and a `?` overtakes such lines, so
        only one asked from now on comes behind them all (restart_settled)."""
        if self._restart_s is not None:
            self._restart_s = max(self._restart_s, now_s)

    def restart_settled(self) -> bool:
        """True once no line sent before a restart can still start the machine.

        That is when the restarted controller has answered Idle to two `?`s in a row, both
        written after its banner (or after restart_wire_clear), the second after the first
        report came back. Each `?` went behind every line sent before it (the wire keeps the
        order of bytes), and Grbl parses a jog line within milliseconds once no cancel holds
        its main loop, so a line still to start would show as Jog by the second
        (firmware-facts §3.7). Also true in a
        state that starts no jog (Alarm; Hold, Door and Sleep, which the re-handshake waits
        out, the cancel staying owed) and when no jog line was unanswered at the banner.
        """
        since_s = self._restart_s
        if since_s is None:
            return True
        state = self.model.state
        if state is not None and state not in JOG_STATES:
            return True
        after = sum(
            1 for asked_s in self._idle_asked_s if asked_s is not None and asked_s >= since_s
        )
        return after >= 2 + self._others_poll()

    def reset_machine(self, limits: EngineLimits) -> None:
        """Start over after a re-handshake (the controller was reset).

        A cancel owed for jog lines sent before the reset was seen stays owed: they may still
        start the machine (it is sent once a report shows Jog). A press made after the banner
        (while the settings were re-read, a second at 9600 baud) is a new press: it is kept,
        and runs once the machine may jog.
        """
        owed = self._cancel_owed
        intent, steps = self._intent, list(self._steps)
        self._restart_s = None
        self.limits = limits
        self._forget_pending()
        self._abandon_motion()
        self._cancel_owed = owed or self._cancel_owed
        self._intent = intent
        self._steps.extend(step for step in steps if not isinstance(step, _WheelRun))

    # ----------------------------------------------------------------- the driver's tick
    def poll(self, now_s: float) -> list[Output]:
        """Everything to send now; call on every reply and at least every next_deadline_s()."""
        out: list[Output] = []
        if (
            not self._changed
            and self.phase is Phase.JOGGING
            and self._wake_at_s is not None
            and now_s < self._wake_at_s
        ):
            # Hot path: nothing was heard or asked since the last poll and the queue is not due
            # for a top-up (the machine cannot drain it faster than its wake-up assumed), so
            # only a status query can be owed; a held jog comes here some 20 times a second.
            self._poll_status(now_s, out)
            return out
        if self._wake_at_s is not None and now_s > self._wake_at_s:
            # Woken late for a planned top-up (a busy host, a slow timer): the queue drained
            # that much further, so it is sized for the late end of such wake-ups as well.
            # Only late ones are counted, so this is a percentile of the late ones: counting
            # wake-ups on time as 0 took the margin to 0 on a virtual clock and shortened the
            # FTDI coast (S4) from 1.55 to 1.49 x v²/2a, but it let slow jogs over the Wi-Fi
            # bridge run dry in its round trips' slow tail, and each dry queue's FS:0 read as
            # an outside stop (3 false alarms over the bridge in the fault-free fuzz, none
            # before; see bench/results/links.md, "Tried and not kept").
            self._late_s.add(now_s - self._wake_at_s)
            ranked = self._late_s.ranked
            self._lateness_s = ranked[(9 * len(ranked)) // 10]
        self._changed = False
        self._wake_at_s = None
        self._rx_blocked = False
        self._track.update_estimate(now_s)
        # A report can be as old as its `?` wait plus the slowest round trip seen (a stall).
        self._track.prune(0.3 + self._rtt_hi_s)
        self._act_on_intent(now_s)
        if self.phase is Phase.IDLE:
            if self._steps and self._may_jog():
                self.phase = Phase.STEPPING
            elif self._intent is not None and self._may_jog():
                self._start_jogging(now_s)
        elif (
            self.phase is Phase.SETTLING
            and self._settle_resumable
            and self._steps
            and isinstance(self._steps[0], _WheelRun)
        ):
            # A wheel turned while its earlier moves run out: queue behind them at once rather
            # than stop, report Idle and start again (a stutter at every report).
            self.phase = Phase.STEPPING
            self._fresh_status_wanted = False
        try:
            if self.phase is Phase.JOGGING:
                if not self._may_jog():
                    if self.model.jog_lock is not None:
                        self._fault_now(now_s, f"jogging stopped: {self.model.jog_lock}", "")
                        # A stick held through the other program's job is no new press: the
                        # jog does not start again by itself when the lock is lifted.
                        self._await_press = self._intent is not None
                        self._intent = None
                    self._begin_stop(now_s)
                else:
                    self._stream(now_s, out)
            if self.phase is Phase.STEPPING:
                self._stream_steps(now_s, out)
        except JogBuildError as exc:
            # A line that cannot be written (a value no axis can reach, say): never send it,
            # stop what runs, and say why; the driver keeps running.
            self._fault_now(
                now_s, f"jog not sent: {exc}", "check the intent that asked for it", refusal=True
            )
            self._intent = None
            self._steps.clear()
            self._begin_stop(now_s)
        if self.phase is Phase.STOPPING:
            self._advance_stop(now_s, out)
        self._poll_status(now_s, out)
        return out

    def next_deadline_s(self, now_s: float) -> float:
        """The latest time the driver should call poll again (it also polls on every reply).

        Nothing is polled on a fixed tick: the engine wakes when its queue will have drained to
        the target (or the planner freed a block), when a status report is due, and while a
        queue runs out or steps wait for room, every settle_tick_s. Replies and reports wake it
        anyway, so a wait on the controller costs nothing.
        """
        asked_s = self._status_asked_s
        if asked_s is not None:
            due_s = asked_s + self.tuning.status_timeout_s  # re-ask if the report never came
        elif self._status_urgent():
            due_s = now_s
        else:
            due_s = self._status_due_s()
        if self.phase is Phase.JOGGING and self._wake_at_s is not None:
            due_s = min(due_s, self._wake_at_s)
        elif self._restart_s is not None and self._jog_unbraked and self._restart_replies_due > 0:
            # A jog seen running waits for the old lines' replies: cancel it when they go quiet.
            due_s = min(due_s, self._restart_reply_s + self._restart_quiet_s())
        elif self.phase in (Phase.SETTLING, Phase.STEPPING):
            due_s = min(due_s, now_s + self.tuning.settle_tick_s)
        return max(due_s, now_s + self.tuning.tick_s)

    # ----------------------------------------------------------------- continuous jogging
    def _velocity(self) -> inc.VectorMove | None:
        """The per-axis velocity the current intent asks for, capped as Grbl caps it."""
        intent = self._intent
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
        # Speed, deflection and ratio are fractions of each axis's own maximum ($11x), as the
        # docs say: Z at 25 % runs at a quarter of $112, not at a quarter of the fastest axis.
        vel = tuple(
            intent.axes.get(axis, 0.0)
            * self._ratios.get(axis, 1.0)
            * intent.speed
            * mm_min_to_mm_s(self._axis_feed_mm_min(rate_mm_min))
            for axis, rate_mm_min in zip(self.limits.axes, self.limits.max_rate_mm_min, strict=True)
        )
        move = inc.vector_move(vel, self.limits.max_rate_mm_min, self.limits.accel_mm_s2)
        if move is None or move.speed_mm_s < MIN_FEED_MM_S:
            return None  # below Grbl's 1 mm/min floor the stick is as good as neutral
        return move

    def _max_feed_mm_min(self) -> float:
        return self.tuning.max_feed_mm_min or max(self.limits.max_rate_mm_min)

    def _axis_feed_mm_min(self, rate_mm_min: float) -> float:
        """An axis's full jog speed: its $11x, or the configured top feed if that is lower."""
        cap = self.tuning.max_feed_mm_min
        return min(rate_mm_min, cap) if cap else rate_mm_min

    def _start_jogging(self, now_s: float) -> None:
        mpos = self.model.mpos_mm
        if mpos is None:
            return  # no position yet: wait for the first status report
        self.phase = Phase.JOGGING
        self._track.begin(self._track.on_step_grid(mpos), now_s)
        self._track.moving_since_ack = False  # the estimate waits for the first jog's ok
        # A new run is judged once a report shows it at speed, whatever reports came between.
        self._cruised = False
        self._seen_at_speed = None
        self._rest_inside = None
        self._prev_jog_report = None

    def _ahead_s(self, block_s: float, now_s: float) -> float:
        """Queue time beyond the stopping distance: committed segments, the time a line needs
        to reach the planner (_queue_rtt_s), how late the host wakes, the configured margin.

        The firmware commits segments of the blocks already queued, so the longest of those
        (or of the next one) decides how much time five segments can hold.
        """
        longest_s = self._track.longest_queued_s(block_s)
        committed = min(inc.committed_s(longest_s), self.tuning.committed_s)
        return committed + self._queue_rtt_s(now_s) + self._lateness_s + self.tuning.link_margin_s

    def _queue_rtt_s(self, now_s: float) -> float:
        """The link's share of the queue: the time a new line may need to reach the planner,
        beyond how far ahead of the machine the estimate runs.

        With the estimate placed by its reports' round trips (see linksplit), that is the
        line's own wire time, the controller's parse and the jitter of the way out; it never
        exceeds the slow end of the round trips, which is all there is before a cruise has
        shown its split, and all there is while a stall is remembered.
        """
        spread_s = self._split.spread_s()
        floors_s = self._split.fastest_s()
        if spread_s is None or floors_s is None or self._stall_sized:
            return self._rtt_hi_s
        line_s = self._line_bytes * self._byte_s
        ok_s = len("ok\r\n") * self._byte_s
        # The fastest jog round trip less the wire times of the line and its ok is the
        # controller's parse and plan plus both ways' floors; the fastest report round trip
        # less its wire time is those floors alone (a `?` is read at once, a line only once
        # the ones before it are parsed: lines waiting in the RX buffer show up here).
        ranked = self._rtts.ranked
        fastest_s = ranked[0] if ranked else self._rtt_s
        parse_s = max(fastest_s - line_s - ok_s - floors_s, 0.0)
        # A `?` that came while a line was parsed is answered after it (the parse holds the
        # main loop), so the spread holds the parse already when it is the larger.
        backlog_s = max(self._wire_free_s - now_s, 0.0)
        return min(self._rtt_hi_s, backlog_s + line_s + max(parse_s, spread_s))

    def _block_s(self, move: inc.VectorMove) -> float:
        """Duration of one increment at this speed: just over one 10 ms segment when possible.

        A block of 10-20 ms makes the firmware's five prepared segments cover ~31 ms instead of
        50 ms (see increments.committed_s), so less is committed when the stick is released. It
        must still satisfy the corrected bound dt >= v/(2a(N-1)) and let the planner hold the
        stopping distance within the blocks the engine allows itself.
        """
        cache = self._block_cache
        if (
            cache is not None
            and cache[0] is move
            and cache[1] is self.limits
            and cache[2] == (self._rtt_hi_s, self._line_bytes)
        ):
            return cache[3]  # a held jog asks for the same move at every poll
        usable = max(self.limits.planner_blocks - self.tuning.planner_reserve_blocks, 2)
        # The link: each line must reach the controller before the queue needs the next one
        # (a 9600 baud wire takes 25 ms for a jog line), and the lines the RX buffer holds
        # must span the round trip until their replies make room for more.
        rx_lines = max(self.limits.rx_buffer_bytes // self._line_bytes - 1, 1)
        line_s = self._line_bytes * self._byte_s
        block_s = max(
            line_s / LINE_SHARE,
            # A release waits for the `ok` of a line still crossing the wire before its cancel
            # (firmware-facts §3.1). A line is on its way line_s / block_s of the time and then
            # has line_s / 2 left on average: long blocks keep that expected wait short.
            line_s * line_s / (2.0 * RELEASE_WAIT_S),
            self._rtt_hi_s / rx_lines,
            self.tuning.dt_floor_s,
            inc.min_block_s(move.speed_mm_s, move.accel_mm_s2, self.limits.planner_blocks),
            inc.stop_distance_mm(move.speed_mm_s, move.accel_mm_s2)
            / (move.speed_mm_s * (usable - 1)),
            # A very slow jog still moves at least a step and a half per block: shorter blocks
            # are all rounding (Grbl plans a block under half a step as nothing).
            MIN_BLOCK_STEPS * self._step_along_mm(move.unit_vec) / move.speed_mm_s,
        )
        self._block_cache = (move, self.limits, (self._rtt_hi_s, self._line_bytes), block_s)
        return block_s

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
        if not self._track.path:
            self._start_from_newest_report(now_s)
        n_blocks = self.limits.planner_blocks
        usable_blocks = max(n_blocks - self.tuning.planner_reserve_blocks, 1)
        block_s = self._block_s(move)
        ahead_s = self._ahead_s(block_s, now_s)
        committed_s = (
            ahead_s - self._queue_rtt_s(now_s) - self._lateness_s - self.tuning.link_margin_s
        )
        blocks = self._track.blocks_in_planner()
        for _ in range(n_blocks):
            queued_mm = self._track.queued_mm()
            # While the machine is still faster than the new speed (a slowdown), size the queue
            # for the speed it has: the slower blocks must be queued before the faster ones run
            # out, or the planner brakes below the new speed.
            speed_mm_s = max(move.speed_mm_s, self._track.v_est_mm_s)
            target_mm = max(
                inc.queue_target_mm(speed_mm_s, move.accel_mm_s2, ahead_s),
                # A slow jog's queue is little more than its committed segments; keep some
                # acknowledged path beyond them, or an outside stop would run it all and rest
                # where a queue that ran dry rests, and could not be told from one.
                inc.queue_target_mm(speed_mm_s, move.accel_mm_s2, committed_s) + QUEUE_FLOOR_MM,
            )
            if queued_mm >= target_mm + QUEUE_TOLERANCE_MM:
                # Nothing to send until the queue has drained to its target.
                self._wake_at_s = self._run_time_s(now_s, queued_mm - target_mm, move)
                return
            if blocks >= usable_blocks:
                # The planner is as full as the engine lets it be until a block is committed.
                lead_mm = self._track.uncommitted_lead_mm()
                if lead_mm is not None:
                    self._wake_at_s = self._run_time_s(now_s, lead_mm, move)
                return
            # Blocks of the planned duration, but never so short that the queue needs more of
            # them than the engine allows itself: while slowing from a higher speed the queue
            # is sized for that speed, and 10 ms blocks at the new one would fill the planner.
            length_mm = max(
                move.speed_mm_s * block_s,
                (target_mm - speed_mm_s * self.tuning.committed_s) / max(usable_blocks - 1, 1),
            )
            if not self._track.path:
                # The firmware commits ~50 ms of segments from the first block alone, planned
                # to stop at its end; make it long enough that this ramp never turns to braking
                # before the next lines arrive (else a fresh jog stutters at ~20 mm/s).
                ramp_s = self.tuning.committed_s + 2.0 * self._rtt_s + self.tuning.dt_floor_s
                length_mm = max(length_mm, min(move.accel_mm_s2 * ramp_s**2, target_mm))
            if not self._send_increment(move, length_mm, now_s, out):
                return
            blocks += 1

    def _start_from_newest_report(self, now_s: float) -> None:
        """Nothing is sent yet in this run: start its path where the newest report puts the
        machine, which is at rest.

        A report damaged on the wire in a way its format cannot show (a lost `-`: X 284.013 on
        a machine at -284.013, noise fuzz, Grbl over the Wi-Fi bridge) puts the model outside the
        travel. No line fits from there, and a run begun there stood for good, a held stick
        doing nothing and saying nothing; the next report now puts the path right.
        """
        mpos = self.model.mpos_mm
        if mpos is None or len(mpos) != len(self.limits.axes):
            return
        start = self._track.on_step_grid(mpos)
        if start != self._track.end_mm:
            self._track.begin(start, now_s)
            self._cruise = None

    def _run_time_s(self, now_s: float, dist_mm: float, move: inc.VectorMove) -> float | None:
        """When the machine will have run dist_mm further, at the faster of its estimated and
        commanded speed (so an accelerating machine is never woken for too late); None at rest.
        """
        speed_mm_s = max(self._track.v_est_mm_s, move.speed_mm_s)
        if not self._track.moving_since_ack or speed_mm_s <= 0.0:
            return None  # nothing drains before the first ok: that reply wakes the engine
        return now_s + dist_mm / speed_mm_s

    def _send_increment(
        self, move: inc.VectorMove, length_mm: float, now_s: float, out: list[Output]
    ) -> bool:
        """Send one G91 increment along move (clipped to the envelope and keep-outs)."""
        start = self._track.end_mm
        assert start is not None
        cruise = self._cruise
        end: Vec | None = None
        if (
            cruise is not None
            and cruise.move is move
            and cruise.length_mm == length_mm
            and cruise.limits is self.limits
            and start == cruise.next_start_mm
            and cruise.clear_mm >= cruise.run_mm + cruise.seg_len_mm
            and cruise.lines < CRUISE_LINES
        ):
            # Hot path: the same increment again, along the ray whose clear distance was
            # worked out when this run began. The firmware's single-precision sums leave
            # each start up to half an ulp per line off that ray, so the run is worked out
            # afresh every CRUISE_LINES lines, and at once if the end would leave the envelope.
            line, deltas, seg_len = cruise.line, cruise.deltas_mm, cruise.seg_len_mm
            run_mm = cruise.run_mm + seg_len
            seg_move = move
            end = g91_end(start, deltas)
            if not self._fits_envelope(end):
                end = None
        if end is None:
            made = self._make_increment(start, move, length_mm)
            if made is None:
                return False
            line, deltas, seg_len, cruise, seg_move = made
            run_mm = seg_len
            # Where the firmware's parser will put the target, not the sum in doubles: the
            # path then stays on the machine's however long the jog (a report off it by more
            # than two steps is taken for an outside stop).
            end = g91_end(start, deltas)
            if not self._fits_envelope(end):
                if not self._track.path and not self._fits_envelope(start):
                    # Outside the soft-limit travel (or a report damaged on the wire).
                    self._tell_once_per_stick(
                        "no jog fits from where the controller reports the machine"
                        f" ({self._where_blocked(start)}): that is outside the soft limits",
                        "if the report was right, move back inside with soft limits off"
                        " ($20=0) or home",
                    )
                return False
        if self.limits.keepouts and not self._ghost_clear(deltas):
            # Sent now, this line would run from wherever an outside stop left the machine
            # (firmware-facts §3.1) and could cut into a keep-out: wait until the machine has
            # come far enough along the path (a turn around a zone's corner is not blended).
            self._wake_at_s = now_s + self.tuning.settle_tick_s
            return False
        if not self._fits_rx(line):
            self._rx_blocked = True
            return False
        if cruise is not None:
            cruise.run_mm = run_mm
            cruise.next_start_mm = end
            cruise.lines += 1
        self._cruise = cruise
        seg = PathSeg(
            start,
            end,
            # The length between the float positions the path keeps (not the exact increment),
            # so the path's own arithmetic stays what it was before repeats were cached.
            norm(tuple(e - s for e, s in zip(end, start, strict=True))),
            # The speed and acceleration of the line as written (a slide has the axes left).
            seg_move.speed_mm_s,
            seg_move.accel_mm_s2,
            self._track.length_mm(),
            unit_vec=cruise.unit_vec if cruise is not None else None,
        )
        self._track.append(seg)
        self._send(line, "jog", now_s, out, seg)
        return True

    def _make_increment(
        self, start: Vec, move: inc.VectorMove, length_mm: float
    ) -> tuple[str, Vec, float, _Cruise | None, inc.VectorMove] | None:
        """Clip, round and write one increment; the cruise to repeat it, when it may be."""
        clipped = self._clip(start, move, length_mm)
        if clipped is None:
            # The stick is still held but there is no room left that way: say why the machine
            # stands.
            self._tell_once_per_stick(
                f"the jog stops at {self._blocked_by} ({self._where_blocked(start)})",
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
        self._line_bytes = max(self._line_bytes, len(line) + 1)  # sizes blocks for the link
        delta_vec = tuple(deltas.get(axis, 0.0) for axis in self.limits.axes)
        seg_len = norm(delta_vec)
        if clipped_move is not move or clipped_mm != length_mm or seg_len <= 0.0:
            # Near an edge: worked out afresh each time; a slide runs at its own speed.
            return line, delta_vec, seg_len, None, clipped_move
        # The rounded increment's own direction: start + k * delta stays exactly on this ray,
        # so its clear distance holds for every repeat (the unrounded direction would drift).
        ray = tuple(d / seg_len for d in delta_vec)
        cruise = _Cruise(
            move=move,
            limits=self.limits,
            length_mm=length_mm,
            line=line,
            deltas_mm=delta_vec,
            seg_len_mm=seg_len,
            unit_vec=ray,
            clear_mm=self._room_along(start, ray)[0],
            run_mm=0.0,
            next_start_mm=start,
        )
        return line, delta_vec, seg_len, cruise, move

    def _ghost_clear(self, deltas: Vec) -> bool:
        """True when a G91 line of these deltas stays out of every keep-out however short of
        its start an outside stop leaves the machine.

        A hold or 0x85 from someone else leaves the lines not yet parsed in the controller's
        buffer, and each then runs its increment from the stopping point (firmware-facts
        §3.1, §3.7): anywhere on the path still ahead of the machine. The firmware checks its
        own soft limits for every such line; keep-outs are smoothjog's alone, so the region
        the line could sweep from there is checked here (the zones grown by half the inset).
        """
        track = self._track
        # From where the machine may really be: the estimate runs ahead of it while it brakes
        # for a corner, so the last report's place counts when it is further back (until a
        # report shows the machine there, a turn at a zone's corner waits).
        reported = track.x_reported_mm
        x_mm = min(track.x_est_mm, reported if reported is not None else 0.0)
        grow = 0.5 * self._inset_mm()
        zones = [
            (tuple(v - grow for v in zone.min_mm), tuple(v + grow for v in zone.max_mm))
            for zone in self.limits.keepouts
        ]
        if not self._suspect_rest_clear(deltas, zones):
            return False
        # The lines sent and not yet answered may be among those left unparsed: they run
        # first, one after another from the stopping point, so this line then starts that
        # much further on (after a reversal, further back: a hold that cut an X+ line short
        # let the X- lines behind it run 2 mm further X- and into the vise, fuzz). Each
        # count of them is an offset of the stopping point.
        offsets: list[Vec] = [tuple(0.0 for _ in deltas)]
        for seg in reversed(track.path):
            if seg.acked:
                break
            offsets.append(
                tuple(
                    o + e - b for o, e, b in zip(offsets[-1], seg.end_mm, seg.start_mm, strict=True)
                )
            )
        # The path behind the machine (kept for late reports) is skipped by bisection: this
        # runs for every line sent near a zone.
        first = track.seg_index_at(x_mm) or 0
        for seg in itertools.islice(track.path, first, None):
            if seg.x0_mm + seg.length_mm <= x_mm:
                continue
            a0 = track.point_at(x_mm) if seg.x0_mm < x_mm else seg.start_mm
            b0 = seg.end_mm
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
                        return False
        return True

    def _suspect_rest_clear(self, deltas: Vec, zones: Sequence[tuple[Vec, Vec]]) -> bool:
        """False when a report at rest inside a block, not yet explained, may be someone
        else's stop there and this line could then enter a zone.

        Until _rested_inside_a_block settles it, such a rest (FS:0 inside an acknowledged
        block) may be an outside hold or 0x85 that struck while the lines behind it were on
        their way. Grbl and FluidNC parse lines in order: those parsed before the stop went
        with the planner, those still in the RX buffer run one after another from the
        stopping point (firmware-facts §3.1), acknowledged by now or not. So this line may
        start at that point plus any unbroken run of the lines after the block. Before, a
        hold 5 ms after a press, with a reversal behind it, let the engine slide along the
        vise on a path 1.5 mm off the machine's, and the machine entered the vise (fuzz,
        FluidNC over CH340).
        """
        suspect = self._rest_inside
        if suspect is None or not zones:
            return True
        _built_s, rest_mm, seg = suspect
        track = self._track
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

    def _room_along(self, start: Vec, ray: Vec) -> tuple[float, str]:
        """How far from start along ray the machine stays inside the inset envelope and clear of
        every inset keep-out (inf if nothing stops it), and what stops it there."""
        inset = self._inset_mm()
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

    def _clip(
        self, start: Vec, move: inc.VectorMove, length_mm: float
    ) -> tuple[inc.VectorMove, float] | None:
        """Shorten (or slide) an increment so it stays in the envelope and out of keep-outs."""
        vel = list(move.velocity_mm_s)
        inset = self._inset_mm()
        for attempt in range(len(vel) + 1):
            # The first try is the move itself (it is already capped as Grbl caps it).
            m = (
                move
                if attempt == 0
                else inc.vector_move(vel, self.limits.max_rate_mm_min, self.limits.accel_mm_s2)
            )
            if m is None:
                return None
            step_mm = self._step_along_mm(m.unit_vec)
            t = length_mm
            if m is not move:
                if m.speed_mm_s < SLIDE_MIN_SHARE * move.speed_mm_s:
                    # Pushed nearly square into the edge: what is left is a crawl (a stick's
                    # wobble), which would hold the planner for seconds. The jog stops there.
                    return None
                # A slide runs slower than the move it is cut from (only the axes left move):
                # the same length would last that much longer, and a stick held nearly square
                # to the edge would queue blocks of seconds that no later stick can undo. Keep
                # the block's time, and at least MIN_BLOCK_STEPS (as _block_s does).
                t = max(length_mm * m.speed_mm_s / move.speed_mm_s, MIN_BLOCK_STEPS * step_mm)
            blocked: int | None = None
            env = self.limits.envelope
            if env is not None:
                lo = tuple(v + inset for v in env.min_mm)
                hi = tuple(v - inset for v in env.max_mm)
                t_env, axis = inc.ray_box_exit(start, m.unit_vec, lo, hi)
                if t_env < t:
                    t = t_env
                    blocked = axis
                    self._blocked_by = "the soft limit"
            for zone in self.limits.keepouts:
                t_in, face = inc.ray_box_entry(start, m.unit_vec, zone.min_mm, zone.max_mm)
                t_in = max(t_in - inset, 0.0)
                if t_in < t:
                    t = t_in
                    blocked = face
                    self._blocked_by = f"the keep-out zone {zone.name!r}"
            if t >= step_mm or blocked is None:
                return (m, t) if t >= step_mm else None
            # Blocked within a step: drop the blocked axis and slide along the boundary.
            vel[blocked] = 0.0
        return None

    def _inset_mm(self) -> float:
        # One step of margin keeps float rounding in the firmware from tipping a target over
        # the edge (error:15 is inclusive at the edge, firmware-facts §2).
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
        # A speed-up from a crawl: the slow blocks queued must run out at their own feed first,
        # which at a few mm/s can take longer than stopping and starting again (a stick or a
        # shuttle ring pushed from the edge of its deadzone to full).
        faster = new.speed_mm_s > 1.25 * previous.speed_mm_s
        if cos > 0.5 and not slower and not faster:
            return
        reverse = cos <= 0.5
        accel = min(previous.accel_mm_s2, new.accel_mm_s2)
        let_run = inc.let_run_turn_s(
            self._track.queued_mm(), previous.speed_mm_s, new.speed_mm_s, accel, reverse=reverse
        )
        cancel = inc.cancel_restart_s(
            previous.speed_mm_s,
            new.speed_mm_s,
            accel,
            committed_s=self.tuning.committed_s,
            idle_delay_s=self.limits.idle_delay_s,
            round_trip_s=self._rtt_s,
        )
        # A cancel also stops the machine for the handshake: for a speed-up alone it must win
        # clearly, or a stick sweeping smoothly up from a reversal would stutter for nothing.
        margin_s = SPEEDUP_CANCEL_MARGIN_S if (cos > 0.5 and not slower) else 0.0
        choice = "cancel" if cancel + margin_s < let_run else "let-run"
        self.stats.turn_choices.append((now_s, choice, let_run, cancel))
        if choice == "cancel":
            self._begin_stop(now_s)

    # ----------------------------------------------------------------- steps and go-to
    def _stream_steps(self, now_s: float, out: list[Output]) -> None:
        if not self._may_jog():
            self._steps.clear()
            self._begin_stop(now_s)
            return
        if self._track.end_mm is None:
            if self.model.mpos_mm is None:
                return
            # moving_since_ack is kept as it was: a step queue after a jog starts estimating
            # from now, not from its first ok.
            self._track.begin(self._track.on_step_grid(self.model.mpos_mm), now_s)
        usable_blocks = max(self.limits.planner_blocks - self.tuning.planner_reserve_blocks, 1)
        while self._steps and self._track.blocks_in_planner() < usable_blocks:
            step = self._steps[0]
            plan: _WheelPlan | None = None
            if isinstance(step, _WheelRun):
                if step.mode == "velocity" and now_s - step.last_s > self.tuning.wheel_timeout_s:
                    # The wheel stopped while these waited for room: the machine rests at the
                    # end of what was sent instead of running on after it.
                    self.stats.wheel_counts_dropped += step.counts
                    self._steps.popleft()
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
                self._steps.popleft()
                continue
            line, seg = line_seg
            if not self._fits_rx(line):
                self._rx_blocked = True
                return
            self._steps.popleft()
            if plan is not None:
                self._commit_wheel(plan, now_s)
            self._track.append(seg)
            self._send(line, "jog", now_s, out, seg)
        if not self._steps and not self._lines_unanswered():
            self._settle(now_s)

    def _wheel_waits(self, run: _WheelRun) -> bool:
        """True while the path queued already keeps the machine at the run's speed.

        Until the queue drains to v²/2a plus the time to the next look (committed segments, a
        round trip, a settle tick), sending the run gains nothing; meanwhile later reports
        merge into it, so a wheel spun faster than the machine sends a few long lines.
        """
        if not self._track.path:
            return False
        speed_mm_s, accel_mm_s2 = self._wheel_feed(run.axis, run.speed)
        ahead_s = (
            self.tuning.committed_s
            + self._rtt_s
            + self.tuning.link_margin_s
            + self.tuning.settle_tick_s
        )
        return self._track.queued_mm() >= inc.queue_target_mm(speed_mm_s, accel_mm_s2, ahead_s)

    def _plan_wheel(self, run: _WheelRun) -> _WheelPlan:
        """The G91 line taking the run's axis to the step nearest its running target.

        The target is clipped at the soft limits (one step inside) and one step short of a
        keep-out zone: a wheel spun into a limit stops there, and the counts past it are
        dropped (the chain starts again at the edge, so turning back moves off it at once).
        """
        start = self._track.end_mm
        assert start is not None
        i = run.axis
        spm = self.limits.steps_per_mm[i]
        chain = self._wheel_chains.get(i)
        # Compared in whole steps: a machine that came to rest between reports reads back its
        # position on the step grid, a float an ulp away from the chain's own sum.
        if chain is None or round(chain.end_mm * spm) != round(start[i] * spm):
            chain = _WheelChain(start[i], Decimal(0), start[i])
        total_mm = chain.total_mm + run.sign * run.dist_mm
        target = inc.nearest_step_mm(Decimal(chain.anchor_mm) + total_mm, spm)
        chain = _WheelChain(chain.anchor_mm, total_mm, start[i])
        room_mm = self._wheel_room_mm(start, i, run.sign)
        clipped = (target - start[i]) * run.sign > room_mm
        if clipped:
            # Round toward the start so the edge's one step of margin is kept.
            edge = (start[i] + run.sign * room_mm) * spm
            target = (math.floor(edge + 1e-9) if run.sign > 0 else math.ceil(edge - 1e-9)) / spm
            chain = _WheelChain(target, Decimal(0), start[i])
        d = float(format_number(target - start[i], MM_DECIMALS))
        end = tuple(s + (d if k == i else 0.0) for k, s in enumerate(start))
        if d * run.sign <= 0.0 or not self._fits_envelope(end):
            return _WheelPlan(i, chain, None, None, clipped)
        feed_mm_min = round(self.limits.max_rate_mm_min[i] * run.speed, 3)
        speed_mm_s, accel_mm_s2 = self._wheel_feed(i, run.speed)
        line = build_jog_line(
            moves={self.limits.axes[i]: d},
            feed_mm_min=feed_mm_min,
            mode="G91",
            axes=self.limits.axes,
            max_line_chars=self.limits.max_line_chars,
        )
        seg = PathSeg(start, end, abs(d), speed_mm_s, accel_mm_s2, self._track.length_mm())
        return _WheelPlan(
            i, _WheelChain(chain.anchor_mm, chain.total_mm, end[i]), line, seg, clipped
        )

    def _commit_wheel(self, plan: _WheelPlan, now_s: float) -> None:
        """The run's line was sent (or moved no step): keep its chain, and say if it was cut.

        The user hears of a limit once, with the line that reaches it; reports that find the
        wheel already there are counted only.
        """
        self._wheel_chains[plan.axis] = plan.chain
        if plan.clipped:
            self.stats.wheel_clips += 1
        if plan.clipped and plan.line is not None:
            axis = self.limits.axes[plan.axis]
            self.events.append(
                EngineEvent(
                    now_s,
                    "info",
                    f"handwheel {axis} stopped at the soft limit or a keep-out zone "
                    f"({axis}={plan.chain.anchor_mm:.4f}); the detents past it were dropped",
                )
            )

    def _wheel_room_mm(self, start: Vec, axis: int, sign: int) -> float:
        """How far a handwheel move may go from start along one axis (inf if nothing stops it)."""
        unit_vec = tuple(float(sign) if k == axis else 0.0 for k in range(len(start)))
        return self._room_along(start, unit_vec)[0]

    def _step_line(self, step: StepIntent | GotoIntent) -> tuple[str, PathSeg] | None:
        start = self._track.end_mm
        assert start is not None
        axes = self.limits.axes
        if isinstance(step, StepIntent):
            i = axes.index(step.axis)
            d = self._step_room_mm(start, i, float(format_number(step.dist_mm, MM_DECIMALS)))
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
        problem = self._path_problem(start, end)
        if problem is not None:
            self._fault_now(
                self._track.est_s,
                f"jog refused: {problem}",
                "jog less far or elsewhere",
                refusal=True,
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
        if self.tuning.max_feed_mm_min:
            top_mm_s = min(top_mm_s, mm_min_to_mm_s(self.tuning.max_feed_mm_min))
        speed_mm_s = top_mm_s * step.speed
        line = build_jog_line(
            moves=moves,
            feed_mm_min=round(mm_s_to_mm_min(speed_mm_s), 3),
            mode=mode,  # type: ignore[arg-type]
            axes=axes,
            max_line_chars=self.limits.max_line_chars,
        )
        seg = PathSeg(
            start, end, norm(delta), speed_mm_s, move.accel_mm_s2, self._track.length_mm()
        )
        return line, seg

    def _step_room_mm(self, start: Vec, axis: int, dist_mm: float) -> float | None:
        """dist_mm, or shorter to stop at the inset soft limit or a keep-out (said in words);
        None (a fault in words) when there is no room at all that way."""
        unit_vec = tuple(
            (1.0 if dist_mm > 0 else -1.0) if k == axis else 0.0 for k in range(len(start))
        )
        room_mm, by = self._room_along(start, unit_vec)
        if room_mm >= abs(dist_mm):
            return dist_mm
        name = f"{self.limits.axes[axis]}{'+' if dist_mm > 0 else '-'}"
        # Toward zero on the 0.001 mm grid, so the shortened step stays inside.
        short_mm = math.floor(room_mm * 10**MM_DECIMALS) / 10**MM_DECIMALS
        if short_mm <= 0.0:
            self._fault_now(
                self._track.est_s,
                f"step refused: no room to jog {name}, {by} is there"
                f" ({self._where_blocked(start)})",
                "jog the other way",
                refusal=True,
            )
            return None
        self.events.append(
            EngineEvent(
                self._track.est_s,
                "info",
                f"step {name} shortened to {short_mm:g} mm (asked {abs(dist_mm):g} mm): {by} is"
                " there",
                "",
            )
        )
        return math.copysign(short_mm, dist_mm)

    def _tell_once_per_stick(self, text: str, hint: str) -> None:
        """Say why a held stick moves nothing, once for this stick position."""
        if self._intent is None or self._edge_told is self._intent:
            return
        self._edge_told = self._intent
        self.events.append(EngineEvent(self._track.est_s, "info", text, hint))

    def _where_blocked(self, start: Vec) -> str:
        """Where the machine is, for a message about an edge."""
        return "at " + ", ".join(
            f"{a} {p:.3f}" for a, p in zip(self.limits.axes, start, strict=True)
        )

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
        self._stop.begin()
        self._stop_wait_s = now_s
        self._suspend_released = False

    def _reply_overdue(self, now_s: float) -> bool:
        """True when the stop has waited for a reply longer than any link delays one.

        While the machine still moves, Grbl may rightly hold a reply until its planner has
        room (a long block on a slow machine), so the wait is then eight times as long;
        once a report since the wait began shows it at rest, the short wait applies.

        That report must answer a `?` written a usual round trip after the wait began (two,
        when another program polls too and may have asked first): the controller had the
        awaited lines before it, and writes a line's reply before any report it builds after
        parsing that line, so the link carried traffic back after the reply was due. An Idle
        report from before a stall proves nothing: at 9600 baud a stall held a sync line's
        reply for 0.58 s, it was given up, and when it came it went to the step sent next,
        which was then taken for done before it moved (the engine 8.8 mm off, and the next
        step went into a keep-out; fuzz, FluidNC).
        """
        since_s = max(self._stop_wait_s, self._last_reply_s)
        limit_s = max(self.tuning.reply_timeout_s, 10.0 * self._rtt_s)
        idle_s = self._idle_since_s
        others = self._others_poll()
        answered_after = sum(
            1 for a in self._idle_asked_s if a is not None and a >= since_s + self._rtt_s
        )
        if idle_s is not None and answered_after >= 1 + others:
            # Reported at rest (every report since the first Idle one) for limit_s of the wait:
            # nothing can still be running that the reply would wait for.
            return now_s - max(idle_s, since_s) > limit_s
        return now_s - since_s > 8.0 * limit_s

    def _release_suspend(self, now_s: float, out: list[Output]) -> bool:
        """Before lines are given up as lost: a Grbl 1.1h that reports Idle yet answers no line
        may be suspended by a 0x85 that reached it as a cancel ended (firmware-facts §3.8);
        `~` releases it. In a plain Idle it does nothing (its planner is empty).

        True when `~` went out now: the lines still in the controller's buffer are then parsed
        and answered, so the wait starts again rather than giving them up. Given up at once,
        each of their late `ok`s went to the next line: the sync's to a 10 mm Z step sent
        after it, which the engine then took for done before it began (fuzz, Grbl, Wi-Fi with
        stalls: 4000 steps of tracking error at that stop)."""
        facts = firmware_facts(self.limits.firmware).jog_cancel
        if self._suspend_released or not (
            facts.late_cancel_suspends and self.model.state == "Idle"
        ):
            return False
        out.append(SendRealtime(CYCLE_START))
        self.stats.suspend_releases += 1
        self._suspend_released = True
        self._stop_wait_s = now_s
        return True

    def _presume_lost(self, now_s: float, kinds: tuple[str, ...]) -> int:
        """Release the engine's unanswered lines of these kinds as answered; say so."""
        lost = [e for e in self._pending if _kind(e) in kinds]
        for entry in lost:
            self._pending.remove(entry)
        self.ledger.presume_answered(lost)
        self.stats.replies_presumed_lost += len(lost)
        waited_s = now_s - max(self._stop_wait_s, self._last_reply_s)
        self._fault_now(
            now_s,
            f"the controller did not answer {len(lost)} line{'s' if len(lost) != 1 else ''}"
            f" within {waited_s:.1f} s: the reply was lost on the link",
            "smoothjog cancelled and re-synced; check the cable or connection if this repeats",
        )
        self._stop_wait_s = now_s
        return len(lost)

    def _settle(self, now_s: float) -> None:
        """The queue was sent whole: wait for the machine to report rest."""
        self.phase = Phase.SETTLING
        self._settle_resumable = True
        self._fresh_status_wanted = True

    def _advance_stop(self, now_s: float, out: list[Output]) -> None:
        if self._stop.phase is StopPhase.WAIT_ACKS:
            if self._jogs_unanswered():
                # Lines left by someone else's stop (or a door, hold or reset) start once it
                # ends, each answered as Grbl parses it, all within a few milliseconds while
                # its planner is empty. One 0x85 after the last of those oks throws them all
                # away together; one sent as soon as the first shows up running would hold the
                # others back in the RX buffer, to start one by one after it (firmware-facts
                # §3.1, §3.7).
                if not self._reply_overdue(now_s):
                    if (
                        self._stop.owed
                        and self._jog_unbraked
                        and firmware_facts(self.limits.firmware).jog_cancel.flushes_rx
                    ):
                        # Where 0x85 empties the RX buffer (grblHAL, firmware-facts §7), the
                        # outside cancel threw some of these lines away: their oks never come,
                        # and the wait would last while the ones that came after it run (10 mm
                        # ran that way over Wi-Fi, 28 mm over a bridge; fuzz). A 0x85 now
                        # throws away the rest with the jog that runs, and no sync is out yet
                        # for it to lose. Each line that still starts later is cut short too.
                        self._send_owed_cancel(out)
                    return  # a cancel now would let these lines run on (firmware-facts §3.1)
                if self._release_suspend(now_s, out):
                    return  # their replies come once `~` acts
                # Their replies were lost: the lines ran (or run); cancel whatever moves.
                self._presume_lost(now_s, ("jog",))
                self._stop.owe_cancel()
            if self._cancel_ending and self.model.state == "Jog":
                # A cancel (someone else's, or one sent for a line that ran after it) has not
                # been seen to end: the jog brakes or rests in Jog. A 0x85 reaching Grbl in
                # that cancel's last moments would leave it suspended (firmware-facts §3.8),
                # and the sync line waits behind the cancel anyway. A line that starts after
                # it shows up running, and is cancelled then.
                cancel = False
            else:
                cancel = bool(self._track.path) or self._stop.cancelled or self.model.state == "Jog"
            if cancel:
                self._jog_unbraked = False
                self._cancel_ending = True
                out.append(SendRealtime(JOG_CANCEL))
                self.stats.cancels += 1
            self._send(SYNC_LINE, "sync", now_s, out)
            self._stop.sync_sent(cancel_sent=cancel)
            self._stop_wait_s = now_s
        elif (
            self._stop.phase is StopPhase.WAIT_SYNC
            and self._stop.owed
            and self._jog_unbraked
            and not firmware_facts(self.limits.firmware).jog_cancel.flushes_rx
        ):
            # The lines left behind an outside stop start as fresh jogs the moment it ends
            # (firmware-facts §3.7); a 0x85 that reached the controller in the instant between
            # (Idle) was dropped. Cancel each jog seen running until the sync line is answered.
            # (Not where 0x85 empties the RX buffer: it would throw the sync away.)
            self._send_owed_cancel(out)
        elif self._stop.phase is StopPhase.WAIT_SYNC and self._reply_overdue(now_s):
            # The sync line's reply was lost: sync again (Grbl answers each G4P0 once it has
            # run every line before it), a bounded number of times.
            if self._release_suspend(now_s, out):
                return  # its reply comes once `~` acts
            self._presume_lost(now_s, ("sync",))
            if self._stop.may_recancel():
                self._stop.recancel()  # back to waiting for acks, then 0x85 and G4P0 again
                self.stats.recancels += 1
                self._advance_stop(now_s, out)
            else:
                self._stop.sync_failed()
                self._fresh_status_wanted = True
                self._status_asked_s = None

    def _send_owed_cancel(self, out: list[Output]) -> None:
        """0x85 for a jog a report showed running; the next one needs a new such report."""
        self._jog_unbraked = False
        self._cancel_ending = True
        out.append(SendRealtime(JOG_CANCEL))
        self.stats.cancels += 1

    def _on_sync_reply(self, resp: Ok | ErrorReply, now_s: float) -> None:
        if self.phase is not Phase.STOPPING:
            return
        if isinstance(resp, Ok):
            self._stop.sync_ok()
            self._fresh_status_wanted = True
            self._status_asked_s = None
            return
        if (
            resp.code == ERR_SYSTEM_GC_LOCK
            and self.model.state != "Alarm"
            and self._stop.may_recancel()
        ):
            # firmware-facts §3.6: the sync line met a jog that restarted: cancel again (it
            # runs, so no cancel is ending).
            self._cancel_ending = False
            self._stop.recancel()
            self.stats.recancels += 1
            self._stop_wait_s = now_s
            return
        self._fault_now(now_s, f"stop sync failed: error:{resp.code}", error_info(resp.code).hint)
        self._stop.sync_failed()
        self._fresh_status_wanted = True
        # As after a good sync: the position is read with a `?` asked now, not with the answer
        # to one asked while the machine was still moving (that could wait status_timeout_s).
        self._status_asked_s = None

    def _finish_stop(self, now_s: float, *, cancelled: bool, recancels: int) -> None:
        """The machine rests: record how the stop went and forget the path."""
        mpos = self.model.mpos_mm
        if mpos is not None:
            # The report rounds to 0.001 mm; the step counts behind it are exact (a step is
            # over 0.002 mm on any axis this is meant for), so compare on the step grid.
            err_mm, err_steps = self._track.tracking_error(
                self._track.on_step_grid(mpos), cancelled=cancelled
            )
            outside = self._stop.owed
            # (A fault already raised in this run, a rejected line or a Run-state race, has
            # said why the path no longer holds; a refused step or jog has not: nothing of it
            # was sent. A step refused at a keep-out hid an outside cancel that threw away the
            # step sent before it, 1 mm short, in the fuzz: FluidNC at 38400 baud.)
            path_faulted, self._path_faulted = self._path_faulted, False
            if err_steps > OFF_PATH_STOP_STEPS and not outside and not path_faulted:
                # Every line smoothjog sent stops on its path, to a step: a rest this far off
                # it is motion that was not smoothjog's (a stop from outside seen only now,
                # whose left-over lines ran from where it left the machine, firmware-facts
                # §3.1). The position is re-read from the report, so nothing builds on it.
                outside = True
                self._fault_now(
                    now_s,
                    f"the machine stopped {err_mm:.2f} mm off the path smoothjog sent: something"
                    " outside smoothjog stopped or moved it",
                    "check for another program, a button or a pendant on the controller;"
                    " smoothjog has re-read the position",
                )
            self.stats.stops.append(
                StopRecord(now_s, cancelled, recancels, err_mm, err_steps, tuple(mpos), outside)
            )
            self.events.append(EngineEvent(now_s, "stop", f"stopped at {_fmt(mpos)}"))
        self._track.reset()
        self._commanded = inc.VectorMove((0.0,) * len(self.limits.axes), 0.0, 1.0)
        self._stop.end()
        self.phase = Phase.IDLE
        wheel_runs = [r for r in self._steps if isinstance(r, _WheelRun)]
        if not wheel_runs:
            self._wheel_dir = None
        for run in wheel_runs:
            # Detents queued behind this stop (a velocity reversal) waited for the engine, not
            # for a still wheel: their timeout runs from now.
            run.last_s = max(run.last_s, now_s)

    def _abandon_motion(self) -> None:
        """Forget the queued path (door, hold, alarm, reset): nothing more is sent.

        Jog lines still unanswered sit in the controller's buffer and run once it resumes
        (firmware-facts §3.1-§3.3): a cancel is owed, sent as soon as the state is Idle or Jog
        again.
        """
        self._cancel_owed = self._jogs_unanswered()
        self._track.drop()
        self._steps.clear()
        self._wheel_dir = None
        self._intent = None
        self._acted_intent = None
        self._stop.end()
        self.phase = Phase.IDLE

    # ----------------------------------------------------------------- replies and status
    def _on_reply(self, entry: Entry, resp: Ok | ErrorReply, now_s: float) -> None:
        pending = entry.tag
        assert isinstance(pending, _LineTag)
        if isinstance(resp, ErrorReply):
            self.stats.error_replies += 1
            if resp.code == ERR_TRAVEL_EXCEEDED:
                self.stats.soft_limit_errors += 1
        if pending.kind == "sync":
            self._on_sync_reply(resp, now_s)
            return
        if pending.kind != "jog" or pending.seg is None:
            return
        if isinstance(resp, Ok):
            # The upper quartile of recent latencies: it follows a jittery link, yet one ok
            # delayed behind a status report on the way back does not move it.
            latency_s = now_s - entry.sent_s
            if latency_s > 2.0 * self._rtt_s + 0.010:
                # A reply held up on the link (a stall): the lines behind it were late too, so
                # the machine may have run short and slowed. That is no outside stop: judge
                # only once a report shows it at speed again.
                self._seen_at_speed = None
                self._cruised = False
            self._rtts.add(latency_s)
            ranked = self._rtts.ranked
            self._rtt_s = ranked[(3 * len(ranked)) // 4]
            # The queue must bridge the slow end of the round trips the link shows (its jitter,
            # firmware-facts §6), not a typical one: the 90th percentile of the last
            # RTT_WINDOW lines that went out first in their poll. (Higher percentiles here are
            # mostly an ok held behind a status report, and would lengthen every coast.)
            # (The others of a burst wait behind it in the parser, one after another: they are
            # not late, and counting them would size every queue for the start of a jog.)
            if entry.sent_s != self._prev_sent_s:
                self._services.add(latency_s)
                # A stall (a Wi-Fi link pausing every few seconds) is remembered for
                # RTT_MEMORY_S: the window alone would forget it between two stalls.
                peaks = self._rtt_peaks
                while peaks and peaks[-1][1] <= latency_s:
                    peaks.pop()
                peaks.append((now_s, min(latency_s, RTT_CAP_S)))
            self._prev_sent_s = entry.sent_s
            peaks = self._rtt_peaks
            while peaks and peaks[0][0] < now_s - RTT_MEMORY_S:
                peaks.popleft()
            ranked_s = self._services.ranked or [latency_s]
            window_s = ranked_s[(9 * len(ranked_s)) // 10]
            # The longest of the memory counts only when it stands out from the window (a
            # stall), so one slow reply does not lengthen the queue for half a minute.
            peak_s = peaks[0][1] if peaks else 0.0
            self._stall_sized = peak_s > 2.0 * window_s + STALL_MIN_S
            self._rtt_hi_s = peak_s if self._stall_sized else window_s
            self._track.ack(pending.seg, now_s)
            return
        # A rejected G91 jog leaves the parser where it was, so every later increment is off:
        # stop, re-sync, and say why.
        info = error_info(resp.code)
        self._fault_now(now_s, f"jog rejected: error:{resp.code} {info.meaning}", info.hint)
        self._track.remove(pending.seg)
        self._steps.clear()
        self._intent = None
        if self.phase in (Phase.JOGGING, Phase.STEPPING, Phase.SETTLING):
            self._begin_stop(now_s)

    def _on_status(self, report: StatusReport, now_s: float) -> float:
        """Take a status report; return how far it moved the estimate forward (mm)."""
        asked_s = self._status_asked_s
        self._status_asked_s = None
        self._last_report_bytes = len(report.raw) + 2
        self._last_report_s = now_s
        # Running, not braking: a cancel (anyone's) only ever slows the jog down, so a speed
        # no lower than the last report's is a jog that is not being cancelled. Without an
        # FS field every Jog report counts.
        # A report of Jog right after one of another state is a jog just started, at any
        # speed but 0; at rest in Jog is a jog ending, whatever came before. A jog too short
        # for its prepared segments to speed up (a 0.01 mm step) reports Jog with FS:0 as it
        # starts: a 0x85 then lands in its last moments and leaves Grbl 1.1h suspended,
        # answering no line (firmware-facts §3.8; fuzz, Grbl over Wi-Fi, after a reset: the
        # settings could not be read again and every later press was ignored).
        feed = report.feed
        if report.state != "Jog":
            self._jog_unbraked = False
            self._prev_feed_mm_min = None
        elif feed is None or self._prev_feed_mm_min is None:
            self._jog_unbraked = feed is None or feed > 0.0
            self._prev_feed_mm_min = feed
        else:
            self._jog_unbraked = feed > 0.0 and feed >= self._prev_feed_mm_min
            self._prev_feed_mm_min = feed
        if report.state != "Jog" or self._jog_unbraked:
            self._cancel_ending = False
        if report.state != "Idle":
            self._idle_since_s = None
            self._idle_asked_s.clear()
        else:
            if self._idle_since_s is None:
                self._idle_since_s = now_s
            self._idle_asked_s.append(asked_s)
            del self._idle_asked_s[:-4]
        state = report.state
        mpos = self.model.mpos_mm
        lead_mm = 0.0
        self._note_pins(report, now_s)
        unread = self._lines_unread(report, asked_s, now_s)
        if mpos is not None:
            if self._last_report is not None and now_s > self._last_report[0]:
                dt = now_s - self._last_report[0]
                self._actual_speed_mm_s = math.dist(mpos, self._last_report[1]) / dt
            self._last_report = (now_s, tuple(mpos))
            # The correction places the estimate at now_s: advance it there first, or the next
            # update would integrate the time since the last poll a second time (the estimate
            # ran ~4 ms ahead of the machine, which a velocity-mode wheel's lead bound felt).
            self._track.update_estimate(now_s)
            predicted_mm = self._track.x_est_mm
            off_path = self._track.correct_estimate(mpos, (len(report.raw) + 2) * self._byte_s)
            if not off_path:
                self._split_by(report, asked_s, now_s)
            else:
                self._split.reset()
            lead_mm = self._track.x_est_mm - predicted_mm
            how = None if off_path else self._lags_outside(report, predicted_mm, asked_s, now_s)
            if how is None and unread is not None:
                how = unread
            if how is not None:
                # Behind the estimate by more than the report's age explains, or at rest with
                # path queued ahead: the machine is braking or resting although the queue runs
                # (an outside feed hold or 0x85; Grbl shows Jog throughout that stop, and may
                # never show Idle before the lines still in its buffer start it again,
                # firmware-facts §3.1-§3.2).
                self._outside_stop(now_s, report, how)
                return lead_mm
            if off_path and self.phase is Phase.JOGGING:
                # The machine is off every jog we sent: something moved or stopped it outside
                # smoothjog (a feed hold, a cancel, another sender), and Grbl re-synced its G91
                # origin. Further increments would land off the tracked path, so stop and sync.
                self._pending_desync = True
        if state == "Run" and self.phase in (Phase.JOGGING, Phase.STEPPING, Phase.STOPPING):
            # firmware-facts §9: a jog block can start in Run (a firmware race); it finishes by
            # itself within the queued path. Stop streaming and wait for Idle.
            self.stats.run_state_seen += 1
            self._fault_now(
                now_s,
                "the controller ran a jog block in Run state (a Grbl race)",
                "smoothjog stopped streaming; the machine stops at the end of what was queued",
            )
            self._intent = None
            self._steps.clear()
            self._stop.end()  # a handshake under way is dropped: the queue runs out instead
            self.phase = Phase.SETTLING
            self._settle_resumable = False  # nothing more is sent until the machine rests
            self._fresh_status_wanted = True
            return lead_mm
        if self._pending_desync:
            self._pending_desync = False
            if self.phase is Phase.JOGGING:
                self._outside_stop(now_s, report, "it left the path smoothjog sent")
                return lead_mm
        pressed = self._pressed_inputs(report)
        if pressed and self.phase in (Phase.JOGGING, Phase.STEPPING, Phase.SETTLING):
            # The hold button or the door switch went active during the motion: Grbl acts on
            # that change and is stopping the jog. (One that read active all along is not a
            # press: Grbl acts on changes only, firmware-facts §5.4, and jogs normally.)
            self._fault_now(
                now_s,
                f"the controller's {pressed} input was pressed: the controller is stopping",
                "release it, resume with ~ if it holds, and jog again",
            )
            self._abandon_motion()
            self._await_press = True
            return lead_mm
        if (
            state == "Idle"
            and self.phase is Phase.JOGGING
            and self._track.moving_since_ack
            and self._track.path
            and mpos is not None
        ):
            path = self._track.path
            at_end = self._track.steps_from(mpos, path[-1].end_mm) <= 2.0
            planned = [seg for seg in path if seg.acked]
            # Resting where the planned (acknowledged) jogs end is a queue that ran dry, not an
            # outside stop: the lines still on their way will start it again.
            at_planned_end = (
                bool(planned) and self._track.steps_from(mpos, planned[-1].end_mm) <= 2.0
            )
            if at_end and not self._jogs_unanswered():
                # Every jog was answered and the machine rests at the end: the queue has run
                # (at the edge of the envelope, or a host that could not keep up).
                self._track.arrive_at_end()
            elif not at_end and not at_planned_end:
                # At rest short of the planned end while jogging: something else
                # stopped the jog (a feed hold or jog cancel from a button or another client).
                # Grbl re-synced its parser to where it stopped, so every further G91 increment
                # would be off: sync, forget the path, and wait for a fresh intent.
                self._outside_stop(now_s, report, "it came to rest short of the path's end")
        fresh = self._fresh_status_wanted
        if state not in JOG_STATES and state != "Run":
            self._fresh_status_wanted = False
            if self.phase is not Phase.IDLE:
                self._fault_now(now_s, f"jogging stopped: {_state_reason(state)}", "")
                self._abandon_motion()
            return lead_mm
        if state == "Idle" and fresh:
            if self.phase is Phase.STOPPING and self._stop.phase is StopPhase.WAIT_STATUS:
                self._fresh_status_wanted = False
                self._finish_stop(
                    now_s, cancelled=self._stop.cancelled, recancels=self._stop.recancels
                )
            elif self.phase is Phase.SETTLING and not self._lines_unanswered():
                # The queue ran out by itself: no cancel to report, even if one was under way.
                self._fresh_status_wanted = False
                self._finish_stop(now_s, cancelled=False, recancels=0)
        return lead_mm

    def _split_by(self, report: StatusReport, asked_s: float | None, now_s: float) -> None:
        """Feed a report of a cruise to the link split; once it is ready, age the estimate by
        the split rather than by the report's wire time alone.

        A cruise here is a Jog report at the commanded feed, on a block of that speed, with the
        estimate cruising too: then the machine ran at that speed since the report before.
        """
        move = self._commanded
        track = self._track
        x_mm = track.x_reported_mm
        here = track.seg_at(x_mm) if x_mm is not None else None
        feed = report.feed
        if (
            x_mm is None
            or here is None
            or asked_s is None
            or report.state != "Jog"
            or self.phase is not Phase.JOGGING
            or feed is None
            or abs(feed - mm_s_to_mm_min(move.speed_mm_s)) > FEED_PRINT_MM_MIN
            or here.speed_mm_s != move.speed_mm_s
            or track.v_est_mm_s != move.speed_mm_s
        ):
            self._split.reset()
            return
        wire_s = (len(report.raw) + 2) * self._byte_s
        self._split.add(
            move, asked_s + self._status_backlog_s, now_s, x_mm, move.speed_mm_s, wire_s
        )
        age_s = self._split.newest_age_s()
        if age_s is not None and age_s > wire_s:
            track.x_est_mm = min(x_mm + track.v_est_mm_s * age_s, track.length_mm())

    def _lags_outside(
        self, report: StatusReport, predicted_mm: float, asked_s: float | None, now_s: float
    ) -> str | None:
        """True when a report shows a jog that ran at speed now braking or at rest for no
        reason of smoothjog's: an outside feed hold or 0x85 (Grbl reports Jog throughout that
        stop and may never report Idle before the lines in its buffer start it again,
        firmware-facts §3.1-§3.2).

        Only a jog already seen at its commanded speed is judged, and only while the planner
        holds (acknowledged) more than the stopping distance, so braking for the queue's end,
        a turn, a slow start or a stalled link is never mistaken for it. The lag must exceed
        what the report's age can explain (it may have been built any time since its `?`).
        """
        move = self._commanded
        if report.state != "Jog" or not self._queue_runs_as_sent():
            self._seen_at_speed = None
            self._cruised = False
            self._rest_inside = None
            self._prev_jog_report = None
            return None
        feed = report.feed
        cmd_mm_min = mm_s_to_mm_min(move.speed_mm_s)
        step_mm = 1.0 / min(self.limits.steps_per_mm)
        rested = self._rested_inside_a_block(report, asked_s, now_s, step_mm)
        if rested is not None:
            return rested
        acked_end_mm = self._acked_end_mm()
        # At speed: the commanded one, or that of the jog it is on (a slide along a keep-out or
        # the envelope runs slower than the stick asks).
        here = self._track.seg_at(self._track.x_est_mm)
        seg_mm_min = mm_s_to_mm_min(here.speed_mm_s) if here is not None else cmd_mm_min
        if feed is not None and feed >= 0.95 * min(cmd_mm_min, seg_mm_min):
            self._cruised = True
        elif feed == 0.0 and asked_s is not None and acked_end_mm is not None:
            # At rest in Jog with acknowledged path ahead (all of it once this run was seen at
            # speed, else the block it rests on; see _rest_ahead_mm): a turn never slows the
            # planner to 0 (the engine stops for a reversal), and a queue that ran dry rests
            # at its end, so wherever the estimate stands (by a junction, on a slide) only
            # someone else's stop rests here. FS is the speed of
            # the segments being prepared, which reaches 0 while the committed ones still
            # run: a queue braking for its end (an edge, a keep-out) may still be short of
            # it by what they cover over a lead of twice the committed time (the segment
            # buffer's lead varies by firmware): at most ½·a·t² at the end of a braking and
            # never more than the whole stop from the speed jogged; at least 0.1 mm
            # (FluidNC's slow jogs were seen resting 0.08 mm short at FS:0 with no outside
            # stop). A slow jog's committed segments run at speed until it brakes and may
            # cover more (Grbl over a stalled Wi-Fi link rested 0.15 mm short at 250 mm/min
            # as its queue ran dry: a false alarm), but allowing v·t there hides a real 0x85
            # of a jog at 500 mm/min, which rests only a few tenths short.
            rest_ahead_mm = self._rest_ahead_mm(acked_end_mm, step_mm)
            v_mm_s = max(move.speed_mm_s, self._track.v_est_mm_s)
            lead_s = 2.0 * self.tuning.committed_s
            committed_mm = max(
                min(
                    0.5 * move.accel_mm_s2 * lead_s**2,
                    inc.stop_distance_mm(v_mm_s, move.accel_mm_s2),
                ),
                FS_LEAD_FLOOR_MM,
            )
            if (
                rest_ahead_mm is not None
                and rest_ahead_mm > committed_mm + max(OUTSIDE_LAG_MM, 3.0 * step_mm)
                and not self._near_a_junction_at_rest()
                and not self._running_out_at_a_boundary(
                    committed_mm + v_mm_s * lead_s + max(OUTSIDE_LAG_MM, 3.0 * step_mm)
                )
            ):
                return f"it stood still {rest_ahead_mm:.2f} mm short of the path it was sent"
        if feed is not None:
            slowed = self._slowed_inside_a_block(feed, step_mm)
            if slowed is None:
                slowed = self._slowed_since_last_report(feed, step_mm)
            if slowed is not None:
                return slowed
        else:
            self._prev_jog_report = None
        if self._seen_at_speed != move:  # by value: an input re-sends the same stick
            if feed is not None and feed >= 0.95 * cmd_mm_min:
                self._seen_at_speed = move
            return None
        if (feed is not None and feed >= 0.9 * cmd_mm_min) or asked_s is None:
            return None
        if here is None or here.unit_vec is None or self._near_a_slow_junction(move):
            # Only a cruise is judged (the same unclipped increment repeated): at a turn, a
            # slide along an edge or a speed change the machine slows and the estimate follows
            # it less closely. Judge again once it is back at speed.
            self._seen_at_speed = None
            return None
        if acked_end_mm is None:
            return None
        # The planner holds at least the acknowledged jogs; a machine braking for their end
        # (lines late on a stalled link) has no more ahead of it than it needs to stop from
        # the speed it reports. One braking with more ahead was stopped by someone else.
        speed_mm_s = mm_min_to_mm_s(feed) if feed is not None else self._track.v_est_mm_s
        age_s = max(now_s - asked_s, 0.0)
        ahead_mm = acked_end_mm - self._track.x_est_mm
        needed_mm = (
            inc.stop_distance_mm(speed_mm_s, move.accel_mm_s2)
            + speed_mm_s * age_s
            + max(OUTSIDE_LAG_MM, 3.0 * step_mm)
        )
        if ahead_mm <= needed_mm:
            return None
        lag_mm = predicted_mm - self._track.x_est_mm
        # A report built any time since its `?` may be this much older than now.
        allowed_mm = max(self._track.v_est_mm_s, move.speed_mm_s) * max(now_s - asked_s, 0.0)
        # The estimate follows short blocks and the end of a queue less closely at speed:
        # allow the larger of OUTSIDE_LAG_MM, two steps and OUTSIDE_LAG_S at the commanded
        # speed, at most OUTSIDE_LAG_CAP_MM (1 mm at 5000 mm/min, 0.25 mm at 500).
        if feed == 0.0:
            # At rest in Jog with path acknowledged ahead (checked above): only a stop that is
            # not smoothjog's rests there; a few steps of estimate error are all to allow.
            margin_mm = 3.0 * step_mm
        else:
            margin_mm = max(
                OUTSIDE_LAG_MM,
                2.0 * step_mm,
                min(move.speed_mm_s * OUTSIDE_LAG_S, OUTSIDE_LAG_CAP_MM),
            )
        if lag_mm > allowed_mm + margin_mm:
            return f"it fell {lag_mm:.2f} mm behind the path it was sent"
        return None

    def _rested_inside_a_block(
        self, report: StatusReport, asked_s: float | None, now_s: float, step_mm: float
    ) -> str | None:
        """A sentence when a Jog report at FS:0 put the machine inside a block and a report
        built after the committed segments surely ran still finds it short of that block's end;
        else None.

        FS:0 says the segments prepared last end at rest. With nothing outside at work the
        planner plans rest only at a block's end (the end of what it holds, or a reversal), so
        the machine reaches that end within the committed lead (at most 2 x committed_s). Only
        someone else's stop rests it inside a block. One report there can be a machine still
        running its last segments; the second, asked that long after the first was built,
        settles it, even when the lines behind the stop already start the machine again: a
        hold at 9600 baud rested a jog 1.24 mm before its block's end, the next report showed
        it moving off again from there, and 22 mm ran (fuzz, Grbl). Another program's `?` may
        answer ours early, so with other pollers on the wire this sign is not used.
        """
        x_mm = self._track.x_reported_mm
        if x_mm is None or self._others_poll():
            self._rest_inside = None
            return None
        margin_mm = max(OUTSIDE_LAG_MM, 4.0 * step_mm)
        if self._rest_inside is not None:
            built_s, rest_mm, seg = self._rest_inside
            if self._track.seg_at(rest_mm) is not seg or x_mm >= seg.x1_mm - margin_mm:
                self._rest_inside = None  # a new path, or it ran on to the block's end
            elif asked_s is not None and asked_s - built_s >= 2.0 * self.tuning.committed_s:
                self._rest_inside = None
                return (
                    f"it rested {seg.x1_mm - rest_mm:.2f} mm before the end of a jog it was"
                    " sent and did not run on to it"
                )
            else:
                return None
        if report.feed != 0.0:
            return None
        here = self._track.seg_at(x_mm)
        if (
            here is not None
            and here.acked
            and x_mm - here.x0_mm > margin_mm
            and here.x1_mm - x_mm > margin_mm
        ):
            # Built at the latest when its last byte left the controller.
            self._rest_inside = (now_s - (len(report.raw) + 2) * self._byte_s, x_mm, here)
        return None

    def _others_poll(self) -> bool:
        """True when another program also asks `?` (or relays its lines): a report may then
        answer its `?` rather than smoothjog's."""
        return self.ledger.relayed or self.ledger.stats.queries_by_others > 0

    def _fs_lead_mm(self, speed_mm_s: float, step_mm: float) -> float:
        """How far ahead of the reported position FS may apply at this speed: the committed
        segments (a lead of up to twice committed_s) and the report's rounding."""
        return speed_mm_s * 2.0 * self.tuning.committed_s + max(OUTSIDE_LAG_MM, 3.0 * step_mm)

    def _slowed_inside_a_block(self, feed_mm_min: float, step_mm: float) -> str | None:
        """A sentence when the reported feed is below the slowest that the block the machine is
        in can run at the reported place, whatever the link did; else None.

        Once a block is planned, the planner speeds the machine up along it at the block's
        acceleration from whatever speed it entered at (at least from rest), and if no block
        followed in time it brakes to rest at the block's end. FS is the speed where the
        segments prepared last end, which is at or ahead of the position by at most the
        committed lead. So x into a block of speed v, length L and acceleration a, FS is at
        least min(v, sqrt(2a·x), sqrt(2a·(L - x - lead))), however late its replies or the
        next line came, and whether the run was ever seen at speed. Lower, someone else is
        braking the machine (or starting it again after such a stop). Short blocks leave this
        no room; the long ones of slow links do: a feed hold at 9600 baud braked a fresh jog
        to rest inside its 13 mm block between two reports, its next line started it again,
        and 17 mm ran (fuzz, Grbl).
        """
        x_mm = self._track.x_reported_mm
        if x_mm is None:
            return None
        seg = self._track.seg_at(x_mm)
        if seg is None or not seg.acked or seg.speed_mm_s <= 0.0:
            return None
        a = seg.accel_mm_s2
        lead_mm = self._fs_lead_mm(seg.speed_mm_s, step_mm)
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

    def _slowed_since_last_report(self, feed_mm_min: float, step_mm: float) -> str | None:
        """A sentence when the reported feed is below the slowest the jogs acknowledged by the
        last report allow at the reported place, starting from that report's feed; else None.

        Every jog answered before a report was built was in the planner then (Grbl writes a
        line's reply before any report it builds after it), and the planner runs them at the
        fastest speed that can still brake for their end and for every junction on the way;
        a line added since only moves the end further. So from the last report's place and
        feed on, FS (the speed where the segments prepared end, at most the committed lead
        ahead of the position) stays at least that feed, each jog's own speed, what each
        junction passed or ahead allows, and what braking for the end of those jogs allows.
        Lower, someone else is braking the machine. A fresh jog still speeding up across its
        first short blocks was missed otherwise: FluidNC cancelled from outside at 40 mm/s,
        the engine sent its next line into the braking, and that line ran 5 mm on (fuzz).
        """
        prev, self._prev_jog_report = self._prev_jog_report, None
        x_mm = self._track.x_reported_mm
        held_end_mm = self._acked_end_mm()
        if x_mm is None or held_end_mm is None or self.ledger.relayed:
            return None
        here = self._track.seg_at(x_mm)
        if here is None:
            return None
        self._prev_jog_report = (x_mm, mm_min_to_mm_s(feed_mm_min), held_end_mm, here)
        if prev is None:
            return None
        x0_mm, fs0_mm_s, end_mm, seg0 = prev
        feed_mm_s = mm_min_to_mm_s(feed_mm_min)
        if feed_mm_s >= SLOWED_SHARE * fs0_mm_s - SLOWED_FLOOR_MM_S:
            return None  # the bound below never exceeds the last feed: a steady feed passes
        path = self._track.path
        if x_mm < x0_mm or not any(seg is seg0 for seg in path):
            return None  # a new path, or a report that went back
        held = [seg for seg in path if seg.x1_mm > x0_mm and seg.x0_mm < end_mm]
        if not held or not all(seg.acked for seg in held):
            return None
        v_top = max(seg.speed_mm_s for seg in held)
        # FS is the speed somewhere in [x_mm, at_mm].
        at_mm = x_mm + self._fs_lead_mm(v_top, step_mm)
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

    def _running_out_at_a_boundary(self, within_mm: float) -> bool:
        """True when everything sent ends at the envelope or a keep-out, within_mm ahead of the
        estimate: the queue runs out there and no line will follow.

        A slow jog's committed segments still run at its speed when FS reads 0, so it rests
        short of that end by up to its speed times their lead: FluidNC at 9600 baud (1.5 mm
        blocks at 350 mm/min) reported FS:0 0.20 mm before the Y soft limit with no outside
        stop. Only at such an end is that allowed; mid-path it would hide a real 0x85 of a slow
        jog, which rests only a few tenths short.
        """
        path = self._track.path
        if not path or self._track.length_mm() - self._track.x_est_mm > within_mm:
            return False
        last = path[-1]
        if last.length_mm <= 0.0:
            return False
        ray = last.unit_vec or tuple(
            (e - s) / last.length_mm for e, s in zip(last.end_mm, last.start_mm, strict=True)
        )
        room_mm = self._room_along(last.end_mm, ray)[0]
        # The last increments stop short of the edge by what rounding leaves (2 steps seen).
        return room_mm <= 4.0 / min(self.limits.steps_per_mm)

    def _rest_ahead_mm(self, acked_end_mm: float, step_mm: float) -> float | None:
        """How much path the planner surely held ahead of a machine reported at rest in Jog;
        None when a rest there says nothing.

        Once the run was seen at speed the planner holds every acknowledged jog. Before that
        (a fresh jog still speeding up, or one whose replies came late), the lines planned so
        far may have run out: the machine then brakes for a block's end, and only the rest of
        the block it is on counts. A queue that runs dry rests at a block's end (short of it
        by what the committed segments cover), never in the middle of a long one, and a
        report at the run's start is a jog not yet moving. A machine that moved off the start
        and rests far inside a block was stopped by someone else: a hold 0.1 s into a fresh
        jog at 9600 baud left the next 13 mm line to start it again (18 mm ran, fuzz).
        """
        if self._cruised:
            return acked_end_mm - self._track.x_est_mm
        # Where the report put it (the estimate moves that on by the report's wire time, as if
        # it still ran).
        x_mm = self._track.x_reported_mm
        if x_mm is None or x_mm <= max(OUTSIDE_LAG_MM, 3.0 * step_mm):
            return None
        here = self._track.seg_at(x_mm)
        if here is None or not here.acked:
            return None
        return here.x1_mm - x_mm

    def _queue_runs_as_sent(self) -> bool:
        """True while jogging, and while smoothjog's own stop still waits for the oks before its
        0x85: the queue then runs as sent, so someone else's stop shows as it does while
        jogging."""
        return self.phase is Phase.JOGGING or (
            self.phase is Phase.STOPPING
            and self._stop.phase is StopPhase.WAIT_ACKS
            and not self._stop.cancelled
        )

    def _lines_unread(
        self, report: StatusReport, asked_s: float | None, now_s: float
    ) -> str | None:
        """A sentence when the controller answers `?` in Jog but has stopped reading lines.

        The engine never fills the planner (it keeps planner_reserve_blocks free), so Grbl reads
        a `$J=` line and answers it as soon as the line is in its RX buffer. Two reports, each
        asked for after the line surely arrived and the second after the first was received,
        so printed after the line was in (the wire keeps order), with that line still
        unanswered: the main loop is in its suspend loop, where an outside feed hold or jog
        cancel keeps it until the stop is over, and then the line starts the machine again
        (firmware-facts §3.1, §3.7). This sign needs no particular speed, position or phase of
        the polls, so it also catches a hold that strikes a jog already braking, where neither
        a lag nor a rest short of the path shows. Another program's `?` may answer ours
        early (a relay, a proxied sender): then a third report is asked for. The last report
        must show the jog braking or at rest (a full planner runs on at speed).
        """
        oldest = self.ledger.oldest()
        if (
            oldest is None
            or oldest.owner != ENGINE
            or _kind(oldest) != "jog"
            or not oldest.on_wire
            or not self._queue_runs_as_sent()
        ):
            self._unread_entry = None
            return None
        if oldest is not self._unread_entry:
            self._unread_entry = oldest
            self._unread_reports = 0
            tag = oldest.tag
            assert isinstance(tag, _LineTag)
            # Written by written_by_s, the line reaches the controller one way of the link later
            # (a Wi-Fi bridge: 20-60 ms) and is answered after its parse. A report asked
            # before then can come back ahead of that `ok` though nothing is wrong: on the
            # bridge two such reports took a slow jog for an outside stop. The usual round
            # trip (a low percentile, not the slow end, which a stall inflates to 0.5 s and
            # which would blind the sign for the holds it is there for) covers that.
            self._unread_seen_s = (
                tag.written_by_s + self._rtt_s if oldest.echo_s is None else oldest.echo_s
            )
        if asked_s is None or asked_s <= self._unread_seen_s:
            return None
        self._unread_reports += 1
        self._unread_seen_s = now_s
        others = self._others_poll()
        if report.state != "Jog" or self._unread_reports < UNREAD_REPORTS + others:
            return None
        # A planner filled after all (the blocks of a turn from a fast move to a slow one are
        # counted out by the estimate before the machine has run them) leaves a line unread
        # too, with the machine running on at its speed: only a jog braking or at rest below
        # the speed it was sent, away from a junction it may rest at, is judged.
        feed = report.feed
        cmd_mm_min = mm_s_to_mm_min(self._commanded.speed_mm_s)
        if (
            self._jog_unbraked
            or (feed is not None and feed >= 0.95 * cmd_mm_min)
            or self._near_a_junction_at_rest()
        ):
            return None
        unread_ms = (now_s - oldest.sent_s) * 1000.0
        return f"the controller left a jog line unread for {unread_ms:.0f} ms while answering `?`"

    def _acked_end_mm(self) -> float | None:
        """Where along the path the acknowledged jogs end (replies come in order, so they are
        a prefix of the path), or None before the first ok."""
        for seg in reversed(self._track.path):
            if seg.acked:
                return seg.x0_mm + seg.length_mm
        return None

    def _near_a_junction_at_rest(self) -> bool:
        """True while the estimate is within braking reach of a junction the planner passes at
        (nearly) no speed: a reversal the engine let the queue run through rests there."""
        x = self._track.x_est_mm
        prev = None
        for seg in self._track.path:
            before, prev = prev, seg
            if before is None or seg.entry_cap_mm_s >= 0.1 * seg.speed_mm_s:
                # The path's first segment starts from rest, which is no junction: a jog
                # speeding up from there reports a rising FS, never a braking one. Counted as
                # one, it hid a feed hold 14 mm into a fresh jog, and 37 mm ran on (fuzz).
                continue
            reach_mm = seg.speed_mm_s**2 / seg.accel_mm_s2 + OUTSIDE_LAG_MM
            # The machine brakes into the junction from the block before it, which may be the
            # faster one (a step run out into a slow jog back): FluidNC reported FS:0 0.41 mm
            # before such a junction, its last segments still running. FS is the speed at the
            # end of the segments already prepared, which run ahead of the machine by the
            # committed time: a slow jog cruising into the junction shows FS:0 about that far
            # before it (a stick swept slowly through zero gave FS:0 0.165 mm, 32 ms, before
            # the reversal of a 313 mm/min jog, still moving).
            lead_mm = inc.braking_lead_mm(
                before.speed_mm_s, before.accel_mm_s2, self.tuning.committed_s
            )
            reach_in_mm = max(
                reach_mm,
                before.speed_mm_s**2 / before.accel_mm_s2,
                lead_mm + OUTSIDE_LAG_MM,
            )
            if seg.x0_mm - reach_in_mm <= x <= seg.x0_mm + reach_mm:
                return True
        return False

    def _near_a_slow_junction(self, move: inc.VectorMove) -> bool:
        """True while the estimate is within a speed-up's reach past a junction the planner
        slows for (or just before one it brakes for)."""
        x = self._track.x_est_mm
        longest_mm = 2.0 * inc.stop_distance_mm(move.speed_mm_s, move.accel_mm_s2)
        for seg in reversed(self._track.path):
            # Twice the distance to reach the block's speed at its own acceleration: a slide
            # along an edge leaves the axes with the lowest acceleration.
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

    def _outside_stop(self, now_s: float, report: StatusReport, how: str) -> None:
        """Someone else stopped the jog: say so, sync, and wait for a new press."""
        pins = report.pins or ""
        if "H" in pins:
            who = "the controller's feed-hold input"
        elif "D" in pins:
            who = "the controller's door input"
        else:
            who = "a feed hold or jog cancel from outside smoothjog (a button, another program)"
        self._fault_now(
            now_s,
            f"the jog was stopped outside smoothjog: {how}; stopped by {who}",
            "release the stick (or key) and press it again to jog on",
        )
        # A stick still held must be pressed anew; one already let go (the stop under way is
        # the release's) has nothing to latch, and the next press simply jogs.
        self._await_press = self._intent is not None
        self._intent = None
        self._acted_intent = None
        self._cancel_ending = report.state == "Jog" and not self._jog_unbraked
        self._begin_stop(now_s)
        # The lines it had not yet run start again the moment that stop ends (firmware-facts
        # §3.1, §3.7): cut each one short as soon as a report shows it.
        self._stop.owe_cancel()

    def _note_pins(self, report: StatusReport, now_s: float) -> None:
        """Remember the inputs that read active at rest, and warn once about hold and door."""
        if report.state != "Idle" or self.phase is not Phase.IDLE:
            return
        self._rest_pins = report.pins or ""
        stuck = "".join(p for p in "HD" if p in self._rest_pins and p not in self._pins_warned)
        if stuck:
            self._pins_warned += stuck
            names = " and ".join(_PIN_NAMES[p] for p in stuck)
            self.events.append(
                EngineEvent(
                    now_s,
                    "info",
                    f"the controller reports its {names} input active while Idle"
                    f" (Pn:{report.pins})",
                    "Grbl acts only when an input changes, so jogging works; check the wiring"
                    " or the input's invert setting ($14)",
                )
            )

    def _pressed_inputs(self, report: StatusReport) -> str:
        """Hold or door inputs active now that were not active while the machine rested."""
        pins = report.pins or ""
        return " and ".join(_PIN_NAMES[p] for p in "HD" if p in pins and p not in self._rest_pins)

    def _status_urgent(self) -> bool:
        """A report is needed now: to end a stop, or a queue the estimate says has run out."""
        return self._fresh_status_wanted and (
            (self.phase is Phase.SETTLING and self._track.at_rest_at_end())
            or (self.phase is Phase.STOPPING and self._stop.phase is StopPhase.WAIT_STATUS)
        )

    def _poll_interval_s(self) -> float:
        if self._restart_s is not None:
            # Watching a restarted controller (restart_outputs): the engine writes no line until
            # the settings are read, so no reply of a new line needs the return wire's room (the
            # old lines' replies are what it waits for); one `?` at a time keeps reports from
            # piling up. At 9600 baud the usual share spaced them 150 ms apart, and a line that
            # ran after the reset's cancel went 13 mm.
            return OWED_POLL_S
        busy = self.phase is not Phase.IDLE or self.model.state not in (None, "Idle")
        interval_s = self.tuning.poll_moving_s if busy else self.tuning.poll_idle_s
        if self._cancel_owed or (
            self.phase is Phase.STOPPING
            and self._stop.phase in (StopPhase.WAIT_ACKS, StopPhase.WAIT_SYNC)
            and self._stop.owed
        ):
            # Lines left by a door, hold or reset may start the machine any moment (someone
            # else resumes it): look often, so the owed cancel comes within a block or two.
            interval_s = OWED_POLL_S
        # Reports must leave the return wire room for the replies: at 9600 baud a 50-byte
        # report takes 52 ms, so 20 Hz would fill it.
        report = self._last_report_bytes * self._byte_s / REPORT_SHARE
        return max(interval_s, report)

    def _status_due_s(self) -> float:
        """When the next routine status query is due."""
        return self._last_status_sent_s + self._poll_interval_s()

    def _poll_status(self, now_s: float, out: list[Output]) -> None:
        asked = self._status_asked_s
        if asked is not None and now_s - asked < self.tuning.status_timeout_s:
            return  # one `?` at a time: Grbl folds a second one into the first anyway (§5.2)
        if self._status_urgent() or now_s >= self._status_due_s():
            out.append(SendRealtime(STATUS_QUERY))
            self._status_asked_s = now_s
            self._last_status_sent_s = now_s
            # A `?` written behind the engine's own lines waits for them on the wire.
            self._status_backlog_s = max(self._wire_free_s - now_s, 0.0)
            self._wire_free_s = max(self._wire_free_s, now_s) + self._byte_s

    # ----------------------------------------------------------------- lines in flight
    # The engine's lines go into the host's ledger, which counts every owner's bytes against
    # the controller's RX buffer; the engine keeps its own entries to match replies to kinds.
    def _send(
        self, line: str, kind: str, now_s: float, out: list[Output], seg: PathSeg | None = None
    ) -> None:
        """Send a line and remember it until its ok/error."""
        in_flight_bytes = self.ledger.in_flight_bytes + line_cost_bytes(line)
        tag = _LineTag(kind, seg, now_s + in_flight_bytes * self._byte_s)
        self._wire_free_s = max(self._wire_free_s, now_s) + line_cost_bytes(line) * self._byte_s
        self._pending.append(self.ledger.record_line(ENGINE, line, now_s, tag))
        self.stats.lines_sent += 1
        if kind == "jog":
            self.stats.jogs_sent += 1
        out.append(SendLine(line))

    def _fits_rx(self, line: str) -> bool:
        """True when the line fits in the controller's RX buffer beside every owner's lines."""
        return self.ledger.fits(line)

    def _lines_unanswered(self) -> bool:
        """True while any line sent awaits its ok/error."""
        return bool(self._pending)

    def _jogs_unanswered(self) -> bool:
        """True while any jog line sent awaits its ok/error."""
        return any(_kind(e) == "jog" for e in self._pending)

    def _forget_pending(self) -> None:
        """Forget every line unanswered (the controller was reset and dropped them)."""
        self._pending.clear()

    # ----------------------------------------------------------------- bookkeeping

    def _may_jog(self) -> bool:
        return self.can_jog()[0]

    def can_jog(self) -> tuple[bool, str | None]:
        """Whether a jog may be sent now, and why not in words."""
        if self.model.jog_lock is not None:
            return False, self.model.jog_lock
        state = self.model.state
        if state is None:
            return False, "waiting for the controller's first status report"
        if state not in JOG_STATES:
            return False, _state_reason(state)
        # An unhomed machine (MPos 0,0,0 after $X) may jog: the envelope then lies where it was
        # switched on, and a machine on a limit switch must be jogged off it. The page warns.
        return True, None

    def _fault_now(self, now_s: float, text: str, hint: str, *, refusal: bool = False) -> None:
        """Show a fault. A refusal (a step or jog not sent) leaves the path already sent as
        it was; any other fault says why that path may no longer hold (see _finish_stop)."""
        self._fault = (text, hint)
        if not refusal:
            self._path_faulted = True
        self.events.append(EngineEvent(now_s, "fault", text, hint))

    # ----------------------------------------------------------------- views
    def stop_point_mm(self) -> Vec | None:
        """Where the machine would come to rest if the jog were released now."""
        mpos = self.model.mpos_mm
        if mpos is None:
            return None
        if not self._track.path:
            return tuple(mpos)
        return self._track.stop_point_mm()

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
            queued_mm=self._track.queued_mm(),
            queued_blocks=self._track.blocks_in_planner(),
            fault=self._fault,
        )

    def ask_status(self) -> None:
        """Someone saw the controller change: ask for a report at the next poll (while idle;
        a jog polls often enough by itself)."""
        if self.phase is Phase.IDLE:
            self._last_status_sent_s = -math.inf
            self._changed = True

    def clear_fault(self) -> None:
        """Forget the last fault (the user saw it)."""
        self._fault = None

    def _alarm_over(self) -> None:
        """A report shows the controller out of Alarm ($X, $H, a reset into Idle): the alarm's
        fault no longer holds, so it is not shown any more (a later fault stays)."""
        if self._fault is self._alarm_fault:
            self._fault = None
        self._alarm_fault = None


def _fmt(v: Sequence[float]) -> str:
    return ", ".join(f"{x:.3f}" for x in v)


def _kind(entry: Entry) -> str:
    """The kind of one of the engine's ledger entries."""
    tag = entry.tag
    return tag.kind if isinstance(tag, _LineTag) else ""
