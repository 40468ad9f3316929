"""The pendant server without a browser: access rules, roles, dead-man, view stream, failures."""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import aiohttp
import pytest
import pytest_asyncio

from smoothjog.core.errors import JogBuildError
from smoothjog.core.intents import ContinuousIntent, StepIntent, StopIntent
from smoothjog.inputs.base import Input, InputHandle
from smoothjog.web.protocol import PendantError
from smoothjog.web.server import STATIC_DIR, STEP_SPEED, format_banner, run_pendant
from tests.web.conftest import Pendant, StartPendant
from tests.web.recording import RecordingBackend

JOG_X = {"type": "jog", "axes": {"X": 0.5}, "speed": 0.5}


@pytest_asyncio.fixture(loop_scope="session")
async def http() -> AsyncIterator[aiohttp.ClientSession]:
    """A plain HTTP client that keeps cookies even for the 127.0.0.1 IP address."""
    async with aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True)) as session:
        yield session


async def open_ws(
    http: aiohttp.ClientSession, p: Pendant, *, origin: str | None = "same", query: str = ""
) -> aiohttp.ClientWebSocketResponse:
    """Open /ws as the page would (Origin of the page) unless told otherwise."""
    headers = {}
    if origin is not None:
        headers["Origin"] = p.origin if origin == "same" else origin
    return await http.ws_connect(p.base_url + "ws" + query, headers=headers)


async def next_message(
    ws: aiohttp.ClientWebSocketResponse, kind: str, timeout_s: float = 3.0, *, stops: bool = False
) -> dict[str, Any]:
    """The next server message of one type, skipping the others (and, unless stops, the
    "stopped" announcement every page gets of a stop)."""
    async with asyncio.timeout(timeout_s):
        while True:
            msg = await ws.receive()
            assert msg.type == aiohttp.WSMsgType.TEXT, f"socket ended: {msg}"
            data: dict[str, Any] = json.loads(msg.data)
            if data["type"] == kind and (stops or data.get("code") != "stopped"):
                return data


async def until_role(ws: aiohttp.ClientWebSocketResponse, role: str) -> None:
    """Read role messages (each broadcast of roles sends one) until the given role arrives."""
    while (await next_message(ws, "role"))["role"] != role:
        pass


async def send(ws: aiohttp.ClientWebSocketResponse, message: dict[str, Any] | str) -> None:
    """Send a message (a dict as JSON, a str as is)."""
    await ws.send_str(message if isinstance(message, str) else json.dumps(message))


class Handwheel(Input):
    """Another kind of input on the same arbiter as the pages."""

    name = "test handwheel"
    kind = "handwheel"
    lease_s = None

    async def run(self, handle: InputHandle) -> None:
        return None


# -- access ---------------------------------------------------------------------------------------


