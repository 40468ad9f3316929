"""Grbl 1.1h's serial protocol and state machine around the motion model, with time passed in.

The model follows the firmware's structure so its flaws come out the same (firmware-facts §1-§5):
- an ISR model takes each received byte at its arrival time: realtime bytes only set flags (or
  reset at once), every other byte goes to the RX ring, which drops bytes when full;
- a main-loop model reads lines from the ring, spends `line_time_s` parsing and planning each,
  blocks in "mc_line" while the planner is full, and runs the realtime checkpoint
  (protocol_execute_realtime) whenever the firmware would: while polling, while blocked for a
  planner slot, a buffer sync or a dwell, and inside the suspend loop (hold, door, jog cancel);
- the stepper ISR's step-idle delay ($1 ms) freezes the main loop after every cycle stop, and
  once more inside a jog cancel's st_reset (firmware-facts §3.1; the delay itself is from the code);
- a jog cancel does not flush the RX ring nor the line blocked in mc_line (firmware-facts §3.1);
  when its stop completes, the code that waited in the checkpoint carries on without another
  one, so a status request pending then is answered by the next checkpoint the firmware reaches
  (firmware-facts §3.7);
- lengths are computed as the firmware computes them, in 32-bit floats and whole steps (f32.py):
  the parser position, jog targets and the soft-limit test in singles, the machine position in
  steps, MPos and WPos converted back in singles (firmware-facts §1.5).

Nothing here reads a clock: `receive`, `advance` and the constructor take the time.
"""

from __future__ import annotations

import functools
import math
import re
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

from smoothjog.core.codes import (
    ALARM_ABORT_CYCLE,
    ALARM_HARD_LIMIT,
    ALARM_HOMING_FAIL_DOOR,
    ALARM_HOMING_FAIL_RESET,
    ALARM_SOFT_LIMIT,
    ERR_BAD_NUMBER_FORMAT,
    ERR_IDLE_ERROR,
    ERR_INVALID_STATEMENT,
    ERR_LINE_LENGTH_EXCEEDED,
    ERR_OVERFLOW,
    ERR_SETTING_DISABLED,
    ERR_SYSTEM_GC_LOCK,
    ERR_TRAVEL_EXCEEDED,
    STATUS_OK,
)
from smoothjog.core.firmware import BITS_PER_BYTE_8N1, DEFAULT_BAUD, JogClip
from smoothjog.core.gcode import (
    TLO_AXIS,
    ExecResult,
    ParserState,
    TravelBox,
    check_jog_dispatch,
    execute_block,
    gc_modes_report,
    preparse,
    read_number,
)
from smoothjog.core.realtime import EXTENDED_START, Realtime
from smoothjog.core.units import ALL_AXES
from smoothjog.sim.f32 import (
    MM_PER_INCH_F32,
    f32,
    lround,
    print_coord,
    read_float,
    steps_to_mm,
)
from smoothjog.sim.motion import CYCLE_STOP, AxisLimits, Motion, TraceSegment
from smoothjog.sim.profiles import (
    GRBL,
    FirmwareProfile,
    MachineProfile,
    load_machine_profile,
)
from smoothjog.sim.rxbuffer import RxRing, classify
from smoothjog.sim.settings import Eeprom, GrblSettings
from smoothjog.sim.status import StatusInputs, StatusReporter

Vec = tuple[float, ...]

# Speed: the comments marked "hot path" here and in motion.py / rig.py are optimisations that
# keep every result bit for bit (ground-truth traces and the bytes on the wire were compared
# before and after). Measured on `python -m bench sim` (the 60 s jog stream): under callgrind,
# which machine load does not disturb, 1768 M instructions before them and 1325 M after
# (x1.33) for sim/ as a whole; CPU time about 200 ms -> 175 ms; the bench's wall-clock figure,
# runs interleaved with the old code on the 2-core development machine, 169-187x -> 195-314x
# under heavy load (load average 3) and about 300x -> 340x under light load.

# Machine states, spelled as status reports print them.
IDLE = "Idle"
ALARM = "Alarm"
CHECK = "Check"
HOMING = "Home"
CYCLE = "Run"
HOLD = "Hold"
JOG = "Jog"
DOOR = "Door"
SLEEP = "Sleep"

# sys.suspend bits (system.h).
SUSPEND_HOLD_COMPLETE = 1 << 0
SUSPEND_RETRACT_COMPLETE = 1 << 2
SUSPEND_INITIATE_RESTORE = 1 << 3
SUSPEND_RESTORE_COMPLETE = 1 << 4
SUSPEND_SAFETY_DOOR_AJAR = 1 << 5
SUSPEND_MOTION_CANCEL = 1 << 6
SUSPEND_JOG_CANCEL = 1 << 7

# sys_rt_exec_state bits: requests from the ISRs to the main loop.
EXEC_STATUS_REPORT = 1 << 0
EXEC_CYCLE_START = 1 << 1
EXEC_CYCLE_STOP = 1 << 2
EXEC_FEED_HOLD = 1 << 3
EXEC_RESET = 1 << 4
EXEC_SAFETY_DOOR = 1 << 5
EXEC_MOTION_CANCEL = 1 << 6
EXEC_SLEEP = 1 << 7
_HOLD_GROUP = EXEC_MOTION_CANCEL | EXEC_FEED_HOLD | EXEC_SAFETY_DOOR | EXEC_SLEEP

#: `delay_sec` in a dwell sleeps in 50 ms steps (DWELL_TIME_STEP), so G4 P is rounded up to them.
DWELL_STEP_S = 0.050
#: Door resume waits for the spindle / coolant to come back (SAFETY_DOOR_*_DELAY).
SPINDLE_RESTORE_S = 4.0
COOLANT_RESTORE_S = 1.0
#: EEPROM_LINE_SIZE: a stored startup line holds at most this many characters.
STARTUP_LINE_CHARS = 80
#: A line the main loop keeps raw bytes of; beyond this the tail is dropped (only comments can
#: be this long, and the pre-parser flags overflow long before for anything else).
_RAW_LINE_CAP = 65536
_EPS_S = 1e-12

HELP_LINE = "[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]"

#: Feed and spindle override flags in the order protocol_exec_rt_system applies them: a reset to
#: 100 %, then each step; the sum is clamped to 10-200 % once, after all of them (firmware-facts
#: §5.2).
_FEED_STEPS: tuple[tuple[Realtime, int | None], ...] = (
    (Realtime.FEED_OVR_RESET, None),
    (Realtime.FEED_OVR_COARSE_PLUS, 10),
    (Realtime.FEED_OVR_COARSE_MINUS, -10),
    (Realtime.FEED_OVR_FINE_PLUS, 1),
    (Realtime.FEED_OVR_FINE_MINUS, -1),
)
_SPINDLE_STEPS: tuple[tuple[Realtime, int | None], ...] = (
    (Realtime.SPINDLE_OVR_RESET, None),
    (Realtime.SPINDLE_OVR_COARSE_PLUS, 10),
    (Realtime.SPINDLE_OVR_COARSE_MINUS, -10),
    (Realtime.SPINDLE_OVR_FINE_PLUS, 1),
    (Realtime.SPINDLE_OVR_FINE_MINUS, -1),
)
#: Rapid override flags in the order applied (the last one set wins).
_RAPID_STEPS: tuple[tuple[Realtime, int], ...] = (
    (Realtime.RAPID_OVR_RESET, 100),
    (Realtime.RAPID_OVR_MEDIUM, 50),
    (Realtime.RAPID_OVR_LOW, 25),
)


def _stepped(pct: int, flags: set[Realtime], steps: tuple[tuple[Realtime, int | None], ...]) -> int:
    """One override after the flags raised since the main loop last looked.

    The sum is a uint8_t in protocol.c, so it wraps before the clamp: at 10 %, -10 and -1
    together give 255 and so 200 %, as on the chip.
    """
    for flag, change in steps:
        if flag in flags:
            pct = 100 if change is None else (pct + change) & 0xFF
    return min(200, max(10, pct))


# ------------------------------------------------------------------------------------------
# The main loop's work list: what the line being executed still has to do, in order.


@dataclass
class _Busy:
    """The main loop computes (parse + plan) for dt_s; no checkpoint meanwhile."""

    dt_s: float
    until_s: float | None = None


@dataclass
class _Execute:
    """Dispatch one preparsed line (protocol_main_loop's if-chain)."""

    text: str
    overflow: bool


@dataclass
class _Plan:
    """mc_line: wait (checkpointing) for a planner slot, then queue the block."""

    target_mm: Vec
    feed_mm_min: float
    rapid: bool
    jog: bool
    dropped: bool = False


@dataclass
class _Sync:
    """protocol_buffer_synchronize: wait until the planner is empty and the cycle over."""


@dataclass
class _Dwell:
    """delay_sec in dwell mode: 50 ms steps, each starting with a checkpoint."""

    seconds: float
    end_s: float | None = None
    #: The next step's checkpoint (None once the last step is under way).
    check_s: float | None = None
    #: When a hold or door suspended the dwell inside a checkpoint (the steps wait meanwhile).
    paused_s: float | None = None
    #: A reset was seen at a checkpoint: the abort happens when this step's sleep ends.
    aborting_s: float | None = None


