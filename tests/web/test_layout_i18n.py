"""The pendant's layout (no shift, landscape, every viewport) and its two languages, in Chromium."""

from __future__ import annotations

import asyncio
import re
from pathlib import Path
from typing import Any

import pytest

from smoothjog.web.server import STATIC_DIR
from tests.web.conftest import DESKTOP, PHONE, OpenPage, StartPendant

LANDSCAPE = {"width": 740, "height": 360}
TABLET = {"width": 768, "height": 1024}
VIEWPORTS = {"phone": PHONE, "phone-landscape": LANDSCAPE, "tablet": TABLET, "desktop": DESKTOP}

#: Words that stay as they are in the Chinese page: the product's name, units, key and G-code
#: names, and the key names of the keyboard bindings.
LATIN_OK = re.compile(r"^(smoothjog|XY|mm|in|min|Ctrl|Arrow\w+|Page\w+|Wi|Fi|G\d+|M\d+|blk)$")
#: Elements that show the machine's own words (firmware name, parser modes, console output) or
#: the names of the languages in the switch; they are not the page's strings.
MACHINE_TEXT = "#firmware, #modal, #console-log, #wcs, #wcs-now, #lang"

VISIBLE_TEXT = """(skip) => {
  const out = [];
  const skipped = [...document.querySelectorAll(skip)];
  const walker = document.createTreeWalker(document.body, NodeFilter.SHOW_TEXT);
  for (let n = walker.nextNode(); n; n = walker.nextNode()) {
    const el = n.parentElement;
    if (!el || skipped.some((s) => s.contains(el))) continue;
    if (el.closest("[hidden]")) continue;
    if (n.textContent.trim()) out.push(n.textContent.trim());
  }
  for (const el of document.querySelectorAll("[aria-label], [placeholder], [title]")) {
    if (skipped.some((s) => s.contains(el) && s !== el)) continue;
    for (const a of ["aria-label", "placeholder", "title"]) {
      const v = el.getAttribute(a);
      if (v) out.push(v);
    }
  }
  out.push(document.title);
  return out;
}"""


async def open_in(
    pendant: StartPendant, open_page: OpenPage, viewport: dict[str, int], locale: str = "en-US"
) -> tuple[Any, Any]:
    p = await pendant()
    context_page = await open_page(
        p.url, viewport=viewport, touch=viewport is not DESKTOP, locale=locale
    )
    await context_page.wait_for_selector("#role:has-text('in control'), #role:has-text('控制中')")
    return p, context_page


