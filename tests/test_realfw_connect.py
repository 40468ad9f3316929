"""Connecting to real Grbl 1.1h and real grblHAL behind a pty: no banner wait without a reset."""

from __future__ import annotations

import time

import pytest

from smoothjog.handshake import handshake
from smoothjog.links.serial import DEFAULT_WAIT_BANNER_S, SerialLink
from tests.realfw import real_firmware


@pytest.mark.parametrize("kind", ["grblhal", "grbl"])
async def test_connect_without_reset_on_open_takes_well_under_a_second(kind: str) -> None:
    """Real grblHAL does not reset when the port opens (nor Grbl without the DTR reset): the
    connect asks `?` at once instead of waiting DEFAULT_WAIT_BANNER_S for a banner."""
    with real_firmware(kind) as path:
        start_s = time.monotonic()
        async with SerialLink(path, wait_banner_s=DEFAULT_WAIT_BANNER_S) as link:
            model = await handshake(link, timeout_s=5)
        elapsed_s = time.monotonic() - start_s
    assert not link.banner_seen
    assert model.firmware == kind
    assert model.state == "Idle"
    assert elapsed_s < 1.0


async def test_connect_to_grbl_that_resets_on_open_reads_it_after_the_banner() -> None:
    """Real Grbl soft-reset on each open (an Arduino's DTR reset): the banner is seen and the
    handshake reads the restarted controller."""
    with real_firmware("grbl", dtr_reset=True) as path:
        async with SerialLink(path, wait_banner_s=DEFAULT_WAIT_BANNER_S) as link:
            model = await handshake(link, timeout_s=5)
    assert link.banner_seen
    assert (model.firmware, model.version) == ("grbl", "1.1h")
    assert model.state == "Idle"
