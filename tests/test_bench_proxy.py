"""`python -m bench proxy`: its job ends where it began, its table, and one tiny real run."""

from __future__ import annotations

from pathlib import Path

from bench import proxy


def test_the_job_goes_out_and_back() -> None:
    job = proxy.job_lines(300)
    assert len(job) == 302
    assert job[0] == b"G21G91\n"
    assert job[-1] == b"G90\n"
    moves = job[1:-1]
    assert sum(-1 if b"X-" in m else 1 for m in moves) == 0
    assert all(len(m) < 128 for m in job)


def test_the_table_shows_both_paths_and_the_difference() -> None:
    results = {
        "direct": proxy.PathResult([0.003] * 99 + [0.010], [1.0, 1.1]),
        "proxy": proxy.PathResult([0.004] * 99 + [0.020], [1.1, 1.2]),
    }
    rows = proxy.table(results, 300)
    assert rows[0].startswith("| path | round trip median | round trip p99")
    assert "| direct: the simulator's pty | 3.00 ms |" in rows[2]
    assert rows[-1].startswith("| the proxy adds | +1.00 ms |")
    assert "+0.100 s (+9.5 %)" in rows[-1]


def test_a_tiny_run_measures_both_paths(tmp_path: Path) -> None:
    results = proxy.run_all(1, 5, 10, tmp_path, lambda line: None)
    for path in proxy.PATHS:
        assert len(results[path].round_trips_s) == 5
        assert len(results[path].jobs_s) == 1
        assert all(0 < t < 1.0 for t in results[path].round_trips_s)
