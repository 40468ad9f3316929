"""The phase machine: intents, controller replies and the time in; lines and realtime bytes out.

Continuous jogging streams short `$J=G21G91...` increments, keeping queued ahead of the machine
just what holding the speed needs and never filling the planner, so every `ok` comes back at
once and a stop never leaves a line in flight. A stop is a full handshake (firmware-facts §3.1,
§3.6): every `$J` answered, 0x85, `G4P0`, then the position. Every line names G21 and G91 (or
G53), so the controller's modal state never changes.

The engine never reads a clock (every call takes `now_s`) and never writes to a link (`poll`
returns `Output`s). This is the only part that changes the engine's phase; the parts beside it
(streaming, steps, clearance, the stop handshake, the link clock, report reading, the
outside-event signs, the restart watch) keep their own state and return what to do.
"""

from __future__ import annotations

from collections.abc import Mapping

from smoothjog.core.codes import ERR_TRAVEL_EXCEEDED, alarm_info, error_info
from smoothjog.core.engine.limits import JOG_STATES, EngineLimits
from smoothjog.core.engine.lines import LineTag, kind
from smoothjog.core.engine.phase import ROUTINE_LEAD_MM, PhaseCore
from smoothjog.core.engine.records import EngineView, Output, Phase, SendRealtime
from smoothjog.core.errors import JogBuildError
from smoothjog.core.firmware import firmware_facts
from smoothjog.core.intents import (
    GotoIntent,
    HandwheelIntent,
    Intent,
    StepIntent,
    StopIntent,
    validate_intent,
)
from smoothjog.core.ledger import Entry
from smoothjog.core.realtime import JOG_CANCEL
from smoothjog.core.responses import (
    AlarmReply,
    Banner,
    ErrorReply,
    Message,
    Ok,
    Response,
    StatusReport,
)
from smoothjog.core.units import Vec