@dataclass
class _SoftLimit:
    """limits_soft_check failed for a G-code target: hold if moving, then reset + ALARM:2."""

    hold_requested: bool = False
    raised: bool = False


@dataclass
class _Home:
    """The homing cycle: runs the moves with no checkpoint except for reset."""

    started: bool = False
    final_steps: tuple[int, ...] = ()


@dataclass
class _Emit:
    """Send one line to the host."""

    text: str


@dataclass
class _Call:
    """Run a piece of the line's execution that needs the current time."""

    fn: Callable[[float], None]


_Step = _Busy | _Execute | _Plan | _Sync | _Dwell | _SoftLimit | _Home | _Emit | _Call
#: Steps during which the line has been parsed and is "inside" execution: a reset then still
#: gets that line's reply (the stray ok of firmware-facts §3.4).
_IN_EXECUTION = (_Plan, _Sync, _Dwell, _SoftLimit, _Home)
#: Steps that wait inside protocol_execute_realtime (a checkpoint before each look at them).
_AT_CHECKPOINT = (_Plan, _Sync, _Dwell, _SoftLimit)


@dataclass
class _Overrides:
    """Feed, rapid and spindle overrides in percent."""

    pct: list[int] = field(default_factory=lambda: [100, 100, 100])


class GrblFirmware:
    """A simulated Grbl-family controller: bytes in at a time, time-stamped lines out."""

    def __init__(
        self,
        firmware: FirmwareProfile = GRBL,
        machine: MachineProfile | str | None = None,
        *,
        eeprom: Eeprom | None = None,
        on_eeprom_write: Callable[[Eeprom], None] | None = None,
        now_s: float = 0.0,
        keep_trace: bool = True,
    ) -> None:
        """Power the controller up at now_s: banner, then Idle or Alarm (firmware-facts §2,
        §5.3). keep_trace False keeps no ground-truth segments (a machine that runs all day)."""
        if machine is None:
            machine = "grbl-defaults"
        if isinstance(machine, str):
            machine = load_machine_profile(machine)
        self.profile = firmware
        self.machine = machine
        self.n_axes = machine.n_axes
        self.on_eeprom_write = on_eeprom_write
        self.settings = GrblSettings(self.n_axes, firmware.extra_settings, firmware.word_settings)
        machine.apply(self.settings)
        coords: tuple[Vec, ...] | None = None
        g28: Vec | None = None
        g30: Vec | None = None
        self.startup_lines: list[str] = ["", ""]
        self.build_info = ""
        if eeprom is not None:
            for number, value in eeprom.settings.items():
                self.settings.force(number, value)
            coords, g28, g30 = eeprom.coord_systems_mm, eeprom.g28_mm, eeprom.g30_mm
            self.startup_lines = list(eeprom.startup_lines)
            self.build_info = eeprom.build_info
        self.motion = Motion(
            self._axis_limits(),
            junction_deviation_mm=self.settings[11],
            planner_blocks=firmware.facts.planner_usable_blocks,
        )
        self.motion.keep_trace = keep_trace
        self.parser = ParserState.initial(
            self.n_axes, coord_systems_mm=coords, g28_mm=g28, g30_mm=g30
        )
        self.rx = RxRing(firmware.facts.rx_buffer_bytes)
        #: Motion blocks planned from G-code lines, not jogs (a garbled jog line becomes one).
        self.gcode_blocks = 0
        self.reporter = StatusReporter()
        self.state = IDLE
        self.suspend = 0
        self._now_s = now_s
        self._rt = 0
        self._rt_alarm = 0
        self._exec_hold = False  # STEP_CONTROL_EXECUTE_HOLD
        self._soft_limit = False  # sys.soft_limit
        self._locked = False  # in the critical-alarm loop, waiting for a reset
        self._frozen_until_s = now_s
        self._after_freeze: Callable[[float], None] | None = None
        # A jog cancel's stop completed inside a checkpoint: the main loop returns to the code
        # that called it, which goes on without checking again (firmware-facts §3.7).
        self._resume_past_checkpoint = False
        self._steps: deque[_Step] = deque()
        self._line_buf = bytearray()
        self._held_line: bytes | None = None
        #: What each jog cancel threw away, for test benches (the firmware keeps no such
        #: record): (time the machine came to rest, steps of planned motion left unrun on the
        #: busiest axis, lines dropped unread since the cancel began). The firmware finishes
        #: the cancel $1 ms after that rest (firmware-facts §3.7); a bench compares the record
        #: with the rest it sees in the motion trace, so the rest is what it is stamped with.
        self.cancel_log: list[tuple[float, int, int]] = []
        self._ran_out_s = 0.0  # when the steppers last ran out (the stepper ISR's cycle stop)
        self._lines_dropped = 0
        self._overrides = _Overrides()
        # Override requests are flags, as in the firmware: one raised twice before the main loop
        # services it counts once (firmware-facts §5.2).
        self._pending_overrides: set[Realtime] = set()
        self._accessories_off = False  # spindle/coolant cut by a door or sleep
        self._restore_until_s: float | None = None
        self._sleep_reported = False
        self._output: list[tuple[float, bytes]] = []
        #: Time one output byte takes on the wire (the default baud, 8N1, unless the rig says
        #: otherwise), and when the UART will have sent everything queued so far.
        self.tx_byte_s = BITS_PER_BYTE_8N1 / DEFAULT_BAUD
        self._tx_done_s = 0.0
        #: A run of plain line bytes (line bytes other than a line end), for receive's fast path.
        plain = b"".join(
            re.escape(bytes((b,))) for b in range(256) if self.is_line_byte(b) and b not in b"\n\r"
        )
        self._plain_run = re.compile(b"[" + plain + b"]+" if plain else b"(?!)")
        #: Lines executed, in order, with their reply (for tests and debugging).
        self.lines_executed = 0
        self._power_up(now_s)

    # ------------------------------------------------------------------ public interface
    def receive(self, data: bytes, now_s: float) -> None:
        """Bytes arriving at the controller's UART at now_s (one ISR call per byte)."""
        self.advance(now_s)
        # Hot path (every received byte; with the rig's run hand-over and _main_loop_waiting,
        # 1418 M -> 1325 M instructions in bench sim): the fast path only appends to _line_buf,
        # which _polling_quietly does not look at, so a whole run of plain line bytes is taken
        # at once and the test is redone only after the slow path.
        line_buf = self._line_buf
        plain_run = self._plain_run.match
        quiet = self._polling_quietly()
        i, n = 0, len(data)
        while i < n:
            if quiet:
                match = plain_run(data, i)
                if match is not None:
                    # Fast path, same effect as ring + _poll: the idle main loop takes them at
                    # once (bytes beyond the raw-line cap are dropped, as one by one).
                    end = match.end()
                    room = _RAW_LINE_CAP - len(line_buf)
                    if room > 0:
                        line_buf += data[i : min(end, i + room)]
                    i = end
                    continue
            self._isr(data[i], now_s)
            self._service(now_s)
            quiet = self._polling_quietly()
            i += 1

    def is_line_byte(self, byte: int) -> bool:
        """True when byte goes to the RX ring (it is not a realtime command or discarded)."""
        return byte < EXTENDED_START and byte not in self.profile.realtime

    def _polling_quietly(self) -> bool:
        """The main loop sits in its reader with nothing pending: a byte is consumed at once."""
        return (
            not self._steps
            and self._held_line is None
            and not self._rt
            and not self.suspend
            and not self._locked
            and self._after_freeze is None
            and not self._resume_past_checkpoint
            and self._frozen_until_s <= self._now_s
            and not len(self.rx)
            and (self.state != IDLE or self.motion.planner_empty())
        )

    def advance(self, to_s: float) -> None:
        """Let time pass up to to_s, running every event on the way in time order."""
        if to_s < self._now_s:
            return
        self._advance_from(self._next_internal_s(), to_s, next_needed=False)

    def _advance_from(self, t: float | None, to_s: float, *, next_needed: bool) -> float | None:
        """advance(to_s) (not before the current time), given t = _next_internal_s().

        Returns _next_internal_s() afterwards when next_needed (else None).
        """
        stalled = 0
        settled = False
        at_s = self._now_s
        next_internal_s = self._next_internal_s
        while t is not None and t <= to_s:
            # An event at or before the current time must be consumed by running there once.
            stalled = stalled + 1 if t <= self._now_s else 0
            if stalled > 1000:
                raise RuntimeError(f"simulated firmware stuck at t={t} (a bug in the model)")
            at_s = max(t, self._now_s)
            # _run_at(at_s), remembering whether the main loop had nothing to do there.
            self._motion_to(at_s)
            self._now_s = at_s
            settled = self._main_loop_waiting(at_s)
            if not settled:
                self._service(at_s)
            t = next_internal_s()
        if settled and at_s == to_s:
            # Hot path (most events; 1295 M -> 1275 M instructions in bench sim): the last
            # event ran at to_s and only moved the motion there, so the closing
            # _motion_to(to_s) below would find nothing to do and t is still the next event.
            return t
        # Every event up to to_s has run; only the motion's interpolated position moves on.
        self._motion_to(to_s)
        self._now_s = to_s
        return next_internal_s() if next_needed else None

    def next_event_s(self) -> float | None:
        """When something will next happen on its own, or None if only input can change it."""
        return self._next_internal_s()

    def run_events(
        self, until_s: float, before_s: float | None = None, ratio: float = 1.0
    ) -> float | None:
        """Run the coming events one at a time, each as `advance(its time)` would.

        Events run while their time over ratio (the caller's clock, see SimRig's clock_ratio)
        is at most until_s and, if given, earlier than before_s. Returns the next event time
        (this clock), as next_event_s would. Hot path: the rig's loop over events happens here,
        with no look-up repeated between events (1325 M -> 1315 M instructions in bench sim).
        """
        next_internal_s = self._next_internal_s
        t = next_internal_s()
        while t is not None:
            caller_t = t / ratio
            if caller_t > until_s or (before_s is not None and caller_t >= before_s):
                break
            # advance(max(t, now)), which would first look up t again.
            t = self._advance_from(t, max(t, self._now_s), next_needed=True)
        return t

    def take_output(self) -> list[tuple[float, bytes]]:
        """The lines sent since the last call, each with its send time and `\\r\\n`."""
        out, self._output = self._output, []
        return out

    @property
    def now_s(self) -> float:
        """The time the firmware has been advanced to."""
        return self._now_s

    @property
    def trace(self) -> list[TraceSegment]:
        """Ground truth: every executed step segment with its times and end points."""
        return self.motion.trace

    def status_state(self) -> str:
        """The state as a status report would print it (`Hold:0`, `Door:1`, `Jog`...)."""
        sub = self._substate()
        return self.state if sub is None else f"{self.state}:{sub}"

    def mpos_mm(self) -> Vec:
        """Machine position from the step counters, steps / steps-per-mm in double (exact mm).

        For callers that measure; what the firmware itself computes from the counters (reports,
        gc_sync_position) is _mpos_single_mm.
        """
        steps = self.motion.position_steps()
        return tuple(s / self.settings[100 + i] for i, s in enumerate(steps))

    def wpos_mm(self) -> Vec:
        """Work position: MPos minus the work coordinate offset (exact mm, as mpos_mm)."""
        wco = self.parser.work_offset_mm
        return tuple(m - w for m, w in zip(self.mpos_mm(), wco, strict=True))

    def _mpos_single_mm(self) -> Vec:
        """system_convert_array_steps_to_mpos: the step counters in mm, in singles."""
        return tuple(
            [
                steps_to_mm(s, spm)
                for s, spm in zip(
                    self.motion.position_steps(), self.motion.steps_per_mm, strict=True
                )
            ]
        )

    def _wco_mm(self) -> Vec:
        """report_realtime_status's WCO: coord_system + coord_offset (+ TLO on Z), in singles."""
        p = self.parser
        wcs = p.coord_systems_mm[p.wcs_index]
        tlo = f32(p.tool_length_offset_mm)
        return tuple(
            f32(f32(f32(c) + f32(g)) + (tlo if i == TLO_AXIS else 0.0))
            for i, (c, g) in enumerate(zip(wcs, p.g92_offset_mm, strict=True))
        )

    def eeprom(self) -> Eeprom:
        """What this controller would keep over a power cycle."""
        return Eeprom(
            settings=self.settings.snapshot(),
            coord_systems_mm=self.parser.coord_systems_mm,
            g28_mm=self.parser.g28_mm,
            g30_mm=self.parser.g30_mm,
            startup_lines=(self.startup_lines[0], self.startup_lines[1]),
            build_info=self.build_info,
        )

    # ------------------------------------------------------------------ power-up and reset
    def _power_up(self, now_s: float) -> None:
        """main(): HOMING_INIT_LOCK puts a machine with $22=1 in Alarm at power-up only."""
        if self.machine.start == "homed":
            # Assumption (documented in the profile): start as if `$H` had just completed.
            self.motion.set_position_steps(self._homed_position_steps())
            self.state = IDLE
        elif self.settings.int_value(22):
            self.state = ALARM
        self.parser = self.parser.with_position(self._mpos_single_mm())
        self._reinit_delay(now_s)

    def _main_loop_start(self, now_s: float) -> None:
        """Start of protocol_main_loop: the unlock message in Alarm, else the startup lines."""
        if self.state in (ALARM, SLEEP):
            self._emit(now_s, "[MSG:'$H'|'$X' to unlock]")
            self.state = ALARM
        else:
            self.state = IDLE
            self._run_startup_lines(now_s)

    def _abort(self, now_s: float) -> None:
        """A soft reset reaches the main loop: stray reply, then re-initialise (firmware-facts
        §3.4)."""
        head = self._steps[0] if self._steps else None
        if isinstance(head, _IN_EXECUTION):
            # The line was inside mc_line / a sync / a dwell: it returns and gets its reply.
            self._emit(now_s, "ok")
        self._steps.clear()
        self._rt = 0
        self._rt_alarm = 0
        self.suspend = 0
        self._exec_hold = False
        self._soft_limit = False
        self._locked = False
        self._after_freeze = None
        self._resume_past_checkpoint = False
        self._restore_until_s = None
        self._sleep_reported = False
        self._accessories_off = False
        self._overrides = _Overrides()
        self._pending_overrides.clear()
        self.reporter.reset()
        self.rx.clear()
        self._line_buf.clear()
        self._held_line = None
        self._lines_dropped = 0
        self.motion.kill()
        self.motion.set_overrides(100, 100, now_s)  # sys.f_override and r_override back to 100
        self.parser = self.parser.after_reset().with_position(self._mpos_single_mm())
        self._reinit_delay(now_s)

    def _reinit_delay(self, now_s: float) -> None:
        """st_reset's st_go_idle holds the main loop for $1 ms before the banner.

        Assumption (code, not the facts): main() re-initialises the stepper subsystem on every
        power-up and reset, and st_go_idle waits the step-idle delay unless $1=255 (or the
        state before was Sleep), with no alarm pending any more at that point.
        """
        self._step_idle_delay(now_s)
        if self._frozen(now_s):
            self._after_freeze = self._banner
        else:
            self._banner(now_s)

    def _banner(self, now_s: float) -> None:
        """report_init_message, then the main loop starts."""
        self._emit(now_s, "")
        self._emit(now_s, self.profile.banner)
        self._main_loop_start(now_s)

    def _run_startup_lines(self, now_s: float) -> None:
        """system_execute_startup: each stored line runs and prints `>line:ok` or its error."""
        for line in self.startup_lines:
            if not line:
                continue
            res = execute_block(line, self.parser, jog=False, n_axes=self.n_axes)
            if res.ok:
                self.parser = _in_singles(res.state)
                if res.wco_changed:
                    self.reporter.force_wco()
                for motion in res.motions:
                    if self.motion.planner_free() > 0:
                        self.motion.plan_line(
                            _singles(motion.target_mm), motion.feed_mm_min, rapid=motion.rapid
                        )
            reply = "ok" if res.ok else f"error:{res.error}"
            self._emit(now_s, f">{line}:{reply}")

    # ------------------------------------------------------------------ the ISR model
    def _isr(self, byte: int, now_s: float) -> None:
        """serial.c's receive ISR: realtime bytes set flags, others go to the ring."""
        kind = classify(byte, self.profile.realtime)
        if kind is None:
            self.rx.push(byte)
            return
        if kind is Realtime.RESET:
            self._mc_reset(now_s)
        elif kind is Realtime.STATUS:
            self._rt |= EXEC_STATUS_REPORT
        elif kind is Realtime.CYCLE_START:
            self._rt |= EXEC_CYCLE_START
        elif kind is Realtime.FEED_HOLD:
            self._rt |= EXEC_FEED_HOLD
        elif kind is Realtime.SAFETY_DOOR:
            self._rt |= EXEC_SAFETY_DOOR
        elif kind is Realtime.JOG_CANCEL:
            if self.profile.facts.jog_cancel.flushes_rx:
                # grblHAL: the input buffer and a half-read line are dropped in any state (§7).
                self._lines_dropped += self.rx.line_ends() + bool(self._line_buf)
                self.rx.clear()
                self._line_buf.clear()
            # The state test happens here, at arrival, not when the flag is serviced (§3.1).
            if self.state == JOG:
                self._rt |= EXEC_MOTION_CANCEL
        elif kind is not Realtime.DISCARD:
            self._pending_overrides.add(kind)

    def _mc_reset(self, now_s: float) -> None:
        """mc_reset, run inside the ISR: kill motion now; ALARM:3 (6 when homing) if moving."""
        if self._rt & EXEC_RESET:
            return
        self._rt |= EXEC_RESET
        moving = self.state in (CYCLE, HOMING, JOG) or self.motion.is_running()
        if moving:
            self._rt_alarm = ALARM_HOMING_FAIL_RESET if self.state == HOMING else ALARM_ABORT_CYCLE
            self._motion_to(now_s)
            self.motion.kill()
            # st_go_idle, still inside the ISR: the step-idle delay (always, with an alarm set;
            # not while homing), so ALARM:3 comes $1 ms later (code, not the facts).
            self._step_idle_delay(now_s)

    # ------------------------------------------------------------------ time stepping
    def _next_internal_s(self) -> float | None:
        """The earliest time at which the motion or the main loop changes by itself."""
        # Hot path (several calls per event): a running minimum instead of a list and min();
        # like min(), a later candidate wins only when strictly earlier.
        best = self.motion.next_event_s()
        if self._frozen_until_s > self._now_s:
            frozen = self._frozen_until_s
            return frozen if best is None or frozen < best else best
        if self._steps:
            head = self._steps[0]
            due: float | None = None
            if isinstance(head, _Busy):
                due = head.until_s
            elif isinstance(head, _Dwell) and head.aborting_s is not None:
                due = head.aborting_s
            elif isinstance(head, _Dwell) and not self.suspend:
                due = head.check_s if head.check_s is not None else head.end_s
            if due is not None and (best is None or due < best):
                best = due
        restore = self._restore_until_s
        if restore is not None and (best is None or restore < best):
            best = restore
        return best

    def _run_at(self, t_s: float) -> None:
        """Advance the motion to t_s, then let the main loop run there."""
        self._motion_to(t_s)
        self._now_s = t_s
        if not self._main_loop_waiting(t_s):
            self._service(t_s)

    def _main_loop_waiting(self, now_s: float) -> bool:
        """True when one main-loop step at now_s would find nothing to do (and change nothing).

        Hot path (most events are the end of a step segment, while the main loop polls an empty
        RX ring or waits in mc_line for a planner slot; see the speed note at the top): those
        two waits with no flag raised are recognised here without going through _step_once.
        Anything else answers False and takes the full path, so this only ever skips a no-op.
        """
        if (
            self._rt
            or self._rt_alarm
            or self._pending_overrides
            or self.suspend
            or self._locked
            or self._after_freeze is not None
            or self._resume_past_checkpoint
            or self._frozen_until_s > now_s
        ):
            return False
        if self.state == IDLE and not self.motion.planner_empty():
            return False  # protocol_auto_cycle_start would act
        if not self._steps:
            return self._held_line is None and not len(self.rx)
        head = self._steps[0]
        return (
            isinstance(head, _Plan)
            and not head.dropped
            and self.state != CHECK
            and self.motion.planner_free() <= 0
        )

    def _motion_to(self, t_s: float) -> None:
        """Advance the motion; a cycle stop is the stepper ISR's st_go_idle + EXEC_CYCLE_STOP."""
        events = self.motion.advance(t_s)
        if not events:
            return
        for event_s, name in events:
            if name == CYCLE_STOP:
                self._rt |= EXEC_CYCLE_STOP
                self._ran_out_s = event_s
                self._step_idle_delay(event_s)

    def _step_idle_delay(self, t_s: float) -> None:
        """st_go_idle's delay of $1 ms, which keeps the main loop from running (firmware-facts
        §3.1)."""
        lock_ms = self.settings.int_value(1)
        if (lock_ms != 255 or self._rt_alarm or self.state == SLEEP) and self.state != HOMING:
            self._freeze(t_s, lock_ms / 1000.0)

    def _freeze(self, t_s: float, dt_s: float) -> None:
        """The main loop gets no CPU for dt_s from t_s (an ISR delay or a blocking pause)."""
        if dt_s <= 0.0:
            return
        start = max(self._frozen_until_s, t_s)
        self._frozen_until_s = start + dt_s
        head = self._steps[0] if self._steps else None
        if isinstance(head, _Busy) and head.until_s is not None and head.until_s > t_s:
            # The ISR steals the time from the line being parsed.
            head.until_s += dt_s

    def _service(self, now_s: float) -> None:
        """Run the main loop at now_s until it has to wait for time or input."""
        step_once = self._step_once
        for _ in range(100_000):
            if not step_once(now_s):
                return
        raise RuntimeError("simulated main loop made no progress (a bug in the model)")

    def _frozen(self, now_s: float) -> bool:
        """True while the main loop gets no CPU (an ISR delay, a blocking pause, a TX wait)."""
        return self._frozen_until_s > now_s + _EPS_S

    def _taken_over(self, head: _Step | None, now_s: float) -> bool:
        """After a checkpoint: True when a freeze, an abort or an alarm now decides what runs."""
        if self._after_freeze is not None or self._frozen(now_s) or self._locked:
            return True
        return head is not (self._steps[0] if self._steps else None)

    def _step_once(self, now_s: float) -> bool:
        """One unit of main-loop work at now_s; False when it must wait."""
        if self._frozen(now_s):
            return False
        if self._after_freeze is not None:
            fn, self._after_freeze = self._after_freeze, None
            fn(now_s)
            return True
        if self._locked:
            # The critical-alarm loop: nothing but a reset, not even status reports (§2).
            if self._rt & EXEC_RESET:
                self._abort(now_s)
                return True
            return False
        head = self._steps[0] if self._steps else None
        # Hot path: the usual heads (None: polling; _Plan: blocked in mc_line) skip the tests for
        # the steps that run without a checkpoint.
        if head is not None and not isinstance(head, _AT_CHECKPOINT):
            if isinstance(head, _Busy):
                if head.until_s is None:
                    head.until_s = now_s + head.dt_s
                if now_s + _EPS_S >= head.until_s:
                    self._steps.popleft()
                    return True
                return False
            if isinstance(head, _Execute):
                self._steps.popleft()
                self.lines_executed += 1
                self._steps.extendleft(reversed(self._execute_line(head, now_s)))
                return True
            if isinstance(head, _Emit):
                self._steps.popleft()
                self._emit(now_s, head.text)
                return True
            if isinstance(head, _Call):
                self._steps.popleft()
                head.fn(now_s)
                return True
            if isinstance(head, _Home):
                return self._homing_step(head, now_s)
        if isinstance(head, _Dwell):
            return self._dwell_step(head, now_s)
        # Everything else waits inside protocol_execute_realtime: a checkpoint first, unless this
        # is the return from the checkpoint in which a jog cancel's stop just completed.
        if self._resume_past_checkpoint:
            self._resume_past_checkpoint = False
            changed = True
        else:
            changed = self._checkpoint(now_s)
            if self._taken_over(head, now_s):
                return True
            if self.suspend:
                return changed
        if head is None:
            return self._poll(now_s) or changed
        if isinstance(head, _Plan):
            return self._plan_step(head, now_s) or changed
        if isinstance(head, _Sync):
            idle = self.motion.planner_empty() and not self.motion.is_running()
            if idle and self.state != CYCLE:
                self._steps.popleft()
                return True
            return self._auto_cycle_start() or changed
        if isinstance(head, _SoftLimit):
            return self._soft_limit_step(head, now_s) or changed
        raise AssertionError(f"unknown step {head!r}")

    def _dwell_step(self, head: _Dwell, now_s: float) -> bool:
        """delay_sec: ceil(P / 50 ms) steps, a checkpoint at the start of each, then a sleep.

        Realtime bytes that arrive during a step wait for the next step's checkpoint (a `?`
        can take up to 50 ms to be answered); `G4P0` has no step and so no checkpoint. A hold
        or door raised at a checkpoint suspends the dwell there until it is resumed.
        """
        if head.end_s is None:
            n_steps = max(math.ceil(head.seconds / DWELL_STEP_S - 1e-9), 0)
            head.end_s = now_s + n_steps * DWELL_STEP_S
            head.check_s = now_s if n_steps else None
        if head.aborting_s is not None:
            # A reset seen at a checkpoint only sets sys.abort: the step's 50 ms sleep still
            # runs, and delay_sec returns at the top of its next pass.
            if now_s + _EPS_S < head.aborting_s:
                return False
            self._checkpoint(now_s)
            return True
        if head.paused_s is None and (head.check_s is None or now_s + _EPS_S < head.check_s):
            if head.check_s is None and now_s + _EPS_S >= head.end_s:
                self._steps.popleft()
                return True
            return False  # asleep inside a step
        if self._rt & EXEC_RESET and not self._rt_alarm:
            head.aborting_s = now_s + DWELL_STEP_S
            return False
        changed = self._checkpoint(now_s)
        if self._taken_over(head, now_s):
            return True
        if self.suspend:
            if head.paused_s is None:
                head.paused_s = now_s
            return changed
        if head.paused_s is not None:
            # Resumed: the steps left run from here, as the sleep resumes after the suspend loop.
            shift = now_s - head.paused_s
            head.paused_s = None
            head.end_s += shift
            if head.check_s is not None:
                head.check_s += shift
        if head.check_s is not None and now_s + _EPS_S >= head.check_s:
            nxt = head.check_s + DWELL_STEP_S
            head.check_s = nxt if nxt < head.end_s - _EPS_S else None
        return True

    # ------------------------------------------------------------------ line reading
    def _poll(self, now_s: float) -> bool:
        """protocol_main_loop's reader: take bytes until a line end, then execute that line."""
        if self._held_line is not None:
            raw, self._held_line = self._held_line, None
            pre = preparse(raw, max_line_chars=self.profile.facts.max_line_chars)
            if pre.text and not pre.overflow:
                self._steps.append(_Busy(self.profile.line_time_s))
            self._steps.append(_Execute(pre.text, pre.overflow))
            return True
        while True:
            byte = self.rx.pop()
            if byte is None:
                break
            if byte in (0x0A, 0x0D):
                # The line is complete; the checkpoint at its EOL runs before it executes.
                self._held_line = bytes(self._line_buf)
                self._line_buf.clear()
                return True
            if len(self._line_buf) < _RAW_LINE_CAP:
                self._line_buf.append(byte)
        return self._auto_cycle_start()

    def _auto_cycle_start(self) -> bool:
        """protocol_auto_cycle_start: queued blocks start a cycle (only Idle reacts to it)."""
        if (
            self.state == IDLE
            and not self.motion.planner_empty()
            and not self._rt & EXEC_CYCLE_START
        ):
            self._rt |= EXEC_CYCLE_START
            return True
        return False

    # ------------------------------------------------------------------ the realtime checkpoint
    def _checkpoint(self, now_s: float) -> bool:
        """protocol_execute_realtime: service the flags, then one pass of the suspend loop."""
        # Hot path (every main-loop wait): with no flag raised protocol_exec_rt_system does nothing.
        raised = self._rt or self._rt_alarm or self._pending_overrides
        changed = self._rt_system(now_s) if raised else False
        if self._locked or self._after_freeze is not None or self._frozen(now_s):
            return True
        if self.suspend:
            changed = self._suspend_pass(now_s) or changed
        return changed

    def _rt_system(self, now_s: float) -> bool:
        """protocol_exec_rt_system: alarms, reset, status, holds, cycle start/stop, overrides."""
        if self._rt_alarm:
            code, self._rt_alarm = self._rt_alarm, 0
            self.state = ALARM
            self._emit(now_s, f"ALARM:{code}")
            if self.motion.is_running():
                # Only one race leaves the steppers running here: a reset struck during a jog
                # cancel's st_reset delay, and the line held in mc_line was planned and started
                # before this checkpoint saw the reset. report_alarm_message's 500 ms delay runs
                # in the main program, which alone refills the segment buffer (st_prep_buffer):
                # the steppers run what is prepared, then stop (firmware-facts §3.4).
                self.motion.starve()
            self._freeze(now_s, self.profile.alarm_pause_s)
            if code in (ALARM_HARD_LIMIT, ALARM_SOFT_LIMIT):
                self._after_freeze = self._enter_critical_lock
            return True
        flags = self._rt
        if flags & EXEC_RESET:
            self._abort(now_s)
            return True
        changed = False
        if flags & EXEC_STATUS_REPORT:
            self._rt &= ~EXEC_STATUS_REPORT
            self._emit(now_s, self._status_report())
            changed = True
        if flags & _HOLD_GROUP:
            self._hold_events(flags, now_s)
            self._rt &= ~_HOLD_GROUP
            changed = True
        if flags & EXEC_CYCLE_START:
            self._cycle_start(flags, now_s)
            self._rt &= ~EXEC_CYCLE_START
            changed = True
        if flags & EXEC_CYCLE_STOP:
            self._rt &= ~EXEC_CYCLE_STOP
            self._cycle_stop(now_s)
            changed = True
        if self._pending_overrides:
            self._apply_overrides(now_s)
            changed = True
        return changed

    def _enter_critical_lock(self, now_s: float) -> None:
        """After ALARM:1/2 and its pause: block everything until a new reset (§2)."""
        self._emit(now_s, "[MSG:Reset to continue]")
        self._rt &= ~EXEC_RESET
        self._locked = True

    def _hold_events(self, flags: int, now_s: float) -> None:
        """Motion cancel, feed hold, safety door and sleep, with Grbl's state rules (§3)."""
        if (
            not self.profile.facts.jog_cancel.feed_hold_cancels
            and self.state == JOG
            and not flags & (EXEC_MOTION_CANCEL | EXEC_SAFETY_DOOR | EXEC_SLEEP)
        ):
            return  # grblHAL ignores a feed hold while jogging (firmware-facts §7)
        if self.state not in (ALARM, CHECK):
            if self.state in (CYCLE, JOG) and not self.suspend & (
                SUSPEND_MOTION_CANCEL | SUSPEND_JOG_CANCEL
            ):
                self.motion.hold(now_s)
                self._exec_hold = True
                if self.state == JOG and not flags & EXEC_SLEEP:
                    # Any hold event in Jog is a jog cancel (§3.2, §3.3).
                    self.suspend |= SUSPEND_JOG_CANCEL
                    if self.profile.facts.jog_cancel.drops_blocked_jog:
                        self._drop_blocked_jog()
            if self.state == IDLE:
                # Not moving: the hold is complete at once; lines stop being read (§3.2). A
                # cancel whose flag was set in Jog but is serviced in Idle lands here too.
                self.suspend = SUSPEND_HOLD_COMPLETE
            if flags & EXEC_MOTION_CANCEL and self.state != JOG:
                self.suspend |= SUSPEND_MOTION_CANCEL
            if flags & EXEC_FEED_HOLD and self.state not in (DOOR, JOG, SLEEP):
                self.state = HOLD
            if flags & EXEC_SAFETY_DOOR:
                self._emit(now_s, "[MSG:Check Door]")
                if not self.suspend & SUSPEND_JOG_CANCEL and self.state != SLEEP:
                    self.state = DOOR
                self.suspend |= SUSPEND_SAFETY_DOOR_AJAR
        if flags & EXEC_SLEEP:
            if self.state == ALARM:
                self.suspend |= SUSPEND_RETRACT_COMPLETE | SUSPEND_HOLD_COMPLETE
            self.state = SLEEP

    def _drop_blocked_jog(self) -> None:
        """FluidNC's mc_cancel_jog: a jog waiting for a planner slot is dropped, answered ok."""
        head = self._steps[0] if self._steps else None
        if isinstance(head, _Plan) and head.jog:
            head.dropped = True
            self._lines_dropped += 1

    def _cycle_start(self, flags: int, now_s: float) -> None:
        """`~` and auto cycle start: resume a completed hold or door, start queued blocks."""
        if flags & (EXEC_FEED_HOLD | EXEC_MOTION_CANCEL | EXEC_SAFETY_DOOR):
            return  # a start at the same time as a hold request is ignored
        if self.state == DOOR and not self.suspend & SUSPEND_SAFETY_DOOR_AJAR:
            if self.suspend & SUSPEND_RESTORE_COMPLETE:
                self.state = IDLE
            elif self.suspend & SUSPEND_RETRACT_COMPLETE:
                self.suspend |= SUSPEND_INITIATE_RESTORE
        if self.state == IDLE or (self.state == HOLD and self.suspend & SUSPEND_HOLD_COMPLETE):
            self._exec_hold = False
            if not self.motion.planner_empty() and not self.suspend & SUSPEND_MOTION_CANCEL:
                self.suspend = 0
                self.state = CYCLE
                if self.motion.hold_complete():
                    self.motion.resume(now_s)
                else:
                    self.motion.start_cycle(now_s)
            else:
                self.suspend = 0
                self.state = IDLE
                if self.motion.hold_active():
                    self.motion.clear_after_stop()

    def _cycle_stop(self, now_s: float) -> None:
        """The steppers ran out: a hold is complete, or motion is over (jog cancel: flush)."""
        if (
            self.state in (HOLD, DOOR, SLEEP)
            and not self._soft_limit
            and not self.suspend & SUSPEND_JOG_CANCEL
        ):
            if self._exec_hold:
                self.suspend |= SUSPEND_HOLD_COMPLETE
            self._exec_hold = False
            return
        if self.suspend & SUSPEND_JOG_CANCEL:
            # plan_reset + st_reset + gc_sync_position + plan_sync_position. The blocked line
            # and the RX ring are left alone: that is the ghost jog of firmware-facts §3.1.
            self._exec_hold = False
            self.cancel_log.append(
                (self._ran_out_s, self.motion.unrun_steps(), self._lines_dropped)
            )
            self._lines_dropped = 0
            self.motion.clear_after_stop()
            self.parser = self.parser.with_position(self._mpos_single_mm())
            # st_reset calls st_go_idle once more: a second $1 delay, still in state Jog.
            self._step_idle_delay(now_s)
            self._after_freeze = self._finish_jog_cancel
            return
        self._finish_motion_complete(now_s)

    def _finish_jog_cancel(self, now_s: float) -> None:
        """After st_reset's delay: Idle (or Door), and the suspend loop returns to its caller.

        protocol_exec_rt_suspend leaves its loop in the same pass, and the code that called the
        checkpoint (mc_line, the line reader) goes on at once: mc_line plans the line it held,
        which jog_execute starts in Jog, before any checkpoint could answer a `?` that came
        during the delay (firmware-facts §3.7).
        """
        self._finish_motion_complete(now_s)
        if not self.suspend:
            self._resume_past_checkpoint = True

    def _finish_motion_complete(self, now_s: float) -> None:
        """End of a cycle: Idle, or Door when the door opened during a jog cancel."""
        del now_s
        if self.suspend & SUSPEND_SAFETY_DOOR_AJAR:
            self.suspend &= ~SUSPEND_JOG_CANCEL
            self.suspend |= SUSPEND_HOLD_COMPLETE
            self.state = DOOR
        else:
            self.suspend = 0
            self.state = IDLE

    def _suspend_pass(self, now_s: float) -> bool:
        """One pass of protocol_exec_rt_suspend (no parking: the default build)."""
        if not self.suspend & SUSPEND_HOLD_COMPLETE:
            return False
        if self.state not in (DOOR, SLEEP):
            return False
        if not self.suspend & SUSPEND_RETRACT_COMPLETE:
            self._accessories_off = True
            self.suspend |= SUSPEND_RETRACT_COMPLETE
            return True
        if self.state == SLEEP:
            if not self._sleep_reported:
                self._sleep_reported = True
                self._emit(now_s, "[MSG:Sleeping]")
                return True
            return False
        changed = False
        if self.suspend & SUSPEND_SAFETY_DOOR_AJAR:
            # No door pin in the simulator: the door reads closed at once (Door:1 -> Door:0).
            self.suspend &= ~SUSPEND_SAFETY_DOOR_AJAR
            changed = True
        if self.suspend & SUSPEND_INITIATE_RESTORE and not self.suspend & SUSPEND_RESTORE_COMPLETE:
            if self._restore_until_s is None:
                delay_s = SPINDLE_RESTORE_S if self.parser.spindle != "M5" else 0.0
                if self.parser.coolant_flood or self.parser.coolant_mist:
                    delay_s += COOLANT_RESTORE_S
                self._restore_until_s = now_s + delay_s
                changed = True
            if now_s + _EPS_S >= self._restore_until_s:
                self._restore_until_s = None
                self._accessories_off = False
                self.suspend |= SUSPEND_RESTORE_COMPLETE
                self._rt |= EXEC_CYCLE_START
                changed = True
        return changed

    def _apply_overrides(self, now_s: float) -> None:
        """Service the override and accessory flags raised since the last checkpoint.

        Feed and rapid changes re-plan the queued blocks (jogs keep their speed, firmware-facts
        §4.2); Ov: is forced into the next report only when a value or the coolant really changed.
        """
        flags = self._pending_overrides
        pct = self._overrides.pct
        feed = _stepped(pct[0], flags, _FEED_STEPS)
        rapid = pct[1]
        for flag, value in _RAPID_STEPS:
            if flag in flags:
                rapid = value
        spindle = _stepped(pct[2], flags, _SPINDLE_STEPS)
        changed = False
        if (feed, rapid) != (pct[0], pct[1]):
            pct[0], pct[1] = feed, rapid
            self.motion.set_overrides(feed, rapid, now_s)
            changed = True
        if spindle != pct[2]:
            pct[2] = spindle
            changed = True
        if Realtime.FLOOD_TOGGLE in flags and self.state in (IDLE, CYCLE, HOLD, JOG):
            self.parser = replace(self.parser, coolant_flood=not self.parser.coolant_flood)
            changed = True
        # Mist needs ENABLE_M7 (off by default) and the spindle-stop toggle needs a running
        # spindle in Hold; neither changes what a jog host sees, so both are ignored.
        flags.clear()
        if changed:
            self.reporter.force_ovr()

    # ------------------------------------------------------------------ reports
    def _substate(self) -> int | None:
        """The number after `Hold:` / `Door:`."""
        if self.state == HOLD:
            return 0 if self.suspend & SUSPEND_HOLD_COMPLETE else 1
        if self.state == DOOR:
            if self.suspend & SUSPEND_INITIATE_RESTORE:
                return 3
            if self.suspend & SUSPEND_RETRACT_COMPLETE:
                return 1 if self.suspend & SUSPEND_SAFETY_DOOR_AJAR else 0
            return 2
        return None

    def _status_report(self) -> str:
        """report_realtime_status for the current instant."""
        p = self.parser
        spindle_on = p.spindle != "M5" and not self._accessories_off
        accessories = ""
        if spindle_on:
            accessories += "S" if p.spindle == "M3" else "C"
        if not self._accessories_off:
            accessories += ("F" if p.coolant_flood else "") + ("M" if p.coolant_mist else "")
        inputs = StatusInputs(
            state=self.state,
            substate=self._substate(),
            mpos_mm=self._mpos_single_mm(),
            wco_mm=self._wco_mm(),
            planner_free=self.motion.planner_free(),
            rx_free=self.rx.free(),
            feed_mm_min=self.motion.realtime_rate_mm_min(),
            spindle_rpm=p.spindle_speed_rpm if spindle_on else 0.0,
            overrides_pct=(
                self._overrides.pct[0],
                self._overrides.pct[1],
                self._overrides.pct[2],
            ),
            accessories=accessories,
        )
        return self.reporter.build(
            inputs,
            status_mask=self.settings.int_value(10),
            inches=bool(self.settings.int_value(13)),
        )

    def _emit(self, now_s: float, text: str) -> None:
        """Queue one line to the host; if the TX ring cannot take it all, the main loop waits.

        serial_write busy-waits for room (firmware-facts §5.1): the main loop is free again once the
        last byte is in the ring, i.e. when no more than the TX buffer's bytes are left to send.
        """
        data = text.encode("ascii") + b"\r\n"
        self._output.append((now_s, data))
        byte_s = self.tx_byte_s
        self._tx_done_s = max(self._tx_done_s, now_s) + len(data) * byte_s
        free_at = self._tx_done_s - self.profile.facts.tx_buffer_bytes * byte_s
        if free_at > self._frozen_until_s and free_at > now_s + _EPS_S:
            self._frozen_until_s = free_at

    # ------------------------------------------------------------------ line execution
    def _execute_line(self, step: _Execute, now_s: float) -> list[_Step]:
        """protocol_main_loop's dispatch of one complete line; returns the work it starts."""
        text = step.text
        if step.overflow:
            return [_Emit(f"error:{ERR_OVERFLOW}")]
        if not text:
            return [_Emit("ok")]
        if text[0] == "$":
            return self._system_line(text, now_s)
        if self.state in (ALARM, JOG):
            return [_Emit(f"error:{ERR_SYSTEM_GC_LOCK}")]
        return self._gcode_line(text)

    def _envelope(self) -> TravelBox | None:
        """The soft-limit box when $20=1: -$13x <= target <= 0 on every axis (firmware-facts §2).

        The bounds are singles (settings.max_travel is a float stored negated), so a single
        target tests as system_check_travel_limits tests it. The sim has no
        HOMING_FORCE_SET_ORIGIN build, whose box runs 0..+$13x on axes homing to -.
        """
        if not self.settings.int_value(20):
            return None
        travel = [f32(self.settings[130 + i]) for i in range(self.n_axes)]
        return TravelBox(tuple(-t for t in travel), tuple(0.0 for _ in travel))

    def _gcode_line(self, text: str) -> list[_Step]:
        """A plain G-code line: parse, then the sync / dwell / motions it asks for, then ok."""
        res = execute_block(
            text,
            self.parser,
            jog=False,
            envelope=self._envelope(),
            n_axes=self.n_axes,
            arc_tolerance_mm=self.settings[12],
        )
        if not res.ok:
            return [_Emit(f"error:{res.error}")]
        before = self.parser
        self.parser = _in_singles(res.state)
        stored = (before.coord_systems_mm, before.g28_mm, before.g30_mm)
        if stored != (res.state.coord_systems_mm, res.state.g28_mm, res.state.g30_mm):
            self._eeprom_written()  # G10, G28.1 and G30.1 write EEPROM
        return [*self._gcode_actions(res), _Emit("ok")]

    def _gcode_actions(self, res: ExecResult) -> list[_Step]:
        """The execution body of one accepted G-code block, in the firmware's order."""
        steps: list[_Step] = []
        check = self.state == CHECK
        if res.dwell_s is not None and not check:
            steps += [_Sync(), _Dwell(res.dwell_s)]
        if res.wco_changed:
            # FORCE_BUFFER_SYNC_DURING_WCO_CHANGE is on in the default build.
            steps += [_Sync(), _Call(lambda _t: self.reporter.force_wco())]
        if res.spindle_changed or res.coolant_changed:
            steps.append(_Call(lambda _t: self.reporter.force_ovr()))
        if not check:
            steps += [
                _Plan(_singles(m.target_mm), m.feed_mm_min, m.rapid, jog=False) for m in res.motions
            ]
        if res.soft_limit_violation:
            steps.append(_SoftLimit())
            return steps
        if res.program_flow == "M0" and not check:
            steps += [_Sync(), _Call(self._program_pause)]
        elif res.program_end:
            steps += [_Sync(), _Emit("[MSG:Pgm End]")]
        return steps

    def _program_pause(self, now_s: float) -> None:
        """M0: a feed hold once the buffer is synced."""
        del now_s
        self._rt |= EXEC_FEED_HOLD

    def _jog_line(self, text: str) -> list[_Step]:
        """`$J=`: parse as a jog, check the travel, queue it; Idle starts Jog at once (§1.4)."""
        res = execute_block(text, self.parser, jog=True, envelope=None, n_axes=self.n_axes)
        if not res.ok or res.motion is None:
            return [_Emit(f"error:{res.error}")]
        # core's parser decides whether the line is valid; the target is recomputed here in the
        # firmware's single precision, so a G91 stream accumulates as on the chip.
        target = self._jog_target(text)
        box = self._envelope()
        # jog_execute -> system_check_travel_limits: single target against single bounds.
        if box is not None and not box.contains(target):
            clip = self.profile.facts.jog_clip
            if clip is JogClip.CLIP_PER_AXIS:
                target = _singles(_clip_per_axis(target, box))
            elif clip is JogClip.CLIP_IF_40 and self.settings.int_value(40):
                target = _singles(_clip_along_line(self.parser.position_mm, target, box))
            else:
                return [_Emit(f"error:{ERR_TRAVEL_EXCEEDED}")]
        # The parser position moves only once mc_line returns (gc_execute_line copies the target
        # after jog_execute), so a cancel's gc_sync_position during a blocked jog is overwritten
        # by that jog's target: the ghost jog of firmware-facts §3.1 ends exactly where the queue
        # would.
        return [_Plan(target, res.motion.feed_mm_min, rapid=False, jog=True), _Emit("ok")]

    def _jog_target(self, text: str) -> Vec:
        """gc_execute_line's target for an accepted `$J=` line, computed in singles.

        The values are read by read_float; G20 multiplies them by MM_PER_INCH; G91 adds the parser
        position, G90 the work offset (coord system + G92, then TLO on Z), G53 takes them as they
        are; an axis not named keeps the parser position, and a line with no axis word targets
        machine zero (STEP 3 [12] and [19], firmware-facts §1.3, §1.5). Each sum is rounded to a
        single, as storing it in gc_block.values.xyz does.
        """
        p = self.parser
        words = _jog_words(text, self.n_axes)
        if not words.values:
            return (0.0,) * self.n_axes
        inches = p.units == "G20" if words.inches is None else words.inches
        incremental = p.distance == "G91" if words.incremental is None else words.incremental
        machine_frame = words.machine_frame
        wcs = p.coord_systems_mm[p.wcs_index]
        target = list(p.position_mm)
        for axis, value in words.values:
            v = f32(value * MM_PER_INCH_F32) if inches else value
            if machine_frame:
                target[axis] = v
            elif incremental:
                target[axis] = f32(v + p.position_mm[axis])
            else:
                t = f32(v + f32(f32(wcs[axis]) + f32(p.g92_offset_mm[axis])))
                if axis == TLO_AXIS:
                    t = f32(t + f32(p.tool_length_offset_mm))
                target[axis] = t
        return tuple(target)

    def _plan_step(self, step: _Plan, now_s: float) -> bool:
        """mc_line's wait for a free block, then plan_buffer_line (and jog_execute's start)."""
        if step.dropped:
            self._steps.popleft()
            return True
        if self.state == CHECK:
            self._steps.popleft()  # mc_line returns at once in check mode
            return True
        if self.motion.planner_free() <= 0:
            return self._auto_cycle_start()
        self.motion.plan_line(
            step.target_mm, step.feed_mm_min, rapid=step.rapid, feed_override=not step.jog
        )
        self.gcode_blocks += not step.jog
        self._steps.popleft()
        if step.jog:
            if self.state == IDLE and not self.motion.planner_empty():
                self.state = JOG
                self.motion.start_cycle(now_s)
            self.parser = self.parser.with_position(step.target_mm)
        return True

    def _soft_limit_step(self, step: _SoftLimit, now_s: float) -> bool:
        """limits_soft_check: stop a running cycle first, then reset with ALARM:2."""
        del now_s
        if step.raised:
            return False
        if self.state == CYCLE and not step.hold_requested:
            step.hold_requested = True
            self._soft_limit = True
            self._rt |= EXEC_FEED_HOLD
            return True
        if step.hold_requested and self.state != IDLE:
            return False
        step.raised = True
        self._rt |= EXEC_RESET
        self._rt_alarm = ALARM_SOFT_LIMIT
        return True

    # ------------------------------------------------------------------ `$` commands
    def _system_line(self, text: str, now_s: float) -> list[_Step]:
        """system_execute_line: the `$` commands with their state rules (§1.4, §5.3)."""
        if text == "$":
            return [_Emit(HELP_LINE), _Emit("ok")]
        cmd = text[1]
        if cmd == "J":
            err = check_jog_dispatch(text, self.state)
            if err is not None:
                return [_Emit(f"error:{err}")]
            return self._jog_line(text)
        if cmd in "$GCX":
            if len(text) != 2:
                return self._reply(ERR_INVALID_STATEMENT)
            if cmd == "$":
                if self.state in (CYCLE, HOLD):
                    return self._reply(ERR_IDLE_ERROR)
                return [*(_Emit(line) for line in self.settings.dollar_lines()), _Emit("ok")]
            if cmd == "G":
                inches = bool(self.settings.int_value(13))
                return [_Emit(gc_modes_report(self.parser, inches)), _Emit("ok")]
            if cmd == "C":
                if self.state == CHECK:
                    self._mc_reset(now_s)
                    return [_Emit("[MSG:Disabled]"), _Emit("ok")]
                if self.state != IDLE:
                    return self._reply(ERR_IDLE_ERROR)
                self.state = CHECK
                return [_Emit("[MSG:Enabled]"), _Emit("ok")]
            if self.state == ALARM:  # $X
                self.state = IDLE
                return [_Emit("[MSG:Caution: Unlocked]"), _Emit("ok")]
            return [_Emit("ok")]
        if self.state not in (IDLE, ALARM):
            return self._reply(ERR_IDLE_ERROR)
        if cmd == "#":
            if len(text) != 2:
                return self._reply(ERR_INVALID_STATEMENT)
            return [*(_Emit(line) for line in self._parameter_lines()), _Emit("ok")]
        if cmd == "H":
            if not self.settings.int_value(22):
                return self._reply(ERR_SETTING_DISABLED)
            if len(text) != 2:
                return self._reply(ERR_INVALID_STATEMENT)
            return [_Home(), _Emit("ok")]
        if cmd == "S":
            if text != "$SLP":
                return self._reply(ERR_INVALID_STATEMENT)
            self._rt |= EXEC_SLEEP
            return [_Emit("ok")]
        if cmd == "I":
            if len(text) == 2:
                return [
                    _Emit(self.profile.version_line.format(user=self.build_info)),
                    _Emit(self.profile.options_line),
                    _Emit("ok"),
                ]
            if text[2] != "=":
                return self._reply(ERR_INVALID_STATEMENT)
            self.build_info = text[3:]
            self._eeprom_written()
            return [_Emit("ok")]
        if cmd == "R":
            return self._restore(text, now_s)
        if cmd == "N" and len(text) == 2:
            lines = [_Emit(f"$N{i}={line}") for i, line in enumerate(self.startup_lines)]
            return [*lines, _Emit("ok")]
        return self._store_line(text)

    def _reply(self, code: int) -> list[_Step]:
        """A single `error:N` reply (or ok for 0)."""
        return [_Emit("ok" if code == STATUS_OK else f"error:{code}")]

    def _restore(self, text: str, now_s: float) -> list[_Step]:
        """`$RST=$`, `$RST=#`, `$RST=*`: restore EEPROM data, then a soft reset."""
        if len(text) != 6 or not text.startswith("$RST=") or text[5] not in "$#*":
            return self._reply(ERR_INVALID_STATEMENT)
        which = text[5]
        if which in "$*":
            fresh = GrblSettings(
                self.n_axes, self.profile.extra_settings, self.profile.word_settings
            )
            for number, value in fresh.items():
                self.settings.force(number, value)
            self._reconfigure_motion()
        if which in "#*":
            zero = (0.0,) * self.n_axes
            self.parser = replace(
                self.parser,
                coord_systems_mm=tuple(zero for _ in range(6)),
                g28_mm=zero,
                g30_mm=zero,
            )
        if which == "*":
            self.startup_lines = ["", ""]
        self._eeprom_written()
        self._mc_reset(now_s)
        return [_Emit("[MSG:Restoring defaults]"), _Emit("ok")]

    def _store_line(self, text: str) -> list[_Step]:
        """`$Nx=line` and `$x=val` (firmware-facts §2 rules for $20/$22 live in
        GrblSettings.store)."""
        startup = text[1] == "N"
        start = 2 if startup else 1
        if startup and self.state != IDLE:
            return self._reply(ERR_IDLE_ERROR)
        number = read_number(text, start)
        if number is None:
            return self._reply(ERR_BAD_NUMBER_FORMAT)
        parameter, index = number
        if index >= len(text) or text[index] != "=":
            return self._reply(ERR_INVALID_STATEMENT)
        rest = text[index + 1 :]
        if startup:
            if len(rest) + 1 > STARTUP_LINE_CHARS:
                return self._reply(ERR_LINE_LENGTH_EXCEEDED)
            # Assumption: the line is checked by parsing it against a copy of the parser state;
            # Grbl executes it for real, which only matters for lines that move.
            res = execute_block(rest, self.parser, jog=False, n_axes=self.n_axes)
            if not res.ok:
                return self._reply(res.error)
            slot = math.trunc(parameter)
            if 0 <= slot < len(self.startup_lines):
                self.startup_lines[slot] = rest
                self._eeprom_written()
            return [_Emit("ok")]
        # settings_store_global_setting gets the value as read_float read it: a single.
        value = read_float(rest, 0)
        if value is None:
            return self._reply(ERR_BAD_NUMBER_FORMAT)
        if value[1] != len(rest) or parameter > 255:
            return self._reply(ERR_INVALID_STATEMENT)
        setting = math.trunc(parameter)
        before = self.settings.snapshot()
        code = self.settings.store(setting, value[0])
        if code == STATUS_OK:
            if setting == 13 and before[13] != self.settings[13]:
                self.reporter.force_wco()
            if setting == 11 or setting >= 100:
                self._reconfigure_motion()
            self._eeprom_written()
        return self._reply(code)

    def _parameter_lines(self) -> list[str]:
        """`$#`: the stored offsets, G92, TLO and the last probe (never probed: zeros)."""
        inches = bool(self.settings.int_value(13))

        def fmt(v: float) -> str:
            return print_coord(f32(v), inches)

        def axes(values: Sequence[float]) -> str:
            return ",".join(fmt(v) for v in values)

        p = self.parser
        lines = [f"[G{54 + i}:{axes(c)}]" for i, c in enumerate(p.coord_systems_mm)]
        lines += [f"[G28:{axes(p.g28_mm)}]", f"[G30:{axes(p.g30_mm)}]"]
        lines += [f"[G92:{axes(p.g92_offset_mm)}]", f"[TLO:{fmt(p.tool_length_offset_mm)}]"]
        lines.append(f"[PRB:{axes((0.0,) * self.n_axes)}:0]")
        return lines

    def _eeprom_written(self) -> None:
        """Tell the owner (e.g. `smoothjog sim --settings FILE`) that EEPROM data changed."""
        if self.on_eeprom_write is not None:
            self.on_eeprom_write(self.eeprom())

    def _axis_limits(self) -> list[AxisLimits]:
        """Motion limits from $100-$122; zeros are raised to a tiny value the planner accepts."""
        limits = []
        for i in range(self.n_axes):
            axis = self.settings.axis(i)
            # Assumption: Grbl accepts 0 here and then divides by it; the model keeps running.
            limits.append(
                AxisLimits(
                    steps_per_mm=max(axis.steps_per_mm, 1e-3),
                    max_rate_mm_min=max(axis.max_rate_mm_min, 1e-3),
                    accel_mm_s2=max(axis.accel_mm_s2, 1e-3),
                )
            )
        return limits

    def _reconfigure_motion(self) -> None:
        """New $1xx or $11 values reach the planner (only set in Idle/Alarm, so nothing moves)."""
        self.motion.reconfigure(self._axis_limits(), self.settings[11])

    # ------------------------------------------------------------------ homing
    def _homed_position_steps(self) -> tuple[int, ...]:
        """sys_position after homing: -$27 for an axis homing to +, -$13x + $27 for one homing to -.

        limits_go_home rounds lround((max_travel + pull-off) x steps/mm), or lround(-pull-off x
        steps/mm), in singles; max_travel is stored negated.
        """
        pull_off = f32(self.settings[27])
        direction_mask = self.settings.int_value(23)
        steps = []
        for i, spm in enumerate(self.motion.steps_per_mm):
            if direction_mask >> i & 1:
                corner = f32(-f32(self.settings[130 + i]) + pull_off)
            else:
                corner = -pull_off
            steps.append(lround(f32(corner * spm)))
        return tuple(steps)

    def _homing_step(self, step: _Home, now_s: float) -> bool:
        """`$H`: Z then X/Y seek their switch corner at $25, then pull off at $24 (§2).

        Assumption: the switches sit at the corner of the current machine frame (MPos 0 for an
        axis homing to +, -$13x for one homing to -), so homing sets the same MPos Grbl would.
        The seek, locate and second pull-off of the real cycle are folded into one seek and one
        pull-off. No status report is made meanwhile, as on the chip (grblHAL makes them when
        `$10` asks, see _homing_report); a `?` asked during the cycle is answered as it ends,
        still in Home, with the homed position (mc_homing_cycle's protocol_execute_realtime).
        """
        if not step.started:
            step.started = True
            self.state = HOMING
            step.final_steps = self._homed_position_steps()
            final = tuple(
                steps_to_mm(n, spm)
                for n, spm in zip(step.final_steps, self.motion.steps_per_mm, strict=True)
            )
            mask = self.settings.int_value(23)
            switch = tuple(
                -self.settings[130 + i] if mask >> i & 1 else 0.0 for i in range(self.n_axes)
            )
            pos = list(self.motion.planner_position_mm())
            cycles = [[2], [i for i in range(self.n_axes) if i != 2]]
            for axes in cycles:
                seek = list(pos)
                for i in axes:
                    seek[i] = switch[i]
                self.motion.plan_line(seek, self.settings[25], feed_override=False)
                pull = list(seek)
                for i in axes:
                    pull[i] = final[i]
                self.motion.plan_line(pull, self.settings[24], feed_override=False)
                pos = pull
            self.motion.start_cycle(now_s)
            return True
        if self._rt & EXEC_SAFETY_DOOR and not self._rt & EXEC_RESET:
            # limits_go_home watches the door as well as reset: ALARM:7, then the reset that
            # mc_reset starts (the door flag dies with the re-initialisation; firmware-facts §5.6).
            self._mc_reset(now_s)
            self._rt_alarm = ALARM_HOMING_FAIL_DOOR
        if self._rt & EXEC_RESET:
            self._checkpoint(now_s)
            return True
        if self.motion.is_running() or not self.motion.planner_empty():
            return self._homing_report(now_s, during=True)
        self.motion.set_position_steps(step.final_steps)
        self.parser = self.parser.with_position(self._mpos_single_mm())
        self._rt &= ~EXEC_CYCLE_STOP
        self._homing_report(now_s, during=False)
        self._steps.popleft()
        self.state = IDLE
        self._step_idle_delay(now_s)
        self._steps.appendleft(_Call(self._run_startup_lines))
        return True

    def _homing_report(self, now_s: float, *, during: bool) -> bool:
        """Answer a pending `?` in Home: as the cycle ends (any firmware), or during it where
        `$10` asks for that (grblHAL's when_homing bit, limits.c's homing loop); True if made."""
        if not self._rt & EXEC_STATUS_REPORT:
            return False
        bit = self.profile.homing_report_bit
        if during and (bit is None or not self.settings.int_value(10) >> bit & 1):
            return False
        self._rt &= ~EXEC_STATUS_REPORT
        self._emit(now_s, self._status_report())
        return True


