"""Machine control (control.py) through the real host against the simulated Grbl, virtual time."""

from __future__ import annotations

from collections.abc import Iterator
from typing import TypeVar

import pytest

from smoothjog.authority.gate import RESET_NEEDED_TEXT
from smoothjog.control import CommandResult, ControlRefused, MachineControl
from smoothjog.core.intents import ContinuousIntent, GotoIntent, StepIntent
from smoothjog.core.ledger import CONSOLE
from smoothjog.core.responses import ErrorReply
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.rig import SimRig
from smoothjog.virtual import VirtualHost
from smoothjog.web.protocol import CommandMessage
from tests.hobby import hobby_router, run

T = TypeVar("T")


@pytest.fixture
def vh() -> Iterator[VirtualHost]:
    host = hobby_router()
    yield host
    host.close()


@pytest.fixture
def alarmed() -> Iterator[VirtualHost]:
    host = hobby_router("power-up")
    yield host
    host.close()


def control(vh: VirtualHost) -> MachineControl:
    return MachineControl(vh.host)


def test_unlock_leaves_alarm_but_an_unhomed_machine_still_may_not_jog(alarmed: VirtualHost) -> None:
    vh = alarmed
    vh.run_until(vh.now_s + 0.3)
    assert vh.model.state == "Alarm"
    result = run(vh, control(vh).unlock())
    assert result == CommandResult("$X", True, ("[MSG:Caution: Unlocked]",))
    vh.run_until(vh.now_s + 0.3)
    assert vh.model.state == "Idle"
    # Unlocked at MPos 0 with soft limits on: the machine may sit on a limit switch, so it may be
    # jogged (inside the envelope as it stands, firmware-facts §2), with a warning to home it.
    from smoothjog.web.session_backend import UNHOMED_WARNING, SessionBackend

    backend = SessionBackend(vh.host)
    assert backend.can_jog() == (True, None)
    assert backend.view()["warning"] == UNHOMED_WARNING
    vh.set_intent(StepIntent("X", -5.0, 0.5))
    vh.run_until(vh.now_s + 2.0)
    assert vh.rig.firmware.mpos_mm()[0] == pytest.approx(-5.0)
    assert backend.view()["warning"] is None
    # Toward + there is no room inside the envelope: refused in words, nothing sent to fail.
    vh.set_intent(StepIntent("X", 10.0, 0.5))
    vh.run_until(vh.now_s + 2.0)
    assert vh.rig.firmware.mpos_mm()[0] == pytest.approx(0.0, abs=0.02)  # one step inside
    assert not [r for _, r in vh.received if isinstance(r, ErrorReply)]


def test_home_runs_the_cycle_and_reads_the_modes_again(alarmed: VirtualHost) -> None:
    vh = alarmed
    c = control(vh)
    seen: list[str | None] = []

    async def home_and_watch() -> CommandResult:
        task = vh.loop.create_task(c.home())
        await __import__("asyncio").sleep(0.5)
        seen.append(c.running)
        seen.append(c.refusal())
        return await task

    result = run(vh, home_and_watch())
    assert result.ok, result
    assert seen[0] == "homing"
    assert seen[1] == "wait: homing has not finished"
    vh.run_until(vh.now_s + 0.3)
    assert vh.model.state == "Idle"
    assert vh.rig.firmware.mpos_mm() == pytest.approx((-1.0, -1.0, -1.0))


def test_a_jog_is_refused_in_words_while_homing(alarmed: VirtualHost) -> None:
    import asyncio

    from smoothjog.web.session_backend import SessionBackend

    vh = alarmed
    backend = SessionBackend(vh.host)
    answers: list[tuple[bool, str | None]] = []

    async def scenario() -> None:
        task = vh.loop.create_task(backend.command(CommandMessage("home", 1)))
        await asyncio.sleep(0.5)
        answers.append(backend.can_jog())
        await task
        await asyncio.sleep(0.3)
        answers.append(backend.can_jog())

    run(vh, scenario())
    assert answers[0] == (False, "jogging waits: homing is running")
    assert answers[1] == (True, None)


def test_home_is_refused_without_homing_switches() -> None:
    rig = SimRig(GrblFirmware(machine="grbl-defaults"))
    vh = VirtualHost(rig)
    vh.handshake()
    try:
        with pytest.raises(ControlRefused, match=r"homing is not enabled .*\$22=0"):
            run(vh, control(vh).home())
    finally:
        vh.close()


