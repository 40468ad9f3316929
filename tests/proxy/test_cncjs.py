"""The real CNCjs 1.11.5 as the sender, on the proxy's pseudo-terminal, the simulator behind it.

CNCjs opens `<scratch>/ttyPROXY` as if it were a machine. Behind the proxy sits the built-in
simulator (Grbl 1.1h, hobby router) driven by the shipped Host in real time, in this test's
event loop, so the pendant can be the real session backend under the arbiter: its jogs are
submitted as the web pendant's are, and refused in the words the page shows. One test runs the
`smoothjog proxy` command itself as a process. The reference run for "nothing changes the job"
is the same file through CNCjs on the simulator's own pty (`smoothjog sim --link`), no proxy.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
from collections.abc import AsyncIterator, Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from smoothjog.authority.arbiter import Arbiter
from smoothjog.core.errors import InputRefused
from smoothjog.core.intents import ContinuousIntent, StopIntent
from smoothjog.host import Host
from smoothjog.inputs.base import Input, InputHandle
from smoothjog.links.sim import SimLink
from smoothjog.proxy import JOB_LOCK, SENDER, PtySender, SenderConnection, SenderProxy
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.web.session_backend import SessionBackend
from tests.cncjs.harness import CncjsRig, CncjsServer, RawClient, make_token
from tests.test_cli_jog import Child

pytestmark = pytest.mark.timeout(120)

#: hobby-router along X: 5000 mm/min and 500 mm/s²; the bench's S1 bound is 2 x v²/2a.
V_MM_S = 5000 / 60
STOP_MM = V_MM_S**2 / (2 * 500)

#: A short file with a work offset, an arc and a change of feed: every modal group it touches
#: must read the same afterwards with and without the proxy.
JOB = """(smoothjog proxy test)
G21 G90 G94
G10 L2 P2 X-100 Y-100 Z0
G55
G1 F3000 X10 Y5 Z-2
G2 X20 Y5 I5 J0
G1 X15 Y15 F2000
G0 Z-1
M5
"""
JOB_END_MPOS = (-85.0, -85.0, -1.0)

#: Long enough to be running when CNCjs resets it.
LONG_JOB = "G21 G90\n" + "".join(f"G1 F1500 X-{10 + k} Y-{5 + k % 3}\n" for k in range(60))


class PendantScript(Input):
    """The pendant as the arbiter sees it: an input whose intents the test submits."""

    name = "test pendant"
    kind = "script"
    lease_s = None

    async def run(self, handle: InputHandle) -> None:  # pragma: no cover - never run
        await asyncio.Event().wait()


@dataclass
class Proxied:
    """CNCjs on the proxy's pty, the host behind it, and the pendant beside it."""

    host: Host
    link: SimLink
    proxy: SenderProxy
    pty: PtySender
    server: CncjsServer
    client: RawClient
    pendant: InputHandle

    @property
    def conn(self) -> SenderConnection:
        assert self.pty.conn is not None
        return self.pty.conn


async def _until(predicate: Callable[[], object], timeout_s: float = 15.0, what: str = "") -> None:
    try:
        async with asyncio.timeout(timeout_s):
            while not predicate():  # noqa: ASYNC110 - the state changes in callbacks, no event
                await asyncio.sleep(0.02)
    except TimeoutError:
        raise AssertionError(f"timed out after {timeout_s} s waiting for {what}") from None


@contextlib.asynccontextmanager
async def _proxied(scratch: Path) -> AsyncIterator[Proxied]:
    await asyncio.to_thread(scratch.mkdir, parents=True, exist_ok=True)
    link = SimLink(GrblFirmware(machine="hobby-router"))
    await link.open()
    host = Host(link, handshake_timeout_s=10.0)
    proxy = SenderProxy()
    proxy.attach(host)
    await host.start()
    proxy.started(host)
    forwarder = asyncio.create_task(proxy.run())
    pty = PtySender(proxy, scratch / "ttyPROXY")
    pty.open()
    server = CncjsServer(scratch, str(scratch / "ttyPROXY"))
    client: RawClient | None = None
    try:
        await asyncio.to_thread(server.start)
        client = RawClient(server.url, str(scratch / "ttyPROXY"), make_token(server.secret))
        await asyncio.to_thread(client.connect)
        # No `?` to wake it: the banner the proxy replays on open is what makes CNCjs ready.
        await asyncio.to_thread(client.open)
        backend = SessionBackend(host)
        arbiter = Arbiter(backend)
        pendant = arbiter.attach(PendantScript())
        yield Proxied(host, link, proxy, pty, server, client, pendant)
    finally:
        if client is not None:
            await asyncio.to_thread(client.close)
        await asyncio.to_thread(server.stop)
        forwarder.cancel()
        await asyncio.gather(forwarder, return_exceptions=True)
        pty.close()
        await host.close()


