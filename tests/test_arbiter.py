"""The arbiter's rules with a fake clock and a recording sink: control, dead-man, stop on leave."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field

import pytest

from smoothjog.authority.arbiter import STALL_GRACE_S, Arbiter, Lease
from smoothjog.core.errors import InputRefused, JogBuildError, SmoothjogError
from smoothjog.core.intents import ContinuousIntent, GotoIntent, Intent, StepIntent, StopIntent
from smoothjog.inputs.base import Input, InputHandle, LeaseExpired, Notice

LEASE_S = 0.15
JOG = ContinuousIntent({"X": 0.5}, 0.5)
JOG_Y = ContinuousIntent({"Y": -1.0}, 0.25)
NEUTRAL = ContinuousIntent({"X": 0.0, "Y": 0.0}, 0.5)
STEP = StepIntent("X", 1.0, 0.5)
GOTO = GotoIntent({"X": -10.0}, 0.5)
STOP = StopIntent()


# -- fakes -----------------------------------------------------------------------------------------


@dataclass
class FakeTimer:
    """One call_at of the fake clock."""

    when: float
    callback: Callable[[], object]
    cancelled: bool = False
    fired: bool = False

    def cancel(self) -> None:
        self.cancelled = True


@dataclass
class FakeClock:
    """The arbiter's clock in tests: time moves only when told, timers fire when passed."""

    now: float = 0.0
    timers: list[FakeTimer] = field(default_factory=list)

    def time(self) -> float:
        return self.now

    def call_at(self, when: float, callback: Callable[[], object], /) -> FakeTimer:
        timer = FakeTimer(when, callback)
        self.timers.append(timer)
        return timer

    def pending(self) -> list[FakeTimer]:
        return [t for t in self.timers if not t.cancelled and not t.fired]

    def advance(self, to_s: float) -> None:
        """Move the clock to to_s, firing every due timer in time order (new ones included)."""
        while True:
            due = sorted((t for t in self.pending() if t.when <= to_s), key=lambda t: t.when)
            if not due:
                break
            timer = due[0]
            self.now = max(self.now, timer.when)
            timer.fired = True
            timer.callback()
        self.now = to_s


class Sink:
    """An IntentSink that records what reaches the machine; it can refuse or fail on cue."""

    def __init__(self) -> None:
        self.intents: list[Intent] = []
        self.jog_ok: tuple[bool, str | None] = (True, None)
        self.raises: dict[type, Exception] = {}
        self.can_jog_calls = 0
        self.can_jog_error: Exception | None = None

    def set_intent(self, intent: Intent) -> None:
        error = self.raises.get(type(intent))
        if error is not None:
            raise error
        self.intents.append(intent)

    def can_jog(self) -> tuple[bool, str | None]:
        self.can_jog_calls += 1
        if self.can_jog_error is not None:
            raise self.can_jog_error
        return self.jog_ok

    def stops(self) -> int:
        return sum(isinstance(i, StopIntent) for i in self.intents)


Script = Callable[[InputHandle], Awaitable[None]]


async def _idle(handle: InputHandle) -> None:
    return None


class FakeInput(Input):
    """An input whose run is a script; it keeps the notices it is given."""

    def __init__(
        self,
        name: str = "pad",
        *,
        kind: str = "gamepad",
        lease_s: float | None = LEASE_S,
        script: Script = _idle,
    ) -> None:
        self.name = name
        self.kind = kind
        self.lease_s = lease_s
        self.script = script
        self.notices: list[Notice] = []

    async def run(self, handle: InputHandle) -> None:
        await self.script(handle)

    def notice(self, notice: Notice) -> None:
        self.notices.append(notice)


@dataclass
class Rig:
    """An arbiter over a recording sink with a fake clock, and a log of control changes."""

    sink: Sink
    clock: FakeClock
    arbiter: Arbiter
    changes: list[str | None]

    def attach(self, name: str = "pad", **kw: object) -> tuple[FakeInput, InputHandle]:
        device = FakeInput(name, **kw)  # type: ignore[arg-type]
        return device, self.arbiter.attach(device)


@pytest.fixture
def rig() -> Rig:
    sink = Sink()
    clock = FakeClock()
    arbiter = Arbiter(sink, clock=clock)
    changes: list[str | None] = []
    arbiter.add_listener(
        lambda: changes.append(None if arbiter.controller is None else arbiter.controller.name)
    )
    return Rig(sink, clock, arbiter, changes)


