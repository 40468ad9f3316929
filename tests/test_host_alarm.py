"""Alarms and resets through the real host against the simulated Grbl, in virtual time.

A console line that a critical alarm leaves unanswered fails at the ALARM, not at its timeout;
`reset_needed` says the controller reads no line until a reset; a reset the user asked for is
news, not a fault; an alarm's fault goes once the controller leaves Alarm.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import TypeVar

import pytest

from smoothjog.core.ledger import CONSOLE
from smoothjog.core.machine import MachineModel
from smoothjog.core.realtime import RESET
from smoothjog.core.responses import AlarmReply, Banner, ErrorReply, Ok
from smoothjog.host import ResetNeededError
from smoothjog.virtual import VirtualHost
from tests.hobby import hobby_router, run

T = TypeVar("T")

#: What `G0 X10` gets on the hobby router, whose machine space is -travel..0 (soft limits on).
SOFT_LIMIT_TEXT = (
    "'G0 X10' got no reply: the controller raised ALARM:2 (soft limit: a G-code move would have"
    " left the machine's travel; it was not run and position is kept) and answers no line until"
    " it is reset: press Reset (Ctrl-X)"
)


def _vhost(start: str = "homed") -> VirtualHost:
    vh = hobby_router(start)
    vh.run_until(vh.now_s + 0.3)
    return vh


@pytest.fixture
def vh() -> Iterator[VirtualHost]:
    host = _vhost()
    yield host
    host.close()


def console(vh: VirtualHost, line: str, timeout_s: float = 30.0) -> Ok | ErrorReply:
    return run(vh, vh.host.console(line, timeout_s=timeout_s))[1]


def user_reset(vh: VirtualHost) -> None:
    """Ctrl-X sent by smoothjog for the user (the console's), then the re-reading after it."""

    async def send() -> None:
        vh.host.send_realtime(CONSOLE, RESET)

    before = vh.model.reset_count
    run(vh, send())
    settle_after_reset(vh, before)


def outside_reset(vh: VirtualHost) -> None:
    """Another program (or a reset pin) resets the controller: smoothjog did not send it."""
    before = vh.model.reset_count
    vh.rig.host_send(b"\x18", vh.now_s)
    settle_after_reset(vh, before)


def settle_after_reset(vh: VirtualHost, before: int) -> None:
    end_s = vh.now_s + 5.0
    while vh.now_s < end_s and (vh.model.reset_count == before or vh.host.rehandshaking):
        vh.run_until(vh.now_s + 0.05)
    assert vh.model.reset_count == before + 1
    assert not vh.host.rehandshaking
    vh.run_until(vh.now_s + 0.3)


def soft_limit_alarm(vh: VirtualHost) -> None:
    t0 = vh.now_s
    with pytest.raises(ResetNeededError) as caught:
        console(vh, "G0 X10")
    assert vh.now_s - t0 < 0.1  # at the ALARM, not at the 30 s timeout
    assert str(caught.value) == SOFT_LIMIT_TEXT
    assert caught.value.code == 2
    # Grbl 1.1h drops a Ctrl-X that comes before it enters its critical loop, after the ALARM's
    # 500 ms pause (`[MSG:Reset to continue]`, firmware-facts §5.6a): reset after that.
    vh.run_until(vh.now_s + 0.6)
    assert vh.model.last_message == "Reset to continue"


# ----------------------------------------------------------------- a line the alarm never answers
def test_a_console_line_a_soft_limit_alarm_never_answers_fails_at_once(vh: VirtualHost) -> None:
    assert not vh.host.reset_needed
    soft_limit_alarm(vh)
    assert vh.host.reset_needed
    assert vh.model.reset_needed
    # The ledger keeps the line: Grbl answers it after the reset, just before its banner.
    assert [e.text for e in vh.host.ledger.outstanding(CONSOLE)] == ["G0 X10"]
    # Seconds later the controller still reads nothing, and a new line is not even written.
    vh.run_until(vh.now_s + 3.0)
    assert vh.host.reset_needed
    written = vh.host.ledger.stats.lines[CONSOLE]
    with pytest.raises(ResetNeededError, match=r"^'\$X' was not sent: the controller raised"):
        console(vh, "$X")
    assert vh.host.ledger.stats.lines[CONSOLE] == written
    # The user's Ctrl-X: its banner ends the wait; the late ok found its line already failed.
    user_reset(vh)
    assert not vh.host.reset_needed
    assert vh.model.state == "Alarm"  # a soft limit alarm leaves Alarm after the reset (§2)
    assert vh.host.ledger.outstanding(CONSOLE) == ()
    assert vh.host.ledger.stats.unowned_replies == 0
    assert console(vh, "$X") == Ok()
    assert vh.host.error is None


def test_only_a_critical_alarm_means_a_reset_is_needed() -> None:
    model = MachineModel()
    model.apply(AlarmReply(3))  # a reset during motion: lines are read again after it
    assert not model.reset_needed
    model.apply(AlarmReply(1))
    assert model.reset_needed
    assert model.critical_alarm == 1
    model.apply(Banner("grbl", "1.1h", "Grbl 1.1h ['$' for help]"))
    assert not model.reset_needed
    # ALARM:10 is a homing failure on Grbl 1.1h, an E-stop (critical) on grblHAL.
    model.apply(AlarmReply(10))
    assert not model.reset_needed
    hal = MachineModel(firmware="grblhal")
    hal.apply(AlarmReply(10))
    assert hal.reset_needed


# ----------------------------------------------------------------- whose reset
def test_a_reset_the_user_asked_for_is_news_not_a_fault() -> None:
    vh = _vhost("power-up")  # in Alarm until homed or unlocked, through resets too
    try:
        reason = vh.host.view().reason
        assert reason is not None
        assert "unlock with $X or home with $H first" in reason
        user_reset(vh)
        events = [(e.kind, e.text) for e in vh.events]
        assert ("info", "the controller was reset") in events
        assert not any(kind == "fault" for kind, _text in events)
        view = vh.host.view()
        assert view.fault is None  # nothing red hides why jogging waits
        assert view.reason == reason
    finally:
        vh.close()


def test_a_reset_from_outside_stays_a_fault(vh: VirtualHost) -> None:
    outside_reset(vh)
    faults = [e for e in vh.events if e.kind == "fault"]
    assert [e.text for e in faults] == ["the controller was reset (its banner arrived mid-session)"]
    assert faults[0].hint.startswith("check why it reset")
    assert vh.host.view().fault == (faults[0].text, faults[0].hint)
    # A reset the user asked for afterwards is news again.
    user_reset(vh)
    assert [e.kind for e in vh.events] == ["fault", "info"]


# ----------------------------------------------------------------- alarm faults that no longer hold
def test_an_alarm_fault_goes_once_the_controller_is_unlocked(vh: VirtualHost) -> None:
    soft_limit_alarm(vh)
    vh.run_until(vh.now_s + 0.3)
    fault = vh.host.view().fault
    assert fault is not None
    assert fault[0].startswith("ALARM:2 ")
    user_reset(vh)
    # Still in Alarm after the reset: the fault still holds.
    assert vh.model.state == "Alarm"
    assert vh.host.view().fault == fault
    assert console(vh, "$X") == Ok()
    vh.run_until(vh.now_s + 0.5)
    assert vh.model.state == "Idle"
    assert vh.host.view().fault is None


def test_an_alarm_fault_goes_once_the_machine_is_homed(vh: VirtualHost) -> None:
    soft_limit_alarm(vh)
    user_reset(vh)
    assert vh.host.view().fault is not None
    assert console(vh, "$H", timeout_s=60.0) == Ok()
    vh.run_until(vh.now_s + 0.3)
    assert vh.model.state == "Idle"
    assert vh.host.view().fault is None
    assert vh.host.view().can_jog