async def test_both_sticks_are_on_screen_on_a_phone_in_landscape(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    _, page = await open_in(pendant, open_page, LANDSCAPE)
    for stick in ("#stick-xy", "#stick-z", "#stop"):
        box = await page.locator(stick).bounding_box()
        assert box is not None
        assert box["y"] >= 0, stick
        assert box["y"] + box["height"] <= LANDSCAPE["height"], (stick, box)
        assert box["x"] + box["width"] <= LANDSCAPE["width"], (stick, box)
    assert await page.evaluate("document.documentElement.scrollWidth") <= LANDSCAPE["width"]


@pytest.mark.parametrize("name", ["phone", "phone-landscape", "desktop"])
async def test_a_notice_or_a_new_reason_never_moves_the_stick_or_stop(
    pendant: StartPendant, open_page: OpenPage, name: str
) -> None:
    p, page = await open_in(pendant, open_page, VIEWPORTS[name])

    async def boxes() -> list[Any]:
        # Where each sits in the page (not the viewport): focusing a field may scroll the page.
        return await page.evaluate(
            """() => ["#stick-xy", "#stick-z", "#stop"].map((s) => {
                 const r = document.querySelector(s).getBoundingClientRect();
                 return [r.left + scrollX, r.top + scrollY, r.width, r.height];
               })"""
        )

    before = await boxes()
    # A notice (an invalid ratio is refused on the page), then a long reason and a fault.
    await page.fill("#ratio-X", "7")
    await page.locator("#ratio-X").dispatch_event("change")
    await page.wait_for_selector("#notice:not([hidden])")
    assert await boxes() == before
    p.backend.set_view(
        can_jog=False,
        state="Hold",
        reason="the controller is in feed hold: resume (~) or reset before jogging",
    )
    await page.wait_for_selector("#status-text:has-text('feed hold')")
    assert await boxes() == before
    p.backend.set_view(
        state="Alarm",
        fault={"text": "ALARM:1 (Hard limit): a limit switch was hit", "hint": "home again"},
    )
    await page.wait_for_selector("#status-actions:not([hidden])")
    assert await boxes() == before
    # The refused ratio is replaced by the value the server kept.
    assert await page.input_value("#ratio-X") == "1"


def _used_keys() -> set[str]:
    html = (STATIC_DIR / "index.html").read_text(encoding="utf-8")
    app = (STATIC_DIR / "app.js").read_text(encoding="utf-8")
    keys = set(re.findall(r'data-i18n(?:-aria|-title|-placeholder)?="([\w.]+)"', html))
    keys |= set(re.findall(r'\bt\("([\w.]+)"', app))
    keys |= set(re.findall(r'i18n(?:Aria)? = "([\w.]+)"', app))
    return keys


async def test_every_string_exists_in_english_and_chinese(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    _, page = await open_in(pendant, open_page, DESKTOP)
    tables = await page.evaluate(
        """async () => {
          const m = await import("/static/i18n.js");
          return { en: Object.keys(m.STRINGS.en), zh: Object.keys(m.STRINGS.zh),
                   zhValues: Object.values(m.STRINGS.zh) };
        }"""
    )
    en, zh = set(tables["en"]), set(tables["zh"])
    assert en - zh == set(), "missing in Chinese"
    assert zh - en == set(), "missing in English"
    used = _used_keys()
    assert len(used) > 60
    assert used - en == set(), "used by the page but in no table"


async def test_the_chinese_page_leaves_no_english_string(
    pendant: StartPendant, open_page: OpenPage, artifacts: Path
) -> None:
    p, page = await open_in(pendant, open_page, DESKTOP, locale="zh-CN")
    assert await page.evaluate("document.documentElement.lang") == "zh-CN"
    await page.click("#settings summary")
    for view in (
        {},
        {
            "can_jog": False,
            "state": "Alarm",
            "reason": "the controller is in Alarm: unlock with $X or home with $H first",
        },
        {
            "state": "Alarm",
            "fault": {
                "text": "ALARM:9 (Homing fail): the switch was not found — check it.",
                "hint": "",
            },
        },
    ):
        p.backend.set_view(**view)
        await asyncio.sleep(0.3)
        texts = await page.evaluate(VISIBLE_TEXT, MACHINE_TEXT)
        english = sorted(
            {
                word
                for text in texts
                for word in re.findall(r"[A-Za-z]{2,}", text)
                if not LATIN_OK.match(word)
            }
        )
        assert english == [], (view, [t for t in texts if re.search(r"[A-Za-z]{2,}", t)][:20])
    await page.screenshot(path=str(artifacts / "pendant-zh-alarm.png"))


@pytest.mark.parametrize("lang", ["en", "zh"])
async def test_screenshots_at_every_viewport(
    pendant: StartPendant, open_page: OpenPage, artifacts: Path, lang: str
) -> None:
    for name, viewport in VIEWPORTS.items():
        p, page = await open_in(
            pendant, open_page, viewport, locale="zh-CN" if lang == "zh" else "en-US"
        )
        await page.keyboard.down("ArrowRight")
        await asyncio.sleep(0.6)
        path = artifacts / f"pendant-{lang}-{name}.png"
        await page.screenshot(path=str(path), full_page=name != "phone-landscape")
        await page.keyboard.up("ArrowRight")
        assert p.backend.jogs()
        assert path.stat().st_size > 10_000
