"""After a reset the settings are read again, or jogging waits and says why.

A stored startup line that moves runs at every reset, and while it runs Grbl refuses `$I`, `$$`
and `$#` with error:8 (firmware-facts §3.4). The re-handshake waits for Idle and asks again; when
the machine is still busy after the wait, the host refuses to jog on the settings from before.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Awaitable
from typing import TypeVar

from smoothjog.core.ledger import CONSOLE
from smoothjog.core.realtime import RESET
from smoothjog.core.responses import Banner, ErrorReply, Ok
from smoothjog.handshake import BUSY_WAIT_S
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import get_firmware_profile, load_machine_profile
from smoothjog.sim.rig import SimRig
from smoothjog.virtual import VirtualHost

T = TypeVar("T")

UNREAD = (
    "smoothjog could not read the controller's settings again after its reset: $$ was refused"
    " with error:8 (not idle) while it was in Run; reset it or reconnect"
)


def _vhost() -> VirtualHost:
    machine = dataclasses.replace(load_machine_profile("hobby-router"), start="homed")
    vh = VirtualHost(SimRig(GrblFirmware(get_firmware_profile("grbl"), machine)))
    vh.handshake()
    vh.run_until(vh.now_s + 0.3)
    return vh


def run(vh: VirtualHost, aw: Awaitable[T]) -> T:
    return vh._run(aw)


def _store(vh: VirtualHost, *lines: str) -> None:
    """Send lines the controller takes quietly (the model does not read them back)."""
    for line in lines:
        assert vh.query_line(line)[-1] == Ok(), line


def _reset_and_reread(vh: VirtualHost, within_s: float) -> float:
    """The user's Ctrl-X; run until the settings were read again; when the banner came."""

    async def send() -> None:
        vh.host.send_realtime(CONSOLE, RESET)

    t0 = vh.now_s
    run(vh, send())
    vh.run_until(vh.now_s + 0.1)
    assert vh.host.rehandshaking
    while vh.host.rehandshaking and vh.now_s < t0 + within_s:
        vh.run_until(vh.now_s + 0.05)
    assert not vh.host.rehandshaking
    assert vh.host.error is None
    return next(t for t, r in vh.received if t >= t0 and isinstance(r, Banner))


def test_settings_are_read_again_once_a_startup_line_that_moves_has_run() -> None:
    vh = _vhost()
    try:
        # 200 mm at 4000 mm/min: about 3 s of Run after each reset.
        _store(vh, "$N0=G91G0X-200", "$110=4000")
        assert vh.model.settings.max_rate_mm_min[0] == 5000.0  # not read back yet
        t_banner = _reset_and_reread(vh, 10.0)
        refused = [
            r for t, r in vh.received if t >= t_banner and isinstance(r, ErrorReply) and r.code == 8
        ]
        assert refused  # the first `$I` came while the startup line moved the machine
        assert vh.model.settings.max_rate_mm_min[0] == 4000.0
        assert vh.engine is not None
        assert vh.engine.limits.max_rate_mm_min[0] == 4000.0
        assert vh.model.jog_lock is None
        assert vh.host.view().can_jog
        assert vh.rig.firmware.mpos_mm()[0] == -201.0
    finally:
        vh.close()


def test_jogging_waits_in_words_when_the_settings_stay_unread() -> None:
    vh = _vhost()
    try:
        # 500 mm at 1500 mm/min: 20 s of Run, far longer than the re-handshake waits.
        _store(vh, "$N0=G91G1X-500F1500", "$110=4000")
        t_banner = _reset_and_reread(vh, BUSY_WAIT_S + 5.0)
        assert vh.now_s - t_banner < BUSY_WAIT_S + 2.0  # bounded
        assert vh.model.jog_lock == UNREAD
        view = vh.host.view()
        assert not view.can_jog
        assert view.reason == UNREAD
        # Once the machine rests, reading `$$` again (what a settings change does) lifts it.
        vh.run_until(vh.now_s + 20.0)
        assert vh.model.state == "Idle"
        run(vh, vh.host.reread_settings())
        assert vh.model.jog_lock is None
        assert vh.model.settings.max_rate_mm_min[0] == 4000.0
        assert vh.host.view().can_jog
    finally:
        vh.close()


def test_a_controller_busy_at_connect_is_not_jogged_on_default_settings() -> None:
    machine = dataclasses.replace(load_machine_profile("hobby-router"), start="homed")
    rig = SimRig(GrblFirmware(get_firmware_profile("grbl"), machine))
    rig.host_send(b"G91G1X-500F1500\n", rig.now_s)  # another program's move: 20 s of Run
    rig.run_until(rig.now_s + 0.5)
    vh = VirtualHost(rig)
    try:
        vh.handshake()
        assert vh.model.jog_lock == (
            "smoothjog could not read the controller's settings: $$ was refused with error:8"
            " (not idle) while it was in Run; reconnect once it is idle"
        )
        assert not vh.host.view().can_jog
    finally:
        vh.close()
