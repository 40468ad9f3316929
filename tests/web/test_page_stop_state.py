"""STOP from every page, who stopped, one state model and per-command controls, in Chromium."""

from __future__ import annotations

import asyncio
import json
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import pytest

from smoothjog.core.intents import StopIntent
from smoothjog.web.protocol import dumps, error_message
from tests.web.conftest import DESKTOP, PHONE, OpenPage, Pendant, StartPendant
from tests.web.recording import COMMANDS, RecordingBackend
from tests.web.test_page import quiet, start

SMALL_PHONE = {"width": 320, "height": 640}
WIDE = {"width": 1440, "height": 900}
STOPPED = "stopped by pendant #2 127.0.0.1: the jog was cancelled"
#: Every state the view may name (Grbl's, grblHAL's Tool, smoothjog's own) and a substate.
STATES: list[tuple[str, int | None]] = [
    ("Idle", None),
    ("Jog", None),
    ("Run", None),
    ("Hold", 0),
    ("Home", None),
    ("Alarm", None),
    ("Door", 1),
    ("Check", None),
    ("Sleep", None),
    ("Tool", None),
    ("Lost", None),
    ("Reading", None),
]
CONTROLLER = "#role:has-text('in control'), #role:has-text('控制中')"

STATE_BOX = """() => {
  const el = document.getElementById("state");
  const r = el.getBoundingClientRect();
  return { text: el.textContent, width: r.width, left: r.left, right: r.right,
           scroll: el.scrollWidth, doc: document.documentElement.scrollWidth,
           inner: innerWidth };
}"""


class FrameLog:
    """Every text frame the server receives, with the loop time and the page's name."""

    def __init__(self, p: Pendant) -> None:
        self.frames: list[tuple[float, str, dict[str, Any]]] = []
        hub = p.hub
        original = hub.on_text

        async def spy(page: Any, text: str) -> None:
            self.frames.append((asyncio.get_running_loop().time(), page.name, json.loads(text)))
            await original(page, text)

        # WebInput.run looks on_text up on the hub for every frame: the spy sees them all.
        hub.on_text = spy  # type: ignore[method-assign]

    def of(self, name_prefix: str, since_s: float, kind: str | None = None) -> list[dict[str, Any]]:
        """The frames of the page whose name starts with name_prefix (pings left out)."""
        return [
            m
            for t_s, name, m in self.frames
            if t_s >= since_s
            and name.startswith(name_prefix)
            and m.get("type") != "ping"
            and (kind is None or m.get("type") == kind)
        ]


async def watcher_of(p: Pendant, open_page: OpenPage, **kw: Any) -> Any:
    """A second page on the same pendant: it watches."""
    page = await open_page(p.url, **kw)
    await page.wait_for_selector("#role:has-text('watching'), #role:has-text('仅观看')")
    return page


# -- 1. STOP works from every page -----------------------------------------------------------------


