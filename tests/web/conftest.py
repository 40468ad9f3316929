"""Fixtures for the pendant tests: a real server on a free loopback port and one shared Chromium.

Every async test under tests/web runs in the session event loop so that the one browser (a
session fixture) and the servers share a loop; end-to-end tests against the real engine use the
same `pendant` and `open_page` fixtures with their own backend.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import pytest
import pytest_asyncio
from aiohttp import web

from smoothjog.web.backend import PendantBackend
from smoothjog.web.server import HUB_KEY, PendantHub, create_app
from tests.web.recording import RecordingBackend

HERE = Path(__file__).parent
ARTIFACTS = HERE.parent.parent / "test-artifacts"
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
CHROMIUM_PRESENT = Path(CHROMIUM).exists()
PHONE = {"width": 360, "height": 740}
DESKTOP = {"width": 1280, "height": 800}


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Run this folder's async tests in the session loop, where the shared browser lives."""
    marker = pytest.mark.asyncio(loop_scope="session")
    for item in items:
        if pytest_asyncio.is_async_test(item) and HERE in Path(str(item.path)).parents:
            item.add_marker(marker, append=False)


async def poll_until(predicate: Callable[[], object], timeout_s: float, what: str) -> None:
    """Check predicate every 20 ms on the loop until it holds; fail naming what never came."""
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout_s
    while not predicate():
        assert loop.time() < end, f"timed out waiting for {what}"
        await asyncio.sleep(0.02)


@dataclass
class Pendant:
    """A running pendant server."""

    base_url: str
    port: int
    app: web.Application
    backend: Any
    token: str | None

    @property
    def hub(self) -> PendantHub:
        """The server's hub (clients, roles, dead-man)."""
        return self.app[HUB_KEY]

    @property
    def url(self) -> str:
        """The URL a user opens (with the token when there is one)."""
        return self.base_url + (f"?token={self.token}" if self.token else "")

    @property
    def origin(self) -> str:
        """The page's own origin, for hand-made WebSocket clients."""
        return self.base_url.rstrip("/")


class StartPendant(Protocol):
    """The `pendant` fixture: start a server around a backend."""

    def __call__(
        self,
        backend: PendantBackend | None = None,
        *,
        token: str | None = None,
        deadman_s: float = 0.15,
        allowed_origins: set[str] | None = None,
    ) -> Awaitable[Pendant]: ...


@pytest_asyncio.fixture(loop_scope="session")
async def pendant() -> AsyncIterator[StartPendant]:
    """Factory: `await pendant(backend, token=...)` serves it on 127.0.0.1 at a free port."""
    runners: list[web.AppRunner] = []

    async def start(
        backend: PendantBackend | None = None,
        *,
        token: str | None = None,
        deadman_s: float = 0.15,
        allowed_origins: set[str] | None = None,
    ) -> Pendant:
        chosen = backend if backend is not None else RecordingBackend()
        app = create_app(chosen, token=token, allowed_origins=allowed_origins, deadman_s=deadman_s)
        runner = web.AppRunner(app, access_log=None)
        await runner.setup()
        runners.append(runner)
        site = web.TCPSite(runner, "127.0.0.1", 0)
        await site.start()
        port = int(runner.addresses[0][1])
        return Pendant(f"http://127.0.0.1:{port}/", port, app, chosen, token)

    yield start
    for runner in reversed(runners):
        await runner.cleanup()


@pytest_asyncio.fixture(loop_scope="session")
async def backend() -> RecordingBackend:
    """A fresh recording backend."""
    return RecordingBackend()


@pytest_asyncio.fixture(scope="session", loop_scope="session")
async def browser() -> AsyncIterator[Any]:
    """One headless Debian Chromium for the whole session (never a downloaded browser)."""
    if not CHROMIUM_PRESENT:
        pytest.skip(f"{CHROMIUM} is not installed (apt-get install chromium)")
    from playwright.async_api import async_playwright

    async with async_playwright() as pw:
        chromium = await pw.chromium.launch(
            executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS
        )
        yield chromium
        await chromium.close()


OpenPage = Callable[..., Awaitable[Any]]


@pytest_asyncio.fixture(loop_scope="session")
async def open_page(browser: Any) -> AsyncIterator[OpenPage]:
    """Factory: `await open_page(url, viewport=PHONE, init_script=..., touch=False, locale=...)`.

    Each page gets its own browser context (own cookies and localStorage); page errors fail
    the test. Returns the Playwright page once the pendant has connected.
    """
    contexts: list[Any] = []
    errors: list[str] = []

    async def open_(
        url: str | None,
        *,
        viewport: dict[str, int] | None = None,
        init_script: str | None = None,
        touch: bool = False,
        wait_connected: bool = True,
        locale: str = "en-US",
    ) -> Any:
        context = await browser.new_context(
            viewport=viewport or DESKTOP, has_touch=touch, is_mobile=False, locale=locale
        )
        contexts.append(context)
        if init_script:
            await context.add_init_script(init_script)
        page = await context.new_page()
        page.on("pageerror", lambda exc: errors.append(f"{url}: {exc}"))
        if url is not None:
            await page.goto(url)
            if wait_connected:
                await page.wait_for_selector("#conn.conn-up", timeout=10_000)
        return page

    yield open_
    for context in contexts:
        with contextlib.suppress(Exception):
            await context.close()
    assert not errors, f"JavaScript errors on the page: {errors}"


@pytest.fixture(scope="session")
def artifacts() -> Path:
    """The folder for screenshots and measurements (gitignored)."""
    ARTIFACTS.mkdir(exist_ok=True)
    return ARTIFACTS
