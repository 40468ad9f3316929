"""`smoothjog sim` on a pty and TCP, and SimLink, in real time (loopback only)."""

from __future__ import annotations

import asyncio
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import serial

from smoothjog.core.errors import LinkError, SimError
from smoothjog.links.sim import SimLink
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.serve import ServeOptions, SimServer, read_trace


def _read_until(port: serial.Serial, predicate: object, timeout_s: float = 5.0) -> list[str]:
    assert callable(predicate)
    lines: list[str] = []
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        raw = port.readline()
        if not raw:
            continue
        line = raw.decode("ascii").rstrip("\r\n")
        lines.append(line)
        if predicate(line):
            return lines
    raise AssertionError(f"timed out; got {lines}")


def test_cli_pty_answers_like_grbl_and_cleans_up(tmp_path: Path) -> None:
    link = tmp_path / "ttyGRBL"
    proc = subprocess.Popen(
        [sys.executable, "-m", "smoothjog", "sim", "--link", str(link)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        ready = proc.stdout.readline()
        assert "smoothjog sim:" in ready
        assert link.is_symlink()
        with serial.Serial(str(link), 115200, timeout=0.2) as port:
            port.write(b"$I\n")
            lines = _read_until(port, lambda x: x == "ok")
            assert lines[-3:] == ["[VER:1.1h.20190830:]", "[OPT:V,15,128]", "ok"]
            port.write(b"?")
            report = _read_until(port, lambda x: x.startswith("<"))[-1]
            assert report.startswith("<Idle|MPos:0.000,0.000,0.000|FS:0,0")
            port.write(b"$Q\n")  # a bad system command: error:2 here, counted in the summary
            assert _read_until(port, lambda x: x.startswith("error"))[-1] == "error:2"
    finally:
        proc.send_signal(signal.SIGINT)
        _out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0
    assert (
        "stopped on SIGINT (RX bytes dropped 0; errors sent: error:2 x1; G-code motion blocks 0)"
        in err
    )
    assert not link.exists()
    assert not link.is_symlink()


def test_cli_trace_holds_the_jog_on_the_monotonic_clock(tmp_path: Path) -> None:
    link = tmp_path / "ttyGRBL"
    trace_path = tmp_path / "trace.jsonl"
    argv = [sys.executable, "-m", "smoothjog", "sim", "--machine", "hobby-router"]
    argv += ["--link", str(link), "--trace", str(trace_path)]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        assert "smoothjog sim:" in proc.stdout.readline()
        with serial.Serial(str(link), 115200, timeout=0.2) as port:
            sent_s = time.monotonic()
            port.write(b"$J=G91 X-10 F3000\n")
            assert _read_until(port, lambda x: x in ("ok", "error:15"))[-1] == "ok"

            def at_rest() -> bool:
                port.write(b"?")
                return _read_until(port, lambda x: x.startswith("<"))[-1].startswith("<Idle")

            time.sleep(0.1)
            end = time.monotonic() + 10
            while not at_rest():
                assert time.monotonic() < end, "the jog never ended"
                time.sleep(0.05)
            rest_s = time.monotonic()
        assert not trace_path.exists()  # written when the simulator stops
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=10)
    assert proc.returncode == 0
    trace = read_trace(trace_path)
    moving = [seg for seg in trace if seg.speed_mm_s > 0]
    assert moving
    # The jog ran between the write and the Idle report, on this process's clock.
    assert sent_s < moving[0].t0_s < moving[-1].t1_s < rest_s
    assert moving[-1].t1_s - moving[0].t0_s > 10 / 50  # 10 mm at 50 mm/s at most
    assert sum(seg.t1_s - seg.t0_s for seg in moving) == pytest.approx(
        moving[-1].t1_s - moving[0].t0_s, rel=0.05
    )
    assert moving[0].start_mm == pytest.approx((-1.0, -1.0, -1.0))
    assert moving[-1].end_mm == pytest.approx((-11.0, -1.0, -1.0), abs=1e-3)
    assert sum(math.dist(s.start_mm, s.end_mm) for s in trace) == pytest.approx(10.0, abs=1e-3)


def test_a_trace_file_that_is_not_one_is_a_sentence(tmp_path: Path) -> None:
    bad = tmp_path / "trace.jsonl"
    bad.write_text('{"t0_s": 1.0, "t1_s": 2.0, "start_mm": [0, 0, 0]}\n')
    with pytest.raises(SimError, match=r"trace\.jsonl:1: not a trace segment"):
        read_trace(bad)


async def _wait_for_port(server: SimServer) -> None:
    for _ in range(500):
        if server.tcp_port is not None:
            return
        await asyncio.sleep(0.01)
    raise AssertionError("the TCP port never opened")


async def test_tcp_serves_the_same_controller() -> None:
    server = SimServer(ServeOptions(pty=False, tcp_port=0), out=lambda _s: None)
    stop = asyncio.Event()
    task = asyncio.create_task(server.serve(stop))
    await _wait_for_port(server)
    assert server.tcp_port is not None
    reader, writer = await asyncio.open_connection("127.0.0.1", server.tcp_port)
    writer.write(b"$G\n")
    line = await asyncio.wait_for(reader.readline(), 5)
    while not line.startswith(b"[GC:"):
        # A client this quick can still catch the power-up banner ($1 ms after the start).
        assert line in (b"\r\n", b"Grbl 1.1h ['$' for help]\r\n"), line
        line = await asyncio.wait_for(reader.readline(), 5)
    assert line == b"[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]\r\n"
    assert await asyncio.wait_for(reader.readline(), 5) == b"ok\r\n"
    writer.close()
    stop.set()
    await asyncio.wait_for(task, 5)


async def test_settings_file_persists_across_runs(tmp_path: Path) -> None:
    path = tmp_path / "eeprom.json"
    for value, expected in (("2", "$10=1"), (None, "$10=2")):
        server = SimServer(
            ServeOptions(pty=False, tcp_port=0, settings_path=path), out=lambda _s: None
        )
        stop = asyncio.Event()
        task = asyncio.create_task(server.serve(stop))
        await _wait_for_port(server)
        assert server.tcp_port is not None
        reader, writer = await asyncio.open_connection("127.0.0.1", server.tcp_port)
        writer.write(b"$$\n")
        lines = []
        while (line := (await asyncio.wait_for(reader.readline(), 5)).strip()) != b"ok":
            lines.append(line.decode())
        assert expected in lines
        if value is not None:
            writer.write(f"$10={value}\n".encode())
            assert (await asyncio.wait_for(reader.readline(), 5)).strip() == b"ok"
        writer.close()
        stop.set()
        await asyncio.wait_for(task, 5)
    assert path.exists()


async def test_sim_link_contract() -> None:
    link = SimLink(GrblFirmware(machine="hobby-router"))
    async with link:
        assert await asyncio.wait_for(link.read_line(), 2) == b""
        assert (await asyncio.wait_for(link.read_line(), 2)).startswith(b"Grbl 1.1h")
        await link.send_line("$J=G91X-1F1000")
        assert await asyncio.wait_for(link.read_line(), 2) == b"ok"
        link.send_realtime(b"?")
        report = await asyncio.wait_for(link.read_line(), 2)
        assert report.startswith((b"<Jog", b"<Idle"))
        assert "hobby-router" in link.describe()
    with pytest.raises(LinkError):
        await link.read_line()


def test_cli_refuses_nothing_to_serve() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "smoothjog", "sim", "--no-pty"],
        check=False,
        capture_output=True,
        text=True,
        timeout=30,
        env={**os.environ},
    )
    assert proc.returncode == 2
    assert "--tcp" in proc.stdout


def test_cli_unknown_machine_is_one_sentence() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "smoothjog", "sim", "--machine", "nope"],
        check=False,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert proc.returncode == 2
    assert "unknown machine profile 'nope'" in proc.stderr
    assert "Traceback" not in proc.stderr
