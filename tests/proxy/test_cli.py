"""`smoothjog proxy` as a real subprocess in front of the built-in simulator."""

from __future__ import annotations

import time
from pathlib import Path

import serial

from tests.test_cli_jog import Child, run_smoothjog

STARTUP_TIMEOUT_S = 30.0


def _read_until(port: serial.Serial, marker: bytes, timeout_s: float = 5.0) -> bytes:
    got = b""
    end = time.monotonic() + timeout_s
    while marker not in got:
        assert time.monotonic() < end, got
        got += port.read(256)
    return got


def test_the_proxy_serves_the_sender_a_pty_and_cleans_up(tmp_path: Path) -> None:
    link = tmp_path / "ttyPROXY"
    child = Child("proxy", "--link", str(link), "--tcp", "0", "--http-port", "0")
    try:
        child.wait_for(r"^smoothjog pendant: http://127\.0\.0\.1:\d+/$", STARTUP_TIMEOUT_S)
        ready = child.wait_for(r"^smoothjog proxy: the sender's port is pty (\S+) \(link ", 10.0)
        assert link.is_symlink()
        assert str(link.resolve()) == ready[1]
        assert "tcp 127.0.0.1:" in child.stdout[-1]
        with serial.Serial(str(link), 115200, timeout=0.1) as port:
            assert _read_until(port, b"]\r\n").startswith(b"Grbl 1.1h ['$' for help]\r\n")
            port.write(b"$G\n")
            got = _read_until(port, b"ok\r\n")
            assert b"[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]\r\nok\r\n" in got
    finally:
        code = child.stop()
    assert code == 0, (child.stdout, child.stderr)
    assert child.stdout[-1] == "smoothjog: stopped\n"
    assert "Traceback" not in "".join(child.stderr)
    assert not link.is_symlink()


def test_the_proxy_needs_a_port_for_the_sender() -> None:
    done = run_smoothjog("proxy", timeout_s=30.0)
    assert done.returncode == 2
    assert "--link PATH" in done.stdout


def test_a_link_path_taken_by_a_file_ends_the_proxy_in_words(tmp_path: Path) -> None:
    taken = tmp_path / "file"
    taken.write_text("mine")
    done = run_smoothjog("proxy", "--link", str(taken), "--http-port", "0", timeout_s=30.0)
    assert done.returncode == 2
    assert f"--link {taken} exists and is not a symlink" in done.stderr
    assert "Traceback" not in done.stderr
    assert taken.read_text() == "mine"
