"""No dead ends, end to end: Chromium, the server, the real host and the simulated Grbl 1.1h.

The default machine (the hobby router, homed, every coordinate <= 0) as `smoothjog` starts it.
Each test drives the page as a user would and checks the simulator's own state beside it.
"""

from __future__ import annotations

import asyncio
import dataclasses
from collections.abc import AsyncIterator

import pytest_asyncio

from smoothjog.core.engine import JogTuning
from smoothjog.core.ledger import CONSOLE
from smoothjog.host import Host
from smoothjog.links.sim import SimLink
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import load_machine_profile
from smoothjog.web.session_backend import SessionBackend
from tests.web.conftest import DESKTOP, OpenPage, StartPendant, poll_until


@dataclasses.dataclass
class Machine:
    link: SimLink
    session: Host
    backend: SessionBackend

    @property
    def state(self) -> str:
        """What the simulated controller itself would report."""
        return self.link.firmware.status_state()


async def _machine(start: str) -> Machine:
    machine = dataclasses.replace(load_machine_profile("hobby-router"), start=start)
    link = SimLink(GrblFirmware(machine=machine))
    await link.open()
    session = Host(link, tuning=JogTuning(link_margin_s=0.005))
    await session.start()
    return Machine(link, session, SessionBackend(session))


@pytest_asyncio.fixture(loop_scope="session")
async def homed() -> AsyncIterator[Machine]:
    m = await _machine("homed")
    yield m
    await asyncio.wait_for(m.session.close(), 10)


@pytest_asyncio.fixture(loop_scope="session")
async def powered_up() -> AsyncIterator[Machine]:
    m = await _machine("power-up")
    yield m
    await asyncio.wait_for(m.session.close(), 10)


async def console(page: object, line: str) -> None:
    await page.fill("#console-input", line)  # type: ignore[attr-defined]
    await page.press("#console-input", "Enter")  # type: ignore[attr-defined]


async def test_a_limit_alarm_from_the_console_ends_the_line_and_reset_unlock_recover(
    pendant: StartPendant, open_page: OpenPage, homed: Machine
) -> None:
    m = homed
    p = await pendant(m.backend)
    page = await open_page(p.url, viewport=DESKTOP)
    await page.wait_for_selector("#role:has-text('in control')")
    await page.wait_for_selector("#console-send:not([disabled])")
    # The console placeholder's own example: X+10 is beyond the soft limit (max 0): ALARM:2.
    await console(page, "G0 X10")
    # The line ends at the alarm (not at a 30 s timeout) and says to reset.
    await page.wait_for_selector("#console-log li.c-err:has-text('ALARM:2')", timeout=5000)
    assert m.session.reset_needed
    # Reset is offered at once, and only Reset: nothing else is read until it.
    await page.wait_for_selector("#offer-reset:not([hidden]):not([disabled])")
    assert await page.is_disabled("#m-unlock")
    assert await page.is_hidden("#alarm-unlock")
    await page.click("#offer-reset")
    await poll_until(lambda: not m.session.reset_needed, 5.0, "the reset")
    # Back in Alarm (the machine's position is no longer trusted): Unlock is offered and works.
    await page.wait_for_selector("#alarm-unlock:not([hidden]):not([disabled])", timeout=5000)
    await page.click("#alarm-unlock")
    await poll_until(lambda: m.state == "Idle", 5.0, "Idle after the unlock")
    await page.wait_for_selector("#state:has-text('Idle')")


async def test_a_reset_the_user_asked_for_is_not_a_fault(
    pendant: StartPendant, open_page: OpenPage, homed: Machine
) -> None:
    m = homed
    p = await pendant(m.backend)
    page = await open_page(p.url, viewport=DESKTOP)
    await page.wait_for_selector("#m-reset:not([disabled])")
    resets = m.session.model.reset_count
    await page.click("#m-reset")
    await poll_until(lambda: m.session.model.reset_count > resets, 5.0, "the banner")
    await poll_until(lambda: not m.session.rehandshaking, 5.0, "the settings read again")
    await asyncio.sleep(0.3)  # a view or two after the reset
    status = await page.get_attribute("#status", "class")
    text = await page.inner_text("#status-text")
    assert "status-bad" not in (status or ""), text
    assert "check why it reset" not in text
    assert m.backend.view()["fault"] is None


async def test_homing_shows_home_then_idle(
    pendant: StartPendant, open_page: OpenPage, powered_up: Machine
) -> None:
    m = powered_up
    p = await pendant(m.backend)
    page = await open_page(p.url, viewport=DESKTOP)
    await page.wait_for_selector("#alarm-home:not([hidden]):not([disabled])")
    await page.click("#alarm-home")
    # Grbl 1.1h reports nothing during the cycle (firmware-facts §5.6a): smoothjog shows Home
    # while its `$H` waits for the reply.
    await page.wait_for_selector("#state:has-text('Home')", timeout=5000)
    await page.wait_for_selector("#state:has-text('Idle')", timeout=20000)
    assert m.state == "Idle"


async def test_a_settings_dump_is_refused_while_a_move_runs(
    pendant: StartPendant, open_page: OpenPage, homed: Machine
) -> None:
    m = homed
    p = await pendant(m.backend)
    page = await open_page(p.url, viewport=DESKTOP)
    await page.wait_for_selector("#console-send:not([disabled])")
    await console(page, "G1 X-100 F600")
    await page.wait_for_selector("#console-log li.c-ok")
    # The move runs: Send is off and says why, and `$$` typed now goes nowhere (it would get
    # error:8 from Grbl during a cycle, firmware-facts §5.8).
    await page.wait_for_selector("#console-send[disabled]")
    assert "the machine is moving" in (await page.get_attribute("#console-send", "title") or "")
    sent = m.session.ledger.stats.lines[CONSOLE]
    await console(page, "$$")
    await asyncio.sleep(0.3)
    assert m.state == "Run"
    assert m.session.ledger.stats.lines[CONSOLE] == sent
    log = await page.locator("#console-log li").all_inner_texts()
    assert not [line for line in log if "error:8" in line]
