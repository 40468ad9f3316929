"""The motion gate through the real host against the simulated Grbl 1.1h, in virtual time.

Every stop here is judged on the simulator's own position and state (the ground truth), not on
smoothjog's view: a stop passes from anyone, does what the motion under way needs, and latches
a jog held elsewhere until that input lets go.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TypeVar

import pytest

from smoothjog.authority.arbiter import Arbiter
from smoothjog.authority.gate import MotionGate, StopRecord
from smoothjog.control import ControlRefused, MachineControl
from smoothjog.core.engine import JogTuning
from smoothjog.core.errors import InputRefused
from smoothjog.core.intents import ContinuousIntent, Intent, StepIntent, StopIntent
from smoothjog.core.ledger import CONSOLE, foreign
from smoothjog.core.responses import ErrorReply
from smoothjog.inputs.base import Input, InputHandle, Notice
from smoothjog.virtual import VirtualHost
from tests.hobby import hobby_router, run

T = TypeVar("T")

JOG = ContinuousIntent({"X": -1.0}, 1.0)
NEUTRAL = ContinuousIntent({"X": 0.0}, 1.0)
#: The hobby router's stopping distance at full jog speed, v²/2a (5000 mm/min, 500 mm/s²), plus
#: one status period of motion (50 ms at 83.3 mm/s): the most a stop may let it run, mm.
STOP_BOUND_MM = (5000 / 60) ** 2 / (2 * 500) + 5000 / 60 * JogTuning().poll_moving_s


@pytest.fixture
def vh() -> Iterator[VirtualHost]:
    host = hobby_router()
    yield host
    host.close()


def stop(vh: VirtualHost, gate: MotionGate, by: str) -> StopRecord:
    """A stop given from inside the session's loop, as every input gives it."""

    async def give() -> StopRecord:
        return gate.stop(by)

    return run(vh, give())


def x_mm(vh: VirtualHost) -> float:
    """Where the simulated machine really is on X."""
    return vh.rig.firmware.mpos_mm()[0]


@dataclass(eq=False)
class Page(Input):
    """An input the test drives by hand through its handle."""

    name: str
    kind: str = "web"
    lease_s: float | None = None
    notices: list[Notice] = field(default_factory=list)

    async def run(self, handle: InputHandle) -> None:  # pragma: no cover - driven by hand
        raise AssertionError("the test drives this input through its handle")

    def notice(self, notice: Notice) -> None:
        self.notices.append(notice)


@dataclass
class Session:
    """A host, its gate and control, an arbiter, and the stops every page would hear."""

    vh: VirtualHost
    control: MachineControl
    arbiter: Arbiter
    stops: list[StopRecord]

    @property
    def gate(self) -> MotionGate:
        return self.control.gate

    def hold(self, handle: InputHandle, intent: Intent, seconds: float) -> None:
        """Repeat intent every 30 ms (a page's heartbeat) for seconds of virtual time."""
        end_s = self.vh.now_s + seconds
        while self.vh.now_s < end_s:
            handle.submit(intent)
            self.vh.run_until(self.vh.now_s + 0.03)


@pytest.fixture
def session(vh: VirtualHost) -> Session:
    control = MachineControl(vh.host)
    stops: list[StopRecord] = []
    control.gate.add_stop_listener(stops.append)
    return Session(vh, control, Arbiter(control.gate, clock=vh.loop), stops)


def test_a_watchers_stop_is_not_undone_by_the_held_jogs_next_heartbeat(session: Session) -> None:
    vh = session.vh
    a = session.arbiter.attach(Page("#1 phone"))
    b = session.arbiter.attach(Page("#2 laptop"))
    session.hold(a, JOG, 1.0)
    b.submit(StopIntent())
    stopped_at = x_mm(vh)
    # Page A's finger stays down and its heartbeats keep coming: every one is refused.
    refusals: list[str] = []
    end_s = vh.now_s + 2.0
    while vh.now_s < end_s:
        with pytest.raises(InputRefused) as refused:
            a.submit(JOG)
        refusals.append(str(refused.value))
        vh.run_until(vh.now_s + 0.03)
    assert vh.rig.firmware.status_state() == "Idle"
    assert abs(x_mm(vh) - stopped_at) <= STOP_BOUND_MM
    assert refusals[0] == (
        "pendant #2 laptop stopped this jog; release the controls and press again"
    )
    assert [s.by for s in session.stops] == ["pendant #2 laptop"]
    assert session.stops[0].text == "stopped by pendant #2 laptop: the jog was cancelled"
    # Released and pressed anew, page A jogs again.
    a.submit(NEUTRAL)
    vh.run_until(vh.now_s + 0.5)
    before = x_mm(vh)
    session.hold(a, JOG, 0.5)
    assert x_mm(vh) < before - 5.0