async def test_page_and_assets_are_served_with_a_strict_policy(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant()
    async with http.get(p.base_url) as r:
        assert r.status == 200
        html = await r.text()
        assert "default-src 'self'" in r.headers["Content-Security-Policy"]
        assert "frame-ancestors 'none'" in r.headers["Content-Security-Policy"]
    assert '<script type="module" src="/static/app.js">' in html
    for name in ("app.js", "style.css", "mixer.js", "stick.js"):
        async with http.get(p.base_url + "static/" + name) as r:
            assert r.status == 200, name
    async with http.get(p.base_url + "static/../server.py") as r:
        assert r.status in {403, 404}


def test_static_files_fetch_nothing_from_outside() -> None:
    for path in STATIC_DIR.iterdir():
        text = path.read_text(encoding="utf-8")
        assert "http://" not in text, path.name
        assert "https://" not in text, path.name
        assert "//cdn" not in text, path.name


async def test_websocket_from_another_origin_is_refused_before_upgrade(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant()
    for origin in ("http://evil.example", "null", f"http://localhost:{p.port}", None):
        with pytest.raises(aiohttp.WSServerHandshakeError) as info:
            await open_ws(http, p, origin=origin)
        assert info.value.status == 403, origin
    assert p.hub.clients == []
    assert p.backend.calls == []


async def test_allowed_origins_extend_the_rule(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant(allowed_origins={"https://pendant.example"})
    ws = await open_ws(http, p, origin="https://pendant.example")
    assert (await next_message(ws, "role"))["role"] == "controller"
    await ws.close()


async def test_a_rebound_dns_name_is_refused_without_a_token(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant()
    async with http.get(p.base_url, headers={"Host": f"evil.example:{p.port}"}) as r:
        assert r.status == 403
        assert "pairing token" in await r.text()


async def test_token_is_required_for_page_and_websocket(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant(token="s3cret-token")
    for url in (p.base_url, p.base_url + "?token=wrong", p.base_url + "static/app.js"):
        async with http.get(url) as r:
            assert r.status == 403, url
    for query in ("", "?token=wrong"):
        with pytest.raises(aiohttp.WSServerHandshakeError) as info:
            await open_ws(http, p, query=query)
        assert info.value.status == 403
    # The right token: moved into an HttpOnly cookie, then everything works with the cookie.
    async with http.get(p.url, allow_redirects=False) as r:
        assert r.status == 303
        assert r.headers["Location"] == "/"
        cookie = r.headers["Set-Cookie"]
        assert "HttpOnly" in cookie
        assert "SameSite=Strict" in cookie
    async with http.get(p.base_url) as r:
        assert r.status == 200
    ws = await open_ws(http, p)
    assert (await next_message(ws, "role"))["role"] == "controller"
    await ws.close()


async def test_token_in_the_websocket_query_works_without_a_cookie(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant(token="abc")
    ws = await open_ws(http, p, query="?token=abc")
    assert (await next_message(ws, "role"))["role"] == "controller"
    await ws.close()


# -- messages and roles ---------------------------------------------------------------------------


async def test_malformed_messages_get_an_error_and_the_socket_lives_on(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant()
    ws = await open_ws(http, p)
    await next_message(ws, "role")
    for bad in ("{", '{"type":"jog","axes":{"X":2},"speed":1}', '{"type":"step"}'):
        await send(ws, bad)
        assert (await next_message(ws, "error"))["text"]
    await ws.send_bytes(b"\x00\x01")
    assert "binary" in (await next_message(ws, "error"))["text"]
    assert p.backend.calls == []
    await send(ws, {"type": "step", "axis": "Y", "dist_mm": -0.1})
    await p.backend.wait_for(lambda: p.backend.named("jog_step"), what="the step")
    assert p.backend.named("jog_step")[0].args == ("Y", -0.1)
    assert p.backend.intents == [StepIntent("Y", -0.1, STEP_SPEED)]
    await ws.close()


async def test_intents_reach_the_backend(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant()
    backend: RecordingBackend = p.backend
    ws = await open_ws(http, p)
    await next_message(ws, "role")
    await send(ws, {"type": "ratios", "ratios": {"X": 1, "Y": 1, "Z": 0.25}})
    await send(ws, JOG_X)
    await send(ws, {"type": "stop"})
    await backend.wait_for(lambda: backend.named("stop"), what="the stop")
    assert [c.name for c in backend.calls] == ["set_speed_ratios", "jog_continuous", "stop"]
    assert backend.intents == [ContinuousIntent({"X": 0.5}, 0.5), StopIntent()]
    await ws.close()


async def test_a_watcher_cannot_jog_and_gets_control_when_the_jog_ends(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant(deadman_s=2.0)
    backend: RecordingBackend = p.backend
    first = await open_ws(http, p)
    assert (await next_message(first, "role"))["role"] == "controller"
    second = await open_ws(http, p)
    role = await next_message(second, "role")
    assert role == {"type": "role", "role": "watcher", "controlled": True, "deadman_s": 2.0}
    for message in (
        JOG_X,
        {"type": "step", "axis": "X", "dist_mm": 1},
        {"type": "ratios", "ratios": {"Z": 0.5}},
    ):
        await send(second, message)
        assert (await next_message(second, "error"))["text"] == (
            "this pendant is watching only; press Take control to drive the machine"
        )
    assert backend.calls == []

    await send(first, JOG_X)
    await backend.wait_for(lambda: backend.named("jog_continuous"), what="the jog")
    await send(second, {"type": "take_control"})
    assert "holding a jog" in (await next_message(second, "error"))["text"]
    # A watcher's STOP is the one thing it may send: any pendant's STOP stops the machine,
    # every page is told who stopped it, and the held jog's next heartbeat does not undo it.
    await send(second, {"type": "stop"})
    await backend.wait_for(lambda: backend.named("stop"), what="the watcher's stop")
    for ws in (first, second):
        told = await next_message(ws, "error", stops=True)
        assert told == {
            "type": "error",
            "code": "stopped",
            "text": "stopped by pendant #2 127.0.0.1: the jog was cancelled",
        }
    await send(first, JOG_X)
    assert (await next_message(first, "error"))["text"] == (
        "pendant #2 127.0.0.1 stopped this jog; release the controls and press again"
    )
    assert len(backend.named("jog_continuous")) == 1
    # Released, then pressed anew: the jog goes again.
    await send(first, {"type": "stop"})
    await backend.wait_for(lambda: len(backend.named("stop")) == 2, what="the release")
    await send(first, JOG_X)
    await backend.wait_for(lambda: len(backend.named("jog_continuous")) == 2, what="jog again")
    await send(first, {"type": "stop"})
    await backend.wait_for(lambda: len(backend.named("stop")) == 3, what="the stop")
    await send(second, {"type": "take_control"})
    assert (await next_message(second, "role"))["role"] == "controller"
    await until_role(first, "watcher")
    await send(first, JOG_X)
    assert "watching only" in (await next_message(first, "error"))["text"]
    await first.close()
    await second.close()


async def test_control_is_free_after_the_controller_leaves(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant()
    first = await open_ws(http, p)
    await next_message(first, "role")
    second = await open_ws(http, p)
    await next_message(second, "role")
    await first.close()
    role = await next_message(second, "role")
    assert role["role"] == "watcher"
    assert role["controlled"] is False
    await send(second, {"type": "take_control"})
    assert (await next_message(second, "role"))["role"] == "controller"
    await second.close()


async def test_jogging_is_refused_in_words_when_the_machine_says_no(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant()
    backend: RecordingBackend = p.backend
    backend.set_view(can_jog=False, state="Alarm", reason="Alarm 1: hard limit; unlock with $X")
    ws = await open_ws(http, p)
    await next_message(ws, "role")
    await send(ws, JOG_X)
    text = (await next_message(ws, "error"))["text"]
    assert text == "jogging is disabled: Alarm 1: hard limit; unlock with $X"
    await send(ws, {"type": "step", "axis": "X", "dist_mm": 1})
    assert "jogging is disabled" in (await next_message(ws, "error"))["text"]
    assert backend.named("jog_continuous") == []
    assert backend.named("jog_step") == []
    await ws.close()


async def test_a_failing_backend_is_answered_and_the_machine_stopped(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant()
    backend: RecordingBackend = p.backend
    backend.fail_on.add("jog_continuous")
    ws = await open_ws(http, p)
    await next_message(ws, "role")
    await send(ws, JOG_X)
    assert "jog refused" in (await next_message(ws, "error"))["text"]
    assert backend.named("stop")
    assert not p.hub.arbiter.lease_armed
    backend.fail_on = {"view"}
    assert "machine view unavailable" in (await next_message(ws, "error"))["text"]
    backend.fail_on = set()
    assert (await next_message(ws, "view"))["state"] == "Idle"
    await ws.close()


async def test_a_failing_ratio_change_is_answered_and_the_machine_stopped(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant(deadman_s=5.0)
    backend: RecordingBackend = p.backend
    backend.fail_on.add("set_speed_ratios")
    ws = await open_ws(http, p)
    await next_message(ws, "role")
    await send(ws, JOG_X)
    await send(ws, {"type": "ratios", "ratios": {"Z": 0.5}})
    text = (await next_message(ws, "error"))["text"]
    assert text == "jog refused: recording backend told to fail on set_speed_ratios"
    assert [c.name for c in backend.calls] == ["jog_continuous", "set_speed_ratios", "stop"]
    assert not p.hub.arbiter.lease_armed
    await ws.close()


async def test_an_invalid_intent_is_refused_in_the_backends_words(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant()
    backend: RecordingBackend = p.backend
    ws = await open_ws(http, p)
    await next_message(ws, "role")

    def refuse(intent: object) -> None:
        raise JogBuildError("speed 0.001 gives 0.05 mm/min, below Grbl's 1 mm/min minimum")

    backend.set_intent = refuse  # type: ignore[method-assign]
    await send(ws, {"type": "step", "axis": "X", "dist_mm": 1})
    assert (await next_message(ws, "error"))["text"] == (
        "jog refused: speed 0.001 gives 0.05 mm/min, below Grbl's 1 mm/min minimum"
    )
    await ws.close()


async def test_another_input_in_control_makes_every_page_a_watcher(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant()
    ws = await open_ws(http, p)
    assert (await next_message(ws, "role"))["role"] == "controller"
    pad = p.hub.arbiter.attach(Handwheel())
    pad.take_control()
    role = await next_message(ws, "role")
    assert role["role"] == "watcher"
    assert role["controlled"] is True
    assert p.hub.controller is None
    pad.detach()
    assert (await next_message(ws, "role"))["controlled"] is False
    await ws.close()


async def test_shutting_the_server_down_stops_a_page_that_was_jogging(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant(deadman_s=5.0)
    backend: RecordingBackend = p.backend
    ws = await open_ws(http, p)
    await next_message(ws, "role")
    await send(ws, JOG_X)
    await backend.wait_for(lambda: backend.named("jog_continuous"), what="the jog")
    # The stop must not wait for the page to answer the close (a stuck page may never).
    page = p.hub.clients[0]
    stopped_before_close: list[bool] = []
    close = page.ws.close

    async def observed_close(**kw: Any) -> bool:
        stopped_before_close.append(bool(backend.named("stop")))
        return await close(**kw)

    page.ws.close = observed_close  # type: ignore[method-assign]
    await p.hub.shutdown()
    assert stopped_before_close[0] is True
    assert p.hub.arbiter.controller is None
    await ws.close()


# -- dead-man -------------------------------------------------------------------------------------


async def test_silence_during_a_held_jog_trips_the_deadman(
    pendant: StartPendant, http: aiohttp.ClientSession, artifacts: Path
) -> None:
    p = await pendant(deadman_s=0.15)
    backend: RecordingBackend = p.backend
    ws = await open_ws(http, p)
    await next_message(ws, "role")
    await send(ws, JOG_X)
    await backend.wait_for(lambda: backend.named("stop"), timeout_s=3.0, what="the dead-man")
    jog = backend.named("jog_continuous")[-1]
    stop = backend.named("stop")[0]
    delay_s = stop.t_s - jog.t_s
    print(f"dead-man stop {delay_s * 1000:.1f} ms after the last heartbeat (window 150 ms)")
    with (artifacts / "deadman-server.txt").open("w") as f:
        f.write(f"{delay_s * 1000:.1f} ms after the last heartbeat, window 150 ms\n")
    assert 0.15 <= delay_s < 1.0
    error = await next_message(ws, "error")
    assert "no heartbeat" in error["text"]
    assert error["code"] == "deadman"  # the page holds its jog until released on this code
    # Heartbeats after the trip (the finger still down) do not restart the jog.
    await send(ws, JOG_X)
    assert "release the controls and press again" in (await next_message(ws, "error"))["text"]
    assert len(backend.named("jog_continuous")) == 1
    await send(ws, {"type": "stop"})
    await send(ws, JOG_X)
    await backend.wait_for(lambda: len(backend.named("jog_continuous")) == 2, what="a new press")
    assert p.hub.deadman_trips >= 1
    await ws.close()


async def test_a_ping_is_answered_at_once_for_watchers_too(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant()
    first = await open_ws(http, p)
    await next_message(first, "role")
    second = await open_ws(http, p)
    await next_message(second, "role")
    for ws, ping_id in ((first, 1), (second, 2**31 - 1)):
        await send(ws, {"type": "ping", "id": ping_id})
        assert await next_message(ws, "pong") == {"type": "pong", "id": ping_id}
    assert p.backend.calls == []
    await first.close()
    await second.close()


async def test_heartbeats_keep_a_jog_alive_and_release_stops_once(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    # A wide window keeps this test about heartbeats, not about a busy test machine.
    p = await pendant(deadman_s=0.5)
    backend: RecordingBackend = p.backend
    ws = await open_ws(http, p)
    await next_message(ws, "role")
    for _ in range(20):
        await send(ws, JOG_X)
        await asyncio.sleep(0.04)
    await backend.wait_for(lambda: len(backend.named("jog_continuous")) == 20, what="20 jogs")
    assert backend.named("stop") == []
    await send(ws, {"type": "jog", "axes": {"X": 0, "Y": 0}, "speed": 0.5})
    await backend.wait_for(lambda: backend.named("stop"), what="the stop")
    await asyncio.sleep(0.7)
    assert len(backend.named("stop")) == 1
    assert p.hub.deadman_trips == 0
    await ws.close()


async def test_closing_the_controller_socket_stops_the_machine(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant(deadman_s=5.0)
    backend: RecordingBackend = p.backend
    ws = await open_ws(http, p)
    await next_message(ws, "role")
    await send(ws, JOG_X)
    await backend.wait_for(lambda: backend.named("jog_continuous"), what="the jog")
    await ws.close()
    await backend.wait_for(lambda: backend.named("stop"), timeout_s=2.0, what="the stop")
    assert p.hub.controller is None


# -- view stream ----------------------------------------------------------------------------------


async def test_view_streams_while_moving_and_only_on_change_when_idle(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    backend = RecordingBackend(animate=False)
    backend.set_view(moving=True, state="Jog")
    p = await pendant(backend)
    ws = await open_ws(http, p)
    await next_message(ws, "view")
    loop = asyncio.get_running_loop()
    start_s = loop.time()
    count = 0
    while loop.time() - start_s < 1.0:
        await next_message(ws, "view")
        count += 1
    # 20 Hz nominal; a loaded test machine may lag, so only a loose lower bound.
    assert count >= 12

    backend.set_view(moving=False, state="Idle")
    await next_message(ws, "view")
    with contextlib.suppress(TimeoutError):
        extra = await next_message(ws, "view", timeout_s=0.4)
        pytest.fail(f"an unchanged idle view was sent again: {extra}")
    backend.set_view(wpos=[1.0, 2.0, 3.0])
    assert (await next_message(ws, "view"))["wpos"] == [1.0, 2.0, 3.0]
    await ws.close()


# -- run_pendant ----------------------------------------------------------------------------------


async def test_run_pendant_prints_its_url_serves_and_stops_when_cancelled(
    capsys: pytest.CaptureFixture[str], http: aiohttp.ClientSession
) -> None:
    backend = RecordingBackend()
    ready: asyncio.Future[str] = asyncio.get_running_loop().create_future()
    task = asyncio.create_task(run_pendant(backend, port=0, on_ready=ready.set_result))
    url = await asyncio.wait_for(ready, 5.0)
    assert url.startswith("http://127.0.0.1:")
    assert f"smoothjog pendant: {url}" in capsys.readouterr().out
    async with http.get(url) as r:
        assert r.status == 200
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task
    with pytest.raises(aiohttp.ClientConnectionError):
        async with http.get(url):
            pass


async def test_run_pendant_refuses_a_network_address_without_lan() -> None:
    with pytest.raises(PendantError, match="--lan"):
        await run_pendant(RecordingBackend(), host="0.0.0.0", port=0)


def test_lan_banner_shows_the_token_url_and_a_qr_code() -> None:
    text = format_banner(8765, host="127.0.0.1", token="TOK", lan_address="192.168.1.20")
    assert "http://192.168.1.20:8765/?token=TOK" in text
    assert "http://127.0.0.1:8765/?token=TOK" in text
    assert "█" in text or "▀" in text or "▄" in text  # the terminal QR code
    assert format_banner(8765, host="127.0.0.1", token=None, lan_address=None) == (
        "smoothjog pendant: http://127.0.0.1:8765/\n"
    )


async def test_a_device_announcement_reaches_every_page(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant()
    first = await open_ws(http, p)
    await next_message(first, "role")
    second = await open_ws(http, p)
    await next_message(second, "role")
    p.hub.arbiter.announce("gamepad Pad: unplugged or asleep")
    for ws in (first, second):
        assert await next_message(ws, "error") == {
            "type": "error",
            "text": "gamepad Pad: unplugged or asleep",
            "code": "device",
        }
    await first.close()
    await second.close()


async def test_the_controllers_own_stop_is_told_but_its_release_is_not(
    pendant: StartPendant, http: aiohttp.ClientSession
) -> None:
    p = await pendant()
    backend: RecordingBackend = p.backend
    first = await open_ws(http, p)
    await until_role(first, "controller")
    second = await open_ws(http, p)
    await until_role(second, "watcher")
    # A release is a neutral jog: the machine stops, nobody is told.
    await send(first, JOG_X)
    await send(first, {"type": "jog", "axes": {"X": 0, "Y": 0, "Z": 0}, "speed": 0.5})
    await backend.wait_for(lambda: backend.named("stop"), what="the release")
    # STOP pressed on the page that holds the jog: every page is told who stopped it.
    await send(first, JOG_X)
    await backend.wait_for(lambda: len(backend.named("jog_continuous")) == 2, what="the jog")
    await send(first, {"type": "stop"})
    for ws in (first, second):
        told = await next_message(ws, "error", stops=True)
        assert told["text"] == "stopped by pendant #1 127.0.0.1: the jog was cancelled"
    # Exactly one stop was told: the release before it was none.
    assert sum(1 for c in backend.calls if c.name == "stop") == 2
    assert [i for i in backend.intents if isinstance(i, StopIntent)] == [StopIntent()]