async def _settings_and_position(client: RawClient) -> tuple[dict[str, str], tuple[float, ...]]:
    """CNCjs read the settings ($$ after the banner) and shows a position."""

    def settings() -> dict[str, str] | None:
        for _t, name, args in reversed(client.events):
            if name == "Grbl:settings" and args and args[0].get("settings"):
                found: dict[str, str] = args[0]["settings"]
                return found
        return None

    await _until(lambda: settings() is not None, what="CNCjs's Grbl:settings")
    found = settings()
    assert found is not None
    # A state from a status report (CNCjs shows zeros until the first report has come).
    mpos = await asyncio.to_thread(client.wait_state, "Idle", 15.0)
    return found, mpos


async def _hold(pendant: InputHandle, x: float, seconds: float) -> None:
    """A held stick: the same intent every 30 ms, as the page's heartbeat sends it."""
    loop = asyncio.get_running_loop()
    end = loop.time() + seconds
    while loop.time() < end:
        pendant.submit(ContinuousIntent({"X": x}, 1.0))
        await asyncio.sleep(0.03)


def _job_result(client: RawClient, *, write: Callable[[str], None]) -> tuple[object, ...]:
    """After a job: where the machine rests, its `$G` modes and its G55 offset, as CNCjs reads
    them (the lines CNCjs's client wrote come back as serialport:read)."""
    mpos = client.wait_state("Idle", timeout_s=30.0)
    since = len(client.reads)
    write("$G\n")
    modes = client.wait_read(lambda x: x.startswith("[GC:"), since)
    since = len(client.reads)
    write("$#\n")
    g55 = client.wait_read(lambda x: x.startswith("[G55:"), since)
    return mpos, modes, g55


def _run_job(client: RawClient, gcode: str) -> None:
    """CNCjs runs gcode from its sender; returns when its workflow is idle again."""
    since = len(client.workflow_states)
    client.start_job(gcode)
    client.wait_for(lambda: "running" in client.workflow_states[since:], 10.0, "the job to run")
    client.wait_for(
        lambda: client.workflow_states[-1] == "idle", 60.0, "CNCjs's workflow idle again"
    )


@pytest.fixture
def direct_job_result(tmp_path: Path) -> Iterator[tuple[object, ...]]:
    """The job through CNCjs on the simulator directly: the reference."""
    rig = CncjsRig.start(tmp_path / "direct")
    try:
        client = rig.client()
        assert client.wait_state("Idle", 15.0) == (-1.0, -1.0, -1.0)
        _run_job(client, JOB)
        yield _job_result(client, write=client.write)
    finally:
        rig.close()


# ----------------------------------------------------------------------------- the tests
def test_the_proxy_command_serves_cncjs_settings_and_position(tmp_path: Path) -> None:
    """`smoothjog proxy --link` (built-in simulator) opened by CNCjs as a machine."""
    link = tmp_path / "ttyPROXY"
    child = Child("proxy", "--link", str(link), "--http-port", "0")
    server = CncjsServer(tmp_path, str(link))
    client: RawClient | None = None
    try:
        child.wait_for(r"^smoothjog proxy: the sender's port is pty ", 30.0)
        server.start()
        client = RawClient(server.url, str(link), make_token(server.secret))
        client.connect()
        client.open()
        settings, mpos = asyncio.run(_settings_and_position(client))
        assert settings["$110"].startswith("5000")  # the hobby router's X max rate
        assert settings["$22"] == "1"
        assert mpos == (-1.0, -1.0, -1.0)
        # The first thing CNCjs heard was the banner (the machine was not reset for it).
        assert client.reads[0] == "Grbl 1.1h ['$' for help]"
    finally:
        if client is not None:
            client.close()
        server.stop()
        code = child.stop()
    assert code == 0, (child.stdout, child.stderr)
    assert "Traceback" not in "".join(child.stderr)


