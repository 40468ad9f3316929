"""A real CNCjs 1.11.5 (tools/cncjs, from scripts/setup.sh test) serving the simulator's pty.

The pieces, each usable alone:

* `SimProcess`: `python -m smoothjog sim --machine hobby-router --link <scratch>/ttyGRBL` as its
  own process (the repository's src on PYTHONPATH).
* `CncjsServer`: `node <cncjs bin> --host 127.0.0.1 --port <free port> --config <scratch cfg>`
  with HOME in the scratch dir (CNCjs writes ~/.cncjs-sessions) and a fixed, known `secret`.
* `make_token`: an HS256 JWT as the CNCjs pendants make one, signed with that secret.
* `RawClient`: "another CNCjs client" (python-socketio 4.x) that records what CNCjs sends it.
* `CncjsRig`: all of it for one test, with kill() and restart() for CNCjs.

The processes are started by bench/cncjs_rig.py, which `python -m bench cncjs` shares; here its
errors (RigError) become test failures that show the process's log.

RawClient runs its own event loop in a thread, so its blocking helpers can be used from plain
tests and its `async_wait_for` from async tests without stalling the loop under test.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
from collections.abc import Callable, Coroutine, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import pytest
import socketio
from bench import cncjs_rig
from bench.cncjs_rig import (
    BAUDRATE,
    CNCJS_START_TIMEOUT_S,
    CONTROLLER,
    MACHINE,
    README_TEST_COMMAND,
    ROOT,
    SIM_START_TIMEOUT_S,
    STOP_GRACE_S,
    TEST_SECRET,
    RigError,
    cncjs_config,
    free_port,
    log_tail,
    stop_process,
)

from smoothjog.links.cncjs_auth import sign_token

__all__ = [
    "BAUDRATE",
    "CNCJS_BIN",
    "CNCJS_DIR",
    "CONTROLLER",
    "MACHINE",
    "README_TEST_COMMAND",
    "ROOT",
    "TEST_SECRET",
    "CncjsRefusedError",
    "CncjsRig",
    "CncjsServer",
    "RawClient",
    "SimProcess",
    "cncjs_config",
    "find_cncjs",
    "find_node",
    "free_port",
    "log_tail",
    "make_token",
    "stop_process",
]

CNCJS_DIR = cncjs_rig.CNCJS_DIR
#: Read by find_cncjs() at each call, so a test can point it elsewhere.
CNCJS_BIN = cncjs_rig.CNCJS_BIN
PENDANT_NAME = "cncjs-pendant"
CALL_TIMEOUT_S = 10.0

# Events a RawClient records (python-socketio 4.x has no catch-all handler).
RECORDED_EVENTS = (
    "startup",
    "serialport:open",
    "serialport:close",
    "serialport:change",
    "serialport:error",
    "serialport:read",
    "serialport:write",
    "controller:settings",
    "controller:state",
    "Grbl:settings",
    "Grbl:state",
    "feeder:status",
    "sender:status",
    "workflow:state",
    "gcode:load",
    "gcode:unload",
    "config:change",
    "task:start",
    "task:finish",
    "task:error",
)

T = TypeVar("T")


@contextlib.contextmanager
def _fails_the_test() -> Iterator[None]:
    """A RigError (a process did not start) as a test failure with its log, no traceback."""
    try:
        yield
    except RigError as exc:
        pytest.fail(str(exc), pytrace=False)


def find_cncjs() -> Path:
    """The CNCjs program at CNCJS_BIN, or a test failure that says how to install it."""
    with _fails_the_test():
        return cncjs_rig.find_cncjs(CNCJS_BIN)


def find_node() -> str:
    """The node program on PATH, or a test failure naming the packages."""
    with _fails_the_test():
        return cncjs_rig.find_node()


# --- tokens -----------------------------------------------------------------------------------


def make_token(
    secret: str = TEST_SECRET,
    *,
    user_id: str = "",
    name: str = PENDANT_NAME,
    lifetime_s: int = 3600,
    expired: bool = False,
    wrong_secret: bool = False,
    now: int | None = None,
) -> str:
    """An HS256 JWT with {"id", "name", "iat", "exp"}, as the CNCjs pendants send in ?token=.

    expired=True makes one that ran out an hour ago; wrong_secret=True signs it with another key.
    Signed by smoothjog's own sign_token, which these tests thereby check against CNCjs.
    """
    issued = int(time.time()) if now is None else now
    if expired:
        issued -= 2 * 3600
        lifetime_s = 3600
    payload: dict[str, object] = {
        "id": user_id,
        "name": name,
        "iat": issued,
        "exp": issued + lifetime_s,
    }
    key = secret + "-not-the-secret" if wrong_secret else secret
    return sign_token(key, payload)


# --- the processes ----------------------------------------------------------------------------


class SimProcess(cncjs_rig.SimProcess):
    """The smoothjog simulator on a pty (bench/cncjs_rig.py); a failed start fails the test."""

    def wait_ready(self, timeout_s: float = SIM_START_TIMEOUT_S) -> None:
        """Wait until the --link symlink points at a live pty; fail with the sim's log if not."""
        with _fails_the_test():
            super().wait_ready(timeout_s)


