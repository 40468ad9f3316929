"""The pendant's web server: serves the page, guards access, relays intents, streams the view.

aiohttp was chosen because it is a mature asyncio HTTP server with first-class WebSocket
support, so the pendant shares the event loop (and its clock) with the jog session.

Safety rules enforced here (docs/pendant.md explains them for users):
- one controlling client at a time; the others watch read-only;
- a held continuous jog is stopped when its heartbeat is silent for `deadman_s` (loop clock)
  or when the controlling WebSocket closes;
- every request passes the guard middleware: Host (loopback mode), pairing token (LAN mode),
  and for /ws the Origin, which must be the host the page was served from.
"""

from __future__ import annotations

import asyncio
import contextlib
import io
import ipaddress
import logging
import secrets
import socket
import sys
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

import segno
from aiohttp import WSMsgType, web

from smoothjog.web.backend import PendantBackend
from smoothjog.web.deadman import DeadMan
from smoothjog.web.protocol import (
    MAX_MESSAGE_BYTES,
    JogMessage,
    PendantError,
    PendantMessageError,
    RatiosMessage,
    StepMessage,
    StopMessage,
    TakeControlMessage,
    dumps,
    error_message,
    parse_client_message,
    role_message,
    view_message,
)

log = logging.getLogger(__name__)

STATIC_DIR: Final = Path(__file__).parent / "static"
#: The view is polled this often (20 Hz); while moving every poll is sent.
VIEW_PERIOD_S: Final = 0.05
TOKEN_COOKIE: Final = "smoothjog_token"
#: A send that cannot complete in this time means the client is stuck; it is dropped.
SEND_TIMEOUT_S: Final = 1.0
DEFAULT_AXES: Final = ("X", "Y", "Z")

_SECURITY_HEADERS: Final = {
    # Everything is served from here; nothing may be framed (click-jacking) or fetched elsewhere.
    "Content-Security-Policy": (
        "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
        "connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'none'"
    ),
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-cache",
}


@dataclass(eq=False)
class _Client:
    """One connected page."""

    ws: web.WebSocketResponse
    label: str


@dataclass
class _Policy:
    """Who may reach the pendant at all."""

    token: str | None
    allowed_origins: frozenset[str]

    def host_ok(self, request: web.Request) -> bool:
        """Without a token only loopback names and IP literals are served (no DNS rebinding)."""
        if self.token is not None:
            return True
        host = request.url.host or ""
        if host == "localhost":
            return True
        try:
            ipaddress.ip_address(host.strip("[]"))
        except ValueError:
            return False
        return True

    def token_ok(self, offered: str | None) -> bool:
        """Constant-time comparison with the pairing token."""
        if self.token is None:
            return True
        return offered is not None and secrets.compare_digest(offered, self.token)

    def origin_ok(self, request: web.Request) -> bool:
        """The page that opens /ws must come from this very host (or an allowed origin)."""
        origin = request.headers.get("Origin")
        if origin is None:
            return False
        if origin in self.allowed_origins:
            return True
        scheme, sep, authority = origin.partition("://")
        return (
            bool(sep)
            and scheme.lower() in {"http", "https"}
            and authority.lower() == request.host.lower()
        )


