"""smoothjog through a real CNCjs 1.11.5: the Host over CncjsLink, beside other CNCjs clients.

Each test runs the smoothjog simulator (Grbl 1.1h, hobby router) on a pseudo-terminal, a real
CNCjs from npm that opens it, and the shipped Host in real time; the simulator's own summary at
its end (RX bytes dropped, errors sent, G-code motion blocks) is the ground truth for "nothing
overran, nothing but jogs ran".
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
import serial

from smoothjog.core.errors import LinkError
from smoothjog.core.intents import ContinuousIntent
from smoothjog.host import Host
from smoothjog.links.cncjs import CncjsLink
from smoothjog.links.cncjs_auth import make_token
from tests.cncjs.harness import CncjsRig

pytestmark = pytest.mark.timeout(90)

#: hobby-router along X: 5000 mm/min and 500 mm/s².
V_MM_S = 5000 / 60
STOP_MM = V_MM_S**2 / (2 * 500)
SUMMARY = re.compile(r"RX bytes dropped (\d+); errors sent: (.*?); G-code motion blocks (\d+)\)")


def _link(rig: CncjsRig, token: str | None = None) -> CncjsLink:
    tok = token if token is not None else make_token(config_path=rig.config_path)
    return CncjsLink(rig.url, rig.port_path, tok, timeout_s=10.0)


def _sim_summary(rig: CncjsRig) -> tuple[int, str, int]:
    """Stop the simulator and read what it says went wrong on its wire."""
    rig.server.stop()
    rig.sim.stop()
    match = SUMMARY.search(rig.sim.log_path.read_text())
    assert match is not None, rig.sim.log_path.read_text()[-2000:]
    return int(match.group(1)), match.group(2), int(match.group(3))


async def _started(rig: CncjsRig) -> Host:
    link = _link(rig)
    await link.open()
    host = Host(link, handshake_timeout_s=10.0)
    await host.start()
    return host


async def _until(predicate: Callable[[], bool], timeout_s: float) -> None:
    """Wait until predicate() holds; fail after timeout_s."""
    async with asyncio.timeout(timeout_s):
        while not predicate():  # noqa: ASYNC110 - the state changes in callbacks, no event
            await asyncio.sleep(0.02)


async def _jog(host: Host, x: float, speed: float, hold_s: float) -> None:
    host.set_intent(ContinuousIntent({"X": x}, speed))
    await asyncio.sleep(hold_s)


async def test_jog_and_stop_through_cncjs(cncjs: CncjsRig) -> None:
    other = cncjs.client()  # the CNCjs web page, say: it must keep its port after smoothjog goes
    host = await _started(cncjs)
    try:
        start = host.model.mpos_mm
        assert start is not None
        await _jog(host, -1.0, 1.0, 1.2)
        assert host.model.state == "Jog"
        await _jog(host, 0.0, 1.0, 0.0)
        await host.wait_idle(10.0)
        end = host.model.mpos_mm
        assert end is not None
        assert start[0] - end[0] > 40.0  # about 1.2 s at 83 mm/s, less the ramps
        engine = host.engine
        assert engine is not None
        assert engine.stats.error_replies == 0
        (stop,) = engine.stats.stops
        assert stop.cancelled
        assert host.ledger.stats.replies_before_echo == 0
        assert host.ledger.stats.unowned_replies == 0
    finally:
        await host.close()
    # smoothjog left without closing the port: the other client still talks to the machine.
    before = len(other.reads)
    other.write("G4P0\n")
    other.wait_for(lambda: "ok" in other.reads[before:], 5.0, "the ok of G4P0")
    assert not any(event == "serialport:close" for _t, event, _args in other.events)
    dropped, errors, gcode_blocks = _sim_summary(cncjs)
    assert (dropped, errors, gcode_blocks) == (0, "none", 0)


async def test_a_second_client_writing_g_every_400_ms_is_counted(cncjs: CncjsRig) -> None:
    # Another CNCjs client (a console left polling) writes `$G` every 400 ms through CNCjs
    # while smoothjog jogs back and forth: every `ok` must still reach its own line.
    other = cncjs.client()
    host = await _started(cncjs)
    try:
        other.start_poller("$G\n", 0.4)
        for x, speed, hold_s in [(-1, 1.0, 0.8), (1, 0.5, 0.6), (-1, 0.3, 0.6), (-1, 1.0, 0.8)]:
            await _jog(host, x, speed, hold_s)
        await _jog(host, 0.0, 1.0, 0.0)
        await host.wait_idle(10.0)
        await asyncio.sleep(0.5)
        other.stop_poller()
        engine = host.engine
        assert engine is not None
        assert engine.stats.error_replies == 0
        foreign = sum(n for owner, n in host.ledger.stats.lines.items() if owner.startswith("f"))
        assert foreign >= 5  # the other client's $G lines, placed by their echoes
        assert host.ledger.stats.replies_before_echo == 0
        assert host.ledger.stats.unechoed_dropped == 0
        # Every ok went to the line it answers: none was left over (an ok of the other
        # client's credited to smoothjog would leave smoothjog's own ok without a line).
        assert host.ledger.stats.unowned_replies == 0
        assert host.ledger.stats.presumed_answered == 0
        states = {s.get("status", {}).get("activeState") for s in other.grbl_states}
        assert states <= {"Idle", "Jog", ""}, states
    finally:
        await host.close()
    dropped, errors, gcode_blocks = _sim_summary(cncjs)
    assert dropped == 0
    assert errors == "none"  # no error:8 (a garbled line) and no other error
    assert gcode_blocks == 0  # never a non-jog move (never Run)


async def test_a_cncjs_job_refuses_jogs_with_a_sentence(cncjs: CncjsRig) -> None:
    other = cncjs.client()
    host = await _started(cncjs)
    try:
        assert host.view().can_jog
        other.start_job("G91\nG1 X-20 F600\nG1 X20\nG90\n")
        await _until(lambda: host.model.jog_lock is not None, 5.0)
        view = host.view()
        assert not view.can_jog
        assert view.reason == "CNCjs is running a job: jogging waits until it ends"
        await _jog(host, -1.0, 1.0, 0.3)
        engine = host.engine
        assert engine is not None
        assert engine.stats.jogs_sent == 0
        other.command("gcode:stop", {"force": True})
        await _until(lambda: host.model.jog_lock is None, 10.0)
    finally:
        await host.close()


async def test_cncjs_killed_mid_jog_stops_the_machine_within_the_queue(cncjs: CncjsRig) -> None:
    host = await _started(cncjs)
    await _jog(host, -1.0, 1.0, 1.5)
    report_mm = host.model.mpos_mm
    assert report_mm is not None
    cncjs.kill()
    killed_s = time.monotonic()
    await host.wait_lost()
    assert "CNCjs" in str(host.link_error)
    await host.close()
    rest = await asyncio.to_thread(_rest_x_mm, cncjs.port_path)
    assert rest is not None, "the machine never came to rest"
    waited_s = time.monotonic() - killed_s
    assert waited_s < 5.0
    # What ran on after the kill: the queue smoothjog kept, sized to stop within about one
    # stopping distance (plus what the last report's age hides): S4's bound.
    ran_mm = report_mm[0] - rest
    assert ran_mm <= 2.0 * STOP_MM + V_MM_S * 0.1


def _rest_x_mm(port_path: str) -> float | None:
    """With CNCjs gone the pty is free: poll `?` until the machine reports Idle; its X."""
    with serial.Serial(port_path, 115200, timeout=0.2) as port:
        for _ in range(100):
            port.write(b"?")
            line = port.readline().decode("ascii", "replace")
            if line.startswith("<Idle"):
                return float(line.split("MPos:")[1].split(",")[0])
            time.sleep(0.05)
    return None


@pytest.mark.parametrize(
    ("kind", "words"),
    [
        ("wrong", "not signed with this CNCjs's secret"),
        ("expired", "has expired"),
        ("none", "got none"),
    ],
)
async def test_a_bad_token_is_refused_with_its_sentence(
    cncjs: CncjsRig, kind: str, words: str
) -> None:
    token = {
        "wrong": cncjs.token(wrong_secret=True),
        "expired": cncjs.token(expired=True),
        "none": "",
    }[kind]
    link = _link(cncjs, token)
    with pytest.raises(LinkError, match=words):
        await link.open()
    await link.close()


def _smoothjog(*args: str) -> list[str]:
    return [sys.executable, "-m", "smoothjog", *args]


def _cncjs_args(rig: CncjsRig) -> list[str]:
    return [
        "--cncjs",
        rig.url,
        "--cncjs-port",
        rig.port_path,
        "--cncjs-config",
        str(rig.config_path),
    ]


def test_info_and_jog_replay_through_cncjs(cncjs: CncjsRig, tmp_path: Path) -> None:
    info = subprocess.run(
        _smoothjog("info", *_cncjs_args(cncjs)),
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        stdin=subprocess.DEVNULL,
    )
    assert info.returncode == 0, info.stderr
    assert "grbl 1.1h" in info.stdout
    replay = tmp_path / "replay.jsonl"
    replay.write_text('{"t": 0.1, "axes": {"x": -1}, "speed": 0.5}\n{"t": 0.8, "axes": {"x": 0}}\n')
    jog = subprocess.run(
        _smoothjog("jog", *_cncjs_args(cncjs), "--replay", str(replay)),
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        stdin=subprocess.DEVNULL,
    )
    assert jog.returncode == 0, jog.stderr
    assert "CNCjs" in jog.stdout + jog.stderr


def test_the_pendant_connects_again_after_cncjs_restarts(cncjs: CncjsRig) -> None:
    proc = subprocess.Popen(
        _smoothjog("pendant", *_cncjs_args(cncjs), "--http-port", "0"),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        stdin=subprocess.DEVNULL,
        text=True,
    )
    seen: list[str] = []
    try:
        assert proc.stdout is not None

        def wait_for(words: str, timeout_s: float) -> None:
            end = time.monotonic() + timeout_s
            while time.monotonic() < end:
                line = proc.stdout.readline()  # type: ignore[union-attr]
                if not line:
                    break
                seen.append(line)
                if words in line:
                    return
            pytest.fail(f"no {words!r} in {''.join(seen)}")

        wait_for("smoothjog pendant: http://", 30.0)
        cncjs.kill()
        wait_for("connecting again every 2 s", 10.0)
        cncjs.restart()
        wait_for("connected again to", 30.0)
    finally:
        proc.terminate()
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(10)
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
        if proc.stdout is not None:
            proc.stdout.close()


async def test_another_client_closing_the_port_ends_the_link_in_words(cncjs: CncjsRig) -> None:
    other = cncjs.client()
    host = await _started(cncjs)
    try:
        await asyncio.to_thread(other.emit_with_ack, "close", cncjs.port_path)
        async with asyncio.timeout(5.0):
            await host.wait_lost()
        assert "CNCjs closed" in str(host.link_error)
    finally:
        await host.close()


async def test_with_users_configured_the_token_must_name_one(cncjs: CncjsRig) -> None:
    # CNCjs watches its config: add a user, then the stock pendant token is refused, and a
    # token for that user (signed from the same config) is accepted.
    config = json.loads(cncjs.config_path.read_text())
    config["users"] = [{"id": "u1", "name": "alice", "enabled": True, "password": "x"}]
    cncjs.config_path.write_text(json.dumps(config))
    with pytest.raises(
        LinkError,
        match=r"users configured .*\(alice\), so a token must name one: give --cncjs-user",
    ):
        make_token(config_path=cncjs.config_path)
    stock = cncjs.token()  # id "", name "cncjs-pendant": no such user now

    async def refused() -> str:
        link = _link(cncjs, stock)
        try:
            await link.open()
        except LinkError as exc:
            return str(exc)
        finally:
            await link.close()
        return ""

    async with asyncio.timeout(10.0):
        while not (said := await refused()):  # noqa: ASYNC110 - until CNCjs reads the file
            await asyncio.sleep(0.2)
    assert "users configured, give --cncjs-user" in said
    link = _link(cncjs, make_token(config_path=cncjs.config_path, user="alice"))
    await link.open()
    await link.close()


async def test_a_move_by_another_client_is_seen_without_polling_fast(cncjs: CncjsRig) -> None:
    # While idle smoothjog asks for status only every IDLE_POLL_S through CNCjs (CNCjs's console
    # shows every `?`); when CNCjs's own reports say the machine moved, it asks at once.
    other = cncjs.client()
    host = await _started(cncjs)
    try:
        start = host.model.mpos_mm
        assert start is not None
        await asyncio.sleep(0.3)
        asked = host.ledger.stats.realtime["engine"]
        other.write("$J=G91 X-3 F3000\n")
        await _until(lambda: (host.model.mpos_mm or start)[0] < start[0] - 2.9, 1.5)
        assert host.ledger.stats.realtime["engine"] - asked < 10
    finally:
        await host.close()