def test_work_zero_of_all_axes_and_one_axis(vh: VirtualHost) -> None:
    c = control(vh)
    vh.set_intent(GotoIntent({"X": -100.0, "Y": -50.0, "Z": -20.0}, 1.0))
    assert vh.run_until_idle(10.0)
    result = run(vh, c.set_work_zero(["X", "Y", "Z"]))
    assert result == CommandResult("G10L20P0X0Y0Z0", True)
    vh.run_until(vh.now_s + 0.3)
    assert vh.model.wpos_mm == pytest.approx((0.0, 0.0, 0.0))
    assert vh.model.offsets_mm["G54"] == pytest.approx((-100.0, -50.0, -20.0))
    vh.set_intent(GotoIntent({"X": -90.0}, 1.0))
    assert vh.run_until_idle(10.0)
    assert run(vh, c.set_work_zero(["X"])).ok
    vh.run_until(vh.now_s + 0.3)
    assert vh.model.offsets_mm["G54"] == pytest.approx((-90.0, -50.0, -20.0))


def test_choosing_another_work_system_shows_in_the_modes(vh: VirtualHost) -> None:
    c = control(vh)
    assert run(vh, c.select_wcs("G55")).ok
    assert vh.model.modal.wcs == "G55"
    with pytest.raises(ControlRefused, match="G60"):
        run(vh, c.select_wcs("G60"))


def test_go_to_work_zero_lifts_z_first_and_lands_on_zero(vh: VirtualHost) -> None:
    c = control(vh)
    vh.set_intent(GotoIntent({"X": -300.0, "Y": -300.0, "Z": -60.0}, 1.0))
    assert vh.run_until_idle(20.0)
    assert run(vh, c.set_work_zero(["X", "Y", "Z"])).ok
    vh.set_intent(GotoIntent({"X": -100.0, "Y": -200.0, "Z": -80.0}, 1.0))
    assert vh.run_until_idle(20.0)
    vh.run_until(vh.now_s + 0.3)
    targets = c.work_zero_targets()
    # Up to 1 mm below the top of Z travel (soft limits give it), across, then down.
    assert targets == [{"Z": pytest.approx(-1.0)}, {"X": -300.0, "Y": -300.0}, {"Z": -60.0}]
    trace_from = len(vh.rig.firmware.trace)
    for target in targets:
        vh.set_intent(GotoIntent(target, 1.0))
    assert vh.run_until_idle(30.0)
    assert vh.rig.firmware.mpos_mm() == pytest.approx((-300.0, -300.0, -60.0), abs=0.01)
    # X and Y moved only while Z stood at the safe height.
    for seg in vh.rig.firmware.trace[trace_from:]:
        if seg.start_mm[:2] != seg.end_mm[:2]:
            assert min(seg.start_mm[2], seg.end_mm[2]) > -1.5, seg


def test_console_line_returns_what_the_controller_printed(vh: VirtualHost) -> None:
    c = control(vh)
    result = run(vh, c.console("$G"))
    assert result.ok
    assert len(result.lines) == 1
    assert result.lines[0].startswith("[GC:G0 G54 G17 G21 G90")
    bad = run(vh, c.console("G1 X1"))  # no feed rate
    assert not bad.ok
    assert bad.error is not None
    assert bad.error.startswith("error:22 ")
    # The console is its own owner in the ledger and got both its replies; none is left open.
    stats = vh.host.ledger.stats
    assert stats.lines[CONSOLE] == stats.replies[CONSOLE] >= 2
    assert stats.unowned_replies == 0
    assert vh.host.ledger.outstanding(CONSOLE) == ()


def test_console_refuses_what_cannot_be_sent_without_writing_anything(vh: VirtualHost) -> None:
    c = control(vh)
    for line, why in (("", "type a line"), ("G0 X1 ?", "realtime"), ("X" * 90, "at most 79")):
        with pytest.raises(ControlRefused, match=why):
            run(vh, c.console(line))
    assert vh.host.ledger.stats.lines[CONSOLE] == 0


def test_a_setting_changed_from_the_console_reaches_the_engine(vh: VirtualHost) -> None:
    c = control(vh)
    engine = vh.engine
    assert engine is not None
    assert engine.limits.max_rate_mm_min[0] == 5000.0
    assert run(vh, c.console("$110=3000")).ok
    assert vh.model.settings.max_rate_mm_min[0] == 3000.0
    assert engine.limits.max_rate_mm_min[0] == 3000.0


def test_no_line_is_sent_while_a_jog_moves(vh: VirtualHost) -> None:
    c = control(vh)
    vh.set_intent(ContinuousIntent({"X": -1.0}, 0.5))
    vh.run_until(vh.now_s + 0.3)
    for command in (c.unlock(), c.console("$G"), c.set_work_zero(["X"])):
        with pytest.raises(ControlRefused, match="press STOP"):
            run(vh, command)
    stats = vh.host.ledger.stats
    assert stats.lines[CONSOLE] == 0
    assert stats.realtime[CONSOLE] == 0
    # An override is a realtime byte for a running program; it changes no line and may go.
    assert run(vh, c.override("feed", "+10")).ok
    assert stats.realtime[CONSOLE] == 1