# -- the lease bookkeeping -------------------------------------------------------------------------


def test_a_lease_runs_out_window_s_after_the_last_thing_heard() -> None:
    lease = Lease(0.15, 10.0)
    assert lease.deadline_s() == pytest.approx(10.15)
    assert not lease.expired(10.149)
    assert lease.expired(10.15)
    lease.last_heard_s = 10.1
    assert not lease.expired(10.2)
    assert lease.expired(10.26)


# -- control ---------------------------------------------------------------------------------------


def test_the_first_attached_controls_and_later_ones_watch(rig: Rig) -> None:
    pad, pad_h = rig.attach("pad")
    web, web_h = rig.attach("page", kind="web")
    assert rig.arbiter.controller is pad
    assert pad_h.in_control
    assert not web_h.in_control
    assert rig.arbiter.inputs == (pad, web)
    assert rig.changes == ["pad"]


@pytest.mark.parametrize("intent", [JOG, NEUTRAL, STEP, GOTO], ids=repr)
def test_a_watcher_is_refused_every_intent_and_nothing_reaches_the_machine(
    rig: Rig, intent: Intent
) -> None:
    rig.attach("pad")
    _, page = rig.attach("page", kind="web")
    with pytest.raises(InputRefused, match="this pendant is watching only; take control"):
        page.submit(intent)
    assert rig.sink.intents == []
    assert rig.sink.can_jog_calls == 0


def test_a_watchers_stop_stops_the_controllers_jog(rig: Rig) -> None:
    # A STOP button on a device that only watches must still stop the machine.
    _, pad = rig.attach("pad")
    _, page = rig.attach("page", kind="web")
    pad.submit(JOG)
    page.submit(STOP)
    assert rig.sink.intents == [JOG, STOP]
    assert not rig.arbiter.holding
    assert not rig.arbiter.lease_armed


def test_a_detached_inputs_stop_is_refused(rig: Rig) -> None:
    rig.attach("pad")
    _, page = rig.attach("page", kind="web")
    page.detach()
    with pytest.raises(InputRefused, match="detached"):
        page.submit(STOP)
    assert rig.sink.intents == []


@pytest.mark.parametrize(
    ("held", "lease_s", "passes"),
    [
        (None, LEASE_S, True),
        (STEP, LEASE_S, True),  # queued steps do not pin control
        (JOG, LEASE_S, False),  # a held jog does, with a lease ...
        (JOG, None, False),  # ... or without one
    ],
    ids=["idle", "steps-queued", "held-jog", "held-jog-no-lease"],
)
def test_take_control_passes_unless_the_controller_holds_a_jog(
    rig: Rig, held: Intent | None, lease_s: float | None, passes: bool
) -> None:
    _, pad = rig.attach("pad", lease_s=lease_s)
    _, page = rig.attach("page", kind="web")
    if held is not None:
        pad.submit(held)
    if passes:
        page.take_control()
        assert page.in_control
        assert not pad.in_control
        assert rig.changes == ["pad", "page"]
    else:
        with pytest.raises(
            InputRefused,
            match=r"^another gamepad is holding a jog; control can pass once it releases$",
        ):
            page.take_control()
        assert pad.in_control
        pad.submit(NEUTRAL)
        page.take_control()
        assert page.in_control


def test_take_control_by_the_controller_changes_nothing(rig: Rig) -> None:
    _, pad = rig.attach("pad")
    pad.take_control()
    assert pad.in_control
    assert rig.changes == ["pad"]


def test_when_the_controller_leaves_nobody_controls_until_asked(rig: Rig) -> None:
    _, pad = rig.attach("pad")
    _, page = rig.attach("page", kind="web")
    pad.detach()
    assert rig.arbiter.controller is None
    assert not page.in_control
    assert rig.changes == ["pad", None]
    with pytest.raises(InputRefused, match="watching only"):
        page.submit(JOG)
    page.take_control()
    assert page.in_control
    # A newcomer while someone controls watches.
    _, late = rig.attach("late")
    assert not late.in_control


