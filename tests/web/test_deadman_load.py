"""The dead-man on a busy machine: a held jog under two CPU-bound processes never trips.

Real headless Chromium, the real page and server, the recording backend; the browser's machine
runs two processes that spin on a core each for the whole hold, and the page's own thread is
made to stall STALL_MS every 2 s (200 ms here; 250 ms in the bench, as it was seen to stall
on a busy phone, where stalls of 154 and 268 ms stopped held jogs when the heartbeat came from
that thread). The link worker counts the page's stalls longer than the server's 150 ms window;
its heartbeat must hold the jog through all of them. The hold lasts SMOOTHJOG_DEADMAN_HOLD_S
seconds (45 by default; `python -m bench deadman` holds 5 minutes).
"""

from __future__ import annotations

import asyncio
import itertools
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.web.conftest import OpenPage, StartPendant
from tests.web.test_page import start

HOLD_S = float(os.environ.get("SMOOTHJOG_DEADMAN_HOLD_S", "45"))
#: The page's own thread is kept busy this long, this often. Above the server's 150 ms window
#: (what the test proves survives) and below the worker's 350 ms page gate. In the suite 200 ms:
#: with both cores hogged and the rest of the suite running, a 250 ms busy loop was once seen
#: as more than 350 ms of silence (the gate stopped the jog, as it must for a frozen page), and
#: alone it measured 276-286 ms. `python -m bench deadman` keeps the 250 ms of a busy phone.
STALL_MS = int(os.environ.get("SMOOTHJOG_DEADMAN_STALL_MS", "200"))
STALL_EVERY_MS = 2000
STALLS = f"""() => {{
  window.__stalls = setInterval(() => {{
    const end = performance.now() + {STALL_MS};
    while (performance.now() < end) {{}}
  }}, {STALL_EVERY_MS});
}}"""


@pytest.fixture
def cpu_hogs() -> Iterator[list[subprocess.Popen[bytes]]]:
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    yield hogs
    for hog in hogs:
        hog.kill()
        hog.wait()


@pytest.mark.timeout(HOLD_S + 90)
async def test_a_held_jog_under_cpu_load_has_no_false_trips(
    pendant: StartPendant,
    open_page: OpenPage,
    cpu_hogs: list[subprocess.Popen[bytes]],
    artifacts: Path,
    caplog: pytest.LogCaptureFixture,
) -> None:
    p, backend, page = await start(pendant, open_page)
    assert all(hog.poll() is None for hog in cpu_hogs)
    t0 = backend.now_s()
    await page.keyboard.down("ArrowLeft")
    await backend.wait_for(lambda: backend.named("jog_continuous", t0), what="the held jog")
    held_s = backend.now_s()
    await page.evaluate(STALLS)
    await asyncio.sleep(HOLD_S)
    await page.evaluate("() => clearInterval(window.__stalls)")
    assert all(hog.poll() is None for hog in cpu_hogs), "the load must last the whole hold"
    released_s = backend.now_s()
    await page.keyboard.up("ArrowLeft")
    await backend.wait_for(lambda: backend.named("stop", released_s), what="the release")

    trips = [r.getMessage() for r in caplog.records if r.getMessage().startswith("dead-man")]
    assert p.hub.deadman_trips == 0, trips
    stops = [c for c in backend.named("stop", t0) if c.t_s < released_s]
    # A stop with no server trip is the page's own (its worker's gate on a frozen page, which
    # leaves its reason in the notice): say which.
    assert stops == [], await page.locator("#notice").text_content()
    beats = [c.t_s for c in backend.named("jog_continuous", held_s) if c.t_s < released_s]
    # Reported, not asserted: the server runs on the loaded machine too, and a stall of its own
    # shows here as a gap (the arbiter waits for the heartbeats it held back before it stops).
    worst_gap_ms = max(b - a for a, b in itertools.pairwise(beats)) * 1000
    link = page.locator("#link")
    page_gap_ms = int(await link.get_attribute("data-page-gap-ms") or -1)
    stalls = int(await link.get_attribute("data-page-stalls") or -1)
    rtt_ms = int(await link.get_attribute("data-rtt-ms") or -1)
    assert rtt_ms >= 0  # the link figure is shown
    # The stalls happened (each would have tripped a heartbeat from the page's thread).
    assert stalls >= HOLD_S * 1000 / STALL_EVERY_MS / 2
    assert page_gap_ms >= STALL_MS
    line = (
        f"held jog {HOLD_S:.0f} s under 2 CPU hogs and a {STALL_MS} ms stall of the page's "
        f"thread every {STALL_EVERY_MS / 1000:g} s: 0 dead-man trips, {len(beats)} heartbeats, "
        f"worst gap as the server handled them {worst_gap_ms:.0f} ms (window 150 ms); the page's "
        f"own thread paused up to {page_gap_ms} ms, {stalls} times longer than 150 ms; "
        f"round trip {rtt_ms} ms"
    )
    print(line)
    (artifacts / "deadman-load.txt").write_text(line + "\n")