@dataclass(frozen=True)
class _JogWords:
    """What an accepted `$J=` line names: units and distance mode (None: modal), G53, axes."""

    inches: bool | None
    incremental: bool | None
    machine_frame: bool
    #: (axis index, value as read_float reads it), in the order of the line.
    values: tuple[tuple[int, float], ...]


@functools.lru_cache(maxsize=256)
def _jog_words(text: str, n_axes: int) -> _JogWords:
    """Read the words of an accepted `$J=` line with read_float (only G20/21, G90/91, G53, N, F
    and axis words can be in one).

    Cached: a held jog sends the same line about a hundred times a second.
    """
    letters = ALL_AXES[:n_axes]
    inches: bool | None = None
    incremental: bool | None = None
    machine_frame = False
    values: dict[int, float] = {}
    i, end = 3, len(text)  # after "$J="
    while i < end:
        letter = text[i]
        number = read_float(text, i + 1)
        if number is None:
            break  # not reached: core's parser accepted the line
        value, i = number
        if letter == "G":
            code = math.trunc(value)
            if code in (20, 21):
                inches = code == 20
            elif code in (90, 91):
                incremental = code == 91
            elif code == 53:
                machine_frame = True
        elif letter in letters:
            values[letters.index(letter)] = value
    return _JogWords(inches, incremental, machine_frame, tuple(values.items()))


