"""What the engine is told: its tuning, the machine's limits, and the states a jog may start in."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from smoothjog.core.defaults import DEFAULT_STEP_IDLE_DELAY_MS
from smoothjog.core.firmware import for_model
from smoothjog.core.gcode import TravelBox
from smoothjog.core.machine import KeepOut, MachineModel
from smoothjog.core.responses import KNOWN_STATES
from smoothjog.core.states import SLEEP_TEXT
from smoothjog.core.units import Vec

#: Controller states in which a jog is accepted (firmware-facts §1.4).
JOG_STATES = frozenset({"Idle", "Jog"})

STATE_REASONS = {
    "Alarm": "the controller is in Alarm: unlock with $X or home with $H first",
    "Hold": "the controller is in feed hold: resume (~) or reset before jogging",
    "Door": "the safety door is open: close it and resume (~) before jogging",
    "Check": "the controller is in check mode ($C): leave it before jogging",
    "Run": "the controller is running a program: jogging waits until it is idle",
    "Home": "the controller is homing: jogging waits until it is done",
    "Sleep": SLEEP_TEXT,
}


def state_reason(state: str) -> str:
    """Why no jog goes in this state, in words."""
    reason = STATE_REASONS.get(state)
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