def test_overrides_change_the_reported_values(vh: VirtualHost) -> None:
    c = control(vh)
    assert run(vh, c.override("feed", "+10")).ok
    assert run(vh, c.override("rapid", "25")).ok
    vh.run_until(vh.now_s + 0.5)
    assert vh.model.overrides[:2] == (110, 25)
    with pytest.raises(ControlRefused, match="use reset"):
        run(vh, c.override("feed", "+50"))
    with pytest.raises(ControlRefused, match="no override 'spin'"):
        run(vh, c.override("spin", "+10"))


def test_soft_reset_restarts_and_the_host_reads_it_again(vh: VirtualHost) -> None:
    c = control(vh)
    resets = vh.model.reset_count
    result = run(vh, c.soft_reset())
    assert result == CommandResult("Ctrl-X", True)
    assert vh.model.reset_count == resets + 1
    assert not vh.host.rehandshaking
    vh.set_intent(ContinuousIntent({"X": -1.0}, 0.2))
    vh.run_until(vh.now_s + 0.5)
    assert vh.rig.firmware.mpos_mm()[0] < -2.0


def test_hold_then_resume_a_move_and_each_refused_where_it_means_nothing(vh: VirtualHost) -> None:
    c = control(vh)
    with pytest.raises(ControlRefused, match="nothing to resume: the machine is in Idle"):
        run(vh, c.resume())
    # `!` in Idle would leave the controller in Hold:0 reading no line (firmware-facts §3.2).
    with pytest.raises(ControlRefused, match="nothing to hold: the machine is in Idle"):
        run(vh, c.hold())
    realtime_before = vh.host.ledger.stats.realtime[CONSOLE]
    assert run(vh, c.console("G1X-60F2000")).ok
    vh.run_until(vh.now_s + 0.3)
    assert vh.model.state == "Run"
    assert run(vh, c.hold()) == CommandResult("!", True)
    vh.run_until(vh.now_s + 0.5)
    assert vh.model.state.startswith("Hold")
    held_at = vh.rig.firmware.mpos_mm()[0]
    assert run(vh, c.resume()) == CommandResult("~", True)
    vh.run_until(vh.now_s + 3.0)
    assert vh.model.state == "Idle"
    assert vh.rig.firmware.mpos_mm()[0] < held_at
    assert vh.host.ledger.stats.realtime[CONSOLE] - realtime_before >= 2


def test_a_hold_during_a_jog_ends_it_and_leaves_nothing_to_resume(vh: VirtualHost) -> None:
    # A feed hold while jogging cancels the jog (Grbl 1.1): it ends Idle, and resume, which
    # could otherwise run jog lines still queued, is refused.
    c = control(vh)
    vh.set_intent(ContinuousIntent({"X": -1.0}, 0.5))
    vh.run_until(vh.now_s + 0.3)
    run(vh, c.hold())
    vh.run_until(vh.now_s + 1.0)
    assert vh.model.state == "Idle"
    assert not vh.host.busy()
    with pytest.raises(ControlRefused, match="nothing to resume"):
        run(vh, c.resume())


def test_while_another_program_holds_the_machine_lines_wait_but_reset_and_overrides_pass(
    vh: VirtualHost,
) -> None:
    """A sender's job (the proxy's lock): a line from the pendant would land in it."""
    c = control(vh)
    reason = "the sender is running a job: jogging waits until it is idle"
    vh.host.set_jog_lock("sender", reason)
    assert c.refusal() == reason
    for command in (c.unlock(), c.console("G0 X-5"), c.set_work_zero(["X"]), c.select_wcs("G55")):
        with pytest.raises(ControlRefused, match="the sender is running a job"):
            run(vh, command)
    assert vh.host.ledger.stats.lines[CONSOLE] == 0
    assert run(vh, c.override("feed", "+10")).ok
    assert run(vh, c.soft_reset()).ok
    vh.host.set_jog_lock("sender", None)
    assert c.refusal() is None


def test_reset_right_after_a_limit_alarm_restarts_the_controller(vh: VirtualHost) -> None:
    """The console's own example on a machine whose coordinates are all <= 0: ALARM:2 at once;
    the line ends then, and a Reset pressed at once still restarts the controller (sent again
    past the moment Grbl 1.1h ignores it, firmware-facts §5.6a)."""
    c = control(vh)
    started_s = vh.now_s
    result = run(vh, c.console("G0 X10"))
    assert not result.ok
    assert "ALARM:2" in (result.error or "")
    assert vh.now_s - started_s < 1.0
    assert vh.host.reset_needed
    assert c.gate.command_refusal("reset") is None
    assert c.gate.command_refusal("unlock") == RESET_NEEDED_TEXT
    resets = vh.model.reset_count
    assert run(vh, c.soft_reset()).ok
    assert vh.model.reset_count >= resets + 1
    assert not vh.host.reset_needed
    assert vh.model.state == "Alarm"
    assert run(vh, c.unlock()).ok
