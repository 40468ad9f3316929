"""Real Grbl 1.1h and real grblHAL behind a pty, from the shared realfw folder (skipped without it).

`real_firmware("grbl")` / `real_firmware("grblhal")` build the firmware (cached, about 20 s the
first time), start its harness and yield the pty's path (a symlink); the firmware is booted,
idle and silent when the client opens the port, unless dtr_reset=True makes it soft-reset on each
open like an Arduino.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

#: The shared folder beside this repository (as CI lays it out), or $REALFW_DIR.
REALFW_DIR = Path(
    os.environ.get("REALFW_DIR", Path(__file__).resolve().parents[2] / "shared" / "realfw")
)
_SCRIPTS = {"grbl": "grblpty.py", "grblhal": "grblhalpty.py"}


def _build(kind: str) -> Path:
    """Build the firmware (cached) and return its harness script, or skip the test."""
    script = REALFW_DIR / _SCRIPTS[kind]
    if not script.exists():
        pytest.skip(f"no real firmware harness at {script}")
    build = subprocess.run(
        [str(REALFW_DIR / "build.sh"), kind],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    if build.returncode != 0:
        pytest.fail(f"realfw build.sh {kind} failed: {build.stderr[-300:]}")
    return script


@contextlib.contextmanager
def real_firmware(
    kind: str, *, dtr_reset: bool = False, setup: tuple[str, ...] = ()
) -> Iterator[str]:
    """Run the real firmware behind a pty (its harness as a subprocess); yield the pty's path."""
    script = _build(kind)
    with tempfile.TemporaryDirectory(prefix=f"smoothjog-{kind}-") as tmp:
        link = Path(tmp) / "tty"
        command = [
            sys.executable,
            str(script),
            "--settings",
            str(REALFW_DIR / f"{kind}-hobby.txt"),
            "--link",
            str(link),
            "--run-dir",
            str(Path(tmp) / "run"),
            "--quiet",
        ]
        command += ["--dtr-reset"] if dtr_reset else []
        for line in setup:
            command += ["--setup", line]
        env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
        harness = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env
        )
        try:
            assert harness.stdout is not None
            for text in harness.stdout:  # "port: /dev/pts/N  link: ..." once it is ready
                if text.startswith("port:"):
                    break
            else:
                pytest.fail(f"the {kind} harness ended before its pty was ready")
            yield str(link)
        finally:
            harness.terminate()
            harness.wait(timeout=30)
            if harness.stdout is not None:
                harness.stdout.close()