@dataclass(eq=False)
class PendantHub:
    """The clients, their roles, the dead-man and the view stream around one backend."""

    backend: PendantBackend
    deadman: DeadMan
    clients: list[_Client] = field(default_factory=list)
    controller: _Client | None = None
    axes: tuple[str, ...] = DEFAULT_AXES
    deadman_trips: int = 0
    _timer: asyncio.TimerHandle | None = None
    _last_sent: dict[str, object] | None = None
    _last_text: str | None = None
    _last_view_error: str | None = None
    _count: int = 0

    # -- clients and roles -------------------------------------------------------------------

    async def add(self, ws: web.WebSocketResponse, peer: str) -> _Client:
        """Register a new page; it controls if nobody does, else it watches."""
        self._count += 1
        client = _Client(ws=ws, label=f"#{self._count} {peer}")
        self.clients.append(client)
        if self.controller is None:
            self.controller = client
        log.info("pendant client %s connected", client.label)
        await self._send_roles()
        if self._last_text is not None:
            await self._send(client, self._last_text)
        return client

    async def remove(self, client: _Client) -> None:
        """Forget a page; if it was in control, stop the machine and free the control."""
        if client in self.clients:
            self.clients.remove(client)
        log.info("pendant client %s disconnected", client.label)
        if client is self.controller:
            self.controller = None
            self._release()
            # A closed controller may have left steps queued; nobody is watching over them now.
            self._call_stop("controller disconnected")
            await self._send_roles()

    async def _send_roles(self) -> None:
        controlled = self.controller is not None
        for client in list(self.clients):
            role = "controller" if client is self.controller else "watcher"
            message = role_message(role, controlled=controlled, deadman_s=self.deadman.window_s)
            await self._send(client, dumps(message))

    # -- intents -----------------------------------------------------------------------------

    async def refuse(self, client: _Client, text: str) -> None:
        """Answer a page with an error in words."""
        await self._send(client, dumps(error_message(text)))

    async def on_text(self, client: _Client, text: str) -> None:
        """Handle one text frame from a page; every failure is answered, none propagates."""
        try:
            message = parse_client_message(text, self.axes)
        except PendantMessageError as exc:
            await self.refuse(client, str(exc))
            return
        if isinstance(message, TakeControlMessage):
            await self._take_control(client)
            return
        if client is not self.controller:
            await self.refuse(
                client, "this pendant is watching only; press Take control to drive the machine"
            )
            return
        try:
            self._dispatch(message)
        except PendantMessageError as exc:
            await self.refuse(client, str(exc))
        except Exception as exc:  # the backend may fail in any way; the machine must stop
            log.exception("pendant backend failed on %r", message)
            self._release()
            self._call_stop("backend error")
            await self.refuse(client, f"jog refused: {exc}")

    def _dispatch(self, message: JogMessage | StopMessage | StepMessage | RatiosMessage) -> None:
        if isinstance(message, JogMessage):
            if message.neutral:
                if self.deadman.armed:
                    self._release()
                    self.backend.stop()
                return
            if not self.deadman.armed:
                self._require_can_jog()
            self.backend.jog_continuous(message.axes, message.speed)
            self.deadman.feed(asyncio.get_running_loop().time())
            self._schedule_deadman()
        elif isinstance(message, StopMessage):
            self._release()
            self.backend.stop()
        elif isinstance(message, StepMessage):
            self._require_can_jog()
            self.backend.jog_step(message.axis, message.dist_mm)
        else:
            self.backend.set_speed_ratios(message.ratios)

    def _require_can_jog(self) -> None:
        """Refuse a new jog in words when the machine says jogging is disabled."""
        view = self.backend.view()
        if view.get("can_jog") is False:
            reason = view.get("reason") or f"machine state is {view.get('state')}"
            raise PendantMessageError(f"jogging is disabled: {reason}")

    async def _take_control(self, client: _Client) -> None:
        """Grant control when nobody holds it or the holder has no continuous jog active."""
        if client is self.controller:
            await self._send_roles()
            return
        if self.controller is not None and self.deadman.armed:
            await self.refuse(
                client, "another pendant is holding a jog; control can pass once it releases"
            )
            return
        log.info("pendant client %s takes control", client.label)
        self.controller = client
        await self._send_roles()

    # -- dead-man ----------------------------------------------------------------------------

    def _release(self) -> None:
        self.deadman.disarm()
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _schedule_deadman(self) -> None:
        deadline = self.deadman.deadline_s()
        if self._timer is None and deadline is not None:
            # One timer per window, not per heartbeat: it re-arms itself if fed meanwhile.
            self._timer = asyncio.get_running_loop().call_at(deadline, self._on_deadman_timer)

    def _on_deadman_timer(self) -> None:
        self._timer = None
        now_s = asyncio.get_running_loop().time()
        if not self.deadman.expired(now_s):
            self._schedule_deadman()
            return
        silent_s = now_s - (self.deadman.last_heard_s or now_s)
        self.deadman.disarm()
        self.deadman_trips += 1
        log.warning("pendant dead-man: no heartbeat for %.0f ms, stopping", silent_s * 1000)
        self._call_stop("dead-man")
        controller = self.controller
        if controller is not None:
            text = dumps(
                error_message(
                    f"jog stopped: no heartbeat from this pendant for {silent_s * 1000:.0f} ms "
                    "(weak Wi-Fi or a busy device?)"
                )
            )
            task = asyncio.get_running_loop().create_task(self._send(controller, text))
            _background.add(task)
            task.add_done_callback(_background.discard)

    def _call_stop(self, why: str) -> None:
        try:
            self.backend.stop()
        except Exception:  # a failing stop must not take the server down; it is logged loudly
            log.exception("pendant backend failed to stop (%s)", why)

    # -- view stream -------------------------------------------------------------------------

    async def stream_views(self) -> None:
        """Poll the view every VIEW_PERIOD_S; send it while moving or when it changed."""
        loop = asyncio.get_running_loop()
        next_s = loop.time()
        while True:
            next_s += VIEW_PERIOD_S
            delay_s = next_s - loop.time()
            if delay_s < 0.0:
                # Fell behind (a busy loop): resume the cadence from now rather than burst.
                next_s = loop.time()
                delay_s = 0.0
            await asyncio.sleep(delay_s)
            await self.poll_view()

    async def poll_view(self) -> None:
        """Take one snapshot and send it if it is worth sending."""
        try:
            message = view_message(self.backend.view())
            text = dumps(message)
        except Exception as exc:  # a broken view must not stop the stream or the dead-man
            reason = f"machine view unavailable: {exc}"
            if reason != self._last_view_error:
                log.exception("pendant backend view failed")
                self._last_view_error = reason
                await self._broadcast(dumps(error_message(reason)))
            return
        self._last_view_error = None
        axes = message.get("axes")
        if isinstance(axes, list) and axes and all(isinstance(a, str) for a in axes):
            self.axes = tuple(axes)
        # t_s changes on every poll; it alone does not make an idle view worth sending.
        comparable = {k: v for k, v in message.items() if k != "t_s"}
        if message.get("moving") is True or comparable != self._last_sent:
            self._last_sent = comparable
            self._last_text = text
            await self._broadcast(text)

    async def _broadcast(self, text: str) -> None:
        await asyncio.gather(*(self._send(c, text) for c in list(self.clients)))

    async def _send(self, client: _Client, text: str) -> None:
        if client.ws.closed:
            return
        try:
            await asyncio.wait_for(client.ws.send_str(text), SEND_TIMEOUT_S)
        except TimeoutError:
            log.warning("pendant client %s is not reading; closing it", client.label)
            await client.ws.close()
        except (ConnectionError, RuntimeError):
            # The peer vanished between the closed check and the write; remove() follows.
            pass

    async def shutdown(self) -> None:
        """Close every page and leave the machine at rest."""
        self._release()
        self._call_stop("server shutting down")
        for client in list(self.clients):
            await client.ws.close(code=1001, message=b"pendant server shutting down")


