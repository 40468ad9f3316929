"""The harness against the real CNCjs: auth, opening the pty, raw writes, oks, and a CNCjs job."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

import pytest

from tests.cncjs import harness
from tests.cncjs.harness import CncjsRefusedError, CncjsRig, RawClient

JOB = "G21 G91\nG1 X-5 F1200\nG1 Y-5\nG1 X5\nG1 Y5\nG90\n"  # about 1 s of Run


def is_reply(line: str) -> bool:
    """An ok or error line from Grbl."""
    return line == "ok" or line.startswith("error:")


def test_connects_with_a_good_token_and_opens_the_pty(cncjs: CncjsRig) -> None:
    client = cncjs.client(connect=False)
    client.connect()
    startup = client.wait_for(
        lambda: next((args for _, name, args in client.events if name == "startup"), None),
        what="startup",
    )
    assert [port["path"] for port in startup[0]["ports"]] == [cncjs.port_path]
    client.open()
    opened = client.wait_for(
        lambda: next((args for _, name, args in client.events if name == "serialport:open"), None),
        what="serialport:open",
    )
    assert opened[0]["port"] == cncjs.port_path
    assert opened[0]["controllerType"] == "Grbl"
    assert opened[0]["inuse"] is True


def test_grbl_state_reaches_idle_with_an_mpos(cncjs: CncjsRig) -> None:
    # No wake-up `?`: CNCjs polls the silent pty by itself (its first `?` 2 s after the open).
    client = cncjs.client(wake=False)
    x, y, z = client.wait_state("Idle", timeout_s=6)
    # The hobby-router profile starts homed at its pull-off corner.
    assert (x, y, z) == pytest.approx((-1.0, -1.0, -1.0), abs=1e-3)


def test_a_written_jog_gets_ok_and_moves_one_millimetre(cncjs: CncjsRig) -> None:
    client = cncjs.client()
    x0, y0, z0 = client.wait_state("Idle")
    wait_settings_dump(client)
    since = len(client.reads)
    client.write("$J=G91 X1 F600\n")
    assert client.wait_read(is_reply, since=since, timeout_s=5) == "ok"
    assert ("$J=G91 X1 F600\n", {"source": "client"}) in client.writes

    def moved() -> tuple[float, float, float] | None:
        pos = client.mpos()
        idle = client.active_state() == "Idle"
        return pos if idle and pos is not None and abs(pos[0] - (x0 + 1.0)) < 1e-3 else None

    x, y, z = client.wait_for(moved, timeout_s=10, what="Idle at X+1 mm")
    assert x - x0 == pytest.approx(1.0, abs=1e-3)
    assert (y, z) == pytest.approx((y0, z0), abs=1e-3)


def test_a_token_signed_with_another_secret_is_refused(cncjs: CncjsRig) -> None:
    client = cncjs.client(token=cncjs.token(wrong_secret=True), connect=False)
    with pytest.raises(CncjsRefusedError, match="invalid signature") as refused:
        client.connect()
    assert refused.value.data["code"] == "invalid_token"


def test_an_expired_token_is_refused(cncjs: CncjsRig) -> None:
    client = cncjs.client(token=cncjs.token(expired=True), connect=False)
    assert client.try_connect()["message"] == "jwt expired"


def test_any_id_and_name_are_accepted_while_cncjs_has_no_users(cncjs: CncjsRig) -> None:
    client = cncjs.client(token=cncjs.token(user_id="42", name="smoothjog"), open_port=False)
    assert client.connected


def test_a_missing_cncjs_fails_naming_the_test_command(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setattr(harness, "CNCJS_BIN", harness.ROOT / "tools" / "cncjs" / "absent")
    with pytest.raises(pytest.fail.Exception, match=r"\./scripts/test"):
        harness.CncjsRig.start(tmp_path / "rig")


def test_a_cncjs_job_runs_and_the_workflow_returns_to_idle(cncjs: CncjsRig) -> None:
    client = cncjs.client()
    client.wait_state("Idle")
    wait_settings_dump(client)
    status = client.start_job(JOB)
    assert status["total"] == len(JOB.splitlines()) + 1  # CNCjs appends a %wait line
    client.wait_for(lambda: "running" in client.workflow_states, 5, "workflow:state running")
    running_at = client.workflow_states.index("running")
    client.wait_for(
        lambda: "idle" in client.workflow_states[running_at:],
        timeout_s=20,
        what="workflow:state back to idle",
    )
    states = {state["status"]["activeState"] for state in client.grbl_states}
    assert "Run" in states
    assert client.mpos() == pytest.approx((-1.0, -1.0, -1.0), abs=1e-3)


def test_a_second_client_sees_the_first_ones_writes_and_the_poller(cncjs: CncjsRig) -> None:
    first = cncjs.client()
    other = cncjs.client()
    first.wait_state("Idle")
    wait_settings_dump(first)
    other.start_poller("$G\n", period_s=0.4)
    first.wait_for(
        lambda: sum(1 for data, _ in first.writes if data == "$G\n") >= 3,
        timeout_s=5,
        what="three $G echoes from the poller",
    )
    other.stop_poller()
    # A client's $G is answered to every client ([GC:...] then ok); CNCjs's own $G polls are not.
    first.wait_for(
        lambda: sum(1 for line in first.reads if line.startswith("[GC:")) >= 3,
        timeout_s=5,
        what="three [GC:...] replies",
    )
    first.write("G4P0\n")
    other.wait_for(lambda: ("G4P0\n", {"source": "client"}) in other.writes, 5, "G4P0 echo")


def test_kill_and_restart_give_a_fresh_cncjs_on_the_same_url(cncjs: CncjsRig) -> None:
    client = cncjs.client()
    client.wait_state("Idle")
    url = cncjs.url
    started = time.monotonic()
    cncjs.kill()
    client.wait_for(lambda: client.disconnected, 5, "the disconnect after SIGKILL")
    cncjs.restart()
    assert cncjs.url == url
    again = cncjs.client()
    again.wait_state("Idle")
    assert time.monotonic() - started < 15
    assert "CNCjs start #2" in cncjs.log_path.read_text()


async def test_async_waits_leave_the_test_loop_running(cncjs: CncjsRig) -> None:
    client = cncjs.client()
    ticks = 0

    async def ticker() -> None:
        nonlocal ticks
        while True:
            ticks += 1
            await asyncio.sleep(0.01)

    task = asyncio.create_task(ticker())
    started = time.monotonic()
    try:
        await client.async_wait_for(
            lambda: client.active_state() == "Idle" and client.mpos(), 5, "Grbl:state Idle"
        )
    finally:
        task.cancel()
    # The ticker ran about every 10 ms while the client waited (a blocking wait gives 1 tick).
    assert ticks >= min(5, (time.monotonic() - started) / 0.02)


def wait_settings_dump(client: RawClient) -> None:
    """Wait until CNCjs's own $$ after the first open has been answered (its ok is broadcast)."""
    client.wait_for(
        lambda: any(data == "$$\n" for data, _ in client.writes) and "ok" in client.reads,
        timeout_s=10,
        what="the end of CNCjs's $$ dump",
    )
