"""The pendant end to end: Chromium, the server, the real jog engine and the simulated Grbl.

Times are the simulator's (its ground-truth trace); the machine must move when the page jogs,
stop when it lets go, never restart after a stop, and stop when the page dies. Bounds are the
firmware's physics plus generous slack for a shared machine's scheduling, never tight timings.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest_asyncio
from bench import measure

from smoothjog.core.engine import JogTuning
from smoothjog.core.intents import ContinuousIntent, Intent
from smoothjog.host import Host
from smoothjog.links.sim import SimLink
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.web.session_backend import SessionBackend
from tests.web.conftest import DESKTOP, PHONE, OpenPage, StartPendant, poll_until
from tests.web.test_page import FAKE_GAMEPAD, center

V_MAX_MM_S = 5000 / 60  # hobby router X/Y
A_MM_S2 = 500.0


class TimedBackend(SessionBackend):
    """The real backend, noting (in simulator time) when the page asked for what."""

    def __init__(self, session: Host, link: SimLink) -> None:
        super().__init__(session)
        self.link = link
        self.calls: list[tuple[float, str]] = []

    def now_s(self) -> float:
        """Simulator time now."""
        return self.link._sim.now_s()

    def set_intent(self, intent: Intent) -> None:
        moving = isinstance(intent, ContinuousIntent) and not intent.is_neutral()
        self.calls.append((self.now_s(), "jog" if moving else "stop"))
        super().set_intent(intent)

    def first(self, name: str, after_s: float) -> float | None:
        """Time of the first call of name after after_s."""
        return next((t for t, n in self.calls if n == name and t > after_s), None)


@dataclass
class Machine:
    """A started session on the simulated hobby router with its pendant backend."""

    link: SimLink
    session: Host
    backend: TimedBackend

    def mpos(self) -> tuple[float, ...]:
        """Ground-truth machine position."""
        return self.link.firmware.mpos_mm()

    async def wait_until(self, predicate: Any, timeout_s: float = 5.0, what: str = "") -> None:
        """Poll a condition on the machine."""
        await poll_until(predicate, timeout_s, what)

    async def wait_rest(self, timeout_s: float = 5.0) -> None:
        """Wait until the engine is idle and the machine stands still."""
        await self.wait_until(
            lambda: not self.session.busy() and self.link.firmware.motion.speed_mm_s() == 0.0,
            timeout_s,
            "the machine to come to rest",
        )
        await asyncio.sleep(0.3)  # anything moving after this would be a ghost jog


@pytest_asyncio.fixture(loop_scope="session")
async def machine() -> AsyncIterator[Machine]:
    """The simulated hobby router in real time, a jog session and its pendant backend."""
    link = SimLink(GrblFirmware(machine="hobby-router"))
    await link.open()
    session = Host(link, tuning=JogTuning(link_margin_s=0.005))
    await session.start()
    backend = TimedBackend(session, link)
    yield Machine(link, session, backend)
    await asyncio.wait_for(session.close(), 10)


async def in_control(pendant: StartPendant, open_page: OpenPage, m: Machine, **kw: Any) -> Any:
    p = await pendant(m.backend)
    page = await open_page(p.url, **kw)
    await page.wait_for_selector("#role:has-text('in control')")
    return page


def assert_clean_stop(m: Machine, t_stop_s: float, speed_mm_s: float) -> tuple[float, float]:
    """After the stop request: one deceleration, within the firmware's physics; no restart."""
    trace = m.link.firmware.trace
    dist = measure.distance_after(trace, t_stop_s)
    end = measure.last_motion_end(trace)
    # Firmware floor: 50 ms of committed segments then v²/2a; slack: 150 ms of scheduling.
    assert dist <= speed_mm_s * 0.2 + speed_mm_s**2 / (2 * A_MM_S2) + 0.05, dist
    assert measure.restarts_after(trace, t_stop_s) == 0
    engine = m.session.engine
    assert engine is not None
    assert engine.stats.stops[-1].tracked_error_steps <= 1.0
    assert engine.stats.soft_limit_errors == 0
    return dist, end - t_stop_s


async def test_dragging_the_stick_moves_the_machine_and_letting_go_stops_it(
    pendant: StartPendant, open_page: OpenPage, machine: Machine
) -> None:
    page = await in_control(pendant, open_page, machine)
    x0 = machine.mpos()[0]
    cx, cy = await center(page, "#stick-xy")
    await page.mouse.move(cx, cy)
    await page.mouse.down()
    await page.mouse.move(cx - 200, cy, steps=5)  # full -X deflection
    await machine.wait_until(lambda: machine.mpos()[0] < x0 - 5.0, what="the machine to move -X")
    await asyncio.sleep(0.3)
    # The stop that counts is the one letting go sends (a neutral at the press, which a busy
    # page may send before the drag moves, is not it).
    t_release = machine.backend.now_s()
    await page.mouse.up()
    await machine.wait_rest()
    t_stop = machine.backend.first("stop", t_release)
    assert t_stop is not None
    speed = 0.25 * V_MAX_MM_S  # the page's default speed is 25 %
    assert_clean_stop(machine, t_stop, speed)
    assert machine.mpos()[1] == -1.0  # a pure X drag moved only X


