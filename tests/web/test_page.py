"""The pendant page in a real headless Chromium against a recording backend."""

from __future__ import annotations

import asyncio
import itertools
import logging
from pathlib import Path
from typing import Any

import pytest
from aiohttp import web

from tests.web.conftest import DESKTOP, PHONE, OpenPage, Pendant, StartPendant
from tests.web.recording import RecordingBackend

WS_PROBE = """(url) => new Promise((resolve) => {
  const ws = new WebSocket(url);
  ws.onopen = () => { ws.close(); resolve("open"); };
  ws.onerror = () => resolve("refused");
  setTimeout(() => resolve("timeout"), 5000);
})"""

FAKE_GAMEPAD = """
window.__pad = null;
Object.defineProperty(Navigator.prototype, "getGamepads", {
  configurable: true,
  value: function () { return [window.__pad]; },
});
window.__setPad = (axes, pressed) => {
  const buttons = Array.from({ length: 17 }, (_, i) => ({
    pressed: pressed.includes(i), touched: pressed.includes(i), value: pressed.includes(i) ? 1 : 0,
  }));
  window.__pad = { id: "Test pad (standard)", index: 0, connected: true, mapping: "standard",
                   timestamp: performance.now(), axes, buttons };
};
"""


async def start(
    pendant: StartPendant, open_page: OpenPage, *, viewport: dict[str, int] | None = None, **kw: Any
) -> tuple[Pendant, RecordingBackend, Any]:
    """A pendant with a recording backend and one page in control of it."""
    init_script = kw.pop("init_script", None)
    touch = kw.pop("touch", False)
    p = await pendant(**kw)
    page = await open_page(p.url, viewport=viewport, init_script=init_script, touch=touch)
    await page.wait_for_selector("#role:has-text('in control')")
    return p, p.backend, page


async def quiet(backend: RecordingBackend, name: str, since_s: float, for_s: float = 0.3) -> None:
    """Assert that no call of `name` arrives for for_s seconds after since_s."""
    await asyncio.sleep(for_s)
    assert backend.named(name, since_s) == [], f"unexpected {name}: {backend.named(name, since_s)}"


async def center(page: Any, selector: str) -> tuple[float, float]:
    """The centre of an element in page coordinates."""
    box = await page.locator(selector).bounding_box()
    assert box is not None, selector
    return box["x"] + box["width"] / 2, box["y"] + box["height"] / 2


FLICK_JS = """([x, y]) => new Promise((done) => {
  const el = document.querySelector("#stick-xy");
  const at = (type, dx) => el.dispatchEvent(new PointerEvent(type, {
    pointerId: 1, pointerType: "mouse", isPrimary: true, bubbles: true, cancelable: true,
    clientX: x + dx, clientY: y, buttons: type === "pointerup" ? 0 : 1,
  }));
  at("pointerdown", 0);
  let step = 0;
  const next = () => {
    step += 1;
    at("pointermove", 40 * step);
    if (step < 5) setTimeout(next, 8);
    else { at("pointerup", 40 * step); done(); }
  };
  setTimeout(next, 8);
})"""


# -- sticks ---------------------------------------------------------------------------------------


