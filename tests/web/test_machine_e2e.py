"""Machine control end to end: Chromium, the server, the real host and the simulated Grbl.

The hobby router starts as after power-up: homing is on, so it is in Alarm at MPos 0 (the
firmware's HOMING_INIT_LOCK). The page unlocks it, homes it, sets and goes to work zero, and
sends console lines, each checked against the simulator's own state.
"""

from __future__ import annotations

import asyncio
import dataclasses
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import pytest
import pytest_asyncio

from smoothjog.core.engine import JogTuning
from smoothjog.core.intents import GotoIntent
from smoothjog.host import Host
from smoothjog.links.sim import SimLink
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import load_machine_profile
from smoothjog.web.session_backend import SessionBackend
from tests.web.conftest import DESKTOP, OpenPage, StartPendant, poll_until


@dataclasses.dataclass
class PoweredUp:
    link: SimLink
    session: Host
    backend: SessionBackend

    def mpos(self) -> tuple[float, ...]:
        return self.link.firmware.mpos_mm()

    async def until(
        self, predicate: Callable[[], object], what: str, timeout_s: float = 10.0
    ) -> None:
        await poll_until(predicate, timeout_s, what)


@pytest_asyncio.fixture(loop_scope="session")
async def powered_up() -> AsyncIterator[PoweredUp]:
    machine = dataclasses.replace(load_machine_profile("hobby-router"), start="power-up")
    link = SimLink(GrblFirmware(machine=machine))
    await link.open()
    session = Host(link, tuning=JogTuning(link_margin_s=0.005))
    await session.start()
    yield PoweredUp(link, session, SessionBackend(session))
    await asyncio.wait_for(session.close(), 10)


async def console(page: object, line: str) -> None:
    # Commands wait until the machine stands still and the page has heard so.
    await page.wait_for_selector("#console-send:not([disabled])")  # type: ignore[attr-defined]
    await page.fill("#console-input", line)  # type: ignore[attr-defined]
    await page.press("#console-input", "Enter")  # type: ignore[attr-defined]


async def test_unlock_home_work_zero_and_the_console_from_the_page(
    pendant: StartPendant, open_page: OpenPage, powered_up: PoweredUp, artifacts: Path
) -> None:
    m = powered_up
    p = await pendant(m.backend)
    page = await open_page(p.url, viewport=DESKTOP)
    await page.wait_for_selector("#role:has-text('in control')")
    await page.wait_for_selector("#state:has-text('Alarm')")
    # In Alarm the way out is offered on the status line itself.
    assert await page.is_visible("#alarm-home")
    assert await page.is_visible("#alarm-unlock")
    await page.screenshot(path=str(artifacts / "pendant-e2e-alarm.png"))

    await page.click("#alarm-unlock")
    await page.wait_for_selector("#state:has-text('Idle')")
    assert m.link.firmware.state == "Idle"
    # Unlocked but not homed: jogging stays off and the page says why.
    await page.wait_for_selector("#status-text:has-text('home it with $H')")
    assert not await page.is_visible("#alarm-unlock")

    await page.click("#m-home")
    await m.until(lambda: m.mpos() == pytest.approx((-1.0, -1.0, -1.0)), "homing")
    await page.wait_for_selector("#status-text:has-text('Ready to jog')")
    await page.wait_for_selector("#console-log li.c-ok")

    m.session.set_intent(GotoIntent({"X": -200.0, "Y": -150.0, "Z": -30.0}, 1.0))
    await m.until(lambda: m.mpos() == pytest.approx((-200.0, -150.0, -30.0)), "the move")
    await m.until(lambda: not m.session.busy(), "the engine to be idle")
    await page.wait_for_selector("#m-reset:not([disabled])")
    await page.click("button:has-text('Zero all')")
    await m.until(
        lambda: m.session.model.offsets_mm.get("G54") == pytest.approx((-200.0, -150.0, -30.0)),
        "work zero to be set",
    )
    await page.wait_for_selector("#dro-body tr:first-child td.w:text-is('0.000')")
    assert "-200.000" in await page.inner_text("#wcs-offset")

    m.session.set_intent(GotoIntent({"X": -50.0, "Y": -60.0, "Z": -70.0}, 1.0))
    await m.until(lambda: m.mpos() == pytest.approx((-50.0, -60.0, -70.0)), "the move away")
    await m.until(lambda: not m.session.busy(), "the engine to be idle")
    trace_from = len(m.link.firmware.trace)
    await page.wait_for_selector("#m-reset:not([disabled])")
    await page.click("button:has-text('Go to zero')")
    await m.until(
        lambda: m.mpos() == pytest.approx((-200.0, -150.0, -30.0), abs=0.01), "work zero", 20.0
    )
    # X and Y moved only with Z up at the safe height (1 mm under the top of its travel).
    for seg in m.link.firmware.trace[trace_from:]:
        if seg.start_mm[:2] != seg.end_mm[:2]:
            assert min(seg.start_mm[2], seg.end_mm[2]) >= -1.01, seg

    await console(page, "$G")
    await page.wait_for_selector("#console-log li.c-out:has-text('[GC:G0 G54')")
    await console(page, "G1 X1")
    await page.wait_for_selector("#console-log li.c-err:has-text('error:22')")
    # History: arrow up brings the last line back.
    await page.press("#console-input", "ArrowUp")
    assert await page.input_value("#console-input") == "G1 X1"
    # The modal line shows what the controller reports.
    await page.wait_for_selector("#modal:has-text('G54')")
    await page.screenshot(path=str(artifacts / "pendant-e2e-machine.png"))
