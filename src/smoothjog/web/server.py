"""The pendant's web server: serves the page, guards access, relays intents, streams the view.

aiohttp was chosen because it is a mature asyncio HTTP server with first-class WebSocket
support, so the pendant shares the event loop (and its clock) with the jog session.

Each connected page is one input of the session's Arbiter (smoothjog.authority.arbiter), which
enforces the safety rules for every input (docs/pendant.md explains them for users): one
controlling input at a time, the others watch; a held jog stops when the page's heartbeat is
silent for `deadman_s` (its lease) or when the controlling page's WebSocket closes. Enforced here:
every request passes the guard middleware: Host (loopback mode), pairing token (LAN mode), and for
/ws the Origin, which must be the host the page was served from.
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
from collections.abc import AsyncIterator, Awaitable, Callable, Coroutine
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

import segno
from aiohttp import WSMsgType, web

from smoothjog.authority.arbiter import Arbiter
from smoothjog.authority.commands import GOTO_SPEED
from smoothjog.authority.gate import StopRecord
from smoothjog.config import DEFAULT_HTTP_PORT
from smoothjog.control import ControlRefused
from smoothjog.core.errors import InputRefused, SmoothjogError
from smoothjog.core.intents import ContinuousIntent, GotoIntent, Intent, StepIntent, StopIntent
from smoothjog.inputs.base import Input, InputHandle, Notice
from smoothjog.web.backend import PendantBackend
from smoothjog.web.protocol import (
    MAX_MESSAGE_BYTES,
    CommandMessage,
    JogMessage,
    PendantError,
    PendantMessageError,
    PingMessage,
    RatiosMessage,
    StepMessage,
    StopMessage,
    TakeControlMessage,
    dumps,
    error_message,
    parse_client_message,
    pong_message,
    result_message,
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
#: Step jogs run at this fraction of the top jog speed (fine positioning wants control, not haste).
STEP_SPEED: Final = 0.5

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
class WebInput(Input):
    """One connected page: an input of kind "web" whose lease is the hub's dead-man window."""

    hub: PendantHub
    ws: web.WebSocketResponse
    name: str
    lease_s: float | None
    kind: str = "web"
    handle: InputHandle | None = None

    async def run(self, handle: InputHandle) -> None:
        """Greet the page, then handle its frames until its socket closes."""
        self.handle = handle
        await self.hub.greet(self)
        async for msg in self.ws:
            if msg.type == WSMsgType.TEXT:
                await self.hub.on_text(self, msg.data)
            elif msg.type == WSMsgType.BINARY:
                await self.hub.refuse(self, "binary frames are not understood; send JSON text")

    def notice(self, notice: Notice) -> None:
        """Tell the page why its jog stopped (sent in the background: the arbiter cannot wait)."""
        text = (
            f"jog stopped: no heartbeat from this pendant for {notice.silent_s * 1000:.0f} ms "
            "(weak Wi-Fi or a busy device?)"
        )
        _spawn(self.hub.send(self, dumps(error_message(text, code="deadman"))))


