"""The simulator and a real CNCjs as processes: the parts of the CNCjs rig that start and stop them.

Shared by `python -m bench cncjs` and the CNCjs link's tests (tests/cncjs/harness.py, which turns
a RigError into a test failure):

* `SimProcess`: `python -m smoothjog sim --machine hobby-router --link <scratch>/ttyGRBL` as its
  own process (the repository's src on PYTHONPATH), optionally with `--trace` and `--settings`.
* `CncjsServer`: `node <cncjs bin> --host 127.0.0.1 --port <free port> --config <scratch cfg>`
  with HOME in the scratch dir (CNCjs writes ~/.cncjs-sessions) and a fixed, known `secret`.

CNCjs 1.11.5 lives in tools/cncjs (installed by `scripts/setup.sh test`, which the README's test
command runs).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
CNCJS_DIR = ROOT / "tools" / "cncjs"
CNCJS_BIN = CNCJS_DIR / "node_modules" / "cncjs" / "bin" / "cncjs"
README_TEST_COMMAND = "./scripts/test"

#: A fixed secret (CNCjs keeps the one it finds in its config), so tokens can be signed.
TEST_SECRET = "$2a$10$smoothjogtestsecret0000"
BAUDRATE = 115200
CONTROLLER = "Grbl"
MACHINE = "hobby-router"

SIM_START_TIMEOUT_S = 15.0
CNCJS_START_TIMEOUT_S = 30.0
STOP_GRACE_S = 5.0
LOG_TAIL_CHARS = 4000
ANSI_COLOUR = re.compile(r"\x1b\[[0-9;]*m")  # CNCjs colours its log levels


class RigError(Exception):
    """A process of the rig could not be started; the message says why and shows its log."""


def find_cncjs(program: Path = CNCJS_BIN) -> Path:
    """The CNCjs program under tools/cncjs, or a RigError that says how to install it."""
    if not program.is_file():
        try:
            shown: Path | str = program.relative_to(ROOT)
        except ValueError:
            shown = program
        raise RigError(
            f"CNCjs is not installed ({shown} is missing): run the README's test command,"
            f" {README_TEST_COMMAND}, whose set-up installs it with npm ci in tools/cncjs"
        )
    return program


def find_node() -> str:
    """The node program on PATH, or a RigError naming the packages."""
    node = shutil.which("node")
    if node is None:
        raise RigError(
            "node is not on PATH: install nodejs and npm (apt-get install nodejs npm) and run"
            f" {README_TEST_COMMAND}"
        )
    return node


def cncjs_version(program: Path = CNCJS_BIN) -> str:
    """The version in the installed CNCjs's package.json ('unknown' if it cannot be read)."""
    try:
        data = json.loads((program.parents[1] / "package.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return "unknown"
    return str(data.get("version", "unknown")) if isinstance(data, dict) else "unknown"


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nobody listens on right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def write_report(out_dir: str | Path, name: str, text: list[str]) -> None:
    """Write a bench's report lines to out_dir/name (made if missing) and print them."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / name).write_text("\n".join(text) + "\n", encoding="utf-8")
    print("\n".join(text))


def log_tail(path: Path, chars: int = LOG_TAIL_CHARS) -> str:
    """The end of a log file without its colour codes, for error messages."""
    try:
        text = ANSI_COLOUR.sub("", path.read_text(errors="replace"))
    except FileNotFoundError:
        return "(no log)"
    return text[-chars:] if text else "(empty log)"


def signal_group(proc: subprocess.Popen[bytes], sig: signal.Signals) -> None:
    """Send sig to the process group proc leads (the rig starts each in its own session)."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, sig)


def stop_process(proc: subprocess.Popen[bytes], grace_s: float = STOP_GRACE_S) -> int:
    """SIGTERM, wait up to grace_s, then SIGKILL; returns the exit code."""
    if proc.poll() is None:
        signal_group(proc, signal.SIGTERM)
        try:
            proc.wait(grace_s)
        except subprocess.TimeoutExpired:
            signal_group(proc, signal.SIGKILL)
            proc.wait(grace_s)
    return proc.returncode


# --- the simulator ----------------------------------------------------------------------------


def _wait_ready(
    proc: subprocess.Popen[bytes],
    ready: Callable[[], bool],
    timeout_s: float,
    poll_s: float,
    *,
    exited: Callable[[int], str],
    late: str,
    log_path: Path,
) -> None:
    """Poll ready() until it holds; RigError with the log's tail if proc exits or time is up."""
    end = time.monotonic() + timeout_s
    while not ready():
        code = proc.poll()
        if code is not None:
            raise RigError(f"{exited(code)}:\n{log_tail(log_path)}")
        if time.monotonic() > end:
            raise RigError(f"{late}:\n{log_tail(log_path)}")
        time.sleep(poll_s)


class SimProcess:
    """The smoothjog simulator on a pty, as its own process, with a stable symlink to it.

    trace: a file for `--trace` (the ground truth, written when it stops); settings: a file
    for `--settings` (its EEPROM, e.g. with $20=0 stored beforehand).
    """

    def __init__(
        self,
        scratch: Path,
        machine: str = MACHINE,
        *,
        trace: Path | None = None,
        settings: Path | None = None,
    ) -> None:
        """Prepare paths in scratch; start() runs it."""
        self.scratch = scratch
        self.machine = machine
        self.trace_path = trace
        self.settings_path = settings
        self.link = scratch / "ttyGRBL"
        self.log_path = scratch / "sim.log"
        self.proc: subprocess.Popen[bytes] | None = None

    def argv(self) -> list[str]:
        """The command line it runs."""
        argv = [sys.executable, "-m", "smoothjog", "sim", "--machine", self.machine]
        argv += ["--link", str(self.link)]
        if self.trace_path is not None:
            argv += ["--trace", str(self.trace_path)]
        if self.settings_path is not None:
            argv += ["--settings", str(self.settings_path)]
        return argv

    def spawn(self) -> None:
        """Start the process; wait_ready() waits for its pty."""
        env = dict(os.environ)
        src = str(ROOT / "src")
        env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        with self.log_path.open("ab") as log:
            self.proc = subprocess.Popen(
                self.argv(),
                cwd=self.scratch,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )

    def wait_ready(self, timeout_s: float = SIM_START_TIMEOUT_S) -> None:
        """Wait until the --link symlink points at a live pty; RigError with its log if not."""
        assert self.proc is not None, "spawn() first"
        # exists() follows the link: the pty itself is there.
        _wait_ready(
            self.proc,
            self.link.exists,
            timeout_s,
            0.02,
            exited=lambda code: f"the simulator exited with {code} before making {self.link}",
            late=f"the simulator made no {self.link} in {timeout_s:.0f} s",
            log_path=self.log_path,
        )

    def start(self) -> None:
        """Start and wait for the pty."""
        self.spawn()
        self.wait_ready()

    def stop(self) -> None:
        """SIGTERM (it removes its symlink, writes its trace), then SIGKILL if it lingers."""
        if self.proc is not None:
            stop_process(self.proc)
            self.proc = None


# --- CNCjs ------------------------------------------------------------------------------------


def cncjs_config(port_path: str, secret: str = TEST_SECRET) -> dict[str, Any]:
    """A CNCjs config (~/.cncrc format) for one pty, loopback only, no users, a known secret."""
    return {
        "ports": [{"path": port_path, "manufacturer": "smoothjog sim"}],
        "baudrates": [BAUDRATE],
        "allowRemoteAccess": False,
        "state": {"allowAnonymousUsageDataCollection": False, "checkForUpdates": False},
        "commands": [],
        "events": [],
        "macros": [],
        "users": [],
        "secret": secret,
    }


class CncjsServer:
    """One CNCjs process on 127.0.0.1, its config, HOME and log in a scratch dir."""

    def __init__(
        self,
        scratch: Path,
        port_path: str,
        secret: str = TEST_SECRET,
        *,
        program: Path = CNCJS_BIN,
    ) -> None:
        """Write the config; start() runs CNCjs."""
        self.scratch = scratch
        self.port_path = port_path
        self.secret = secret
        self.program = program
        self.home = scratch / "home"
        self.home.mkdir(exist_ok=True)
        self.config_path = scratch / "cncrc.json"
        self.config_path.write_text(json.dumps(cncjs_config(port_path, secret), indent=2) + "\n")
        self.log_path = scratch / "cncjs.log"
        self.http_port = free_port()
        self.url = f"http://127.0.0.1:{self.http_port}"
        self.proc: subprocess.Popen[bytes] | None = None
        self.starts = 0

    def spawn(self) -> None:
        """Start node on the same port as before; wait_ready() waits for HTTP."""
        argv = [find_node(), str(find_cncjs(self.program)), "--host", "127.0.0.1"]
        argv += ["--port", str(self.http_port), "--config", str(self.config_path), "-vv"]
        env = dict(os.environ, HOME=str(self.home))
        self.starts += 1
        with self.log_path.open("ab") as log:
            log.write(f"=== harness: CNCjs start #{self.starts}: {' '.join(argv)}\n".encode())
            log.flush()
            self.proc = subprocess.Popen(
                argv,
                cwd=self.scratch,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )

    def _answers(self) -> bool:
        """Whether GET / answers now (no proxy: loopback only)."""
        opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))
        try:
            with opener.open(self.url + "/", timeout=1.0) as reply:
                return bool(200 <= reply.status < 500)
        except urllib.error.HTTPError as exc:
            return exc.code < 500
        except (urllib.error.URLError, OSError):
            return False

    def wait_ready(self, timeout_s: float = CNCJS_START_TIMEOUT_S) -> None:
        """Wait until http://127.0.0.1:<port>/ answers; RigError with CNCjs's output if not."""
        assert self.proc is not None, "spawn() first"
        _wait_ready(
            self.proc,
            self._answers,
            timeout_s,
            0.05,
            exited=lambda code: (
                f"CNCjs exited with {code} before answering on {self.url} (log {self.log_path})"
            ),
            late=f"CNCjs did not answer on {self.url} within {timeout_s:.0f} s"
            f" (log {self.log_path})",
            log_path=self.log_path,
        )

    def start(self) -> None:
        """Start and wait until it answers."""
        self.spawn()
        self.wait_ready()

    @property
    def running(self) -> bool:
        """Whether the CNCjs process is alive."""
        return self.proc is not None and self.proc.poll() is None

    def stop(self) -> None:
        """SIGTERM, then SIGKILL if it lingers."""
        if self.proc is not None:
            stop_process(self.proc)
            self.proc = None

    def kill(self) -> None:
        """SIGKILL at once, as when CNCjs dies mid-jog; the pty and the sim stay."""
        if self.proc is not None:
            signal_group(self.proc, signal.SIGKILL)
            self.proc.wait(STOP_GRACE_S)
            self.proc = None

    def restart(self) -> None:
        """Stop (if running) and start again on the same port with the same config."""
        self.stop()
        self.start()


def start_side_by_side(sim: SimProcess, server: CncjsServer | None) -> None:
    """Start the simulator and CNCjs at once (CNCjs needs the pty only on open), then wait for
    both; on any failure stop whichever started."""
    try:
        if server is not None:
            find_cncjs(server.program)
        sim.spawn()
        if server is not None:
            server.spawn()
        sim.wait_ready()
        if server is not None:
            server.wait_ready()
    except BaseException:
        if server is not None:
            server.stop()
        sim.stop()
        raise