def test_the_holders_own_release_is_no_announced_stop(session: Session) -> None:
    a = session.arbiter.attach(Page("#1 phone"))
    session.hold(a, JOG, 0.5)
    a.submit(StopIntent())
    session.vh.run_until(session.vh.now_s + 1.0)
    assert session.stops == []
    assert session.vh.rig.firmware.status_state() == "Idle"


def test_stop_feed_holds_a_console_move(session: Session) -> None:
    vh = session.vh
    start = x_mm(vh)
    task = vh.loop.create_task(session.control.console("G1X-150F3000"))
    vh.run_until(vh.now_s + 0.5)
    assert task.done()
    assert task.result().ok
    record = stop(vh, session.gate, "pendant #2 laptop")
    assert record.actions == ("hold",)
    assert "feed hold: press Resume" in record.text
    vh.run_until(vh.now_s + 2.0)
    assert vh.rig.firmware.status_state() == "Hold:0"
    assert x_mm(vh) > -149.0  # held far from the target, at rest
    moved = x_mm(vh)
    vh.run_until(vh.now_s + 2.0)
    assert x_mm(vh) == moved
    assert start - moved > 1.0
    assert session.control.gate.command_refusal("resume") is None
    from smoothjog.web.session_backend import SessionBackend

    control = SessionBackend(vh.host, control=session.control).view()["control"]
    assert isinstance(control, dict)
    assert control["offer"] == ["resume", "reset"]


def test_stop_feed_holds_a_console_move_the_last_report_does_not_show_yet(
    session: Session,
) -> None:
    vh = session.vh
    task = vh.loop.create_task(session.control.console("G1X-150F3000"))
    # The `ok` is in; no report since has said Run (the model may still say Idle).
    while not task.done():
        vh.run_until(vh.now_s + 0.001)
    vh.model.state = "Idle"
    record = stop(vh, session.gate, "pendant #1 phone")
    assert record.actions == ("hold",)
    vh.run_until(vh.now_s + 2.0)
    assert vh.rig.firmware.status_state() == "Hold:0"


def test_stop_during_homing_resets_and_says_so() -> None:
    vh = hobby_router("power-up")
    try:
        control = MachineControl(vh.host)
        task = vh.loop.create_task(control.home())
        vh.run_until(vh.now_s + 1.0)
        assert control.running == "homing"
        record = stop(vh, control.gate, "the keyboard")
        assert record.actions == ("reset",)
        assert "homing was ended with a reset" in record.text
        vh.run_until(vh.now_s + 1.0)
        assert task.done()
        result = task.result()
        # The alarm homing ends with is said, as a failure or in the lines the command printed.
        assert "ALARM" in f"{result.error} {result.lines}"
        at = vh.rig.firmware.mpos_mm()
        vh.run_until(vh.now_s + 2.0)
        assert vh.rig.firmware.mpos_mm() == at
        assert vh.rig.firmware.status_state() == "Alarm"
    finally:
        vh.close()


def test_stop_of_a_step_cancels_it(session: Session) -> None:
    vh = session.vh
    a = session.arbiter.attach(Page("#1 phone"))
    a.submit(StepIntent("X", -100.0, 1.0))
    vh.run_until(vh.now_s + 0.5)
    record = stop(vh, session.gate, "pendant #1 phone")
    assert record.actions == ("cancel",)
    vh.run_until(vh.now_s + 1.0)
    assert vh.rig.firmware.status_state() == "Idle"
    assert x_mm(vh) > -100.0 + 50.0