async def test_two_held_keys_jog_a_diagonal_and_release_stops(
    pendant: StartPendant, open_page: OpenPage, machine: Machine
) -> None:
    page = await in_control(pendant, open_page, machine)
    x0, y0, _ = machine.mpos()
    await page.keyboard.down("ArrowLeft")
    await page.keyboard.down("ArrowDown")
    await machine.wait_until(
        lambda: machine.mpos()[0] < x0 - 3 and machine.mpos()[1] < y0 - 3, what="a -X-Y diagonal"
    )
    xa, ya, _ = machine.mpos()
    await asyncio.sleep(0.3)
    xb, yb, _ = machine.mpos()
    # While both keys are held, both axes move at the same speed: a 45° line.
    assert abs((xa - xb) - (ya - yb)) <= 0.1 * (xa - xb)
    t_release = machine.backend.now_s()
    await page.keyboard.up("ArrowLeft")
    await page.keyboard.up("ArrowDown")
    await machine.wait_rest()
    t_stop = machine.backend.first("stop", t_release)
    assert t_stop is not None
    assert_clean_stop(machine, t_stop, 0.25 * V_MAX_MM_S * 2**0.5)


async def test_a_gamepad_stick_jogs_the_machine(
    pendant: StartPendant, open_page: OpenPage, machine: Machine
) -> None:
    page = await in_control(pendant, open_page, machine, init_script=FAKE_GAMEPAD)
    y0 = machine.mpos()[1]
    await page.evaluate("window.__setPad([0, 1, 0, 0], [])")  # left stick down: -Y
    await machine.wait_until(lambda: machine.mpos()[1] < y0 - 3, what="the pad to jog -Y")
    t_release = machine.backend.now_s()
    await page.evaluate("window.__setPad([0, 0, 0, 0], [])")
    await machine.wait_rest()
    t_stop = machine.backend.first("stop", t_release)
    assert t_stop is not None
    assert_clean_stop(machine, t_stop, 0.25 * V_MAX_MM_S)


async def test_a_frozen_or_closed_page_stops_the_machine(
    pendant: StartPendant, open_page: OpenPage, machine: Machine, artifacts: Path
) -> None:
    page = await in_control(pendant, open_page, machine)
    x0 = machine.mpos()[0]
    await page.keyboard.down("ArrowLeft")
    await machine.wait_until(lambda: machine.mpos()[0] < x0 - 3, what="a held jog")
    t_freeze = machine.backend.now_s()
    freeze = asyncio.ensure_future(
        page.evaluate(
            "() => { const end = performance.now() + 1500; while (performance.now() < end) {} }"
        )
    )
    await machine.wait_rest(timeout_s=5.0)
    trace = machine.link.firmware.trace
    t_stop = machine.backend.first("stop", t_freeze)
    assert t_stop is not None
    last_beat = max(t for t, n in machine.backend.calls if n == "jog" and t <= t_stop)
    rest_s = measure.last_motion_end(trace) - last_beat
    speed = 0.25 * V_MAX_MM_S
    # The worker stops a frozen page within a heartbeat (30 ms) of its last one, then the
    # stop's own physics (committed segments + v/a), + slack.
    assert t_stop - last_beat < 0.2
    assert rest_s < 0.2 + speed / A_MM_S2 + 0.25, rest_s
    # The page gate (350 ms) is how long a frozen page's jog runs on before that stop.
    assert t_stop - t_freeze < 0.35 + 0.4
    assert measure.restarts_after(trace, t_stop) == 0
    await freeze
    await page.keyboard.up("ArrowLeft")
    await machine.wait_rest()

    # The tab closes mid-jog: the socket closes and the server stops at once.
    x1 = machine.mpos()[0]
    await page.keyboard.down("ArrowLeft")
    await machine.wait_until(lambda: machine.mpos()[0] < x1 - 3, what="the jog again")
    t_close = machine.backend.now_s()
    await page.close()
    await machine.wait_rest()
    closed_rest_s = measure.last_motion_end(machine.link.firmware.trace) - t_close
    assert closed_rest_s < 0.05 + speed / A_MM_S2 + 0.4, closed_rest_s
    line = (
        f"end to end (simulated hobby router, 25 % speed): frozen page came to rest "
        f"{1000 * rest_s:.0f} ms after its last heartbeat (dead-man 150 ms, stop "
        f"{1000 * (t_stop - last_beat):.0f} ms after it); closed tab at rest "
        f"{1000 * closed_rest_s:.0f} ms after close()"
    )
    print(line)
    (artifacts / "deadman-e2e.txt").write_text(line + "\n")


async def test_screenshots_of_the_real_pendant(
    pendant: StartPendant, open_page: OpenPage, machine: Machine, artifacts: Path
) -> None:
    for name, viewport in (("phone", PHONE), ("desktop", DESKTOP)):
        page = await in_control(pendant, open_page, machine, viewport=viewport)
        x0 = machine.mpos()[0]
        await page.keyboard.down("ArrowLeft")
        await machine.wait_until(lambda x0=x0: machine.mpos()[0] < x0 - 8, what="motion")
        await page.screenshot(path=str(artifacts / f"pendant-e2e-{name}.png"), full_page=True)
        await page.keyboard.up("ArrowLeft")
        await machine.wait_rest()
        state = await page.locator("#state").inner_text()
        assert "Idle" in state