def test_a_detached_handle_is_refused_and_detach_twice_is_harmless(rig: Rig) -> None:
    _, pad = rig.attach("pad")
    pad.detach()
    pad.detach()
    actions: list[Callable[[], None]] = [lambda: pad.submit(STOP), pad.take_control]
    for action in actions:
        with pytest.raises(InputRefused, match="is detached; attach it again"):
            action()
    assert rig.sink.intents == []


@pytest.mark.parametrize("lease_s", [0.0, -0.1, float("nan"), float("inf")])
def test_an_input_with_an_impossible_lease_is_refused(rig: Rig, lease_s: float) -> None:
    with pytest.raises(InputRefused, match="lease_s must be a positive number of seconds"):
        rig.attach("pad", lease_s=lease_s)
    assert rig.arbiter.inputs == ()


def test_the_same_input_cannot_attach_twice(rig: Rig) -> None:
    pad, _ = rig.attach("pad")
    with pytest.raises(InputRefused, match="already attached"):
        rig.arbiter.attach(pad)


def test_input_refused_belongs_to_the_error_tree() -> None:
    assert issubclass(InputRefused, SmoothjogError)


# -- can_jog ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("before", "intent", "asks"),
    [
        ([], JOG, True),  # a new continuous jog
        ([], STEP, True),
        ([], GOTO, True),
        ([JOG], JOG_Y, False),  # a held jog's change and heartbeat are not new jogs
        ([JOG], STEP, True),  # a step always is
        ([JOG], NEUTRAL, False),
        ([], STOP, False),
        ([JOG], STOP, False),
    ],
    ids=["jog", "step", "goto", "held-change", "step-while-held", "neutral", "stop", "stop-held"],
)
def test_can_jog_is_asked_before_every_new_jog_only(
    rig: Rig, before: list[Intent], intent: Intent, asks: bool
) -> None:
    _, pad = rig.attach("pad")
    for earlier in before:
        pad.submit(earlier)
    asked = rig.sink.can_jog_calls
    rig.sink.jog_ok = (False, "the controller is in Alarm: unlock with $X or home with $H first")
    if asks:
        with pytest.raises(InputRefused) as info:
            pad.submit(intent)
        assert str(info.value) == (
            "jogging is disabled: the controller is in Alarm: unlock with $X or home with $H first"
        )
        assert intent not in rig.sink.intents[len(before) :]
    else:
        pad.submit(intent)
        assert rig.sink.can_jog_calls == asked
    sent = rig.sink.intents[len(before) :]
    assert sent == ([] if asks else [intent])


def test_jogging_disabled_without_a_reason_still_says_so(rig: Rig) -> None:
    _, pad = rig.attach("pad")
    rig.sink.jog_ok = (False, None)
    with pytest.raises(InputRefused, match=r"^jogging is disabled: the machine gives no reason$"):
        pad.submit(STEP)


def test_a_failing_can_jog_refuses_and_stops(rig: Rig) -> None:
    _, pad = rig.attach("pad")
    rig.sink.can_jog_error = RuntimeError("view broken")
    with pytest.raises(InputRefused, match=r"^view broken$") as info:
        pad.submit(JOG)
    assert isinstance(info.value.__cause__, RuntimeError)
    assert rig.sink.intents == [STOP]


# -- the sink's refusals ---------------------------------------------------------------------------


@pytest.mark.parametrize("intent", [JOG, STEP, GOTO], ids=repr)
def test_a_jog_build_error_reaches_the_input_in_the_same_words_and_arms_nothing(
    rig: Rig, intent: Intent
) -> None:
    _, pad = rig.attach("pad")
    _, page = rig.attach("page", kind="web")
    error = JogBuildError("speed 0.001 gives 0.05 mm/min, below Grbl's 1 mm/min minimum")
    rig.sink.raises[type(intent)] = error
    with pytest.raises(InputRefused) as info:
        pad.submit(intent)
    assert str(info.value) == str(error)
    assert info.value.__cause__ is error
    assert not rig.arbiter.lease_armed
    assert not rig.arbiter.holding
    assert rig.clock.pending() == []
    assert rig.sink.intents == []
    page.take_control()  # nothing is held, so control can pass
    # Nothing was started, so leaving stops nothing either.
    pad.detach()
    assert rig.sink.intents == []