_background: set[asyncio.Task[None]] = set()

HUB_KEY: Final = web.AppKey("pendant_hub", PendantHub)
POLICY_KEY: Final = web.AppKey("pendant_policy", _Policy)


def _forbidden(request: web.Request, text: str) -> web.Response:
    log.warning(
        "pendant refused %s %s from %s: %s", request.method, request.path, request.remote, text
    )
    return web.Response(status=403, text=f"smoothjog pendant: {text}\n")


@web.middleware
async def _guard(
    request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]
) -> web.StreamResponse:
    """Apply the access rules to every route, so no endpoint can bypass them."""
    policy = request.app[POLICY_KEY]
    if not policy.host_ok(request):
        return _forbidden(
            request,
            f"host {request.host!r} is not served without a pairing token; open the pendant as "
            "http://127.0.0.1:PORT/ or start it with --lan",
        )
    if policy.token is not None:
        offered = request.query.get("token")
        if offered is not None:
            if not policy.token_ok(offered):
                return _forbidden(
                    request,
                    "wrong pairing token; open the URL or scan the QR code printed in the "
                    "terminal that started smoothjog",
                )
            if request.path != "/ws" and request.method == "GET":
                # Move the token into an HttpOnly cookie and out of the address bar and history.
                response = web.Response(status=303, headers={"Location": request.path})
                response.set_cookie(
                    TOKEN_COOKIE, offered, httponly=True, samesite="Strict", path="/"
                )
                return response
        elif not policy.token_ok(request.cookies.get(TOKEN_COOKIE)):
            return _forbidden(
                request,
                "pairing token required; open the URL or scan the QR code printed in the "
                "terminal that started smoothjog",
            )
    if request.path == "/ws" and not policy.origin_ok(request):
        origin = request.headers.get("Origin", "no Origin header")
        return _forbidden(
            request,
            f"WebSocket from {origin} refused: only the pendant page served by this host may "
            "control the machine",
        )
    return await handler(request)


async def _add_headers(request: web.Request, response: web.StreamResponse) -> None:
    if request.path != "/ws":
        response.headers.update(_SECURITY_HEADERS)


async def _index(request: web.Request) -> web.FileResponse:
    return web.FileResponse(STATIC_DIR / "index.html")


async def _websocket(request: web.Request) -> web.WebSocketResponse:
    hub = request.app[HUB_KEY]
    # The oversize limit sits above MAX_MESSAGE_BYTES so that a long message gets a worded
    # refusal from the parser; only absurd frames close the connection.
    ws = web.WebSocketResponse(max_msg_size=16 * MAX_MESSAGE_BYTES, heartbeat=5.0)
    await ws.prepare(request)
    client = await hub.add(ws, request.remote or "?")
    try:
        async for msg in ws:
            if msg.type == WSMsgType.TEXT:
                await hub.on_text(client, msg.data)
            elif msg.type == WSMsgType.BINARY:
                await hub.refuse(client, "binary frames are not understood; send JSON text")
    finally:
        await hub.remove(client)
    return ws


