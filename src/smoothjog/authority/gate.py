"""The motion gate: whether an owner may start motion now, and what a stop does.

One per session, over its host. Every owner asks it before it moves the machine: an input
(through the arbiter, which says which input speaks), a machine command or console line
(through MachineControl), and the proxy's sender. The gate also takes every stop, from
whoever gives it, and picks what the motion under way needs (docs/pendant.md says it for users):

- a jog, step, go-to or handwheel run of smoothjog's engine: the engine's full cancel handshake;
- somebody else's jog (Jog with the engine idle): 0x85;
- any other motion (a console G0/G1, a sender's job, a CNCjs job): feed hold `!`; the pages
  then offer Resume (`~`) or Reset;
- homing, which Grbl does not pause: a soft reset, which leaves Alarm.

A stop always passes, and it is told to every listener with who gave it. An input that held
motion when someone else stopped it must release before its motion starts again: the arbiter
keeps that latch, the one thing about a stop that only the input side can see end.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

from smoothjog.authority.commands import command
from smoothjog.core import realtime
from smoothjog.core.engine import Phase
from smoothjog.core.intents import Intent, StopIntent
from smoothjog.core.ledger import CONSOLE, ENGINE, HANDSHAKE
from smoothjog.core.responses import StatusReport
from smoothjog.core.states import (
    LINK_LOST,
    MOVING_STATES,
    MOVING_TEXT,
    READING_SETTINGS,
    SETTLED_STATES,
    LineKind,
    line_kind,
    line_refusal,
    state_refusal,
)
from smoothjog.core.states import moves as line_moves
from smoothjog.host import Host

log = logging.getLogger(__name__)

#: Why nothing may move once the link is gone.
LINK_LOST_TEXT: Final = "the connection to the controller is lost"
#: Why nothing may move while a restarted controller's settings are read again.
REREADING_TEXT: Final = "the controller restarted: wait while smoothjog reads its settings again"
#: Why nothing but a reset goes after a critical alarm (a limit, an e-stop: the controller reads
#: no line until then, firmware-facts §5.6a).
RESET_NEEDED_TEXT: Final = (
    "the controller stopped at a critical alarm and reads nothing until it is reset: press Reset"
)
#: A report this long after a motion line's `ok` shows whether that line started the machine
#: (a report asked just before the line ran can still say Idle).
SETTLE_MARGIN_S: Final = 0.1


@dataclass(frozen=True)
class StopRecord:
    """One stop: who gave it, what was sent, and the sentence every page shows."""

    by: str
    actions: tuple[str, ...]
    text: str
    t_s: float


class MotionGate:
    """Who may start motion now, and what a stop does; the arbiter's and the commands' sink."""

    def __init__(self, host: Host) -> None:
        """A gate over host (started); attach() a new host after a reconnect."""
        self.host = host
        #: The machine command in flight, in words ("homing"), or None.
        self.running: str | None = None
        #: When a G-code line that may move the machine (a console G0) was sent, until a report
        #: after its reply shows the machine settled; None when no such motion is known.
        self._motion_sent_s: float | None = None
        self._motion_answered_s: float | None = None
        self.last_stop: StopRecord | None = None
        self._stop_listeners: list[Callable[[StopRecord], None]] = []
        self._report_waiters: list[asyncio.Future[None]] = []
        host.add_line_listener(self._on_line)

    def attach(self, host: Host) -> None:
        """Gate a new host (the link was lost and opened again)."""
        self.host = host
        self.running = None
        self._motion_sent_s = self._motion_answered_s = None
        host.add_line_listener(self._on_line)

    def add_stop_listener(self, callback: Callable[[StopRecord], None]) -> None:
        """Call callback with every stop, whoever gave it."""
        self._stop_listeners.append(callback)

    # -------------------------------------------------------------- may motion start
    def session_refusal(self) -> str | None:
        """Why nothing at all may start now (the link, a re-read, a limit alarm), or None."""
        if self.host.link_error is not None:
            return LINK_LOST_TEXT
        if self.host.rehandshaking:
            return REREADING_TEXT
        if self.host.reset_needed:
            return RESET_NEEDED_TEXT
        return None

    def jog_refusal(self) -> str | None:
        """Why an input's new jog may not start now, in words, or None when it may."""
        why = self.session_refusal()
        if why is not None:
            return why
        if self.running is not None:
            return f"jogging waits: {self.running} is running"
        view = self.host.view()
        if not view.can_jog:
            return view.reason or "the machine gives no reason"
        return None

    def can_jog(self) -> tuple[bool, str | None]:
        """The arbiter's question (IntentSink): may a new jog start now, and if not why."""
        why = self.jog_refusal()
        return why is None, why

    def machine_moving(self) -> bool:
        """True while anything may still move the machine: the engine, a line, a program."""
        if self.engine_moving():
            return True
        return self.host.model.state in MOVING_STATES or self._motion_sent_s is not None

    def engine_moving(self) -> bool:
        """True while smoothjog's own engine has anything in hand (a jog, steps, its stop)."""
        return self.host.driver is not None and self.host.busy()

    def busy_refusal(self, *, locked_ok: bool = False) -> str | None:
        """Why no line of a command may go now (motion, another command, a job), or None.

        While another program holds the machine (a sender's job through the proxy, a CNCjs
        job) a line would land in the middle of its job, so lines wait in the lock's words;
        locked_ok lets through what cannot change a job.
        """
        host = self.host
        if host.link_error is not None:
            return LINK_LOST_TEXT
        if self.running is not None:
            return f"wait: {self.running} has not finished"
        if host.model.jog_lock is not None and not locked_ok:
            return host.model.jog_lock
        if host.rehandshaking:
            return REREADING_TEXT
        if host.reset_needed:
            return RESET_NEEDED_TEXT
        if self.machine_moving():
            return MOVING_TEXT
        return None

    def command_refusal(self, name: str, line: str | None = None) -> str | None:
        """Why the catalogue's command name (a console line: line) may not run now, or None."""
        entry = command(name)
        host = self.host
        if host.link_error is not None:
            return LINK_LOST_TEXT
        if not entry.always:
            why = self.busy_refusal(locked_ok=entry.locked_ok)
            if why is not None:
                return why
        state = host.model.state
        if line is not None:
            return line_refusal(line, state)
        if entry.states is None or state is None or state in entry.states:
            return None
        return _state_refusal(name, state)

    # -------------------------------------------------------------- commands in flight
    def begin(self, doing: str) -> None:
        """A machine command starts, doing what it says (MachineControl asked first)."""
        self.running = doing

    def end(self) -> None:
        """The machine command in flight ended."""
        self.running = None

    def motion_line_sent(self, text: str) -> None:
        """A G-code line that may move the machine went out (a `$H` shows as Home in the model
        until its reply, Host._note_homing)."""
        if line_kind(text) is LineKind.GCODE and line_moves(text):
            self._motion_sent_s = self.host.now_s()
            self._motion_answered_s = None

    def motion_line_answered(self) -> None:
        """That line was answered; a report some time after it says whether it moves."""
        if self._motion_sent_s is not None:
            self._motion_answered_s = self.host.now_s()

    # -------------------------------------------------------------- intents (IntentSink)
    def set_intent(self, intent: Intent) -> None:
        """The arbiter's intents: a stop is a stop of everything, the rest go to the engine."""
        if isinstance(intent, StopIntent):
            if intent.release:
                self.host.set_intent(intent)  # the holder let go of its own jog: no news
            else:
                self.stop(intent.by or "an input")
            return
        self.host.set_intent(intent)

    # -------------------------------------------------------------- the stop
    def stop(self, by: str) -> StopRecord:
        """Stop whatever moves, for whoever asks; always passes. Returns what was done."""
        actions = self._stop_actions()
        record = StopRecord(by, tuple(actions), _stop_text(by, actions), self._now_s())
        if actions:
            log.warning("%s", record.text)
            self.last_stop = record
            for callback in list(self._stop_listeners):
                try:
                    callback(record)
                except Exception:  # a listener that cannot show it must not hide the stop
                    log.exception("a stop listener failed")
        return record

    def _stop_actions(self) -> list[str]:
        """Send what the motion under way needs; the names of what was sent."""
        host = self.host
        if host.link_error is not None or host.driver is None:
            return []
        actions: list[str] = []
        if self.engine_moving():
            actions.append("cancel")
        # Always: a stop also drops queued steps and ends a held jog the engine merely holds.
        host.set_intent(StopIntent())
        state = host.model.state
        if state == "Home":  # the model shows Home while anyone's `$H` waits for its reply
            host.send_realtime(CONSOLE, realtime.RESET)
            actions.append("reset")
        elif state == "Run" or self._other_motion():
            host.send_realtime(CONSOLE, realtime.FEED_HOLD)
            actions.append("hold")
        elif state == "Jog" and "cancel" not in actions:
            host.send_realtime(CONSOLE, realtime.JOG_CANCEL)
            actions.append("cancel")
        return actions

    def _other_motion(self) -> bool:
        """A line of someone else's may be moving the machine, or about to (a stale report)."""
        host = self.host
        if self._motion_sent_s is not None:
            return True
        if host.model.jog_lock is not None and host.model.state not in SETTLED_STATES:
            return True  # a sender's or CNCjs's job holds the machine
        return any(
            e.owner not in (ENGINE, HANDSHAKE)
            and line_kind(e.text) is LineKind.GCODE
            and line_moves(e.text)
            for e in host.ledger.outstanding()
        )

    # -------------------------------------------------------------- the state shown
    def shown_state(self) -> str:
        """The one state word every page shows: Grbl's, or smoothjog's own."""
        host = self.host
        if host.link_error is not None:
            return LINK_LOST
        if host.rehandshaking:
            return READING_SETTINGS
        return host.model.state or "Unknown"

    async def next_report(self) -> None:
        """Ask `?` and return once a status report arrives (the caller bounds the wait)."""
        waiter: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._report_waiters.append(waiter)
        try:
            self.host.send_realtime(CONSOLE, realtime.STATUS_QUERY)
            await waiter
        finally:
            if waiter in self._report_waiters:
                self._report_waiters.remove(waiter)

    # -------------------------------------------------------------- internals
    def _on_line(self, resp: object, now_s: float) -> None:
        if isinstance(resp, StatusReport) and self._report_waiters:
            waiters, self._report_waiters = self._report_waiters, []
            for waiter in waiters:
                if not waiter.done():
                    waiter.set_result(None)
        answered = self._motion_answered_s
        if (
            isinstance(resp, StatusReport)
            and answered is not None
            and now_s - answered >= SETTLE_MARGIN_S
            and resp.state in SETTLED_STATES
        ):
            self._motion_sent_s = self._motion_answered_s = None

    def _now_s(self) -> float:
        try:
            return self.host.now_s()
        except RuntimeError:  # a host that never started has no clock yet
            return 0.0


