"""`python -m bench cncjs`: one short scenario through a real CNCjs and direct, and its table."""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from bench import cncjs

ROOT = Path(__file__).resolve().parents[1]


def _measured(
    scenario: str, link: str, phase: int, dies: str = "", **metrics: float
) -> cncjs.Measured:
    return cncjs.Measured(cncjs.Case(scenario, link, dies), phase, dict(metrics), 1.0)


def test_s4_runs_three_ways_and_the_order_alternates_by_phase() -> None:
    s4 = cncjs.cases_of("S4")
    assert [(c.link, c.dies) for c in s4] == [
        (cncjs.DIRECT, cncjs.SMOOTHJOG_DIES),
        (cncjs.CNCJS, cncjs.SMOOTHJOG_DIES),
        (cncjs.CNCJS, cncjs.CNCJS_DIES),
    ]
    s1 = cncjs.cases_of("S1")
    assert [c.link for c in cncjs.order_of(s1, 0)] == [cncjs.DIRECT, cncjs.CNCJS]
    assert [c.link for c in cncjs.order_of(s1, 1)] == [cncjs.CNCJS, cncjs.DIRECT]


def test_the_simulator_starts_with_soft_limits_off() -> None:
    image = json.loads(cncjs.soft_limits_off_eeprom())
    assert image["settings"]["20"] == 0
    assert image["settings"]["110"] == 5000  # still the hobby router's X max rate


def test_ratios_pair_the_runs_of_one_phase() -> None:
    results = [
        _measured(
            "S4", cncjs.DIRECT, 0, cncjs.SMOOTHJOG_DIES, dist_mm=10.0, time_s=0.2, queued_mm=9.0
        ),
        _measured(
            "S4", cncjs.CNCJS, 0, cncjs.SMOOTHJOG_DIES, dist_mm=11.0, time_s=0.2, queued_mm=9.0
        ),
        _measured("S4", cncjs.CNCJS, 0, cncjs.CNCJS_DIES, dist_mm=15.0, time_s=0.3, queued_mm=9.0),
        _measured(
            "S4", cncjs.DIRECT, 1, cncjs.SMOOTHJOG_DIES, dist_mm=20.0, time_s=0.2, queued_mm=9.0
        ),
        _measured(
            "S4", cncjs.CNCJS, 1, cncjs.SMOOTHJOG_DIES, dist_mm=20.0, time_s=0.2, queued_mm=9.0
        ),
        _measured("S4", cncjs.CNCJS, 1, cncjs.CNCJS_DIES, dist_mm=30.0, time_s=0.3, queued_mm=9.0),
    ]
    assert cncjs.ratios(results, "S4", cncjs.SMOOTHJOG_DIES) == pytest.approx([1.1, 1.0])
    assert cncjs.ratios(results, "S4", cncjs.CNCJS_DIES) == pytest.approx([1.5, 1.5])
    rows = cncjs.table(results, ["S4"])
    assert len(rows) == 2 + 3  # both deaths through CNCjs get a row
    assert "| 22.50 mm (15.00-30.00; 3.24x v²/2a) / 0.300 s; queued 9.00 mm |" in rows[4]
    assert "| 15.50 mm (11.00-20.00; 2.23x v²/2a) / 0.200 s; queued 9.00 mm |" in rows[3]


def _finite_numbers(row: str) -> list[float]:
    return [float(x) for x in re.findall(r"-?\d+(?:\.\d+)?", row.split("|", 2)[2])]


@pytest.mark.timeout(120)
def test_one_short_scenario_on_both_links_gives_both_rows(tmp_path: Path) -> None:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "src"), str(ROOT)]))
    argv = ["-m", "bench", "cncjs", "--phases", "1", "--scenarios", "S5", "--out", str(tmp_path)]
    done = subprocess.run(
        [sys.executable, *argv],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=110,
        check=False,
        stdin=subprocess.DEVNULL,
    )
    assert done.returncode == 0, done.stderr
    progress = [line for line in done.stderr.splitlines() if line.startswith("phase 1/1 S5")]
    assert len(progress) == 2  # one line per run
    written = (tmp_path / "cncjs.md").read_text(encoding="utf-8")
    assert written.strip() == done.stdout.strip()
    rows = [line for line in written.splitlines() if line.startswith("| ")]
    direct = [r for r in rows if r.startswith("| direct")]
    through = [r for r in rows if r.startswith("| through CNCjs")]
    ratio = [r for r in rows if r.startswith("| CNCjs / direct")]
    assert len(direct) == len(through) == len(ratio) == 1
    for row in (*direct, *through, *ratio):
        assert not re.search(r"never|nan|inf|n/a", row), row
        numbers = _finite_numbers(row)
        assert numbers, row
        assert all(math.isfinite(n) for n in numbers)
    # A 10 % release moves the machine a little, on both links.
    assert _finite_numbers(direct[0])[0] > 0
    assert _finite_numbers(through[0])[0] > 0
    assert "CNCjs 1.11.5" in written
    assert "every run ended with RX bytes dropped 0" in written