@dataclass(eq=False)
class PendantHub:
    """The pages, their roles and the view stream around one backend; the arbiter rules."""

    backend: PendantBackend
    arbiter: Arbiter
    deadman_s: float = 0.15
    clients: list[WebInput] = field(default_factory=list)
    axes: tuple[str, ...] = DEFAULT_AXES
    _last_sent: dict[str, object] | None = None
    _last_text: str | None = None
    _last_view_error: str | None = None
    _roles_dirty: bool = False
    _count: int = 0

    def __post_init__(self) -> None:
        """Check the dead-man window and follow the arbiter's changes of control."""
        if not self.deadman_s > 0.0:
            raise PendantError(
                f"dead-man window must be positive, got {self.deadman_s!r} s; "
                "pass e.g. deadman_s=0.15 to create_app"
            )
        self.arbiter.add_listener(self._control_changed)
        self.arbiter.add_notice_listener(self._announce)
        self.backend.add_stop_listener(self._stopped)

    @property
    def controller(self) -> WebInput | None:
        """The page in control, or None (nobody, or another kind of input, controls)."""
        controller = self.arbiter.controller
        return controller if isinstance(controller, WebInput) else None

    @property
    def deadman_trips(self) -> int:
        """How many held jogs the dead-man stopped (the arbiter counts them for every input)."""
        return self.arbiter.trips

    # -- pages and roles ---------------------------------------------------------------------

    def connect(self, ws: web.WebSocketResponse, peer: str) -> WebInput:
        """A new page, listed here; it becomes an input when the arbiter runs it."""
        self._count += 1
        page = WebInput(hub=self, ws=ws, name=f"#{self._count} {peer}", lease_s=self.deadman_s)
        self.clients.append(page)
        log.info("pendant client %s connected", page.name)
        return page

    async def greet(self, page: WebInput) -> None:
        """Send a page just attached its role (all pages theirs if control changed) and the view."""
        if self._roles_dirty:
            await self._flush_roles()
        else:
            await self._send_roles(only=page)
        if self._last_text is not None:
            await self.send(page, self._last_text)

    async def disconnect(self, page: WebInput) -> None:
        """Forget a page the arbiter detached (it stopped the machine if the page drove it)."""
        if page in self.clients:
            self.clients.remove(page)
        log.info("pendant client %s disconnected", page.name)
        await self._flush_roles()

    def _announce(self, text: str) -> None:
        # A device's sentence (unplugged, asleep, refused): every page shows it.
        message = dumps(error_message(text, code="device"))
        for page in list(self.clients):
            _spawn(self.send(page, message))

    def _stopped(self, record: StopRecord) -> None:
        # Every page hears who stopped the machine; a page holding a jog lets go of it.
        message = dumps(error_message(record.text, code="stopped"))
        for page in list(self.clients):
            _spawn(self.send(page, message))

    def _control_changed(self) -> None:
        # The arbiter calls this synchronously; the pages hear of it as soon as the loop can.
        self._roles_dirty = True
        _spawn(self._flush_roles())

    async def _flush_roles(self) -> None:
        if self._roles_dirty:
            self._roles_dirty = False
            await self._send_roles()

    async def _send_roles(self, only: WebInput | None = None) -> None:
        controller = self.arbiter.controller
        controlled = controller is not None
        for page in [only] if only is not None else list(self.clients):
            role = "controller" if page is controller else "watcher"
            message = role_message(role, controlled=controlled, deadman_s=self.deadman_s)
            await self.send(page, dumps(message))

    # -- intents -----------------------------------------------------------------------------

    async def refuse(self, page: WebInput, text: str) -> None:
        """Answer a page with an error in words."""
        await self.send(page, dumps(error_message(text)))

    async def on_text(self, page: WebInput, text: str) -> None:
        """Handle one text frame from a page; every failure is answered, none propagates."""
        try:
            message = parse_client_message(text, self.axes)
        except PendantMessageError as exc:
            await self.refuse(page, str(exc))
            return
        handle = page.handle
        assert handle is not None, "a page sends frames only while it runs as an input"
        if isinstance(message, PingMessage):
            await self.send(page, dumps(pong_message(message.id)))
            return
        if isinstance(message, TakeControlMessage):
            await self._take_control(page, handle)
            return
        if isinstance(message, StopMessage) and not handle.in_control:
            # Any page's STOP stops the machine (the arbiter lets a stop through from anyone).
            with contextlib.suppress(InputRefused):
                handle.submit(StopIntent(button=True))
            return
        if not handle.in_control:
            await self.refuse(
                page, "this pendant is watching only; press Take control to drive the machine"
            )
            return
        if isinstance(message, RatiosMessage):
            await self._set_ratios(page, handle, message)
            return
        if isinstance(message, CommandMessage):
            if message.name == "goto_zero":
                await self._goto_zero(page, handle, message)
            else:
                # A command may last as long as the controller takes (homing): its own task,
                # so this page's heartbeats and STOP keep flowing meanwhile.
                _spawn(self._command(page, message))
            return
        try:
            handle.submit(_intent_of(message))
        except InputRefused as exc:
            # A refusal the machine side raised (not a rule of the arbiter) says so first.
            await self.refuse(page, str(exc) if exc.__cause__ is None else f"jog refused: {exc}")

    async def _set_ratios(
        self, page: WebInput, handle: InputHandle, message: RatiosMessage
    ) -> None:
        try:
            self.backend.set_speed_ratios(message.ratios)
        except Exception as exc:  # the backend may fail in any way; the machine must stop
            log.exception("pendant backend failed on %r", message)
            with contextlib.suppress(InputRefused):
                handle.submit(StopIntent())
            await self.refuse(page, f"jog refused: {exc}")

    async def _command(self, page: WebInput, message: CommandMessage) -> None:
        """Run one machine command and answer the page with its result, or why it cannot run."""
        try:
            result = await self.backend.command(message)
        except SmoothjogError as exc:
            if not isinstance(exc, ControlRefused):
                log.warning("pendant command %s failed: %s", message.name, exc)
            reply = result_message(message.id, message.name, ok=False, lines=(), error=str(exc))
        else:
            reply = result_message(
                message.id, result.command, ok=result.ok, lines=result.lines, error=result.error
            )
        await self.send(page, dumps(reply))

    async def _goto_zero(
        self, page: WebInput, handle: InputHandle, message: CommandMessage
    ) -> None:
        """Queue the moves to work zero as jogs, so STOP and the dead-man rules apply to them."""
        try:
            targets = self.backend.work_zero_targets()
            for target in targets:
                handle.submit(GotoIntent(target, GOTO_SPEED))
        except (ControlRefused, InputRefused) as exc:
            text = str(exc) if exc.__cause__ is None else f"jog refused: {exc}"
            reply = result_message(message.id, "goto_zero", ok=False, lines=(), error=text)
        else:
            reply = result_message(message.id, "goto_zero", ok=True, lines=(), error=None)
        await self.send(page, dumps(reply))

    async def _take_control(self, page: WebInput, handle: InputHandle) -> None:
        """Ask the arbiter for control; it refuses in words while another holds a jog."""
        if handle.in_control:
            await self._send_roles()
            return
        try:
            handle.take_control()
        except InputRefused as exc:
            await self.refuse(page, str(exc))
            return
        await self._flush_roles()

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
        await asyncio.gather(*(self.send(c, text) for c in list(self.clients)))

    async def send(self, page: WebInput, text: str) -> None:
        """Send one frame; a page that cannot take it in SEND_TIMEOUT_S is closed."""
        if page.ws.closed:
            return
        try:
            await asyncio.wait_for(page.ws.send_str(text), SEND_TIMEOUT_S)
        except TimeoutError:
            log.warning("pendant client %s is not reading; closing it", page.name)
            await page.ws.close()
        except (ConnectionError, RuntimeError):
            # The peer vanished between the closed check and the write; disconnect() follows.
            pass

    async def shutdown(self) -> None:
        """Detach every page (which stops the machine if a page drove it), then close them."""
        for page in list(self.clients):
            if page.handle is not None:
                page.handle.detach()
        for page in list(self.clients):
            await page.ws.close(code=1001, message=b"pendant server shutting down")