def test_a_held_jog_whose_new_intent_is_refused_is_stopped(rig: Rig) -> None:
    _, pad = rig.attach("pad")
    pad.submit(JOG)
    rig.sink.raises[ContinuousIntent] = JogBuildError("deflection X=2 must be in [-1, 1]")
    with pytest.raises(InputRefused, match=r"^deflection X=2 must be in \[-1, 1\]$"):
        pad.submit(JOG_Y)
    assert rig.sink.intents == [JOG, STOP]
    assert not rig.arbiter.lease_armed
    assert not rig.arbiter.holding


def test_a_failing_sink_refuses_and_stops(rig: Rig) -> None:
    _, pad = rig.attach("pad")
    pad.submit(JOG)
    rig.sink.raises[StepIntent] = RuntimeError("backend exploded")
    with pytest.raises(InputRefused, match=r"^backend exploded$") as info:
        pad.submit(STEP)
    assert isinstance(info.value.__cause__, RuntimeError)
    assert rig.sink.intents == [JOG, STOP]
    assert not rig.arbiter.lease_armed


def test_a_failing_stop_is_logged_and_the_arbiter_carries_on(
    rig: Rig, caplog: pytest.LogCaptureFixture
) -> None:
    _, pad = rig.attach("pad")
    pad.submit(JOG)
    rig.sink.raises[StopIntent] = RuntimeError("link gone")
    with caplog.at_level(logging.ERROR, logger="smoothjog.authority.arbiter"):
        rig.clock.advance(1.0)
    assert rig.arbiter.trips == 1
    assert "failed to stop (the dead-man (nothing heard from pad" in caplog.text


# -- release ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("release", [NEUTRAL, STOP], ids=["neutral", "stop"])
def test_release_passes_even_when_jogging_is_disabled_and_disarms_the_lease(
    rig: Rig, release: Intent
) -> None:
    _, pad = rig.attach("pad")
    pad.submit(JOG)
    timer = rig.clock.pending()[0]
    rig.sink.jog_ok = (False, "the controller is in feed hold")
    pad.submit(release)
    assert rig.sink.intents == [JOG, release]
    assert not rig.arbiter.lease_armed
    assert timer.cancelled
    rig.clock.advance(10.0)
    assert rig.arbiter.trips == 0


def test_a_neutral_stick_with_nothing_held_does_not_cancel_queued_steps(rig: Rig) -> None:
    _, pad = rig.attach("pad")
    pad.submit(STEP)
    pad.submit(NEUTRAL)
    assert rig.sink.intents == [STEP]
    # The steps are still the controller's motion: leaving stops them.
    pad.detach()
    assert rig.sink.intents == [STEP, STOP]


# -- the dead-man lease ----------------------------------------------------------------------------


def test_silence_for_the_lease_stops_once_counts_a_trip_and_tells_the_input(rig: Rig) -> None:
    pad, handle = rig.attach("pad")
    rig.clock.now = 5.0
    handle.submit(JOG)
    assert rig.arbiter.deadline_s() == pytest.approx(5.15)
    assert not rig.arbiter.check(5.149)
    assert rig.arbiter.check(5.2)
    assert rig.sink.intents == [JOG, STOP]
    assert rig.arbiter.trips == 1
    (notice,) = pad.notices
    assert isinstance(notice, LeaseExpired)
    assert notice.silent_s == pytest.approx(0.2)
    assert notice.lease_s == LEASE_S
    assert "200 ms" in pad.notices[0].text
    assert not rig.arbiter.check(6.0)
    assert rig.sink.stops() == 1
    assert rig.arbiter.trips == 1
    # Still the controller, but a jog never restarts by itself under a finger still held: the
    # next heartbeats are refused until the input releases, then a new press jogs.
    with pytest.raises(InputRefused, match="release the controls and press again"):
        handle.submit(JOG)
    assert rig.sink.intents == [JOG, STOP]
    assert not rig.arbiter.lease_armed
    handle.submit(NEUTRAL)
    handle.submit(JOG)
    assert rig.arbiter.lease_armed
    assert rig.sink.intents == [JOG, STOP, JOG]


