"""A homing cycle through the real host against the simulator, in virtual time.

While `$H` waits for its reply the model says Home (Grbl reads no line and reports nothing during
the cycle, firmware-facts §5.6a), the host keeps asking `?` at the moving rate, and where the
firmware reports during homing (grblHAL with `$10` bit 12) the position is seen moving.
"""

from __future__ import annotations

import asyncio
import dataclasses
import itertools

from smoothjog.core.responses import ErrorReply, Ok, Response, StatusReport
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import get_firmware_profile, load_machine_profile
from smoothjog.sim.rig import SimRig
from smoothjog.virtual import VirtualHost

Sample = tuple[float, str | None, tuple[float, ...] | None]


def _vhost(firmware: str, machine: str = "hobby-router") -> VirtualHost:
    profile = dataclasses.replace(load_machine_profile(machine), start="power-up")
    vh = VirtualHost(SimRig(GrblFirmware(get_firmware_profile(firmware), profile)))
    vh.handshake()
    vh.run_until(vh.now_s + 0.3)
    return vh


def _home(vh: VirtualHost) -> tuple[Ok | ErrorReply, list[Sample], list[tuple[float, bytes]]]:
    """Run `$H` from the console; its reply, the model every 20 ms, and the bytes written."""
    written: list[tuple[float, bytes]] = []
    real_send = vh.rig.host_send

    def record(data: bytes, now_s: float) -> float:
        written.append((now_s, data))
        return real_send(data, now_s)

    vh.rig.host_send = record  # type: ignore[method-assign]
    samples: list[Sample] = []

    async def home() -> Ok | ErrorReply:
        task = asyncio.ensure_future(vh.host.console("$H", timeout_s=120.0))
        while not task.done():
            await asyncio.sleep(0.02)
            samples.append((vh.now_s, vh.model.state, vh.model.mpos_mm))
        return (await task)[1]

    try:
        reply = vh._run(home())
    finally:
        vh.rig.host_send = real_send  # type: ignore[method-assign]
    return reply, samples[:-1], written  # the last sample may come after the reply


def _reports(received: list[tuple[float, Response]], since_s: float) -> list[StatusReport]:
    return [r for t, r in received if t >= since_s and isinstance(r, StatusReport)]


def test_grbl_shows_home_for_the_whole_cycle_and_is_asked_all_along() -> None:
    vh = _vhost("grbl")
    try:
        assert vh.model.state == "Alarm"  # power-up with homing on
        t0 = vh.now_s
        reply, samples, written = _home(vh)
        assert reply == Ok()
        t_end = samples[-1][0]
        assert t_end - t0 > 1.0
        assert {state for _t, state, _pos in samples} == {"Home"}
        # `?` keeps going out while the cycle runs (Grbl answers only at its end).
        asked = [t for t, data in written if data == b"?" and t0 < t < t_end]
        assert len(asked) >= (t_end - t0) / 0.6
        # The one report Grbl makes during the cycle: Home, at the homed corner, before `ok`.
        homing_reports = [r for r in _reports(vh.received, t0) if r.state == "Home"]
        assert len(homing_reports) == 1
        assert homing_reports[0].mpos == (-1.0, -1.0, -1.0)
        vh.run_until(vh.now_s + 0.3)
        assert vh.model.state == "Idle"
        assert vh.host.view().can_jog
    finally:
        vh.close()


def test_grblhal_reporting_while_homing_shows_the_machine_moving_home() -> None:
    vh = _vhost("grblhal")
    try:
        assert vh.query_line("$10=4097")[-1] == Ok()  # MPos, and report while homing
        t0 = vh.now_s
        reply, samples, _written = _home(vh)
        assert reply == Ok()
        homing_reports = [r for r in _reports(vh.received, t0) if r.state == "Home"]
        assert len({r.mpos for r in homing_reports}) >= 2
        # Asked at the moving rate (50 ms), not the idle one (250 ms).
        times = [t for t, r in vh.received if t >= t0 and isinstance(r, StatusReport)]
        gaps = sorted(b - a for a, b in itertools.pairwise(times))
        assert gaps[len(gaps) // 2] < 0.1
        # The model follows: Home, and a position that changes while it says so.
        assert {state for _t, state, _pos in samples} == {"Home"}
        assert len({pos for _t, _state, pos in samples}) >= 5
        vh.run_until(vh.now_s + 0.3)
        assert vh.model.state == "Idle"
        assert vh.model.mpos_mm == (-1.0, -1.0, -1.0)
    finally:
        vh.close()


def test_a_refused_home_leaves_the_state_it_found() -> None:
    vh = _vhost("grbl", machine="grbl-defaults")  # $22=0: no homing cycle
    try:
        assert vh.model.state == "Idle"
        reply, _samples, _written = _home(vh)
        assert isinstance(reply, ErrorReply)
        assert reply.code == 5
        assert vh.model.state == "Idle"
    finally:
        vh.close()