class CncjsServer(cncjs_rig.CncjsServer):
    """One CNCjs process on 127.0.0.1 (bench/cncjs_rig.py); a failed start fails the test."""

    def spawn(self) -> None:
        """Start node on the same port as before; wait_ready() waits for HTTP."""
        with _fails_the_test():
            super().spawn()

    def wait_ready(self, timeout_s: float = CNCJS_START_TIMEOUT_S) -> None:
        """Wait until http://127.0.0.1:<port>/ answers; fail with CNCjs's output if not."""
        with _fails_the_test():
            super().wait_ready(timeout_s)


# --- a raw CNCjs client -----------------------------------------------------------------------


class CncjsRefusedError(AssertionError):
    """CNCjs answered the socket.io handshake with connect_error."""

    def __init__(self, data: Any) -> None:
        """Keep CNCjs's error payload ({'message', 'code', 'type'})."""
        self.data = data
        message = data.get("message") if isinstance(data, dict) else data
        super().__init__(f"CNCjs refused the connection: {message!r} ({data!r})")
        self.message = str(message)


def _position(state: dict[str, Any], key: str = "mpos") -> tuple[float, float, float] | None:
    """(x, y, z) from a Grbl:state payload's status.mpos (CNCjs sends strings), if present."""
    pos = state.get("status", {}).get(key)
    if not isinstance(pos, dict) or not all(pos.get(axis) for axis in "xyz"):
        return None
    return (float(pos["x"]), float(pos["y"]), float(pos["z"]))