def test_a_stop_also_ends_the_trip_and_other_inputs_are_not_held_back(rig: Rig) -> None:
    _, pad = rig.attach("pad")
    _, page = rig.attach("page", kind="web")
    pad.submit(JOG)
    assert rig.arbiter.check(10.0)
    pad.submit(STOP)
    pad.submit(JOG)
    assert rig.sink.intents[-1] == JOG
    pad.submit(STOP)
    assert rig.arbiter.check(20.0) is False  # nothing held
    pad.submit(JOG)
    assert rig.arbiter.check(30.0)
    page.take_control()
    page.submit(JOG)  # another input was not the one that tripped
    assert rig.sink.intents[-1] == JOG


def test_a_late_timer_first_lets_the_heartbeats_the_stall_held_back_arrive(rig: Rig) -> None:
    # The session's own loop stalled 300 ms (a loaded machine): the page's heartbeats of that
    # time are waiting in the socket and are handled right after the timer; no false trip.
    _, pad = rig.attach("pad")
    pad.submit(JOG)
    (timer,) = rig.clock.pending()
    rig.clock.now = timer.when + 0.3
    timer.fired = True
    timer.callback()
    assert rig.arbiter.trips == 0
    pad.submit(JOG)  # the held-back heartbeat
    rig.clock.advance(rig.clock.now + 0.1)
    assert rig.arbiter.trips == 0
    assert rig.sink.stops() == 0


def test_a_late_timer_still_stops_a_silent_input_after_the_grace(rig: Rig) -> None:
    _, pad = rig.attach("pad")
    pad.submit(JOG)
    (timer,) = rig.clock.pending()
    late_s = timer.when + 0.3
    rig.clock.now = late_s
    timer.fired = True
    timer.callback()
    assert rig.arbiter.trips == 0
    rig.clock.advance(late_s + STALL_GRACE_S)
    assert rig.arbiter.trips == 1
    assert rig.sink.stops() == 1


@pytest.mark.parametrize("renew", ["submit", "alive"])
def test_submit_and_alive_renew_the_lease(rig: Rig, renew: str) -> None:
    _, handle = rig.attach("pad")
    handle.submit(JOG)
    rig.clock.now = 0.1
    if renew == "submit":
        handle.submit(JOG)
    else:
        handle.alive()
    assert not rig.arbiter.check(0.2)
    assert rig.arbiter.check(0.25)
    expected = [JOG, JOG, STOP] if renew == "submit" else [JOG, STOP]
    assert rig.sink.intents == expected


def test_alive_from_a_watcher_or_with_nothing_held_renews_nothing(rig: Rig) -> None:
    _, pad = rig.attach("pad")
    _, page = rig.attach("page", kind="web")
    pad.alive()
    assert not rig.arbiter.lease_armed
    pad.submit(JOG)
    rig.clock.now = 0.1
    page.alive()
    assert rig.arbiter.check(0.15)
    assert rig.sink.intents == [JOG, STOP]


def test_an_input_without_a_lease_never_trips(rig: Rig) -> None:
    _, keys = rig.attach("keys", kind="keyboard", lease_s=None)
    keys.submit(JOG)
    assert not rig.arbiter.lease_armed
    assert rig.clock.pending() == []
    rig.clock.advance(100.0)
    assert not rig.arbiter.check(100.0)
    assert rig.sink.intents == [JOG]


def test_one_timer_per_window_rearms_itself_until_the_silence_is_real(rig: Rig) -> None:
    pad, handle = rig.attach("pad")
    for t in (0.0, 0.04, 0.08, 0.12):
        rig.clock.now = t
        handle.submit(JOG)
    assert [t.when for t in rig.clock.timers] == [pytest.approx(0.15)]
    rig.clock.advance(0.2)  # the first timer fires; the lease was renewed at 0.12
    assert rig.arbiter.trips == 0
    assert [t.when for t in rig.clock.pending()] == [pytest.approx(0.27)]
    rig.clock.advance(0.3)
    assert rig.arbiter.trips == 1
    assert rig.sink.intents[-1] == STOP
    assert len(pad.notices) == 1
    assert rig.clock.pending() == []


def test_an_input_that_cannot_show_the_notice_does_not_hide_the_stop(rig: Rig) -> None:
    pad, handle = rig.attach("pad")

    def broken(notice: Notice) -> None:
        raise RuntimeError("display unplugged")

    pad.notice = broken  # type: ignore[method-assign]
    handle.submit(JOG)
    assert rig.arbiter.check(1.0)
    assert rig.sink.intents == [JOG, STOP]