async def test_a_cncjs_job_refuses_the_pendant_and_ends_as_without_the_proxy(
    tmp_path: Path, direct_job_result: tuple[object, ...]
) -> None:
    async with _proxied(tmp_path / "proxied") as p:
        _settings, mpos = await _settings_and_position(p.client)
        assert mpos == (-1.0, -1.0, -1.0)
        assert p.host.model.reset_count == 0  # CNCjs's open reset nothing
        await asyncio.to_thread(p.client.start_job, JOB)
        await _until(lambda: p.host.model.jog_lock is not None, what="the sender's jog lock")
        assert p.host.model.jog_lock == JOB_LOCK
        with pytest.raises(InputRefused, match=f"jogging is disabled: {JOB_LOCK}"):
            p.pendant.submit(ContinuousIntent({"X": -1.0}, 1.0))
        states = p.client.workflow_states
        await asyncio.to_thread(
            p.client.wait_for,
            lambda: states[-1] == "idle" and "running" in states,
            60.0,
            "the job to end",
        )
        engine = p.host.engine
        assert engine is not None
        assert engine.stats.lines_sent == 0  # nothing of smoothjog's moved meanwhile
        result = await asyncio.to_thread(_job_result, p.client, write=p.client.write)
        assert result == direct_job_result
        assert result[0] == JOB_END_MPOS
        assert p.link.firmware.rx.dropped == 0
        assert p.host.ledger.stats.unowned_replies == 0

        # After the job the pendant jogs, and stops within S1's bound of 2 x v²/2a.
        await _until(lambda: p.host.model.jog_lock is None, what="the lock lifted")
        await _hold(p.pendant, -1.0, 1.5)
        at_release = p.host.model.mpos_mm
        assert at_release is not None
        assert at_release[0] < JOB_END_MPOS[0] - 50.0  # it ran at speed
        p.pendant.submit(StopIntent())
        await _until(p.host.at_rest, what="rest after the pendant's jog")
        await asyncio.sleep(0.3)
        rest = p.host.model.mpos_mm
        assert rest is not None
        assert 0.0 <= at_release[0] - rest[0] <= 2.0 * STOP_MM
        # CNCjs saw it all in the reports.
        await _until(lambda: p.client.mpos() == tuple(rest), what="CNCjs showing the rest")


async def test_cncjs_s_feed_hold_stops_the_pendant_s_jog_for_good(tmp_path: Path) -> None:
    async with _proxied(tmp_path / "proxied") as p:
        await _settings_and_position(p.client)
        holding = asyncio.create_task(_hold(p.pendant, -1.0, 4.0))
        await _until(lambda: p.host.model.state == "Jog", what="the pendant's jog")
        await asyncio.sleep(0.5)
        p.client.command("feedhold")
        await _until(lambda: p.host.model.state == "Idle", 5.0, "the machine stopped")
        await asyncio.sleep(0.3)
        stopped = p.host.model.mpos_mm
        # The stick is still held: smoothjog does not start the jog again.
        await asyncio.sleep(1.5)
        assert p.host.model.mpos_mm == stopped
        assert p.host.model.state == "Idle"
        holding.cancel()
        engine = p.host.engine
        assert engine is not None
        fault = engine.view(p.host.now_s()).fault
        assert fault is not None
        assert "stopped outside smoothjog" in fault[0]
        assert p.host.ledger.stats.realtime[SENDER] >= 1  # CNCjs's `!` (and its `?` polls)


async def test_cncjs_s_reset_mid_job_leaves_no_stale_reply_on_either_side(
    tmp_path: Path,
) -> None:
    async with _proxied(tmp_path / "proxied") as p:
        await _settings_and_position(p.client)
        # Every line CNCjs wrote and every reply it got, in order, at the proxy.
        log: list[tuple[str, bytes]] = []
        conn = p.conn
        sent, line_from = conn.send, p.proxy.line_from

        def send(data: bytes) -> None:
            log.append(("to", data))
            sent(data)

        def from_sender(c: SenderConnection, raw: bytes) -> None:
            log.append(("from", raw))
            line_from(c, raw)

        conn.send = send  # type: ignore[method-assign]
        p.proxy.line_from = from_sender  # type: ignore[method-assign]
        await asyncio.to_thread(p.client.start_job, LONG_JOB)
        await _until(lambda: p.host.model.state == "Run", what="the job running")
        await asyncio.sleep(0.5)
        reads_before = len(p.client.reads)
        p.client.command("reset")
        await _until(
            lambda: any(x.startswith("Grbl 1.1h") for x in p.client.reads[reads_before:]),
            what="CNCjs seeing the banner",
        )
        await _until(lambda: not p.host.rehandshaking, what="the host's second handshake")
        await asyncio.sleep(1.5)  # CNCjs polls; the host reads the settings again
        banner = next(i for i, (d, data) in enumerate(log) if data.startswith(b"Grbl 1.1h"))
        owed = 0
        for direction, data in log[banner + 1 :]:
            if direction == "from":
                owed += 1
            elif re.fullmatch(rb"(ok|error:\d+)\r\n", data):
                owed -= 1
                assert owed >= 0, "a reply reached CNCjs for no line of its own"
        assert owed == 0
        after = p.client.reads[reads_before:]
        assert not [x for x in after if x.startswith(("[VER:", "[OPT:", "[G54:", "[TLO:"))]
        assert p.host.ledger.stats.unowned_replies == 0
        assert p.host.error is None
        assert p.link.firmware.rx.dropped == 0
        # Both sides go on: CNCjs's line is answered, and the pendant may jog once unlocked.
        since = len(p.client.reads)
        p.client.write("$X\n")
        await asyncio.to_thread(p.client.wait_read, lambda x: x == "ok", since)
        await _until(lambda: p.host.model.jog_lock is None, what="the lock lifted")
        assert p.host.view().can_jog
