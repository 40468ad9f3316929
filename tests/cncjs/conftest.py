"""Fixtures: a running simulator plus a real CNCjs for one test (tests/cncjs/harness.py)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.cncjs.harness import CncjsRig


@pytest.fixture
def cncjs(tmp_path: Path) -> Iterator[CncjsRig]:
    """The simulator (hobby-router) on a pty and CNCjs on a free loopback port, both running.

    The rig offers url, port_path (the pty), config_path, secret, log_path, token(), client(),
    kill() and restart(); its logs stay in the test's tmp dir (cncjs.log, sim.log).
    """
    rig = CncjsRig.start(tmp_path / "cncjs")
    try:
        yield rig
    finally:
        rig.close()