class Jogger(PhaseCore):
    """The jog engine; drive it with set_intent, on_response and poll, always passing now_s."""

    # ----------------------------------------------------------------- inputs
    def set_intent(self, intent: Intent, now_s: float) -> None:
        """Take the newest intent; the next poll acts on the latest one only.

        Steps, go-tos and handwheel detents queue in order behind each other.
        """
        self._changed = True
        if isinstance(intent, StepIntent | GotoIntent):
            self._validate(intent)
            self.steps.queue.append(intent)  # steps queue in order; a held stick is released
            self._intent = None
            self._await_press = False  # a step is a press of its own
            self.notices.fault = None  # and the user has seen what went wrong before it
            self.notices.path_faulted = False
            return
        if isinstance(intent, HandwheelIntent):
            self._validate(intent)
            if intent.counts:  # a report of no detents (a button) is no motion, nor a sign of life
                self._stop_requested = self.steps.take_wheel(
                    intent,
                    now_s,
                    stop_requested=self._stop_requested,
                    stopping=self.phase is Phase.STOPPING,
                )
                self._intent = None
            return
        if isinstance(intent, StopIntent) or intent.is_neutral():
            self._intent = None
            self.steps.queue.clear()
            self._stop_requested = True
            self._await_press = False
            self._released = True
            return
        # A neutral stick is a stop and is not checked further (an unknown axis at 0 is fine).
        self._validate(intent)
        if self._released:
            # A new press after a release: the fault shown since was seen; clear the banner.
            self._released = False
            self.notices.fault = None
            self.notices.path_faulted = False
        if self._await_press:
            # Someone else stopped this jog: the stick still held is not a new press.
            return
        self._intent = intent

    def _validate(self, intent: Intent) -> None:
        """Refuse, in words, an intent this machine cannot run."""
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
            self.stopping.handshake.owe_cancel()
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
            elif intent is not self._acted_intent and self.stream.turn_wants_cancel(intent, now_s):
                self._begin_stop(now_s)
        self._acted_intent = intent

    @property
    def planned_end_mm(self) -> Vec | None:
        """Where the last jog sent ends (machine mm): the machine never goes beyond it."""
        return self.track.end_mm

    def busy(self) -> bool:
        """True while anything is queued, streaming or stopping, or an intent is held, or lines
        sent before a reset may still start the restarted controller (restart_settled)."""
        return (
            self.phase is not Phase.IDLE
            or bool(self.steps.queue)
            or self._intent is not None
            or not self.restart_settled()
        )

    def set_speed_ratios(self, ratios: Mapping[str, float]) -> None:
        """Per-axis speed ratios in (0, 1]."""
        self._changed = True
        self.stream.set_speed_ratios(ratios)

    def on_reply(self, entry: Entry, resp: Ok | ErrorReply, now_s: float) -> bool:
        """The reply to one of the engine's own lines (the ledger matched it to entry).

        Returns whether the engine has anything to do at once: the `ok` of a jog while the
        stream runs normally changes nothing a poll would act on (the queue is sized in
        distance), which saves half the wake-ups of a held jog.
        """
        self._changed = True
        if not self.lines.answered(entry):
            # Grbl answers in order: anything else means the ledger was reset under us.
            self.notices.info(now_s, f"a reply to {entry.text!r} came out of order")
            return True
        self.stopping.replied(now_s)
        first_ack = not self.track.moving_since_ack
        self._on_reply(entry, resp, now_s)
        routine = (
            self.phase is Phase.JOGGING
            and isinstance(resp, Ok)
            and kind(entry) == "jog"
            and not first_ack  # the estimate starts moving: the wake-up time changes
            and not self.lines.rx_blocked  # the RX buffer held a line back: there is room now
        )
        return not routine

    def on_response(self, resp: Response, now_s: float) -> bool:
        """Any other line the controller sent (the host has folded it into the model).

        Returns whether the engine has anything to do at once: a report that finds a held jog
        where the estimate expected it (or behind it) changes nothing the next poll would not.
        """
        self._changed = True
        if isinstance(resp, StatusReport):
            if self.notices.alarm_fault is not None and resp.state != "Alarm":
                self._alarm_over()
            fault = self.notices.fault
            lead_mm = self._on_status(resp, now_s)
            wake_s = self.stream.wake_at_s
            return not (
                self.phase is Phase.JOGGING
                # A planned top-up polls before the next `?` is due.
                and wake_s is not None
                and wake_s <= self._status_due_s()
                and resp.state == "Jog"
                and lead_mm <= ROUTINE_LEAD_MM
                and not self._pending_desync
                and self.notices.fault is fault
            )
        if isinstance(resp, AlarmReply):
            info = alarm_info(resp.code)
            self.notices.fault_now(now_s, f"ALARM:{resp.code} {info.meaning}", info.hint)
            self.notices.alarm_fault = self.notices.fault
            self._abandon_motion()
        elif isinstance(resp, Banner):
            self._on_banner(now_s)
        elif isinstance(resp, Message) and resp.text == "Check Door":
            self.notices.fault_now(now_s, "the safety door opened", "close the door and resume (~)")
            # The door already cancels the jog; lines in the buffer would run after the resume:
            # cancel those still unanswered then.
            self._abandon_motion()
        return True

    def _on_banner(self, now_s: float) -> None:
        """The controller was reset: say so, and owe a cancel for jog lines on the wire."""
        jogs = self.lines.jogs_pending()
        lost = (
            f"; {jogs} jog line{'s' if jogs != 1 else ''} had no reply yet: any that reach"
            " the restarted controller are cancelled once a report shows them running"
            if jogs
            else ""
        )
        if self.reset_expected:
            # The user's own reset: news, and no fault that would hide why jogs wait now.
            self.reset_expected = False
            self.notices.path_faulted = True
            self.notices.info(
                now_s,
                f"the controller was reset{lost}",
                "smoothjog reads its settings again before jogging",
            )
        else:
            self.notices.fault_now(
                now_s,
                f"the controller was reset (its banner arrived mid-session){lost}",
                "check why it reset; smoothjog re-reads its settings before jogging again",
            )
        # Lines still on the wire run as new jogs: owe them a cancel (computed before the
        # replies they will never get are forgotten), and send one at once (reset_outputs).
        watching = self.restart.watching
        owed = self._cancel_owed
        self.restart.reset_cancel = jogs > 0 or watching
        self._abandon_motion()
        self.lines.forget()
        if self.restart.banner(now_s, jogs=jogs, watching=watching):
            self._cancel_owed = self._cancel_owed or owed
            self.reports.restarted()

    def reset_outputs(self) -> list[Output]:
        """What to send the moment a banner shows the controller reset: one 0x85, arriving
        right behind the jog lines still on their way (firmware-facts §3.8: no cancel can be
        ending after a restart; with nothing running it is dropped)."""
        if not self.restart.reset_cancel:
            return []
        self.restart.reset_cancel = False
        self.reports.cancel_ending = True
        self.stats.cancels += 1
        return [SendRealtime(JOG_CANCEL)]

    def restart_outputs(self, now_s: float) -> list[Output]:
        """What to send while the host waits to re-read a restarted controller's settings:
        realtime bytes only (`?`, and 0x85 for each jog a report shows running; restart.py)."""
        out: list[Output] = []
        if not self.restart.watching:
            return out
        due = self.restart.cancel_due(
            now_s, flushes_rx=firmware_facts(self.limits.firmware).jog_cancel.flushes_rx
        )
        if self.reports.jog_unbraked and self.model.state == "Jog" and due:
            self.stopping.send_cancel(out)
        self._poll_status(now_s, out)
        return out

    def restart_wire_clear(self, now_s: float) -> None:
        """Every line written before the reset has left the host now (restart.py)."""
        self.restart.wire_clear(now_s)

    def restart_settled(self) -> bool:
        """True once no line sent before a restart can still start the machine (restart.py)."""
        return self.restart.settled(self.model.state)

    def reset_machine(self, limits: EngineLimits) -> None:
        """Start over after a re-handshake (the controller was reset).

        A cancel owed for jog lines sent before the reset stays owed, and a press made while
        the settings were re-read is a new press: it runs once the machine may jog.
        """
        owed = self._cancel_owed
        intent, queued = self._intent, list(self.steps.queue)
        self.restart.since_s = None
        self.limits = limits
        self.lines.forget()
        self._abandon_motion()
        self._cancel_owed = owed or self._cancel_owed
        self._intent = intent
        self.steps.keep_steps(queued)

    # ----------------------------------------------------------------- the driver's tick
    def poll(self, now_s: float) -> list[Output]:
        """Everything to send now; call on every reply and at least every next_deadline_s()."""
        out: list[Output] = []
        wake_s = self.stream.wake_at_s
        if (
            not self._changed
            and self.phase is Phase.JOGGING
            and wake_s is not None
            and now_s < wake_s
        ):
            # Hot path: nothing was heard or asked since the last poll and the queue is not
            # due for a top-up, so only a status query can be owed.
            self._poll_status(now_s, out)
            return out
        if wake_s is not None and now_s > wake_s:
            # Woken late for a planned top-up: size the queue for such wake-ups as well.
            self.clock.woke_late(now_s - wake_s)
        self._changed = False
        self.stream.wake_at_s = None
        self.lines.rx_blocked = False
        self.track.update_estimate(now_s)
        # A report can be as old as its `?` wait plus the slowest round trip seen (a stall).
        self.track.prune(0.3 + self.clock.rtt_hi_s)
        self._act_on_intent(now_s)
        self._start_or_resume(now_s)
        try:
            if self.phase is Phase.JOGGING:
                self._jog(now_s, out)
            if self.phase is Phase.STEPPING:
                self._step(now_s, out)
        except JogBuildError as exc:
            # A line that cannot be written: never send it, stop what runs, and say why.
            self.notices.fault_now(
                now_s, f"jog not sent: {exc}", "check the intent that asked for it", refusal=True
            )
            self._intent = None
            self.steps.queue.clear()
            self._begin_stop(now_s)
        if self.phase is Phase.STOPPING and self.stopping.advance(now_s, out):
            self._want_fresh_status()
        self._poll_status(now_s, out)
        return out

    def _start_or_resume(self, now_s: float) -> None:
        """Idle with something to do: start it; settling with a handwheel run: resume."""
        if self.phase is Phase.IDLE:
            if self.steps.queue and self._may_jog():
                self.phase = Phase.STEPPING
            elif self._intent is not None and self._may_jog():
                self._start_jogging(now_s)
        elif self.phase is Phase.SETTLING and self._settle_resumable and self.steps.wheel_next():
            # A wheel turned while its earlier moves run out: queue behind them at once rather
            # than stop, report Idle and start again (a stutter at every report).
            self.phase = Phase.STEPPING
            self._fresh_status_wanted = False

    def _jog(self, now_s: float, out: list[Output]) -> None:
        if self._may_jog():
            self.stream.stream(now_s, out, self._intent, self.signs.rest_inside)
            return
        if self.model.jog_lock is not None:
            self.notices.fault_now(now_s, f"jogging stopped: {self.model.jog_lock}", "")
            # A stick held through the other program's job is no new press.
            self._await_press = self._intent is not None
            self._intent = None
        self._begin_stop(now_s)

    def _step(self, now_s: float, out: list[Output]) -> None:
        if not self._may_jog():
            self.steps.queue.clear()
            self._begin_stop(now_s)
        elif self.steps.stream(now_s, out):
            # The queue was sent whole: wait for the machine to report rest.
            self.phase = Phase.SETTLING
            self._settle_resumable = True
            self._fresh_status_wanted = True

    def next_deadline_s(self, now_s: float) -> float:
        """The latest time the driver should call poll again (it also polls on every reply).

        The engine wakes when its queue will have drained to the target, when a report is due,
        and every settle_tick_s while a queue runs out or steps wait for room.
        """
        asked_s = self.reports.asked_s
        if asked_s is not None:
            due_s = asked_s + self.tuning.status_timeout_s  # re-ask if the report never came
        elif self._status_urgent():
            due_s = now_s
        else:
            due_s = self._status_due_s()
        restart = self.restart
        if self.phase is Phase.JOGGING and self.stream.wake_at_s is not None:
            due_s = min(due_s, self.stream.wake_at_s)
        elif restart.watching and self.reports.jog_unbraked and restart.replies_due > 0:
            # A jog seen running waits for the old lines' replies: cancel it when they go quiet.
            due_s = min(due_s, restart.reply_s + restart.quiet_s())
        elif self.phase in (Phase.SETTLING, Phase.STEPPING):
            due_s = min(due_s, now_s + self.tuning.settle_tick_s)
        return max(due_s, now_s + self.tuning.tick_s)

    def _start_jogging(self, now_s: float) -> None:
        mpos = self.model.mpos_mm
        if mpos is None:
            return  # no position yet: wait for the first status report
        self.phase = Phase.JOGGING
        self.track.begin(self.track.on_step_grid(mpos), now_s)
        self.track.moving_since_ack = False  # the estimate waits for the first jog's ok
        # A new run is judged once a report shows it at speed, whatever reports came between.
        self.signs.forget_run()

    # ----------------------------------------------------------------- replies and status
    def _on_reply(self, entry: Entry, resp: Ok | ErrorReply, now_s: float) -> None:
        tag = entry.tag
        assert isinstance(tag, LineTag)
        if isinstance(resp, ErrorReply):
            self.stats.error_replies += 1
            if resp.code == ERR_TRAVEL_EXCEEDED:
                self.stats.soft_limit_errors += 1
        if tag.kind == "sync":
            if self.phase is Phase.STOPPING and self.stopping.sync_reply(resp, now_s):
                self._want_fresh_status()
            return
        if tag.kind != "jog" or tag.seg is None:
            return
        if isinstance(resp, Ok):
            if self.clock.jog_ok(now_s - entry.sent_s, entry.sent_s, now_s):
                self.signs.held_up()
            self.track.ack(tag.seg, now_s)
            return
        # A rejected G91 jog leaves the parser where it was, so every later increment is off:
        # stop, re-sync, and say why.
        info = error_info(resp.code)
        self.notices.fault_now(now_s, f"jog rejected: error:{resp.code} {info.meaning}", info.hint)
        self.track.remove(tag.seg)
        self.steps.queue.clear()
        self._intent = None
        if self.phase in (Phase.JOGGING, Phase.STEPPING, Phase.SETTLING):
            self._begin_stop(now_s)

    # ----------------------------------------------------------------- views
    def stop_point_mm(self) -> Vec | None:
        """Where the machine would come to rest if the jog were released now."""
        mpos = self.model.mpos_mm
        if mpos is None:
            return None
        if not self.track.path:
            return tuple(mpos)
        return self.track.stop_point_mm()

    def view(self, now_s: float) -> EngineView:
        """A snapshot for the pendant."""
        ok, reason = self.can_jog()
        jogging = self.phase is Phase.JOGGING
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
            commanded_speed_mm_s=self.stream.commanded.speed_mm_s if jogging else 0.0,
            actual_speed_mm_s=self.reports.actual_speed_mm_s if self.model.state != "Idle" else 0.0,
            stop_point_mm=self.stop_point_mm(),
            queued_mm=self.track.queued_mm(),
            queued_blocks=self.track.blocks_in_planner(),
            fault=self.notices.fault,
        )

    def ask_status(self) -> None:
        """Someone saw the controller change: ask for a report at the next poll (while idle;
        a jog polls often enough by itself)."""
        if self.phase is Phase.IDLE:
            self.reports.last_sent_s = -float("inf")
            self._changed = True

    def clear_fault(self) -> None:
        """Forget the last fault (the user saw it)."""
        self.notices.fault = None

    def _alarm_over(self) -> None:
        """A report shows the controller out of Alarm: the alarm's fault no longer holds."""
        if self.notices.fault is self.notices.alarm_fault:
            self.notices.fault = None
        self.notices.alarm_fault = None
