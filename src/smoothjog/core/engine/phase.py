"""The phase machine's core: its state, and what a status report or a stop's end does to it.

jogger.py builds on it (intents, replies, the tick, the views). Together they are the only code
that changes the engine's phase; the parts beside them keep their own state and return what to
do. The outside-event verdicts come from the sign table (signs.py); the reactions are here.
"""

from __future__ import annotations

from smoothjog.core.engine import bounds
from smoothjog.core.engine.clearance import Clearance
from smoothjog.core.engine.clock import LinkClock
from smoothjog.core.engine.limits import JOG_STATES, EngineLimits, JogTuning, state_reason
from smoothjog.core.engine.lines import EngineLines, others_poll
from smoothjog.core.engine.parts import MotionParts
from smoothjog.core.engine.records import (
    EngineEvent,
    EngineStats,
    Notices,
    Output,
    Phase,
    StopRecord,
)
from smoothjog.core.engine.reports import ReportReader
from smoothjog.core.engine.restart import RestartWatch
from smoothjog.core.engine.signs import Evidence, Reaction, Signs, Stage, stop_off_path, who_stopped
from smoothjog.core.engine.steps import StepQueue
from smoothjog.core.engine.stopper import StopDriver, StopParts, StopPhase
from smoothjog.core.engine.stream import Streamer, still
from smoothjog.core.engine.tracker import PathTracker
from smoothjog.core.intents import (
    ContinuousIntent,
)
from smoothjog.core.ledger import Ledger
from smoothjog.core.machine import MachineModel
from smoothjog.core.responses import (
    StatusReport,
)
from smoothjog.core.units import Vec

#: A report that puts the machine at most this far ahead of the estimate needs no poll of its
#: own: at full speed it is well under a millisecond of queue (the link margin covers more).
ROUTINE_LEAD_MM = 0.05
#: The faults the reactions to outside events show (signs.py says when each comes).
OUTSIDE_HINT = "release the stick (or key) and press it again to jog on"
INPUT_HINT = "release it, resume with ~ if it holds, and jog again"
OFF_PATH_HINT = (
    "check for another program, a button or a pendant on the controller;"
    " smoothjog has re-read the position"
)