def _intent_of(message: JogMessage | StopMessage | StepMessage) -> Intent:
    """The jog intent a page's message asks for."""
    if isinstance(message, JogMessage):
        return ContinuousIntent(dict(message.axes), message.speed)
    if isinstance(message, StepMessage):
        return StepIntent(message.axis, message.dist_mm, STEP_SPEED)
    # The page sends `stop` for its STOP button and Escape (a release is a neutral jog).
    return StopIntent(button=True)


_background: set[asyncio.Task[None]] = set()


def _spawn(coro: Coroutine[object, object, None]) -> None:
    """Run coro in the background, keeping a reference so it is not collected mid-send."""
    task = asyncio.get_running_loop().create_task(coro)
    _background.add(task)
    task.add_done_callback(_background.discard)


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
    page = hub.connect(ws, request.remote or "?")
    try:
        # Attaches the page, serves it until its socket closes, detaches it (stopping the
        # machine if the page was driving it).
        await hub.arbiter.run_input(page)
    finally:
        await hub.disconnect(page)
    return ws


def create_app(
    backend: PendantBackend,
    *,
    token: str | None,
    allowed_origins: set[str] | None = None,
    deadman_s: float = 0.15,
    arbiter: Arbiter | None = None,
) -> web.Application:
    """The pendant as an aiohttp application: page at /, assets at /static/, WebSocket at /ws.

    token None serves loopback names and IP literals only; a token is then required by every
    route (?token= once, then an HttpOnly cookie). allowed_origins adds origins (e.g. a reverse
    proxy's) that may open /ws besides the page's own. Each page is an input of the arbiter
    (a new one over backend unless the session's own is given) with a lease of deadman_s.
    """
    hub = PendantHub(backend=backend, arbiter=arbiter or Arbiter(backend), deadman_s=deadman_s)
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
    port: int = DEFAULT_HTTP_PORT,
    lan: bool = False,
    on_ready: Callable[[str], object] | None = None,
    arbiter: Arbiter | None = None,
) -> None:
    """Serve the pendant until cancelled; prints its URL (and with lan, the token URL and QR).

    Without lan only a loopback host is accepted. With lan it binds 0.0.0.0 and requires a fresh
    pairing token. on_ready receives the URL to open (with the token in LAN mode). arbiter is
    the session's, shared with its other inputs (a new one over backend when None).
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
    runner = web.AppRunner(create_app(backend, token=token, arbiter=arbiter), access_log=None)
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


__all__ = ["STEP_SPEED", "PendantHub", "WebInput", "create_app", "format_banner", "run_pendant"]
