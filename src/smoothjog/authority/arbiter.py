"""The arbiter: one per session, between every input and the machine; it owns the safety rules.

Rules (docs/pendant.md states them for users):
- one controlling input at a time: the first attached controls when nobody does; another takes
  control with `take_control`, refused while the controller holds a continuous jog;
- only the controller's intents reach the machine; a refused submit never does; the one
  exception is a stop, which any attached input may give (a STOP button on a device that is
  only watching must still stop the machine, and stopping is never unsafe); the stop names
  who gave it, and the sink (the session's MotionGate) decides what it sends;
- a stop latches: when another input stops the machine while the controller holds a jog, the
  controller's continuous jogs are refused until it releases (neutral or stop), so its next
  heartbeat cannot undo the stop;
- a new jog (a step, a go-to, or a continuous intent while none is held) is first checked with
  the sink's `can_jog`; neutral and stop intents always pass and end the held jog;
- a continuous jog from an input with a `lease_s` arms a dead-man lease that each continuous
  submit or `alive()` renews; when it runs out the machine is stopped once, the trip counted and
  the input told why; that input's continuous jogs are then refused until it releases
  (neutral or stop), so a jog never restarts by itself under a finger still held;
- when the controlling input goes away (detach, or its `run` returns or raises) while it drives
  any motion (a held jog or queued steps), the machine is stopped; a watcher leaving does nothing.

The rules are plain bookkeeping with time from an injected clock (`check(now_s)` is pure), so
tests drive them with a fake clock; in a session the clock is the event loop, which also runs
the one timer per lease window (`loop.call_at`).
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from smoothjog.core.errors import InputRefused, JogBuildError
from smoothjog.core.intents import ContinuousIntent, Intent, StopIntent
from smoothjog.inputs.base import Input, InputHandle, LeaseExpired, kind_noun

log = logging.getLogger(__name__)


#: A lease timer this late (s) means the session's own loop stalled, not only the input.
LATE_TIMER_S = 0.03
#: How long a late timer waits for the heartbeats the stall held back before it stops (s).
STALL_GRACE_S = 0.02


class IntentSink(Protocol):
    """Where the arbiter sends the intents it lets through (the session, or a test recorder)."""

    def set_intent(self, intent: Intent) -> None:
        """Take the newest intent at once; raises JogBuildError (in words) for an invalid one."""
        ...

    def can_jog(self) -> tuple[bool, str | None]:
        """Whether a new jog may start now, and if not why, in words."""
        ...


class Cancellable(Protocol):
    """A scheduled callback that can be called off (asyncio.TimerHandle is one)."""

    def cancel(self) -> None:
        """Call it off."""
        ...


class Clock(Protocol):
    """Time in seconds and a one-shot timer: the event loop, or a fake one in tests."""

    def time(self) -> float:
        """Now, in seconds on this clock."""
        ...

    def call_at(self, when: float, callback: Callable[[], object], /) -> Cancellable:
        """Run callback once at time `when` on this clock."""
        ...


@dataclass
class Lease:
    """The dead-man of one held jog: it runs out window_s after the last thing heard."""

    window_s: float
    last_heard_s: float

    def deadline_s(self) -> float:
        """When silence becomes a trip."""
        return self.last_heard_s + self.window_s

    def expired(self, now_s: float) -> bool:
        """True when nothing was heard for at least window_s before now_s."""
        return now_s >= self.deadline_s()


def check_lease_s(input_: Input) -> None:
    """Refuse an input whose lease is neither None nor a positive, finite number of seconds."""
    lease_s = input_.lease_s
    if lease_s is not None and not (math.isfinite(lease_s) and lease_s > 0.0):
        raise InputRefused(
            f"{input_.kind} input {input_.name}: its dead-man window lease_s must be a positive "
            f"number of seconds (e.g. 0.15) or None, got {lease_s!r}"
        )


class _Handle:
    """An attached input's InputHandle: every call goes to the arbiter with the clock's time."""

    def __init__(self, arbiter: Arbiter, input_: Input) -> None:
        self.arbiter = arbiter
        self.input = input_
        self.detached = False

    def submit(self, intent: Intent) -> None:
        """See InputHandle.submit."""
        self.arbiter._submit(self, intent, self.arbiter.now_s())

    def alive(self) -> None:
        """See InputHandle.alive."""
        self.arbiter._alive(self, self.arbiter.now_s())

    def take_control(self) -> None:
        """See InputHandle.take_control."""
        self.arbiter._take_control(self)

    @property
    def in_control(self) -> bool:
        """See InputHandle.in_control."""
        return self.arbiter._controller is self

    def detach(self) -> None:
        """See InputHandle.detach; a second call does nothing."""
        self.arbiter._detach(self)


class Arbiter:
    """Decides which input drives the machine and stops it when the driver goes silent or away."""

    def __init__(self, sink: IntentSink, *, clock: Clock | None = None) -> None:
        """Arbitrate for sink; clock None means the running event loop, looked up when needed."""
        self.sink = sink
        self._given_clock = clock
        self._handles: list[_Handle] = []
        self._controller: _Handle | None = None
        #: The controller holds a continuous jog (its stick is deflected).
        self._holding = False
        #: Steps or a go-to were ordered and not stopped since: they may still be running.
        self._motion = False
        self._lease: Lease | None = None
        self._timer: Cancellable | None = None
        self._listeners: list[Callable[[], None]] = []
        self._notice_listeners: list[Callable[[str], None]] = []
        #: How many times the dead-man lease ran out and stopped the machine.
        self.trips = 0
        #: Inputs whose held jog was stopped (the dead-man, another input's STOP) and that have
        #: not released since, with why their jogs wait.
        self._tripped: dict[_Handle, str] = {}
        self._timer_due_s = 0.0
        #: The lease timer ran late once since the last renewal and was given STALL_GRACE_S.
        self._graced = False

    # -- observation -------------------------------------------------------------------------

    @property
    def controller(self) -> Input | None:
        """The input in control, or None."""
        return None if self._controller is None else self._controller.input

    @property
    def inputs(self) -> tuple[Input, ...]:
        """Every attached input, in the order they attached."""
        return tuple(h.input for h in self._handles)

    @property
    def holding(self) -> bool:
        """True while the controller holds a continuous jog."""
        return self._holding

    @property
    def lease_armed(self) -> bool:
        """True while a held jog is watched by the dead-man lease."""
        return self._lease is not None

    def deadline_s(self) -> float | None:
        """When the armed lease runs out, or None."""
        return None if self._lease is None else self._lease.deadline_s()

    def add_listener(self, callback: Callable[[], None]) -> None:
        """Call callback (no arguments) whenever the controlling input changes."""
        self._listeners.append(callback)

    def add_notice_listener(self, callback: Callable[[str], None]) -> None:
        """Call callback with every sentence an input announces for all to see."""
        self._notice_listeners.append(callback)

    def announce(self, text: str) -> None:
        """Tell every notice listener (the pendant's pages) something about an input."""
        for callback in list(self._notice_listeners):
            try:
                callback(text)
            except Exception:  # a listener that cannot show it must not stop the announcer
                log.exception("an arbiter notice listener failed")

    def now_s(self) -> float:
        """The arbiter's clock."""
        return self._clock().time()

    # -- inputs ------------------------------------------------------------------------------

    def attach(self, input_: Input) -> InputHandle:
        """Admit an input; it controls if nobody does, else it watches."""
        check_lease_s(input_)
        if any(h.input is input_ for h in self._handles):
            raise InputRefused(f"{input_.kind} input {input_.name} is already attached")
        handle = _Handle(self, input_)
        self._handles.append(handle)
        log.info("%s input %s attached", input_.kind, input_.name)
        if self._controller is None:
            self._controller = handle
            self._control_changed()
        return handle

    async def run_input(self, input_: Input) -> None:
        """Attach input, run it until it ends, and detach it however it ended."""
        handle = self.attach(input_)
        try:
            await input_.run(handle)
        except Exception:  # any failure of a device means it is gone; the detach handles it
            log.exception("%s input %s failed; detaching it", input_.kind, input_.name)
        else:
            log.info("%s input %s ended", input_.kind, input_.name)
        finally:
            handle.detach()

    # -- the dead-man, pure: time passed in --------------------------------------------------

    def check(self, now_s: float) -> bool:
        """Stop the machine if the lease ran out by now_s; True when it did (a trip)."""
        lease = self._lease
        if lease is None or not lease.expired(now_s):
            return False
        silent_s = now_s - lease.last_heard_s
        holder = self._controller
        self.trips += 1
        name = "?" if holder is None else holder.input.name
        log.warning("dead-man: nothing heard from %s for %.0f ms, stopping", name, silent_s * 1e3)
        self._halt(f"the dead-man (nothing heard from {name} for {silent_s * 1e3:.0f} ms)")
        if holder is not None:
            self._tripped[holder] = (
                "the dead-man stopped this jog; release the controls and press again"
            )
            try:
                holder.input.notice(LeaseExpired(silent_s=silent_s, lease_s=lease.window_s))
            except Exception:  # an input that cannot show the notice must not hide the stop
                log.exception("%s could not be told of its dead-man trip", name)
        return True

    def machine_lost(self) -> None:
        """The link to the controller went away: forget the held jog, and make the input that
        held it let go and press again, so a stick still held does not move the machine the
        moment the link is back."""
        holder = self._controller
        if self._holding and holder is not None:
            self._tripped[holder] = (
                "the link to the controller was lost during this jog; release the controls and"
                " press again"
            )
        self._halt("the lost link to the controller")

    # -- the rules behind the handles --------------------------------------------------------

    def _submit(self, handle: _Handle, intent: Intent, now_s: float) -> None:
        if isinstance(intent, StopIntent) and not handle.detached:
            self._tripped.pop(handle, None)
            by = intent.by or _describe(handle)
            letting_go = handle is self._controller and self._holding and not intent.button
            self._latch_holder(handle, by)
            self._release()
            self._forward(StopIntent(by, release=letting_go))
            return
        self._require_in_control(handle)
        if isinstance(intent, StopIntent) or (
            isinstance(intent, ContinuousIntent) and intent.is_neutral()
        ):
            self._tripped.pop(handle, None)
            # A neutral stick with nothing held is no news; it must not cancel queued steps.
            if self._holding or isinstance(intent, StopIntent):
                self._release()
                self._forward(intent)
            return
        if isinstance(intent, ContinuousIntent):
            latched = self._tripped.get(handle)
            if latched is not None:
                raise InputRefused(latched)
            if not self._holding:
                self._require_can_jog()
            try:
                self._forward(intent)
            except InputRefused:
                if self._holding:
                    # The user changed the held jog into one we cannot do: the old one must end.
                    self._halt(f"{_describe(handle)} (its new jog was refused)")
                raise
            self._holding = True
            if handle.input.lease_s is not None:
                self._renew(handle.input.lease_s, now_s)
            return
        self._require_can_jog()
        self._forward(intent)
        self._motion = True

    def _alive(self, handle: _Handle, now_s: float) -> None:
        if handle is self._controller and self._lease is not None:
            self._renew(self._lease.window_s, now_s)

    def _take_control(self, handle: _Handle) -> None:
        if handle.detached:
            raise InputRefused(self._detached_text(handle))
        current = self._controller
        if current is handle:
            return
        if current is not None and self._holding:
            raise InputRefused(
                f"another {kind_noun(current.input.kind)} is holding a jog; control can pass "
                "once it releases"
            )
        log.info("%s input %s takes control", handle.input.kind, handle.input.name)
        # Steps the old controller queued run on; the new controller now answers for them.
        self._controller = handle
        self._control_changed()

    def _detach(self, handle: _Handle) -> None:
        if handle.detached:
            return
        handle.detached = True
        self._tripped.pop(handle, None)
        self._handles.remove(handle)
        log.info("%s input %s detached", handle.input.kind, handle.input.name)
        if handle is not self._controller:
            return
        if self._holding or self._motion:
            self._halt(f"{_describe(handle)} going away")
        self._controller = None
        self._control_changed()

    # -- helpers -----------------------------------------------------------------------------

    def _require_in_control(self, handle: _Handle) -> None:
        if handle.detached:
            raise InputRefused(self._detached_text(handle))
        if handle is not self._controller:
            noun = kind_noun(handle.input.kind)
            raise InputRefused(f"this {noun} is watching only; take control to drive the machine")

    @staticmethod
    def _detached_text(handle: _Handle) -> str:
        return (
            f"{handle.input.kind} input {handle.input.name} is detached; attach it again "
            "to drive the machine"
        )

    def _require_can_jog(self) -> None:
        try:
            ok, reason = self.sink.can_jog()
        except Exception as exc:  # the machine side may fail in any way; the machine must stop
            log.exception("the intent sink failed to say whether it can jog")
            self._halt("a failure on the machine side")
            raise InputRefused(str(exc)) from exc
        if not ok:
            raise InputRefused(f"jogging is disabled: {reason or 'the machine gives no reason'}")

    def _forward(self, intent: Intent) -> None:
        """Hand the sink an intent; its refusal becomes InputRefused raised from it."""
        try:
            self.sink.set_intent(intent)
        except JogBuildError as exc:
            raise InputRefused(str(exc)) from exc
        except Exception as exc:  # the machine side may fail in any way; the machine must stop
            log.exception("the intent sink failed on %r", intent)
            self._halt("a failure on the machine side")
            raise InputRefused(str(exc)) from exc

    def _renew(self, window_s: float, now_s: float) -> None:
        self._graced = False
        if self._lease is None:
            self._lease = Lease(window_s, now_s)
        else:
            self._lease.window_s = window_s
            self._lease.last_heard_s = now_s
        self._schedule()

    def _release(self) -> None:
        """Forget the held jog and any motion: the machine was told to stop."""
        self._holding = False
        self._motion = False
        self._lease = None
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _latch_holder(self, stopper: _Handle, by: str) -> None:
        """Someone else stopped the held jog: its input must release before it jogs again."""
        holder = self._controller
        if self._holding and holder is not None and holder is not stopper:
            self._tripped[holder] = f"{by} stopped this jog; release the controls and press again"

    def _halt(self, by: str) -> None:
        """Stop the machine for by (who or what stops it, in words); a failing stop is logged
        loudly (nothing more can be done here)."""
        self._release()
        try:
            self.sink.set_intent(StopIntent(by))
        except Exception:
            log.exception("the intent sink failed to stop (%s)", by)

    def _clock(self) -> Clock:
        return self._given_clock if self._given_clock is not None else asyncio.get_running_loop()

    def _schedule(self) -> None:
        # One timer per window, not per heartbeat: when it fires early it re-arms itself.
        if self._timer is None and self._lease is not None:
            self._timer_due_s = self._lease.deadline_s()
            self._timer = self._clock().call_at(self._timer_due_s, self._on_timer)

    def _on_timer(self) -> None:
        self._timer = None
        now_s = self.now_s()
        lease = self._lease
        if (
            lease is not None
            and lease.expired(now_s)
            and now_s - self._timer_due_s > LATE_TIMER_S
            and not self._graced
        ):
            # The timer ran late, so this process itself stalled (a loaded machine): the
            # heartbeats of that time may be read but not yet handled (the reader runs after
            # the timers of the same loop pass). Look again once they are, before stopping.
            self._graced = True
            self._timer_due_s = now_s + STALL_GRACE_S
            self._timer = self._clock().call_at(self._timer_due_s, self._on_timer)
            return
        if not self.check(now_s):
            self._schedule()

    def _control_changed(self) -> None:
        for callback in list(self._listeners):
            try:
                callback()
            except Exception:  # a broken listener must not undo a change of control
                log.exception("an arbiter listener failed")


def _describe(handle: _Handle) -> str:
    """An input as a page names it: its kind's noun and its name ("pendant #2 10.0.0.5"), the
    noun once where the name already starts with it ("gamepad Xbox Wireless Controller")."""
    noun, name = kind_noun(handle.input.kind), handle.input.name
    return name if name.lower().startswith(noun.lower()) else f"{noun} {name}"


__all__ = ["Arbiter", "Cancellable", "Clock", "IntentSink", "Lease", "check_lease_s"]