def test_a_settings_dump_waits_for_a_move_the_report_has_not_shown(session: Session) -> None:
    vh = session.vh
    first = vh.loop.create_task(session.control.console("G0X-2"))
    while not first.done():
        vh.run_until(vh.now_s + 0.001)
    with pytest.raises(ControlRefused, match="the machine is moving"):
        run(vh, session.control.console("$$"))
    vh.run_until(vh.now_s + 1.0)
    assert run(vh, session.control.console("$$")).ok


def test_a_reset_goes_while_a_line_waits_for_its_reply(session: Session) -> None:
    vh = session.vh
    session.gate.begin("homing")  # a command in flight
    assert session.gate.command_refusal("reset") is None
    assert session.gate.command_refusal("unlock") == "wait: homing has not finished"
    session.gate.end()
    result = run(vh, session.control.soft_reset())
    assert result.ok
    assert vh.host.ledger.stats.realtime[CONSOLE] >= 1


def test_a_startup_line_that_moves_is_stored_only_when_sent_twice(session: Session) -> None:
    vh = session.vh
    line = "$N0=G0X-5"
    with pytest.raises(ControlRefused, match="moves the machine at every reset"):
        run(vh, session.control.console(line))
    assert run(vh, session.control.console(line)).ok
    assert vh.rig.firmware.startup_lines[0] == "G0X-5"
    # A startup line that only sets modes goes at once.
    assert run(vh, session.control.console("$N1=G21G90")).ok


def test_commands_follow_the_state_table(session: Session) -> None:
    gate = session.gate
    assert gate.command_refusal("resume") == (
        "nothing to resume: the machine is in Idle, not in Hold"
    )
    assert gate.command_refusal("console", "G0 X-1") is None
    session.vh.model.state = "Alarm"
    assert gate.command_refusal("console", "G0 X-1") == (
        "the controller is in Alarm: unlock ($X) or home ($H) first, or reset it"
    )
    assert gate.command_refusal("console", "$$") is None
    assert gate.command_refusal("unlock") is None
    assert gate.command_refusal("zero") == (
        "the controller is in Alarm: unlock ($X) or home ($H) first, or reset it"
    )


def test_stop_cancels_another_programs_jog(session: Session) -> None:
    vh = session.vh
    assert run(vh, session.control.console("$J=G91X-100F3000")).ok
    vh.run_until(vh.now_s + 0.5)
    assert vh.rig.firmware.status_state() == "Jog"
    record = stop(vh, session.gate, "pendant #1 phone")
    assert record.actions == ("cancel",)
    vh.run_until(vh.now_s + 1.0)
    assert vh.rig.firmware.status_state() == "Idle"
    assert x_mm(vh) > -100.0 + 50.0


def test_a_console_line_is_judged_on_a_fresh_report(session: Session) -> None:
    vh = session.vh

    async def another_program_runs() -> None:
        await vh.host.write_line(foreign("sender"), "G1X-100F3000")

    run(vh, another_program_runs())
    vh.run_until(vh.now_s + 0.3)
    vh.model.state = "Idle"  # the last report is older than the move
    with pytest.raises(ControlRefused, match="the machine is moving"):
        run(vh, session.control.console("$$"))
    assert not [r for _, r in vh.received if isinstance(r, ErrorReply)]


def test_the_state_shown_is_smoothjogs_own_when_the_link_is_lost(session: Session) -> None:
    from smoothjog.core.errors import LinkError
    from smoothjog.web.session_backend import SessionBackend

    backend = SessionBackend(session.vh.host, control=session.control)
    assert backend.view()["state"] == "Idle"
    assert backend.view()["link"] == "up"
    session.vh.host.link_error = LinkError("/dev/ttyUSB0 was unplugged")
    view = backend.view()
    assert (view["state"], view["link"], view["can_jog"]) == ("Lost", "lost", False)
    assert view["reason"] == "the connection to the controller is lost"
    assert view["fault"] == {
        "text": "/dev/ttyUSB0 was unplugged",
        "hint": "check the cable and restart",
    }
    control = view["control"]
    assert isinstance(control, dict)
    assert set(control["commands"].values()) == {"the connection to the controller is lost"}
    session.vh.host.link_error = None