async def test_dragging_the_xy_stick_jogs_by_deflection_and_lifting_stops(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    _, backend, page = await start(pendant, open_page)
    cx, cy = await center(page, "#stick-xy")
    await page.mouse.move(cx, cy)
    await page.mouse.down()
    await quiet(backend, "jog_continuous", 0.0, 0.2)  # touching alone never moves
    await page.mouse.move(cx + 60, cy, steps=4)
    # 60 px of an 87 px travel, through the 8 % deadzone and the 0.4 expo: about 0.51.
    await backend.wait_for(
        lambda: any(0.4 < j["X"] < 0.62 and j["Y"] == 0 == j["Z"] for j in backend.jogs()),
        what="a partial +X jog from the stick",
    )
    assert all(0 <= j["X"] < 0.62 for j in backend.jogs())
    t_s = backend.now_s()
    await page.mouse.move(cx + 6, cy - 150, steps=4)  # past the rim: full, nearly pure +Y
    await backend.wait_for(
        lambda: any(j["Y"] > 0.99 and 0 < j["X"] < 0.06 for j in backend.jogs(t_s)),
        what="a full +Y deflection",
    )
    released_s = backend.now_s()
    await page.mouse.up()
    await backend.wait_for(lambda: backend.named("stop", released_s), what="the stop on lift")
    stop_s = backend.named("stop", released_s)[0].t_s
    await quiet(backend, "jog_continuous", stop_s)


async def test_two_fingers_jog_xy_and_z_together(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    _, backend, page = await start(pendant, open_page, viewport=PHONE, touch=True)
    cdp = await page.context.new_cdp_session(page)
    xy = await center(page, "#stick-xy")
    z = await center(page, "#stick-z")

    async def touch(kind: str, points: list[tuple[float, float]]) -> None:
        await cdp.send(
            "Input.dispatchTouchEvent",
            {
                "type": kind,
                "touchPoints": [{"x": x, "y": y, "id": i + 1} for i, (x, y) in enumerate(points)],
            },
        )

    await touch("touchStart", [xy])
    await touch("touchStart", [xy, z])
    for k in range(1, 5):
        await touch("touchMove", [(xy[0] - 20 * k, xy[1]), (z[0], z[1] - 20 * k)])
    await backend.wait_for(
        lambda: any(j["X"] < -0.5 and j["Z"] > 0.5 for j in backend.jogs()),
        what="one jog with -X and +Z together",
    )
    released_s = backend.now_s()
    await touch("touchEnd", [])
    await backend.wait_for(lambda: backend.named("stop", released_s), what="the stop on lift")


async def test_inertial_flick_coasts_with_decaying_speed_and_a_tap_stops(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    _, backend, page = await start(pendant, open_page)
    await page.check("#inertial")
    cx, cy = await center(page, "#stick-xy")
    # The flick is played inside the page on its own timers: the stick measures the finger's
    # speed in real time, and a gesture sent step by step from here would be as slow as the
    # round trips to a loaded browser. Five 40 px moves 8 ms apart, then the lift.
    await page.evaluate(FLICK_JS, [cx, cy])
    await page.wait_for_selector("#stick-xy.coasting", state="attached")
    # Skip the drag's last jogs, which may still be on their way (sends are 20 ms apart).
    await asyncio.sleep(0.06)
    coast_s = backend.now_s()
    await asyncio.sleep(0.45)
    coasting = [j["X"] for j in backend.jogs(coast_s)]
    assert len(coasting) >= 4, coasting
    assert all(x > 0 for x in coasting)
    assert coasting[-1] < coasting[0]  # decaying
    assert all(b <= a for a, b in itertools.pairwise(coasting))
    tap_s = backend.now_s()
    await page.mouse.down()
    await page.mouse.up()
    await backend.wait_for(lambda: backend.named("stop", tap_s), what="the stop on tap")
    await quiet(backend, "jog_continuous", backend.named("stop", tap_s)[0].t_s)


# -- keyboard -------------------------------------------------------------------------------------


async def test_held_keys_jog_and_two_keys_make_a_diagonal(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    _, backend, page = await start(pendant, open_page)
    await page.keyboard.down("ArrowRight")
    await backend.wait_for(backend.jogs, what="a key jog")
    assert backend.jogs()[0] == {"X": 1, "Y": 0, "Z": 0}
    t_s = backend.now_s()
    await page.keyboard.down("ArrowUp")
    await backend.wait_for(
        lambda: {"X": 1, "Y": 1, "Z": 0} in backend.jogs(t_s), what="the diagonal"
    )
    t_s = backend.now_s()
    await page.keyboard.up("ArrowRight")
    await backend.wait_for(lambda: {"X": 0, "Y": 1, "Z": 0} in backend.jogs(t_s), what="+Y only")
    assert backend.named("stop") == []
    t_s = backend.now_s()
    await page.keyboard.up("ArrowUp")
    await backend.wait_for(lambda: backend.named("stop", t_s), what="the stop on key-up")


async def test_blur_and_hidden_page_stop_and_auto_repeat_does_not_restart(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    _, backend, page = await start(pendant, open_page)
    await page.keyboard.down("PageUp")
    await backend.wait_for(lambda: {"X": 0, "Y": 0, "Z": 1} in backend.jogs(), what="a +Z jog")
    t_s = backend.now_s()
    await page.evaluate("window.dispatchEvent(new Event('blur'))")
    await backend.wait_for(lambda: backend.named("stop", t_s), what="the stop on blur")
    t_s = backend.now_s()
    await page.keyboard.down("PageUp")  # still held: Playwright sends it as an auto-repeat
    await quiet(backend, "jog_continuous", t_s)
    await page.keyboard.up("PageUp")

    await page.keyboard.down("PageDown")
    await backend.wait_for(lambda: {"X": 0, "Y": 0, "Z": -1} in backend.jogs(), what="a -Z jog")
    t_s = backend.now_s()
    await page.evaluate(
        """() => {
          const hidden = { value: "hidden", configurable: true };
          Object.defineProperty(document, "visibilityState", hidden);
          document.dispatchEvent(new Event("visibilitychange"));
        }"""
    )
    await backend.wait_for(lambda: backend.named("stop", t_s), what="the stop when hidden")


# -- gamepad --------------------------------------------------------------------------------------


async def test_gamepad_sticks_speed_buttons_and_deadman_button(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    _, backend, page = await start(pendant, open_page, init_script=FAKE_GAMEPAD)
    await page.evaluate("window.__setPad([1, 0, 0, 0], [])")
    await backend.wait_for(lambda: {"X": 1, "Y": 0, "Z": 0} in backend.jogs(), what="pad +X")
    await page.wait_for_selector("#gamepad-status:has-text('Test pad')", state="attached")
    t_s = backend.now_s()
    await page.evaluate("window.__setPad([0, -1, 0, -1], [])")  # stick up: +Y, right stick up: +Z
    await backend.wait_for(lambda: {"X": 0, "Y": 1, "Z": 1} in backend.jogs(t_s), what="+Y+Z")
    assert backend.named("jog_continuous")[-1].args[1] == 0.25
    t_s = backend.now_s()
    await page.evaluate("window.__setPad([0, -1, 0, -1], [5])")  # RB: speed up one preset
    await backend.wait_for(
        lambda: any(c.args[1] == 0.5 for c in backend.named("jog_continuous", t_s)),
        what="the faster jog",
    )
    assert await page.locator("#speed-out").inner_text() == "50 %"
    t_s = backend.now_s()
    await page.evaluate("window.__setPad([0.02, 0.03, 0, 0], [])")  # inside the deadzone
    await backend.wait_for(lambda: backend.named("stop", t_s), what="the stop at centre")

    await page.click("#settings summary")
    await page.check("#set-gp-deadman")
    await page.fill("#set-gp-deadman-button", "6")
    await page.locator("#set-gp-deadman-button").dispatch_event("change")
    t_s = backend.now_s()
    await page.evaluate("window.__setPad([-1, 0, 0, 0], [])")
    await quiet(backend, "jog_continuous", t_s)  # no dead-man button: no motion
    await page.evaluate("window.__setPad([-1, 0, 0, 0], [6])")
    await backend.wait_for(lambda: {"X": -1, "Y": 0, "Z": 0} in backend.jogs(t_s), what="held")
    t_s = backend.now_s()
    await page.evaluate("window.__setPad([-1, 0, 0, 0], [])")
    await backend.wait_for(lambda: backend.named("stop", t_s), what="the stop on button release")


# -- steps and ratios -----------------------------------------------------------------------------


async def test_step_buttons_send_exact_steps_in_mm_and_inch(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    _, backend, page = await start(pendant, open_page)
    await page.click("[aria-label='Step X plus']")
    await page.click("[aria-label='Step size 0.1 mm']")
    await page.click("[aria-label='Step Y minus']")
    await backend.wait_for(lambda: len(backend.named("jog_step")) == 2, what="two steps")
    backend.set_view(units="inch")
    await page.click("[aria-label='Step size 0.001 in']")
    await page.click("[aria-label='Step Z plus']")
    await backend.wait_for(lambda: len(backend.named("jog_step")) == 3, what="the inch step")
    assert [c.args for c in backend.named("jog_step")] == [("X", 1.0), ("Y", -0.1), ("Z", 0.0254)]
    await page.fill("#ratio-Z", "0.5")
    await page.locator("#ratio-Z").dispatch_event("change")
    await backend.wait_for(lambda: backend.named("set_speed_ratios"), what="the ratios")
    assert backend.named("set_speed_ratios")[0].args == ({"X": 1.0, "Y": 1.0, "Z": 0.5},)


# -- dead-man -------------------------------------------------------------------------------------


async def test_closing_the_tab_or_freezing_it_mid_jog_stops_within_the_window(
    pendant: StartPendant, open_page: OpenPage, artifacts: Path
) -> None:
    p, backend, page = await start(pendant, open_page)
    # Frozen page: its own thread stops; the link worker sees no ping for 350 ms (conn.js
    # PAGE_GATE_MS), sends the stop itself and holds nothing more until the page releases.
    await page.keyboard.down("ArrowLeft")
    await backend.wait_for(lambda: len(backend.jogs()) >= 3, what="a held jog")
    t_s = backend.now_s()
    freeze = asyncio.ensure_future(
        page.evaluate(
            "() => { const end = performance.now() + 1200; while (performance.now() < end) {} }"
        )
    )
    await backend.wait_for(lambda: backend.named("stop", t_s), timeout_s=3.0, what="the stop")
    stop_s = backend.named("stop", t_s)[0].t_s
    last_jog_s = max(c.t_s for c in backend.named("jog_continuous") if c.t_s <= stop_s)
    frozen_ms = (stop_s - last_jog_s) * 1000
    from_freeze_ms = (stop_s - t_s) * 1000
    assert p.hub.deadman_trips == 0  # the worker stopped it before the server's window ran out
    assert frozen_ms < 200  # within 200 ms of the last heartbeat
    # The gate counts from the page's last ping (every 20 ms), which may come up to one ping
    # before t_s was read: the stop may so come that much before t_s + 350 ms.
    assert 350 - 20 <= from_freeze_ms < 1000
    await freeze
    # The key is still down when the page wakes: the jog must not restart by itself.
    await asyncio.sleep(0.3)
    assert not [c for c in backend.named("jog_continuous") if c.t_s > stop_s]
    notice = await page.locator("#notice").inner_text()
    assert "did not respond" in notice
    await page.keyboard.up("ArrowLeft")
    await backend.wait_for(lambda: backend.named("stop", stop_s + 0.001), what="the release")

    # Closed tab: the controller's socket closes.
    await page.keyboard.down("ArrowLeft")
    await backend.wait_for(lambda: backend.jogs(backend.now_s() - 0.1), what="the jog again")
    closed_s = backend.now_s()
    await page.close()
    await backend.wait_for(lambda: backend.named("stop", closed_s), timeout_s=3.0, what="stop")
    closed_ms = (backend.named("stop", closed_s)[0].t_s - closed_s) * 1000
    assert closed_ms < 1000
    line = (
        f"frozen page: stop {frozen_ms:.1f} ms after the last heartbeat, {from_freeze_ms:.0f} ms "
        f"after the freeze began (page gate 350 ms); "
        f"closed tab: stop {closed_ms:.1f} ms after close() was called"
    )
    print(line)
    (artifacts / "deadman-browser.txt").write_text(line + "\n")


# -- security and roles ---------------------------------------------------------------------------


async def test_a_page_from_another_site_cannot_open_the_websocket(
    pendant: StartPendant, open_page: OpenPage, caplog: pytest.LogCaptureFixture
) -> None:
    p = await pendant()
    # The other site is served from loopback too: Chromium itself blocks public pages from
    # reaching loopback, and this test is about the server's own Origin check.
    other = web.Application()

    async def hello(request: web.Request) -> web.Response:
        return web.Response(text="<p>another site</p>", content_type="text/html")

    other.router.add_get("/", hello)
    runner = web.AppRunner(other, access_log=None)
    await runner.setup()
    try:
        site = web.TCPSite(runner, "127.0.0.1", 0)
        await site.start()
        other_port = int(runner.addresses[0][1])
        page = await open_page(f"http://127.0.0.1:{other_port}/", wait_connected=False)
        with caplog.at_level(logging.WARNING, logger="smoothjog.web.server"):
            result = await page.evaluate(WS_PROBE, f"ws://127.0.0.1:{p.port}/ws")
    finally:
        await runner.cleanup()
    assert result == "refused"
    refusal = f"WebSocket from http://127.0.0.1:{other_port} refused"
    assert any(refusal in r.getMessage() for r in caplog.records)
    assert p.hub.clients == []
    assert p.backend.calls == []


async def test_a_wrong_token_is_refused_for_page_and_websocket(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    p = await pendant(token="pairing-token-123")
    page = await open_page(None)
    for url in (p.base_url, p.base_url + "?token=nope"):
        response = await page.goto(url)
        assert response.status == 403, url
        assert "pairing token" in await page.inner_text("body")
    await page.goto(p.url)
    await page.wait_for_selector("#role:has-text('in control')")
    assert "token" not in page.url  # moved into the HttpOnly cookie
    assert "pairing-token-123" not in await page.evaluate("document.cookie")
    assert await page.evaluate(WS_PROBE, f"ws://127.0.0.1:{p.port}/ws?token=nope") == "refused"


async def test_a_watcher_cannot_jog_until_it_takes_control(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    p, backend, first = await start(pendant, open_page)
    second = await open_page(p.url)
    await second.wait_for_selector("#role:has-text('watching')")
    assert await second.is_visible("#take-control")
    assert "another pendant is in control" in await second.inner_text("#status-text")
    assert await second.is_disabled("[aria-label='Step X plus']")
    await second.keyboard.down("ArrowRight")
    await quiet(backend, "jog_continuous", 0.0)
    await second.keyboard.up("ArrowRight")
    await second.click("#take-control")
    await second.wait_for_selector("#role:has-text('in control')")
    await first.wait_for_selector("#role:has-text('watching')")
    await second.keyboard.down("ArrowRight")
    await backend.wait_for(backend.jogs, what="the new controller's jog")
    await second.keyboard.up("ArrowRight")


async def test_can_jog_false_disables_the_controls_and_shows_the_reason(
    pendant: StartPendant, open_page: OpenPage, artifacts: Path
) -> None:
    _, backend, page = await start(pendant, open_page, viewport=PHONE)
    await page.keyboard.down("ArrowDown")
    await backend.wait_for(backend.jogs, what="a jog")
    t_s = backend.now_s()
    backend.set_view(
        can_jog=False,
        state="Alarm",
        reason="Alarm: hard limit hit. Jogging is locked until you unlock ($X).",
        fault={"text": "ALARM:1 Hard limit triggered", "hint": "Move off the switch, then $X."},
    )
    await backend.wait_for(lambda: backend.named("stop", t_s), what="the page's stop")
    # A fault outranks the reason on the one status line, its hint beside it.
    await page.wait_for_selector("#status-text:has-text('ALARM:1 Hard limit triggered')")
    assert "Move off the switch" in await page.inner_text("#status-text")
    assert await page.is_visible("#alarm-unlock")
    assert await page.inner_text("#state") == "Alarm"
    assert await page.is_disabled("[aria-label='Step X plus']")
    assert await page.get_attribute("#stick-xy", "aria-disabled") == "true"
    assert "jog-disabled" in (await page.get_attribute("body", "class") or "")
    await page.keyboard.up("ArrowDown")
    t_s = backend.now_s()
    await page.keyboard.down("ArrowUp")
    cx, cy = await center(page, "#stick-xy")
    await page.mouse.move(cx, cy)
    await page.mouse.down()
    await page.mouse.move(cx + 80, cy, steps=3)
    await page.mouse.up()
    await quiet(backend, "jog_continuous", t_s)
    await page.keyboard.up("ArrowUp")
    await page.screenshot(path=str(artifacts / "pendant-phone-alarm.png"), full_page=True)


# -- layout ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(("name", "viewport"), [("phone", PHONE), ("desktop", DESKTOP)])
async def test_layout_fits_labels_every_control_and_is_captured(
    pendant: StartPendant,
    open_page: OpenPage,
    artifacts: Path,
    name: str,
    viewport: dict[str, int],
) -> None:
    _, backend, page = await start(pendant, open_page, viewport=viewport)
    await page.keyboard.down("ArrowRight")
    await page.keyboard.down("ArrowUp")
    await asyncio.sleep(1.0)
    await page.keyboard.up("ArrowUp")
    await asyncio.sleep(0.5)
    assert await page.evaluate("document.documentElement.scrollWidth") <= viewport["width"]
    unlabelled = await page.evaluate(
        """() => [...document.querySelectorAll(
              "button, input, select, canvas, [role=application], summary")]
            .filter((el) => !el.getAttribute("aria-label") && !(el.labels && el.labels.length))
            .map((el) => el.outerHTML.slice(0, 80))"""
    )
    assert unlabelled == []
    await page.screenshot(path=str(artifacts / f"pendant-{name}.png"), full_page=name == "phone")
    await page.keyboard.up("ArrowRight")
    assert backend.jogs()


async def test_the_speed_starts_at_the_machines_default_until_the_user_picks_one(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    p = await pendant()
    p.backend.set_view(default_speed=0.6)  # [jog] default_speed = 0.6
    page = await open_page(p.url)
    await page.wait_for_selector("#speed-out:has-text('60 %')")
    assert await page.locator("#speed").input_value() == "60"
    # The user's own pick is kept in this browser, over the machine's default.
    await page.locator("#speed").fill("35")
    await page.locator("#speed").dispatch_event("input")
    await page.reload()
    await page.wait_for_selector("#conn.conn-up")
    await page.wait_for_selector("#speed-out:has-text('35 %')")
    await asyncio.sleep(0.3)  # views keep coming: the default must not win now
    assert await page.locator("#speed").input_value() == "35"