class RawClient:
    """A python-socketio 4.x client of CNCjs, standing in for the web UI or another pendant.

    Everything CNCjs sends it is recorded under one lock: `reads` (serialport:read lines),
    `writes` (serialport:write (data, context) echoes), `workflow_states`, `grbl_states` and
    `events` (every recorded event as (monotonic time, name, args)). `wait_for` blocks the calling
    thread; `async_wait_for` is for async tests.
    """

    def __init__(self, url: str, port_path: str, token: str, *, name: str = "raw") -> None:
        """Prepare; connect() connects."""
        self.url = url
        self.port_path = port_path
        self.token = token
        self.name = name
        self.cond = threading.Condition()
        self.reads: list[str] = []
        self.read_times: list[float] = []
        self.writes: list[tuple[str, dict[str, Any]]] = []
        self.workflow_states: list[str] = []
        self.grbl_states: list[dict[str, Any]] = []
        self.events: list[tuple[float, str, tuple[Any, ...]]] = []
        self.connected = False
        self.refusal: Any = None
        self.disconnected = False
        self._poller: asyncio.Task[None] | None = None
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(
            target=self._loop.run_forever, name=f"RawClient {name}", daemon=True
        )
        self._thread.start()
        self._sio: socketio.AsyncClient = self._call(self._make_client())
        self._closed = False

    # -- plumbing

    def _call(self, coro: Coroutine[Any, Any, T], timeout_s: float = CALL_TIMEOUT_S) -> T:
        """Run coro on the client's loop and wait for its result."""
        return asyncio.run_coroutine_threadsafe(coro, self._loop).result(timeout_s)

    async def _make_client(self) -> socketio.AsyncClient:
        """The socketio client, made on its own loop, with a handler for each event."""
        sio = socketio.AsyncClient(reconnection=False)
        sio.on("connect", self._on_connect)
        sio.on("connect_error", self._on_connect_error)
        sio.on("disconnect", self._on_disconnect)
        for event in RECORDED_EVENTS:
            sio.on(event, self._recorder(event))
        return sio

    def _on_connect(self) -> None:
        with self.cond:
            self.connected = True
            self.cond.notify_all()

    def _on_connect_error(self, *args: Any) -> None:
        with self.cond:
            self.refusal = args[0] if len(args) == 1 else args
            self.cond.notify_all()

    def _on_disconnect(self) -> None:
        with self.cond:
            self.connected = False
            self.disconnected = True
            self.cond.notify_all()

    def _recorder(self, event: str) -> Callable[..., None]:
        """A handler that records event's arguments."""

        def record(*args: Any) -> None:
            now = time.monotonic()
            with self.cond:
                self.events.append((now, event, args))
                if event == "serialport:read" and args:
                    self.reads.append(str(args[0]))
                    self.read_times.append(now)
                elif event == "serialport:write" and args:
                    context = args[1] if len(args) > 1 and isinstance(args[1], dict) else {}
                    self.writes.append((str(args[0]), context))
                elif event == "workflow:state" and args:
                    self.workflow_states.append(str(args[0]))
                elif event == "Grbl:state" and args and isinstance(args[0], dict):
                    self.grbl_states.append(args[0])
                self.cond.notify_all()

        return record

    # -- connection

    def connect(self, timeout_s: float = CALL_TIMEOUT_S) -> None:
        """Connect with ?token= and wait for `connect`; connect_error raises CncjsRefusedError."""
        refusal = self.try_connect(timeout_s)
        if refusal is not None:
            raise CncjsRefusedError(refusal)

    def try_connect(self, timeout_s: float = CALL_TIMEOUT_S) -> Any:
        """Connect; None once `connect` came, else CNCjs's connect_error payload."""
        url = f"{self.url}?token={self.token}"
        self._call(self._sio.connect(url, transports=["websocket"]), timeout_s)
        self.wait_for(
            lambda: self.connected or self.refusal is not None,
            timeout_s,
            "connect or connect_error from CNCjs",
        )
        return None if self.connected else self.refusal

    def open(
        self, port_path: str | None = None, *, wake: bool = False, timeout_s: float = CALL_TIMEOUT_S
    ) -> None:
        """emit open(port, {baudrate: 115200, controllerType: 'Grbl'}) and wait for its ack.

        CNCjs takes a freshly opened port as ready only after Grbl's banner or a status report;
        on a pty that stays silent it writes its first `?` 2 s after the open. wake=True writes
        that `?` at once (its status line then also arrives as one serialport:read).
        """
        port = self.port_path if port_path is None else port_path
        options = {"baudrate": BAUDRATE, "controllerType": CONTROLLER}
        ack = self.emit_with_ack("open", port, options, timeout_s=timeout_s)
        if ack and ack[0] is not None:
            raise AssertionError(f"CNCjs could not open {port}: {ack!r} (see the CNCjs log)")
        if wake:
            self.write("?", port)

    def emit(self, event: str, *args: Any) -> None:
        """emit(event, *args) without an ack (the packet is queued when this returns)."""
        self._call(self._sio.emit(event, args))

    def emit_with_ack(
        self, event: str, *args: Any, timeout_s: float = CALL_TIMEOUT_S
    ) -> tuple[Any, ...]:
        """emit(event, *args) and wait for CNCjs's ack; returns the ack's arguments."""
        done = threading.Event()
        reply: list[tuple[Any, ...]] = []

        def on_ack(*ack_args: Any) -> None:
            reply.append(ack_args)
            done.set()

        self._call(self._sio.emit(event, args, callback=on_ack))
        if not done.wait(timeout_s):
            raise AssertionError(f"no ack from CNCjs for {event}{args!r} in {timeout_s} s")
        return reply[0]

    def write(self, text: str, port_path: str | None = None) -> None:
        """emit write(port, text): raw bytes to the serial port at once (text must be str)."""
        if not isinstance(text, str):
            raise TypeError("CNCjs's write takes a str; bytes make it throw")
        self.emit("write", self.port_path if port_path is None else port_path, text)

    def command(self, cmd: str, *args: Any) -> None:
        """emit command(port, cmd, *args), e.g. command('jogCancel')."""
        self.emit("command", self.port_path, cmd, *args)

    def start_job(self, gcode: str, name: str = "smoothjog-test.nc") -> dict[str, Any]:
        """Load gcode into CNCjs's sender and start it, as the web UI does.

        CNCjs 1.11: command(port, 'gcode:load', name, gcode[, context], ack) answers
        ack(err, senderStatus); then command(port, 'gcode:start'). Returns the sender status.
        """
        ack = self.emit_with_ack("command", self.port_path, "gcode:load", name, gcode)
        if not ack or ack[0] is not None:
            raise AssertionError(f"CNCjs did not load the G-code: {ack!r}")
        self.command("gcode:start")
        status: dict[str, Any] = ack[1] if len(ack) > 1 else {}
        return status

    # -- a second writer

    def start_poller(self, text: str = "$G\n", period_s: float = 0.4) -> None:
        """Write text every period_s (as a busy web UI console would) until stop_poller()."""
        self.stop_poller()

        async def start() -> asyncio.Task[None]:
            return asyncio.create_task(self._poll(text, period_s))

        self._poller = self._call(start())

    async def _poll(self, text: str, period_s: float) -> None:
        while True:
            await self._sio.emit("write", (self.port_path, text))
            await asyncio.sleep(period_s)

    def stop_poller(self) -> None:
        """Stop the background writes (no-op if none)."""
        poller, self._poller = self._poller, None
        if poller is not None:

            async def stop() -> None:
                poller.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await poller

            self._call(stop())

    # -- waiting

    def wait_for(
        self, predicate: Callable[[], T | None], timeout_s: float = CALL_TIMEOUT_S, what: str = ""
    ) -> T:
        """Block until predicate() (called under the lock) is truthy; return its value."""
        end = time.monotonic() + timeout_s
        with self.cond:
            while True:
                value = predicate()
                if value:
                    return value
                left = end - time.monotonic()
                if left <= 0:
                    raise AssertionError(self._timeout_message(timeout_s, what or repr(predicate)))
                self.cond.wait(min(left, 0.05))

    async def async_wait_for(
        self, predicate: Callable[[], T | None], timeout_s: float = CALL_TIMEOUT_S, what: str = ""
    ) -> T:
        """wait_for for async tests: polls every 10 ms without blocking the caller's loop."""
        end = time.monotonic() + timeout_s
        while True:
            with self.cond:
                value = predicate()
            if value:
                return value
            if time.monotonic() > end:
                raise AssertionError(self._timeout_message(timeout_s, what or repr(predicate)))
            await asyncio.sleep(0.01)

    def _timeout_message(self, timeout_s: float, what: str) -> str:
        """What was seen, for a failed wait."""
        with self.cond:
            return (
                f"{self.name}: timed out after {timeout_s} s waiting for {what};"
                f" last reads {self.reads[-8:]!r}; workflow {self.workflow_states[-4:]!r};"
                f" state {self.active_state()!r} at {self.mpos()!r}; refusal {self.refusal!r}"
            )

    def active_state(self) -> str:
        """Grbl's state in the last Grbl:state ('' before any)."""
        with self.cond:
            if not self.grbl_states:
                return ""
            return str(self.grbl_states[-1].get("status", {}).get("activeState", ""))

    def mpos(self) -> tuple[float, float, float] | None:
        """Machine position in the last Grbl:state that had one."""
        with self.cond:
            for state in reversed(self.grbl_states):
                pos = _position(state)
                if pos is not None:
                    return pos
            return None

    def wait_state(
        self, active: str, timeout_s: float = CALL_TIMEOUT_S
    ) -> tuple[float, float, float]:
        """Wait for a Grbl:state with activeState == active and an MPos; return that MPos."""

        def reached() -> tuple[float, float, float] | None:
            if not self.grbl_states:
                return None
            last = self.grbl_states[-1]
            if last.get("status", {}).get("activeState") != active:
                return None
            return _position(last)

        return self.wait_for(reached, timeout_s, f"Grbl:state {active} with an MPos")

    def wait_read(
        self, match: Callable[[str], bool], since: int = 0, timeout_s: float = CALL_TIMEOUT_S
    ) -> str:
        """Wait for a serialport:read line (index >= since) that matches; return it."""

        def found() -> str | None:
            return next((line for line in self.reads[since:] if match(line)), None)

        return self.wait_for(found, timeout_s, f"a serialport:read line after #{since}")

    # -- teardown

    def disconnect(self) -> None:
        """Stop the poller and disconnect (the port stays open for the other clients)."""
        self.stop_poller()
        with contextlib.suppress(Exception):
            self._call(self._sio.disconnect(), timeout_s=STOP_GRACE_S)

    def close(self) -> None:
        """Disconnect, close the HTTP session and end the client's loop and thread."""
        if self._closed:
            return
        self._closed = True
        self.disconnect()

        async def settle() -> None:
            http = getattr(self._sio.eio, "http", None)
            if http is not None and not http.closed:
                await http.close()
            current = asyncio.current_task()
            tasks = [task for task in asyncio.all_tasks() if task is not current]
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)

        with contextlib.suppress(Exception):
            self._call(settle(), timeout_s=STOP_GRACE_S)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(STOP_GRACE_S)
        if not self._thread.is_alive():
            self._loop.close()