# -- stop when an input goes away ------------------------------------------------------------------


async def _hold_then_raise(handle: InputHandle) -> None:
    handle.submit(JOG)
    raise OSError("device unplugged")


async def _hold_then_return(handle: InputHandle) -> None:
    handle.submit(JOG)


async def _steps_then_return(handle: InputHandle) -> None:
    handle.submit(STEP)
    handle.submit(STEP)


async def _goto_then_return(handle: InputHandle) -> None:
    handle.submit(GOTO)


async def _release_then_return(handle: InputHandle) -> None:
    handle.submit(JOG)
    handle.submit(NEUTRAL)


async def _hold_then_cancelled(handle: InputHandle) -> None:
    handle.submit(JOG)
    await asyncio.Event().wait()


@pytest.mark.parametrize(
    ("script", "lease_s", "stops"),
    [
        (_hold_then_raise, LEASE_S, 1),
        (_hold_then_return, LEASE_S, 1),
        (_hold_then_return, None, 1),  # no lease, still stopped when it goes away
        (_steps_then_return, LEASE_S, 1),
        (_goto_then_return, None, 1),
        (_release_then_return, LEASE_S, 0),  # released before leaving: nothing left to stop
        (_idle, LEASE_S, 0),
    ],
    ids=["raises", "returns", "returns-no-lease", "steps", "goto", "released", "idle"],
)
async def test_the_controller_going_away_while_driving_stops_the_machine(
    rig: Rig, script: Script, lease_s: float | None, stops: int
) -> None:
    device = FakeInput("pad", lease_s=lease_s, script=script)
    await rig.arbiter.run_input(device)
    assert rig.sink.stops() == stops
    assert rig.arbiter.inputs == ()
    assert rig.arbiter.controller is None
    assert not rig.arbiter.lease_armed
    assert rig.clock.pending() == []


async def test_a_cancelled_input_is_detached_and_its_jog_stopped(rig: Rig) -> None:
    device = FakeInput("pad", script=_hold_then_cancelled)
    task = asyncio.create_task(rig.arbiter.run_input(device))
    await asyncio.sleep(0)
    assert rig.sink.intents == [JOG]
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert rig.sink.intents == [JOG, STOP]
    assert rig.arbiter.inputs == ()


async def test_a_watcher_going_away_changes_nothing(rig: Rig) -> None:
    _, pad = rig.attach("pad")
    pad.submit(JOG)
    pad.submit(STEP)
    watcher = FakeInput("page", kind="web", script=_hold_then_raise)
    await rig.arbiter.run_input(watcher)  # its submit is refused, then it raises
    assert rig.sink.intents == [JOG, STEP]
    assert rig.arbiter.lease_armed
    assert pad.in_control
    assert rig.changes == ["pad"]


def test_the_new_controller_answers_for_steps_it_inherited(rig: Rig) -> None:
    _, pad = rig.attach("pad")
    _, page = rig.attach("page", kind="web")
    pad.submit(STEP)
    page.take_control()
    pad.detach()  # a watcher now: nothing happens
    assert rig.sink.intents == [STEP]
    page.detach()
    assert rig.sink.intents == [STEP, STOP]


def test_the_controller_leaving_mid_jog_disarms_the_lease_without_a_trip(rig: Rig) -> None:
    _, pad = rig.attach("pad")
    pad.submit(JOG)
    timer = rig.clock.pending()[0]
    pad.detach()
    assert rig.sink.intents == [JOG, STOP]
    assert timer.cancelled
    assert rig.arbiter.trips == 0


class SignallingSink(Sink):
    """A Sink that sets an event when a stop reaches it."""

    def __init__(self) -> None:
        super().__init__()
        self.stopped = asyncio.Event()

    def set_intent(self, intent: Intent) -> None:
        super().set_intent(intent)
        if isinstance(intent, StopIntent):
            self.stopped.set()


async def test_the_running_loop_is_the_default_clock_and_runs_the_timer() -> None:
    sink = SignallingSink()
    arbiter = Arbiter(sink)
    handle = arbiter.attach(FakeInput("pad", lease_s=0.01))
    handle.submit(JOG)
    assert arbiter.lease_armed
    await asyncio.wait_for(sink.stopped.wait(), 5.0)  # the loop's timer trips the lease
    assert arbiter.trips == 1
    assert sink.intents == [JOG, STOP]