async def test_a_watchers_stop_button_and_escape_each_stop_the_machine(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    p, backend, _ = await start(pendant, open_page)
    watcher = await watcher_of(p, open_page)
    assert await watcher.is_enabled("#stop")
    t_s = backend.now_s()
    await watcher.click("#stop")
    await backend.wait_for(lambda: backend.named("stop", t_s), what="the watcher's STOP")
    t_s = backend.now_s()
    await watcher.keyboard.press("Escape")
    await backend.wait_for(lambda: backend.named("stop", t_s), what="the watcher's Escape")
    stops = [i for i in backend.intents if isinstance(i, StopIntent)]
    assert len(stops) == 2, backend.intents


@pytest.mark.parametrize(("field", "who"), [("#console-input", "watcher"), ("#ratio-Z", "first")])
async def test_escape_in_a_text_field_stops_and_leaves_the_field(
    pendant: StartPendant, open_page: OpenPage, field: str, who: str
) -> None:
    p, backend, first = await start(pendant, open_page)
    watcher = await watcher_of(p, open_page)
    page = watcher if who == "watcher" else first
    await page.focus(field)
    assert await page.evaluate("document.activeElement.id") == field[1:]
    t_s = backend.now_s()
    await page.keyboard.press("Escape")
    await backend.wait_for(lambda: backend.named("stop", t_s), what="the stop from the field")
    assert isinstance(backend.intents[-1], StopIntent)
    assert await page.evaluate("document.activeElement.id") != field[1:]


# -- 2. every page says who stopped ----------------------------------------------------------------


async def test_a_stop_from_another_page_ends_a_held_jog_until_it_is_pressed_again(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    p, backend, first = await start(pendant, open_page)
    frames = FrameLog(p)
    watcher = await watcher_of(p, open_page)
    await first.keyboard.down("ArrowRight")
    await backend.wait_for(lambda: len(backend.jogs()) >= 3, what="a held jog")
    t_s = backend.now_s()
    await watcher.click("#stop")
    await backend.wait_for(lambda: backend.named("stop", t_s), what="the watcher's stop")
    for page in (first, watcher):
        await page.wait_for_selector("#notice:has-text('#2')")
        assert "stopped" in await page.inner_text("#notice")
    # The key is still down: the page sends no more jogs (its link forgot the held one). A
    # heartbeat the worker sent before it heard so may still be on its way.
    await asyncio.sleep(0.1)
    settled_s = backend.now_s()
    await asyncio.sleep(0.4)
    assert frames.of("#1", settled_s, "jog") == []
    assert p.hub.deadman_trips == 0
    # Its release ends the latch with a neutral jog, not with a stop of its own that every page
    # would be told of as a new stop.
    released_s = backend.now_s()
    await first.keyboard.up("ArrowRight")
    await poll(lambda: frames.of("#1", released_s), "the release")
    sent = frames.of("#1", released_s)
    assert sent[0]["type"] == "jog"
    assert set(sent[0]["axes"].values()) == {0}
    assert frames.of("#1", t_s, "stop") == []
    await quiet(backend, "stop", released_s)
    # Pressed again, it jogs again.
    again_s = backend.now_s()
    await first.keyboard.down("ArrowRight")
    await backend.wait_for(lambda: backend.jogs(again_s), what="the jog pressed again")
    await first.keyboard.up("ArrowRight")


async def test_every_page_shows_a_stopped_message_and_none_answers_it(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    p, backend, first = await start(pendant, open_page)
    frames = FrameLog(p)
    watcher = await watcher_of(p, open_page)
    t_s = backend.now_s()
    await p.hub._broadcast(dumps(error_message(STOPPED, code="stopped")))
    for page in (first, watcher):
        await page.wait_for_selector(f"#notice:has-text('{STOPPED}')")
    await asyncio.sleep(0.4)
    # Nothing was held: no page answers (a stop from each would be told to all, and so on).
    assert frames.of("#", t_s) == []
    assert backend.named("stop", t_s) == []


async def test_the_status_line_says_who_stopped_while_the_stop_is_recent(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    p, backend, first = await start(pendant, open_page)
    watcher = await watcher_of(p, open_page)
    stop = {"by": "pendant #2 127.0.0.1", "text": STOPPED, "actions": ["cancel"]}
    backend.set_view(stop={**stop, "t_s": backend.now_s()})
    for page in (first, watcher):
        await page.wait_for_selector(f"#status-text:has-text('{STOPPED}')")
    # One that is 9.3 s old goes away by itself within a second, with no new view to tell.
    backend.set_view(stop={**stop, "t_s": backend.now_s() - 9.3})
    await first.wait_for_selector("#status-text:has-text('Ready to jog')", timeout=3000)
    assert "another pendant is in control" in await watcher.inner_text("#status-text")
    # An old stop is not shown at all.
    backend.set_view(stop={**stop, "t_s": backend.now_s() - 60})
    await asyncio.sleep(0.3)
    assert await first.inner_text("#status-text") == "Ready to jog."


# -- 3. one state model ----------------------------------------------------------------------------


async def test_a_lost_link_reddens_the_pill_greys_the_readout_and_names_the_state(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    _, backend, page = await start(pendant, open_page)
    idle = await color(page, "#state.s-idle")
    backend.set_view(
        link="lost", state="Lost", can_jog=False, reason="the connection to the controller is lost"
    )
    await page.wait_for_selector("#conn.conn-lost:has-text('controller link lost')")
    assert await page.inner_text("#state") == "Lost"
    assert "stale" in (await page.get_attribute("#dro-table", "class") or "")
    assert "jog-disabled" in (await page.get_attribute("body", "class") or "")
    backend.set_view(link="up", state="Home", can_jog=False, reason="homing")
    await page.wait_for_selector("#conn.conn-up")
    assert "stale" not in (await page.get_attribute("#dro-table", "class") or "")
    # Home is shown as Home, coloured as a moving state.
    await page.wait_for_selector("#state.s-home:text-is('Home')")
    home = await color(page, "#state")
    backend.set_view(state="Run")
    await page.wait_for_selector("#state.s-run")
    assert await color(page, "#state") == home != idle


async def test_the_chinese_page_names_every_state_and_the_lost_link(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    p = await pendant(RecordingBackend(animate=False))
    page = await open_page(p.url, locale="zh-CN")
    await page.wait_for_selector(CONTROLLER)
    words = await page.evaluate(
        """async (states) => {
          const m = await import("/static/i18n.js");
          return states.map((s) => [m.STRINGS.en[`st.${s}`], m.STRINGS.zh[`st.${s}`]]);
        }""",
        [s for s, _ in STATES],
    )
    for (state, _), (en, zh) in zip(STATES, words, strict=True):
        assert en, state
        assert zh, state
        assert en != zh, state
    p.backend.set_view(link="lost", state="Lost", can_jog=False, reason=None)
    await page.wait_for_selector("#conn.conn-lost:has-text('控制器失联')")
    assert await page.inner_text("#state") == "失联"
    assert "smoothjog" in await page.inner_text("#status-text")


# -- 4. the state word at every width --------------------------------------------------------------


async def assert_states_fit(page: Any, backend: RecordingBackend, where: str) -> None:
    """Show every state in turn; the state word is whole and the page never scrolls sideways."""
    for state, sub in STATES:
        backend.set_view(state=state, substate=sub, link="lost" if state == "Lost" else "up")
        suffix = "" if sub is None else f":{sub}"
        await page.wait_for_function(
            """([cls, suffix]) => {
                 const el = document.getElementById("state");
                 return el.classList.contains(cls) && el.textContent.endsWith(suffix);
               }""",
            arg=[f"s-{state.lower()}", suffix],
        )
        box = await page.evaluate(STATE_BOX)
        what = (where, state, box)
        assert box["width"] > 0, what
        # scrollWidth is rounded to whole pixels, the box is not.
        assert box["width"] + 0.5 >= box["scroll"], what
        assert box["left"] >= 0, what
        assert box["right"] <= box["inner"], what
        assert box["doc"] <= box["inner"], what


@pytest.mark.parametrize("lang", ["en", "zh"])
async def test_the_state_word_is_whole_at_every_width(
    pendant: StartPendant, open_page: OpenPage, artifacts: Path, lang: str
) -> None:
    locale = "zh-CN" if lang == "zh" else "en-US"
    for viewport in (SMALL_PHONE, PHONE, WIDE):
        p = await pendant(RecordingBackend(animate=False))
        page = await open_page(p.url, viewport=viewport, locale=locale)
        await page.wait_for_selector(CONTROLLER)
        where = f"{lang} {viewport['width']}x{viewport['height']}"
        await assert_states_fit(page, p.backend, where)
        # A watcher's bar also holds the Take control button.
        watcher = await watcher_of(p, open_page, viewport=viewport, locale=locale)
        await assert_states_fit(watcher, p.backend, f"{where} watcher")
        if viewport is PHONE:
            p.backend.set_view(state="Reading", substate=None, link="up")
            await page.wait_for_selector("#state.s-reading")
            shot = artifacts / f"pendant-state-{lang}-phone.png"
            await page.screenshot(
                path=str(shot), clip={"x": 0, "y": 0, "width": 360, "height": 300}
            )
            await watcher.screenshot(
                path=str(artifacts / f"pendant-state-{lang}-phone-watcher.png")
            )


# -- 5. each command by its own availability -------------------------------------------------------


async def test_each_machine_control_follows_its_own_command_and_says_why(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    p, backend, page = await start(pendant, open_page, viewport=DESKTOP)
    busy = "wait: a console line has not finished"
    commands: dict[str, str | None] = dict.fromkeys(COMMANDS, busy)
    commands.update(reset=None, hold=None, override=None)
    backend.set_control(commands=commands, can_command=False, reason=busy, running="a console line")
    await page.wait_for_selector("#m-home[disabled]")
    # Reset stays enabled while a console line runs; so do the realtime hold and overrides.
    for sel in ("#m-reset", "#m-hold", "[data-cmd=override] >> nth=0"):
        assert await page.is_enabled(sel), sel
    for sel in (
        "#m-home",
        "#m-unlock",
        "#m-resume",
        "#console-send",
        "#wcs",
        "[data-cmd=zero] >> nth=0",
    ):
        assert await page.is_disabled(sel), sel
        assert await page.get_attribute(sel, "title") == busy, sel
    assert await page.get_attribute("#m-reset", "title") is None
    t_s = backend.now_s()
    await page.click("#m-reset")
    await page.click("#m-hold")
    await backend.wait_for(lambda: len(backend.named("command", t_s)) == 2, what="two commands")
    assert [c.args[0].name for c in backend.named("command", t_s)] == ["reset", "hold"]
    # An older server sends no commands: one rule, can_command, for every control.
    control = dict(backend.view_state["control"])  # type: ignore[call-overload]
    del control["commands"]
    backend.set_view(control=control)
    await page.wait_for_selector("#m-reset[disabled]")
    # A watcher may run none of them, and is told why.
    backend.set_control(commands=dict.fromkeys(COMMANDS), can_command=True, reason=None)
    await page.wait_for_selector("#m-resume:not([disabled])")
    watcher = await watcher_of(p, open_page)
    for sel in ("#m-reset", "#m-resume", "#console-send"):
        assert await watcher.is_disabled(sel), sel
        assert "another pendant is in control" in (await watcher.get_attribute(sel, "title") or "")
    await page.click("#m-resume")
    await backend.wait_for(lambda: backend.named("command", t_s)[-1].args[0].name == "resume")


# -- 6. the one next action on the status line ----------------------------------------------------


async def offered(page: Any) -> list[str]:
    """The status line's offered buttons, left to right."""
    return await page.evaluate(
        """() => [...document.querySelectorAll("#status-actions [data-offer]")]
             .filter((b) => !b.hidden && b.offsetParent !== null)
             .sort((a, b) => a.getBoundingClientRect().left - b.getBoundingClientRect().left)
             .map((b) => b.dataset.offer)"""
    )


async def test_the_status_line_offers_exactly_what_the_server_offers(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    _, backend, page = await start(pendant, open_page, viewport=PHONE)
    cases: list[tuple[str, list[str]]] = [
        ("Alarm", ["reset"]),  # after a limit alarm Grbl answers nothing until a reset
        ("Hold", ["resume", "reset"]),
        ("Alarm", ["home", "unlock"]),
        ("Idle", []),
    ]
    for state, offer in cases:
        backend.set_view(state=state, can_jog=state == "Idle")
        backend.set_control(offer=offer)
        await wait_until(page, lambda: offered(page), offer, f"{state} {offer}")
        assert await page.is_hidden("#status-actions") == (offer == [])
    backend.set_view(state="Hold", can_jog=False)
    backend.set_control(offer=["resume", "reset"])
    await page.wait_for_selector("#offer-resume:visible")
    t_s = backend.now_s()
    await page.click("#offer-resume")
    await page.click("#offer-reset")
    await backend.wait_for(lambda: len(backend.named("command", t_s)) == 2, what="the offers")
    assert [c.args[0].name for c in backend.named("command", t_s)] == ["resume", "reset"]
    # With no offer in the view (an older server) Alarm still offers home and unlock.
    control = dict(backend.view_state["control"])  # type: ignore[call-overload]
    del control["offer"]
    backend.set_view(state="Alarm", control=control)
    await wait_until(page, lambda: offered(page), ["home", "unlock"], "the old Alarm offer")


# -- helpers ---------------------------------------------------------------------------------------


async def color(page: Any, selector: str) -> str:
    """The computed text colour of an element."""
    return await page.eval_on_selector(selector, "(el) => getComputedStyle(el).color")


async def poll(predicate: Callable[[], object], what: str, timeout_s: float = 3.0) -> None:
    """Wait on the loop until predicate holds."""
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout_s
    while not predicate():
        assert loop.time() < end, f"timed out waiting for {what}"
        await asyncio.sleep(0.02)


async def wait_until(
    page: Any, read: Callable[[], Awaitable[object]], want: object, what: str
) -> None:
    """Read from the page until it gives want (views arrive every 50 ms at most)."""
    got: object = None
    for _ in range(100):
        got = await read()
        if got == want:
            return
        await asyncio.sleep(0.03)
    raise AssertionError(f"{what}: the page shows {got!r}, not {want!r}")