def _singles(values_mm: Vec) -> Vec:
    """Each value rounded to a single, as the firmware stores a computed float."""
    return tuple([f32(v) for v in values_mm])


def _in_singles(state: ParserState) -> ParserState:
    """A state from core's parser (doubles) with its position held as the firmware's singles.

    Approximation: plain G-code targets are computed by core in doubles and only then rounded,
    so they can be an ulp from the chip's; jog targets are computed in singles (_jog_target).
    """
    return state.with_position(_singles(state.position_mm))


def _clip_per_axis(target_mm: Vec, box: TravelBox) -> Vec:
    """FluidNC's constrain_jog: each axis clamped to its soft limits (firmware-facts §7).

    Simplification: FluidNC's "nudge" for an axis already outside its limits is not modelled.
    """
    return tuple(
        min(max(t, lo), hi) for t, lo, hi in zip(target_mm, box.min_mm, box.max_mm, strict=True)
    )


def _clip_along_line(start_mm: Vec, target_mm: Vec, box: TravelBox) -> Vec:
    """grblHAL's `$40=1` jog limit: stop where the straight path leaves the envelope (firmware-facts
    §7)."""
    fraction = 1.0
    for s, t, lo, hi in zip(start_mm, target_mm, box.min_mm, box.max_mm, strict=True):
        delta = t - s
        if t > hi and delta > 0:
            fraction = min(fraction, max(0.0, (hi - s) / delta))
        elif t < lo and delta < 0:
            fraction = min(fraction, max(0.0, (lo - s) / delta))
    clipped = tuple(s + (t - s) * fraction for s, t in zip(start_mm, target_mm, strict=True))
    return _clip_per_axis(clipped, box)
