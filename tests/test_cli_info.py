"""`smoothjog info` run as a real subprocess against the scripted Grbl on a pty and over TCP."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from tests.peers import PtyPeer, ScriptedGrbl, TcpPeer


def run_info(
    *args: str, env_extra: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    """Run `python -m smoothjog info ARGS` and capture its output."""
    env = {k: v for k, v in os.environ.items() if k != "SMOOTHJOG_CONFIG"}
    env.update(env_extra or {})
    return subprocess.run(
        [sys.executable, "-m", "smoothjog", "info", *args],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
        check=False,
    )


def assert_one_sentence_failure(result: subprocess.CompletedProcess[str], *needles: str) -> None:
    """Non-zero exit, nothing on stdout, one `smoothjog:` line on stderr, no traceback."""
    assert result.returncode != 0
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("smoothjog: ")
    assert "Traceback" not in result.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]


def test_info_over_a_serial_port() -> None:
    """Against a pty: the summary of the scripted Grbl, exit 0."""
    grbl = ScriptedGrbl(mpos=(-3.0, -4.0, -5.0))
    grbl.settings[110] = "4000.000"
    with PtyPeer(grbl, boot_s=0.05) as peer:
        result = run_info("--port", peer.path, "--timeout", "10")
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    out = result.stdout
    assert out.startswith(f"Link          {peer.path} at 115200 baud\n")
    assert "grbl 1.1h, build 20190830" in out
    assert "15 blocks, RX buffer 128 bytes" in out
    assert "4000 mm/min" in out
    assert "State         Idle: ready" in out
    assert "MPos          X -3.000  Y -4.000  Z -5.000 mm" in out
    assert grbl.received_lines == [b"$I", b"$$", b"$G", b"$#"]


def test_info_over_tcp_in_alarm() -> None:
    """Against a TCP server: an Alarm state is described in words."""
    grbl = ScriptedGrbl(state="Alarm")
    grbl.settings[20] = "1"
    with TcpPeer(grbl) as peer:
        result = run_info("--connect", peer.url, "--timeout", "10")
    assert result.returncode == 0, result.stderr
    assert "State         Alarm: locked" in result.stdout
    assert "Soft limits   on (X -200..0" in result.stdout


def test_info_uses_the_config_file(tmp_path: Path) -> None:
    """The [connection] of a config named by $SMOOTHJOG_CONFIG is used when no option is."""
    with TcpPeer() as peer:
        config = tmp_path / "c.toml"
        config.write_text(f'[connection]\nconnect = "{peer.url}"\ntimeout_s = 10\n')
        result = run_info(env_extra={"SMOOTHJOG_CONFIG": str(config)})
    assert result.returncode == 0, result.stderr
    assert "grbl 1.1h" in result.stdout


def _free_port() -> int:
    """A loopback port with nothing listening on it."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
    return port


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--port", "/dev/ttyNOPE0"], ["no serial port at /dev/ttyNOPE0"]),
        (["--port", "/dev/null"], ["/dev/null is not a serial port"]),
        (["--port", "/dev/ttyX", "--connect", "tcp://h:23"], ["not allowed with"]),
        (["--connect", "http://cnc:80"], ["not a tcp:// address"]),
        (["--connect", "tcp://cnc:http"], ["give a number from 1 to 65535"]),
        (["--connect", "tcp://:23"], ["no usable host"]),
        (["--port", "/dev/ttyX", "--baud", "fast"], ["--baud", "not a whole number"]),
        (["--port", "/dev/ttyX", "--timeout", "-1"], ["--timeout", "above 0"]),
        (["--bogus"], ["unrecognized arguments"]),
        # CNCjs: every way it fails before anything connects.
        (["--cncjs", "http://127.0.0.1:9"], ["--cncjs needs --cncjs-port"]),
        (["--cncjs", "cnc:8000", "--cncjs-port", "/dev/x"], ["not a CNCjs address"]),
        (["--cncjs-port", "/dev/ttyUSB0"], ["--cncjs-port goes with --cncjs URL"]),
        (
            ["--cncjs-user", "a", "--cncjs-token", "t.o.k"],
            ["--cncjs-token and --cncjs-user go with --cncjs URL"],
        ),
        (["--cncjs", "http://h", "--port", "/dev/x"], ["not allowed with"]),
        (
            ["--cncjs", "http://127.0.0.1:9", "--cncjs-port", "/dev/x", "--cncjs-token", "abc"],
            ["not a JSON Web Token"],
        ),
        (
            [
                *("--cncjs", "http://127.0.0.1:9", "--cncjs-port", "/dev/x"),
                *("--cncjs-config", "/nonexistent/.cncrc"),
            ],
            ["no CNCjs config at /nonexistent/.cncrc"],
        ),
        (["--config", "/nonexistent/smoothjog.toml", "--port", "/dev/ttyX"], ["does not exist"]),
    ],
)
def test_bad_arguments_fail_with_one_sentence(args: list[str], needles: list[str]) -> None:
    """Every bad invocation: non-zero exit and one line on stderr, never a traceback."""
    assert_one_sentence_failure(run_info(*args), *needles)


def test_refused_port() -> None:
    """A TCP port nobody listens on: refused, in one sentence."""
    port = _free_port()
    assert_one_sentence_failure(
        run_info("--connect", f"tcp://127.0.0.1:{port}"), f"tcp://127.0.0.1:{port} refused"
    )


def test_silent_serial_peer_with_short_timeout() -> None:
    """A port where nothing answers: the timeout message with the baud hint."""
    with PtyPeer(ScriptedGrbl(silent=True), banner_on_open=False) as peer:
        result = run_info("--port", peer.path, "--timeout", "0.3")
    assert_one_sentence_failure(
        result, f"no answer from {peer.path} at 115200 baud within 0.3 s", "baud rate right?"
    )


def test_peer_that_is_not_grbl() -> None:
    """Something that answers, but not like Grbl: said so in one sentence."""
    with TcpPeer(ScriptedGrbl(foreign_reply=b"HTTP/1.1 400 Bad Request\r\n")) as peer:
        result = run_info("--connect", peer.url, "--timeout", "0.5")
    assert_one_sentence_failure(result, "not like a Grbl controller")


def test_without_a_controller_it_describes_the_simulator(tmp_path: Path) -> None:
    """No --port or --connect: the built-in simulator of the config's [sim] is described."""
    config = tmp_path / "sim.toml"
    config.write_text('[sim]\nfirmware = "grbl"\nmachine = "hobby-router"\n')
    result = run_info("--config", str(config))
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("Link          simulated")
    assert "5000 mm/min" in result.stdout
    assert "Soft limits   on (X -800..0" in result.stdout


def test_unknown_simulated_machine(tmp_path: Path) -> None:
    """A [sim] machine that does not exist is one sentence from the simulator."""
    config = tmp_path / "sim.toml"
    config.write_text('[sim]\nmachine = "no-such-machine"\n')
    assert_one_sentence_failure(run_info("--config", str(config)), "no-such-machine")


def test_bad_config_file(tmp_path: Path) -> None:
    """A config error is one sentence naming the file and key."""
    config = tmp_path / "bad.toml"
    config.write_text("[connection]\nbuad = 9600\n")
    assert_one_sentence_failure(run_info("--config", str(config)), "bad.toml", "'buad'")