class PhaseCore:
    """The engine's state and its reactions to reports and stop ends (see Jogger for the API)."""

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
        self.tuning = tuning = tuning or JogTuning()
        self._limits = limits
        self.stats = EngineStats()
        self.notices = Notices()
        self.track = PathTracker(
            limits.steps_per_mm,
            limits.accel_mm_s2,
            limits.junction_deviation_mm,
            tuning.committed_s,
        )
        self.clock = LinkClock(tuning.byte_s)
        self.lines = EngineLines(self.ledger, self.clock, self.stats)
        self.reports = ReportReader(tuning, self.clock, self.notices)
        self.clearance = Clearance(limits, self.track, self.notices)
        self.signs = Signs(self.track, tuning, self.clearance)
        self.restart = RestartWatch(self.ledger, self.clock, self.reports)
        parts = (model, tuning, self.track)
        self.stopping = StopDriver(
            StopParts(*parts, self.lines, self.clock, self.reports, self.notices, self.stats),
            limits,
        )
        movers = MotionParts(
            *parts, self.clock, self.clearance, self.lines, self.notices, self.stats
        )
        self.stream = Streamer(movers, limits)
        self.steps = StepQueue(movers, limits)
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
        #: A settle may go back to streaming when handwheel moves arrive (not after a Run race).
        self._settle_resumable = False
        #: An Idle report is awaited to end a stop or a settle (the next one counts as fresh).
        self._fresh_status_wanted = False
        #: Something reached the engine (an intent, a line, new limits) since its last poll.
        self._changed = True

    @property
    def events(self) -> list[EngineEvent]:
        """Everything told since the host last took the events."""
        return self.notices.events

    @events.setter
    def events(self, events: list[EngineEvent]) -> None:
        self.notices.events = events

    @property
    def limits(self) -> EngineLimits:
        """What the engine knows of the machine; setting it hands the new limits on."""
        return self._limits

    @limits.setter
    def limits(self, limits: EngineLimits) -> None:
        self._limits = limits
        self._changed = True
        for part in (self.clearance, self.stopping, self.stream, self.steps):
            part.limits = limits
        self.track.use_machine(
            limits.steps_per_mm, limits.accel_mm_s2, limits.junction_deviation_mm
        )

    # ----------------------------------------------------------------- stopping
    def _begin_stop(self, now_s: float) -> None:
        if self.phase is Phase.STOPPING:
            return
        self.phase = Phase.STOPPING
        self.stopping.begin(now_s)

    def _want_fresh_status(self) -> None:
        """The stop synced (or gave up): its position is read with a `?` asked now."""
        self._fresh_status_wanted = True
        self.reports.asked_s = None

    def _finish_stop(self, now_s: float, *, cancelled: bool, recancels: int) -> None:
        """The machine rests: record how the stop went and forget the path."""
        mpos = self.model.mpos_mm
        if mpos is not None:
            # The report rounds to 0.001 mm; the step counts behind it are exact.
            err_mm, err_steps = self.track.tracking_error(
                self.track.on_step_grid(mpos), cancelled=cancelled
            )
            outside = self.stopping.handshake.owed
            path_faulted, self.notices.path_faulted = self.notices.path_faulted, False
            if stop_off_path(err_steps, owed=outside, path_faulted=path_faulted) is not None:
                outside = True
                self.notices.fault_now(
                    now_s,
                    f"the machine stopped {err_mm:.2f} mm off the path smoothjog sent: something"
                    " outside smoothjog stopped or moved it",
                    OFF_PATH_HINT,
                )
            self.stats.stops.append(
                StopRecord(now_s, cancelled, recancels, err_mm, err_steps, tuple(mpos), outside)
            )
            self.events.append(EngineEvent(now_s, "stop", f"stopped at {_fmt(mpos)}"))
        self.track.reset()
        self.stream.commanded = still(len(self.limits.axes))
        self.stopping.handshake.end()
        self.phase = Phase.IDLE
        self.steps.after_stop(now_s)

    def _abandon_motion(self) -> None:
        """Forget the queued path (door, hold, alarm, reset): nothing more is sent. Jog lines
        still unanswered run once the controller resumes (firmware-facts §3.1-§3.3): a cancel
        is owed, sent as soon as the state is Idle or Jog again."""
        self._cancel_owed = self.lines.jogs_unanswered()
        self.track.drop()
        self.steps.abandon()
        self._intent = None
        self._acted_intent = None
        self.stopping.handshake.end()
        self.phase = Phase.IDLE

    def _on_status(self, report: StatusReport, now_s: float) -> float:
        """Take a status report; return how far it moved the estimate forward (mm)."""
        track = self.track
        estimate_before_mm = track.x_est_mm
        mpos = self.model.mpos_mm
        asked_s = self.reports.take(report, mpos, now_s)
        self.reports.note_pins(report, now_s, at_rest=self.phase is Phase.IDLE)
        predicted_mm, off_path, lead_mm = estimate_before_mm, False, 0.0
        if mpos is not None:
            # Advance the estimate to now_s first, or the next update would integrate the time
            # since the last poll a second time.
            track.update_estimate(now_s)
            predicted_mm = track.x_est_mm
            off_path = track.correct_estimate(mpos, self.clock.report_wire_s(report))
            if not off_path:
                jogging = self.phase is Phase.JOGGING
                move = self.stream.commanded
                self.clock.split_by(report, asked_s, now_s, move, track, jogging=jogging)
            else:
                self.clock.split.reset()
            lead_mm = track.x_est_mm - predicted_mm
        ev = self._evidence(report, asked_s, now_s, estimate_before_mm, predicted_mm, off_path)
        verdict = self.signs.read(Stage.MOTION, ev)
        if verdict is not None and verdict.reaction is Reaction.DESYNC:
            # Further increments would land off the tracked path: stop and sync (below, unless
            # this report shows a Run race).
            self._pending_desync = True
        elif verdict is not None:
            self._outside_stop(now_s, report, verdict.how)
            return lead_mm
        if report.state == "Run" and self.phase in (Phase.JOGGING, Phase.STEPPING, Phase.STOPPING):
            self._run_race(now_s)
            return lead_mm
        if self._pending_desync:
            self._pending_desync = False
            if self.phase is Phase.JOGGING:
                self._outside_stop(now_s, report, "it left the path smoothjog sent")
                return lead_mm
        if self._react_to_state(report, ev, now_s):
            return lead_mm
        if report.state == "Idle" and self._fresh_status_wanted:
            self._settled_idle(now_s)
        return lead_mm

    def _evidence(
        self,
        report: StatusReport,
        asked_s: float | None,
        now_s: float,
        estimate_before_mm: float,
        predicted_mm: float,
        off_path: bool,
    ) -> Evidence:
        stop = self.stopping.handshake
        return Evidence(
            report=report,
            asked_s=asked_s,
            now_s=now_s,
            mpos=self.model.mpos_mm,
            phase=self.phase,
            runs_as_sent=self.phase is Phase.JOGGING
            or (
                self.phase is Phase.STOPPING
                and stop.phase is StopPhase.WAIT_ACKS
                and not stop.cancelled
            ),
            off_path=off_path,
            predicted_mm=predicted_mm,
            estimate_before_mm=estimate_before_mm,
            commanded=self.stream.commanded,
            jog_unbraked=self.reports.jog_unbraked,
            others_poll=others_poll(self.ledger),
            relayed=self.ledger.relayed,
            oldest=self.ledger.oldest(),
            rtt_s=self.clock.rtt_s,
            report_wire_s=self.clock.report_wire_s(report),
            pressed=self.reports.pressed_inputs(report),
            jogs_unanswered=self.lines.jogs_unanswered(),
        )

    def _run_race(self, now_s: float) -> None:
        """firmware-facts §9: a jog block started in Run (a firmware race); it finishes by
        itself within the queued path. Stop streaming and wait for Idle."""
        self.stats.run_state_seen += 1
        self.notices.fault_now(
            now_s,
            "the controller ran a jog block in Run state (a Grbl race)",
            "smoothjog stopped streaming; the machine stops at the end of what was queued",
        )
        self._intent = None
        self.steps.queue.clear()
        self.stopping.handshake.end()  # a handshake under way is dropped: the queue runs out
        self.phase = Phase.SETTLING
        self._settle_resumable = False  # nothing more is sent until the machine rests
        self._fresh_status_wanted = True

    def _react_to_state(self, report: StatusReport, ev: Evidence, now_s: float) -> bool:
        """React to the state signs; True when the report needs nothing more."""
        verdict = self.signs.read(Stage.STATE, ev)
        state = report.state
        if verdict is not None and verdict.reaction is Reaction.ABANDON_AND_LATCH:
            self.notices.fault_now(now_s, verdict.how, INPUT_HINT)
            self._abandon_motion()
            self._await_press = True
            return True
        if verdict is not None and verdict.reaction is Reaction.STOP_AND_CANCEL:
            self._outside_stop(now_s, report, verdict.how)
        elif ev.mpos is not None and self._queue_ran_out(report):
            # Every jog was answered and the machine rests at the end: the queue has run.
            self.track.arrive_at_end()
        if state not in JOG_STATES and state != "Run":
            self._fresh_status_wanted = False
            if verdict is not None and verdict.reaction is Reaction.ABANDON:
                self.notices.fault_now(now_s, verdict.how, "")
                self._abandon_motion()
            return True
        return False

    def _queue_ran_out(self, report: StatusReport) -> bool:
        mpos = self.model.mpos_mm
        track = self.track
        if not (
            report.state == "Idle"
            and self.phase is Phase.JOGGING
            and track.moving_since_ack
            and track.path
            and mpos is not None
        ):
            return False
        return bounds.at_path_ends(track, mpos)[0] and not self.lines.jogs_unanswered()

    def _settled_idle(self, now_s: float) -> None:
        """A fresh Idle report: a stop's last step, or the end of a queue that ran out."""
        stop = self.stopping.handshake
        if self.phase is Phase.STOPPING and stop.phase is StopPhase.WAIT_STATUS:
            self._fresh_status_wanted = False
            self._finish_stop(now_s, cancelled=stop.cancelled, recancels=stop.recancels)
        elif self.phase is Phase.SETTLING and not self.lines.unanswered():
            # The queue ran out by itself: no cancel to report, even if one was under way.
            self._fresh_status_wanted = False
            self._finish_stop(now_s, cancelled=False, recancels=0)

    def _outside_stop(self, now_s: float, report: StatusReport, how: str) -> None:
        """Someone else stopped the jog: say so, sync, and wait for a new press."""
        who = who_stopped(report)
        self.notices.fault_now(
            now_s, f"the jog was stopped outside smoothjog: {how}; stopped by {who}", OUTSIDE_HINT
        )
        # A stick still held must be pressed anew; one already let go has nothing to latch.
        self._await_press = self._intent is not None
        self._intent = None
        self._acted_intent = None
        self.reports.cancel_ending = report.state == "Jog" and not self.reports.jog_unbraked
        self._begin_stop(now_s)
        # The lines it had not yet run start again the moment that stop ends (firmware-facts
        # §3.1, §3.7): cut each one short as soon as a report shows it.
        self.stopping.handshake.owe_cancel()

    def _status_urgent(self) -> bool:
        """A report is needed now: to end a stop, or a queue the estimate says has run out."""
        return self._fresh_status_wanted and (
            (self.phase is Phase.SETTLING and self.track.at_rest_at_end())
            or (
                self.phase is Phase.STOPPING
                and self.stopping.handshake.phase is StopPhase.WAIT_STATUS
            )
        )

    def _status_due_s(self) -> float:
        """When the next routine status query is due."""
        stop = self.stopping.handshake
        interval_s = self.reports.interval_s(
            watching_restart=self.restart.watching,
            busy=self.phase is not Phase.IDLE or self.model.state not in (None, "Idle"),
            # Lines left by a door, hold or reset may start the machine any moment.
            cancel_owed=self._cancel_owed
            or (
                self.phase is Phase.STOPPING
                and stop.phase in (StopPhase.WAIT_ACKS, StopPhase.WAIT_SYNC)
                and stop.owed
            ),
        )
        return self.reports.last_sent_s + interval_s

    def _poll_status(self, now_s: float, out: list[Output]) -> None:
        self.reports.poll(now_s, out, urgent=self._status_urgent(), due_s=self._status_due_s())

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
            return False, state_reason(state)
        # An unhomed machine may jog: a machine on a limit switch must be jogged off it.
        return True, None


def _fmt(v: Vec) -> str:
    return ", ".join(f"{x:.3f}" for x in v)
