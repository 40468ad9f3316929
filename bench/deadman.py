"""`python -m bench deadman [--minutes 5] [--rounds 1]`: the pendant's dead-man on a busy machine.

Runs the browser test tests/web/test_deadman_load.py (real headless Chromium, the real page and
server, two processes spinning on a core each, the page's own thread made to stall 250 ms every
2 s) with a longer hold, once per round, and prints
what each round measured: dead-man trips (the goal is 0), the worst gap between heartbeats at
the server against its 150 ms window, and how long the page's own thread paused, with the count
of pauses longer than the window (each would have stopped the jog if the heartbeat still came
from that thread, as it did before the link worker). Writes bench/results/deadman.md.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ARTIFACT = ROOT / "test-artifacts" / "deadman-load.txt"


def main(argv: list[str]) -> int:
    """Run the rounds and print the table."""
    parser = argparse.ArgumentParser(prog="python -m bench deadman", description=__doc__)
    parser.add_argument("--minutes", type=float, default=5.0, help="hold per round (default 5)")
    parser.add_argument("--rounds", type=int, default=1, help="rounds (default 1)")
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    args = parser.parse_args(argv)
    if not (args.minutes > 0 and args.rounds > 0):
        parser.error("--minutes and --rounds must be positive")
    hold_s = args.minutes * 60
    rows: list[str] = []
    failed = 0
    for n in range(1, args.rounds + 1):
        ARTIFACT.unlink(missing_ok=True)
        env = dict(
            os.environ, SMOOTHJOG_DEADMAN_HOLD_S=str(hold_s), SMOOTHJOG_DEADMAN_STALL_MS="250"
        )
        print(
            f"round {n}/{args.rounds}: holding a jog {hold_s:.0f} s under two CPU hogs ...",
            file=sys.stderr,
            flush=True,
        )
        t0 = time.monotonic()
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "pytest",
                "-q",
                "-p",
                "no:cacheprovider",
                "tests/web/test_deadman_load.py",
            ],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            check=False,
        )
        wall_s = time.monotonic() - t0
        if done.returncode != 0 or not ARTIFACT.exists():
            failed += 1
            tail = "\n".join(done.stdout.splitlines()[-15:])
            rows.append(f"| {n} | FAILED (exit {done.returncode}) | see below |")
            print(tail, file=sys.stderr)
            continue
        rows.append(f"| {n} | {ARTIFACT.read_text().strip()} | {wall_s:.0f} s |")
    machine = f"{os.cpu_count()} CPUs, load average at the end: {os.getloadavg()[0]:.2f}"
    report = "\n".join(
        [
            "# Dead-man under CPU load",
            "",
            f"Command: `python -m bench deadman --minutes {args.minutes:g} --rounds {args.rounds}`",
            "",
            "- Browser: Debian's Chromium, headless, through Playwright; the pendant page and"
            " server of this checkout against the recording backend (no controller: the"
            " dead-man is the page's and the server's); two `python -c 'while True: pass'`"
            " processes for the whole hold, and a 250 ms busy loop on the page's own thread"
            " every 2 s.",
            f"- Machine: {machine}.",
            "",
            "| round | measured | wall time |",
            "|---|---|---|",
            *rows,
            "",
        ]
    )
    print(report)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "deadman.md").write_text(report)
    return 1 if failed else 0