def test_an_announcement_reaches_every_notice_listener_even_past_a_broken_one(rig: Rig) -> None:
    heard: list[str] = []

    def broken(text: str) -> None:
        raise RuntimeError("cannot show")

    rig.arbiter.add_notice_listener(broken)
    rig.arbiter.add_notice_listener(heard.append)
    rig.arbiter.announce("whb04b: handwheel asleep")
    assert heard == ["whb04b: handwheel asleep"]


# -- the link to the controller lost ----------------------------------------------------------


def test_a_stick_held_across_a_lost_link_must_be_pressed_again(rig: Rig) -> None:
    # The link went (CNCjs restarted) while the pad held a jog; when it is back, the same held
    # stick, re-sent by its input, must not move the machine: release, then press.
    _, pad = rig.attach("pad")
    pad.submit(JOG)
    rig.arbiter.machine_lost()
    assert rig.sink.intents == [JOG, STOP]
    assert not rig.arbiter.lease_armed
    with pytest.raises(InputRefused, match="press again"):
        pad.submit(JOG)
    pad.submit(NEUTRAL)
    pad.submit(JOG)
    assert rig.sink.intents == [JOG, STOP, JOG]


def test_a_lost_link_with_nothing_held_refuses_nothing_later(rig: Rig) -> None:
    _, pad = rig.attach("pad")
    rig.arbiter.machine_lost()
    pad.submit(JOG)
    assert rig.sink.intents == [STOP, JOG]


# -- a stop latches the held jog ----------------------------------------------------------------


def test_a_watchers_stop_latches_the_held_jog_until_it_is_released(rig: Rig) -> None:
    _, pad_h = rig.attach("pad")
    _, page_h = rig.attach("#2 10.0.0.5", kind="web")
    pad_h.submit(JOG)
    page_h.submit(STOP)
    stop = rig.sink.intents[-1]
    assert isinstance(stop, StopIntent)
    assert (stop.by, stop.release) == ("pendant #2 10.0.0.5", False)
    # The held jog's next heartbeat must not undo the stop.
    with pytest.raises(InputRefused, match=r"^pendant #2 10\.0\.0\.5 stopped this jog; release"):
        pad_h.submit(JOG)
    assert rig.sink.intents[-1] is stop
    assert not rig.arbiter.lease_armed
    pad_h.submit(NEUTRAL)
    pad_h.submit(JOG)
    assert rig.sink.intents[-1] == JOG


def test_the_holders_own_stop_is_a_release_and_latches_nothing(rig: Rig) -> None:
    _, pad_h = rig.attach("pad")
    pad_h.submit(JOG)
    pad_h.submit(STOP)
    stop = rig.sink.intents[-1]
    assert isinstance(stop, StopIntent)
    assert (stop.by, stop.release) == ("gamepad pad", True)
    pad_h.submit(JOG)
    assert rig.sink.intents[-1] == JOG


def test_a_stop_with_nothing_held_latches_nothing(rig: Rig) -> None:
    _, pad_h = rig.attach("pad")
    _, page_h = rig.attach("#2", kind="web")
    page_h.submit(STOP)
    stop = rig.sink.intents[-1]
    assert isinstance(stop, StopIntent)
    assert not stop.release
    pad_h.submit(JOG)
    assert rig.sink.intents[-1] == JOG


def test_a_dead_man_stop_names_the_dead_man(rig: Rig) -> None:
    _, pad_h = rig.attach("pad")
    pad_h.submit(JOG)
    rig.clock.advance(1.0)
    stop = rig.sink.intents[-1]
    assert isinstance(stop, StopIntent)
    assert stop.by.startswith("the dead-man (nothing heard from pad for ")


def test_the_holders_stop_button_is_a_stop_every_page_hears(rig: Rig) -> None:
    _, pad_h = rig.attach("pad")
    pad_h.submit(JOG)
    pad_h.submit(StopIntent(button=True))
    stop = rig.sink.intents[-1]
    assert isinstance(stop, StopIntent)
    assert (stop.by, stop.release) == ("gamepad pad", False)