def create_app(
    backend: PendantBackend,
    *,
    token: str | None,
    allowed_origins: set[str] | None = None,
    deadman_s: float = 0.15,
) -> web.Application:
    """The pendant as an aiohttp application: page at /, assets at /static/, WebSocket at /ws.

    token None serves loopback names and IP literals only; a token is then required by every
    route (?token= once, then an HttpOnly cookie). allowed_origins adds origins (e.g. a reverse
    proxy's) that may open /ws besides the page's own.
    """
    hub = PendantHub(backend=backend, deadman=DeadMan(deadman_s))
    app = web.Application(middlewares=[_guard])
    app[HUB_KEY] = hub
    app[POLICY_KEY] = _Policy(token=token, allowed_origins=frozenset(allowed_origins or ()))
    app.router.add_get("/", _index)
    app.router.add_get("/ws", _websocket)
    app.router.add_static("/static/", STATIC_DIR)
    app.on_response_prepare.append(_add_headers)

    async def stream(app: web.Application) -> AsyncIterator[None]:
        task = asyncio.get_running_loop().create_task(hub.stream_views())
        yield
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task

    async def on_shutdown(app: web.Application) -> None:
        await hub.shutdown()

    app.cleanup_ctx.append(stream)
    app.on_shutdown.append(on_shutdown)
    return app


def _lan_address() -> str:
    """This computer's address on its default route, as a phone on the same network sees it."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            # Connecting a UDP socket sends nothing; it only makes the kernel pick the route.
            probe.connect(("192.0.2.1", 9))
            address: str = probe.getsockname()[0]
        except OSError:
            return socket.gethostname()
    return address


def format_banner(port: int, *, host: str, token: str | None, lan_address: str | None) -> str:
    """The text printed when the pendant is ready: its URL(s) and, with a token, a QR code."""
    if token is None:
        return f"smoothjog pendant: http://{host}:{port}/\n"
    phone_url = f"http://{lan_address}:{port}/?token={token}"
    qr = segno.make(phone_url, error="m")
    lines = [
        "smoothjog pendant on your network; the pairing token is required to watch or jog.",
        f"  phone or tablet: {phone_url}",
        f"  this computer:   http://127.0.0.1:{port}/?token={token}",
        "  scan to pair:",
        "",
    ]
    buffer = io.StringIO()
    qr.terminal(out=buffer, compact=True, border=2)
    return "\n".join(lines) + buffer.getvalue()


def is_loopback(host: str) -> bool:
    """True for localhost and loopback addresses (all the pendant serves without --lan)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


async def run_pendant(
    backend: PendantBackend,
    *,
    host: str = "127.0.0.1",
    port: int = 8765,
    lan: bool = False,
    on_ready: Callable[[str], object] | None = None,
) -> None:
    """Serve the pendant until cancelled; prints its URL (and with lan, the token URL and QR).

    Without lan only a loopback host is accepted. With lan it binds 0.0.0.0 and requires a fresh
    pairing token. on_ready receives the URL to open (with the token in LAN mode).
    """
    token: str | None = None
    bind = host
    if lan:
        token = secrets.token_urlsafe(16)
        # LAN mode exists to be reachable from a phone; the token is what guards it.
        bind = "0.0.0.0"
    elif not is_loopback(host):
        raise PendantError(
            f"refusing to serve the pendant on {host}: anyone on the network could jog the "
            "machine; use --lan, which requires a pairing token, or bind 127.0.0.1"
        )
    runner = web.AppRunner(create_app(backend, token=token), access_log=None)
    await runner.setup()
    try:
        site = web.TCPSite(runner, bind, port)
        try:
            await site.start()
        except OSError as exc:
            raise PendantError(
                f"cannot listen on {bind}:{port} ({exc.strerror}); is another smoothjog "
                "running? choose another port with --http-port"
            ) from exc
        actual_port = _bound_port(runner, port)
        shown_host = "127.0.0.1" if lan else host
        lan_address = _lan_address() if lan else None
        sys.stdout.write(
            format_banner(actual_port, host=shown_host, token=token, lan_address=lan_address)
        )
        sys.stdout.flush()
        if on_ready is not None:
            if token is None:
                on_ready(f"http://{host}:{actual_port}/")
            else:
                on_ready(f"http://{lan_address}:{actual_port}/?token={token}")
        await asyncio.Event().wait()
    finally:
        await runner.cleanup()


def _bound_port(runner: web.AppRunner, requested: int) -> int:
    """The port actually bound (differs from the request when it was 0)."""
    for address in runner.addresses:
        if isinstance(address, tuple) and len(address) >= 2:
            return int(address[1])
    return requested


__all__ = ["PendantHub", "create_app", "format_banner", "run_pendant"]