def engine_has_motion(host: Host) -> bool:
    """Whether smoothjog's own engine still has motion under way (a jog, steps, its stop).

    What another owner's motion line waits for. An intent the engine merely holds (a stick
    still pressed under a job's lock) starts nothing, so only a phase other than idle counts.
    """
    engine = host.engine
    if engine is not None:
        return engine.phase is not Phase.IDLE
    return host.driver is not None and host.busy()


def _state_refusal(name: str, state: str) -> str:
    """Why a command does not run in this state, in words."""
    if name == "resume":
        return f"nothing to resume: the machine is in {state}, not in Hold"
    if name == "hold":
        return f"nothing to hold: the machine is in {state}, not running"
    return state_refusal(state, "command")


def _stop_text(by: str, actions: list[str]) -> str:
    """The sentence every page shows for a stop."""
    if "reset" in actions:
        what = (
            "homing was ended with a reset (Grbl cannot pause it); the controller is in Alarm:"
            " home again or unlock"
        )
    elif "hold" in actions:
        what = "the machine is in feed hold: press Resume to go on or Reset to end the program"
    else:
        what = "the jog was cancelled"
    return f"stopped by {by}: {what}"


__all__ = [
    "LINK_LOST_TEXT",
    "MOVING_TEXT",
    "REREADING_TEXT",
    "RESET_NEEDED_TEXT",
    "MotionGate",
    "StopRecord",
    "engine_has_motion",
]
