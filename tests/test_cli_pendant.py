"""The default command (the pendant on the built-in simulator) run as a real subprocess."""

from __future__ import annotations

import socket
import subprocess
import urllib.request

import pytest

from tests.test_cli_jog import Child, run_smoothjog

STARTUP_TIMEOUT_S = 30.0


def run_pendant(*args: str, timeout_s: float = 30.0) -> subprocess.CompletedProcess[str]:
    """Run `python -m smoothjog ARGS` (the default command) for a failure that ends it."""
    return run_smoothjog(*args, timeout_s=timeout_s)


def fetch(url: str) -> tuple[int, str, str]:
    """GET url: status, content type and body."""
    with urllib.request.urlopen(url, timeout=10) as response:
        body = response.read().decode("utf-8")
        return response.status, response.headers.get("Content-Type", ""), body


def test_pendant_on_the_simulator_serves_the_page_and_stops_on_sigint() -> None:
    """No controller given: simulator, summary, URL; the page is served; Ctrl-C stops cleanly."""
    child = Child("--http-port", "0")
    try:
        ready = child.wait_for(
            r"^smoothjog pendant: (http://127\.0\.0\.1:(\d+)/)$", STARTUP_TIMEOUT_S
        )
        url, port = ready[1], int(ready[2])
        assert port != 0
        before = "".join(child.stdout)
        assert before.startswith(
            "smoothjog: no controller given: using the built-in simulator (grbl, hobby-router)\n"
        )
        for needle in (
            "Controller    grbl 1.1h",
            "Soft limits   on (X -800..0, Y -800..0, Z -100..0 mm",
            "State         Idle: ready\n",
            "MPos          X -1.000  Y -1.000  Z -1.000 mm\n",
        ):
            assert needle in before
        status, content_type, body = fetch(url)
        assert status == 200
        assert content_type.startswith("text/html")
        assert "<title>smoothjog pendant</title>" in body
        status, _type, script = fetch(f"{url}static/app.js")
        assert status == 200
        assert script.strip()
    finally:
        code = child.stop()
    assert code == 0, (child.stdout, child.stderr)
    assert child.stdout[-1] == "smoothjog: stopped\n"
    assert "Traceback" not in "".join(child.stderr)


def test_a_serial_port_that_does_not_exist() -> None:
    """--port to nothing: one sentence on stderr, nothing else, a non-zero exit."""
    result = run_pendant("--port", "/dev/nonexistent", "--http-port", "0")
    assert result.returncode != 0
    assert result.stdout == ""
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("smoothjog: no serial port at /dev/nonexistent"), lines[0]


@pytest.mark.parametrize("host", ["0.0.0.0", "::"])
def test_a_network_address_without_lan_is_refused(host: str) -> None:
    """--host on the network without --lan: refused in one sentence, nothing served."""
    result = run_pendant("--host", host, "--http-port", "0")
    assert result.returncode != 0
    assert "Traceback" not in result.stderr
    assert "smoothjog pendant:" not in result.stdout
    lines = result.stderr.splitlines()
    assert lines == [
        f"smoothjog: refusing to serve the pendant on {host}: anyone on the network could jog"
        " the machine; use --lan, which requires a pairing token, or bind 127.0.0.1"
    ], result.stderr


def test_a_busy_http_port_is_one_sentence_naming_the_right_option() -> None:
    """The HTTP port is taken: one sentence that points at --http-port (--port is serial)."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = run_pendant("--http-port", str(port))
    assert result.returncode != 0
    assert "Traceback" not in result.stderr
    assert "smoothjog pendant:" not in result.stdout
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(f"smoothjog: cannot listen on 127.0.0.1:{port}"), lines[0]
    assert "--http-port" in lines[0], lines[0]
