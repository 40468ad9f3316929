"""What the engine hands out: its outputs, events, phase, counters, stop records and view."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

from smoothjog.core.units import Vec


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


class Phase(Enum):
    """What the engine is doing (only the phase machine, jogger.py, changes it)."""

    IDLE = "idle"
    JOGGING = "jogging"  # streaming continuous increments
    STEPPING = "stepping"  # step or go-to jogs queued
    STOPPING = "stopping"  # cancel handshake under way
    SETTLING = "settling"  # waiting for the machine to report rest after the queue ran out


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


class Notices:
    """The events told so far and the fault shown now: every part says things through it."""

    def __init__(self) -> None:
        """No events, no fault."""
        self.events: list[EngineEvent] = []
        self.fault: tuple[str, str] | None = None
        #: The fault an ALARM:N showed: it goes once a report shows the controller out of Alarm.
        self.alarm_fault: tuple[str, str] | None = None
        #: A fault other than a refusal came since the last stop (the stop-off-path sign).
        self.path_faulted = False

    def fault_now(self, now_s: float, text: str, hint: str, *, refusal: bool = False) -> None:
        """Show a fault. A refusal (a step or jog not sent) leaves the path already sent as
        it was; any other fault says why that path may no longer hold."""
        self.fault = (text, hint)
        if not refusal:
            self.path_faulted = True
        self.events.append(EngineEvent(now_s, "fault", text, hint))

    def info(self, now_s: float, text: str, hint: str = "") -> None:
        """Tell news that is no fault."""
        self.events.append(EngineEvent(now_s, "info", text, hint))