# --- everything for one test ------------------------------------------------------------------


@dataclass
class CncjsRig:
    """The simulator plus CNCjs in scratch; clients made with client() are closed by close()."""

    scratch: Path
    sim: SimProcess
    server: CncjsServer
    clients: list[RawClient] = field(default_factory=list)

    @classmethod
    def start(cls, scratch: Path) -> CncjsRig:
        """Start the simulator and CNCjs side by side (CNCjs needs the pty only on open)."""
        scratch.mkdir(parents=True, exist_ok=True)
        sim = SimProcess(scratch)
        server = CncjsServer(scratch, str(sim.link))
        rig = cls(scratch, sim, server)
        try:
            find_cncjs()
            cncjs_rig.start_side_by_side(sim, server)
        except BaseException:
            rig.close()
            raise
        return rig

    @property
    def url(self) -> str:
        """CNCjs's base URL (http://127.0.0.1:<port>)."""
        return self.server.url

    @property
    def port_path(self) -> str:
        """The serial port to open in CNCjs: the simulator's pty (its stable symlink)."""
        return str(self.sim.link)

    @property
    def config_path(self) -> Path:
        """CNCjs's config file (with the secret)."""
        return self.server.config_path

    @property
    def secret(self) -> str:
        """The secret CNCjs signs and checks tokens with."""
        return self.server.secret

    @property
    def log_path(self) -> Path:
        """CNCjs's log (stdout and stderr, every start)."""
        return self.server.log_path

    def token(self, **kwargs: Any) -> str:
        """make_token with this CNCjs's secret (kwargs as make_token's)."""
        return make_token(self.secret, **kwargs)

    def client(
        self,
        *,
        token: str | None = None,
        connect: bool = True,
        open_port: bool = True,
        wake: bool = True,
    ) -> RawClient:
        """A RawClient (closed at teardown), by default connected and with the pty open.

        wake=True (the default) writes `?` after the open so that CNCjs takes the port as ready
        at once instead of 2 s later (RawClient.open).
        """
        client = RawClient(
            self.url,
            self.port_path,
            self.token() if token is None else token,
            name=f"raw{len(self.clients)}",
        )
        self.clients.append(client)
        if connect:
            client.connect()
            if open_port:
                client.open(wake=wake)
        return client

    def kill(self) -> None:
        """SIGKILL CNCjs (the simulator keeps running, as the machine would)."""
        self.server.kill()

    def restart(self) -> None:
        """Start CNCjs again on the same URL (after kill() or while running)."""
        self.server.restart()

    def close(self) -> None:
        """Close the clients, stop CNCjs, then the simulator."""
        for client in self.clients:
            client.close()
        self.server.stop()
        self.sim.stop()
