"""Someone else resets a machine at rest just as a press's first jog lines go out.

The lines reach the restarted controller and start it as fresh jogs (firmware-facts §3.4). The
host reads the settings again only once the engine has cancelled what they started and seen
the machine at rest: before, nothing cancelled them until the settings had been read, and the
whole first burst ran (5.7 mm on the hobby router over the ideal wire).
"""

from __future__ import annotations

import pytest
from bench import measure

from smoothjog.core.intents import ContinuousIntent, StopIntent
from smoothjog.core.realtime import RESET
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import get_firmware_profile
from smoothjog.sim.rig import LinkModel, SimRig
from smoothjog.virtual import VirtualHost

HELD = ContinuousIntent({"X": -1.0}, 1.0)
#: Two runs of the prepared segments from rest (1.25 mm each on the hobby router) at most:
#: one cancelled as it starts, one for lines the cancel held back in the RX buffer.
GHOST_LIMIT_MM = 3.0


def _reset_then_press(firmware: str) -> tuple[VirtualHost, float, list[tuple[float, bytes]]]:
    fw = GrblFirmware(get_firmware_profile(firmware), "hobby-router")
    vs = VirtualHost(SimRig(fw, LinkModel()))
    vs.handshake()
    vs.run_until(vs.now_s + 0.05)
    written: list[tuple[float, bytes]] = []
    original = vs.rig.host_send

    def spy(data: bytes, now_s: float) -> float:
        written.append((now_s, data))
        return original(data, now_s)

    vs.rig.host_send = spy  # type: ignore[method-assign]
    t_reset = vs.now_s

    async def another_sender_resets() -> None:
        vs.link.send_realtime(RESET)

    vs.loop.run_until_complete(another_sender_resets())
    vs.set_intent(HELD)  # pressed before the banner can come back
    vs.run_until(t_reset + 0.3)
    vs.set_intent(StopIntent())
    vs.run_until(t_reset + 1.5)
    return vs, t_reset, written


@pytest.mark.parametrize("firmware", ["grbl", "grblhal"])
def test_lines_that_start_a_reset_controller_are_cancelled_before_its_settings_are_read(
    firmware: str,
) -> None:
    vs, t_reset, written = _reset_then_press(firmware)
    trace = vs.rig.trace
    moved_mm = measure.distance_after(trace, t_reset)
    assert 0.0 < moved_mm <= GHOST_LIMIT_MM
    settings_read_s = next(t for t, data in written if data == b"$I\n")
    assert settings_read_s > measure.last_motion_end(trace)
    assert not vs.host.rehandshaking
    assert any("the controller was reset" in e.text for e in vs.events)
    # The host jogs again on a new press.
    before = vs.model.mpos_mm
    vs.set_intent(HELD)
    vs.run_until(vs.now_s + 0.3)
    vs.set_intent(StopIntent())
    assert vs.run_until_idle(5.0)
    assert before is not None
    assert vs.model.mpos_mm is not None
    assert vs.model.mpos_mm[0] < before[0] - 5.0
    vs.close()


def test_a_restarted_controller_never_seen_at_rest_is_read_again_after_the_time_limit(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The wait before the settings are read is bounded: a controller whose reports never show
    rest (here: an engine that never says so) is read again after RESTART_SETTLE_S."""
    from smoothjog import host as host_module
    from smoothjog.core.engine import Jogger

    monkeypatch.setattr(Jogger, "restart_settled", lambda self: False)
    vs, t_reset, written = _reset_then_press("grbl")
    vs.run_until(t_reset + host_module.RESTART_SETTLE_S + 1.0)
    settings_read_s = next(t for t, data in written if data == b"$I\n")
    # From the banner (some 30 ms after the reset), the limit, then the handshake's first line.
    waited_s = settings_read_s - t_reset
    assert host_module.RESTART_SETTLE_S < waited_s < host_module.RESTART_SETTLE_S + 0.5
    assert not vs.host.rehandshaking
    vs.close()


def test_lines_the_link_still_held_at_the_banner_delay_the_count(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A `?` overtakes lines still queued in the link (a stalled wire): Idle reports asked
    before those lines left count for nothing."""
    from smoothjog.host import Host

    clear_s: list[float] = []

    def held(self: Host) -> bool:
        if not clear_s:
            clear_s.append(self.now_s() + 1.0)  # the first look, at the banner
        return self.now_s() < clear_s[0]

    monkeypatch.setattr(Host, "_lines_held", held)
    vs, _t_reset, written = _reset_then_press("grbl")
    vs.run_until(vs.now_s + 1.0)
    settings_read_s = next(t for t, data in written if data == b"$I\n")
    # Two reports asked once the lines were out, then the settings.
    asked_after = [t for t, data in written if data == b"?" and clear_s[0] <= t < settings_read_s]
    assert len(asked_after) >= 2
    assert not vs.host.rehandshaking
    vs.close()


def test_machine_commands_wait_in_words_while_a_restarted_controller_is_read() -> None:
    from smoothjog.control import MachineControl

    fw = GrblFirmware(get_firmware_profile("grbl"), "hobby-router")
    vs = VirtualHost(SimRig(fw, LinkModel()))
    vs.handshake()
    control = MachineControl(vs.host)

    async def another_sender_resets() -> None:
        vs.link.send_realtime(RESET)

    vs.loop.run_until_complete(another_sender_resets())
    vs.set_intent(HELD)
    while not vs.host.rehandshaking:
        vs.run_until(vs.now_s + 0.001)
    assert control.refusal(locked_ok=True) == (
        "the controller restarted: wait while smoothjog reads its settings again"
    )
    vs.set_intent(StopIntent())
    vs.run_until(vs.now_s + 2.0)
    assert not vs.host.rehandshaking
    assert control.refusal() is None
    vs.close()


def test_a_restarted_grbl_that_answers_no_line_is_sent_one_cycle_start(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A 0x85 that reached Grbl 1.1h as a jog ended leaves it reporting Idle and answering no
    line (firmware-facts §3.8): the settings could never be read again. The re-handshake sends
    `~` once, which releases it, and reads them."""
    from smoothjog.core.errors import ConnectError
    from smoothjog.host import Host

    failures = [ConnectError("simulated grbl did not answer '$I' within 5.0 s")]
    real = Host._handshake

    async def handshake(self: Host) -> None:
        if failures and self.rehandshaking:  # the first reading after the reset
            raise failures.pop()
        await real(self)

    monkeypatch.setattr(Host, "_handshake", handshake)
    vs, t_reset, written = _reset_then_press("grbl")
    cycle_starts = [t for t, data in written if data == b"~"]
    assert len(cycle_starts) == 1
    assert cycle_starts[0] > t_reset
    assert not vs.host.rehandshaking
    assert vs.host.error is None
    vs.close()
