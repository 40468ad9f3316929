"""The hobby router on the simulator behind the real host, in virtual time: the tests' machine."""

from __future__ import annotations

import dataclasses
from collections.abc import Awaitable
from typing import TypeVar

from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import get_firmware_profile, load_machine_profile
from smoothjog.sim.rig import SimRig
from smoothjog.virtual import VirtualHost

T = TypeVar("T")


def hobby_router(start: str = "homed", firmware: str = "grbl") -> VirtualHost:
    """A connected host (handshake done) to the hobby router that starts as start says."""
    machine = dataclasses.replace(load_machine_profile("hobby-router"), start=start)
    vh = VirtualHost(SimRig(GrblFirmware(get_firmware_profile(firmware), machine)))
    vh.handshake()
    return vh


def run(vh: VirtualHost, aw: Awaitable[T]) -> T:
    """Run aw on the host's virtual-clock loop until it is done."""
    return vh._run(aw)
