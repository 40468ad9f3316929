"""What `smoothjog proxy` adds for the sender: a line's round trip and a G-code job's duration.

Usage: `python -m bench proxy [--rounds 3] [--samples 200] [--job-lines 300] [--out bench/results]`.

One simulator process (`smoothjog sim --machine hobby-router --link PTY`, Grbl 1.1h) serves both
paths, in turns, so the machine and its wire are the same:

* direct: the bench is the sender, on the simulator's pty (pyserial at 115200 baud);
* proxy: `smoothjog proxy --port <the simulator's pty> --link <its own pty> --http-port 0` runs
  as its own process (the shipped command: SerialLink, Host with its engine, the pendant's web
  server beside it), and the bench is the sender on the proxy's pty.

Each round measures both paths back to back (direct first in rounds 1, 3, ..., last in 2, 4,
...), a fresh proxy process every round:

* round trip: `G4P0` written, the time until its `ok` is read (one line in flight, the machine
  at rest, status reports that come meanwhile skipped); the first 10 of each round are warm-up;
* job: a file of short G91 moves (half toward -X, half back, F3000) streamed with character
  counting against the 128 bytes of Grbl's RX buffer, as senders stream, timed from the first
  byte written until a status report shows Idle after the last `ok`.
"""

from __future__ import annotations

import argparse
import os
import platform
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from collections import deque
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import serial

from bench.cncjs_rig import ROOT, RigError, SimProcess, log_tail, stop_process, write_report
from bench.cpu import _sigterm_as_interrupt
from bench.links import code_version

MACHINE = "hobby-router"
RX_BYTES = 128
WARM_UP = 10
PROXY_START_TIMEOUT_S = 30.0
REPLY_TIMEOUT_S = 5.0
JOB_TIMEOUT_S = 120.0
PATHS = ("direct", "proxy")


class BenchError(Exception):
    """The bench could not measure (a reply never came, the proxy did not start)."""


# ----------------------------------------------------------------------------- the sender
class Sender:
    """The bench as a desktop sender on a pty: lines out, replies in, reports skipped."""

    def __init__(self, path: Path) -> None:
        """Open the port (a pty: the baud rate is the sender's setting only)."""
        self.port = serial.Serial(str(path), 115200, timeout=0.002)
        self._buf = b""

    def close(self) -> None:
        """Close the port."""
        self.port.close()

    def lines(self) -> Iterator[bytes]:
        """The complete lines read now (none if none came within the read timeout)."""
        waiting = self.port.in_waiting
        self._buf += self.port.read(waiting or 1)
        while b"\n" in self._buf:
            line, self._buf = self._buf.split(b"\n", 1)
            yield line.rstrip(b"\r")

    def drain(self, quiet_s: float = 0.3, most_s: float = 1.0) -> None:
        """Read and drop what comes until quiet_s passes without a byte (the banner, reports),
        most_s at most (through the proxy, smoothjog's own status polls never stop)."""
        give_up = time.monotonic() + most_s
        end = min(time.monotonic() + quiet_s, give_up)
        while time.monotonic() < end:
            if self.port.read(4096):
                end = min(time.monotonic() + quiet_s, give_up)
        self._buf = b""

    def reply(self, timeout_s: float = REPLY_TIMEOUT_S) -> bytes:
        """The next ok/error, skipping everything else."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            for line in self.lines():
                if line == b"ok" or line.startswith(b"error:"):
                    return line
        raise BenchError(f"no reply within {timeout_s} s")

    def round_trip_s(self, text: bytes = b"G4P0\n") -> float:
        """One line written, the time to its reply (which must be ok)."""
        start = time.perf_counter()
        self.port.write(text)
        reply = self.reply()
        took = time.perf_counter() - start
        if reply != b"ok":
            raise BenchError(f"{text!r} was answered {reply!r}")
        return took

    def stream_s(self, job: Sequence[bytes]) -> float:
        """Stream job with character counting; the time until Idle after the last ok."""
        in_flight: deque[int] = deque()
        sent = answered = 0
        start = time.perf_counter()
        deadline = time.monotonic() + JOB_TIMEOUT_S
        while answered < len(job):
            if time.monotonic() > deadline:
                raise BenchError(f"the job stalled after {answered} of {len(job)} replies")
            while sent < len(job) and sum(in_flight) + len(job[sent]) <= RX_BYTES:
                self.port.write(job[sent])
                in_flight.append(len(job[sent]))
                sent += 1
            for line in self.lines():
                if line == b"ok" or line.startswith(b"error:"):
                    if line != b"ok":
                        raise BenchError(f"a job line was answered {line!r}")
                    in_flight.popleft()
                    answered += 1
        while True:
            if time.monotonic() > deadline:
                raise BenchError("the machine never reported Idle after the job")
            self.port.write(b"?")
            for _ in range(10):
                for line in self.lines():
                    if line.startswith(b"<Idle"):
                        return time.perf_counter() - start


def job_lines(count: int) -> list[bytes]:
    """Short relative moves, half toward -X and half back: the machine ends where it began."""
    half = count // 2
    moves = [b"G1X-0.2F3000\n"] * half + [b"G1X0.2F3000\n"] * (count - half)
    return [b"G21G91\n", *moves, b"G90\n"]


# ----------------------------------------------------------------------------- the proxy
@contextmanager
def proxy_process(scratch: Path, controller: Path, number: int) -> Iterator[Path]:
    """`smoothjog proxy --port controller --link <scratch>/ttyPROXY` until the block ends."""
    link = scratch / "ttyPROXY"
    log_path = scratch / f"proxy-{number}.log"
    env = dict(os.environ)
    src = str(ROOT / "src")
    env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    argv = [sys.executable, "-m", "smoothjog", "proxy", "--port", str(controller)]
    argv += ["--link", str(link), "--http-port", "0"]
    with log_path.open("ab") as log:
        proc = subprocess.Popen(
            argv,
            cwd=scratch,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    try:
        end = time.monotonic() + PROXY_START_TIMEOUT_S
        while b"the sender's port is" not in log_path.read_bytes():
            if proc.poll() is not None or time.monotonic() > end:
                raise BenchError(f"the proxy did not start:\n{log_tail(log_path)}")
            time.sleep(0.05)
        yield link
    finally:
        stop_process(proc)


# ----------------------------------------------------------------------------- measuring
@dataclass
class PathResult:
    """Everything measured on one path."""

    round_trips_s: list[float] = field(default_factory=list)
    jobs_s: list[float] = field(default_factory=list)


def measure_path(sender: Sender, samples: int, job: Sequence[bytes], out: PathResult) -> None:
    """One round on one path: round trips, then the job."""
    sender.drain()
    for k in range(WARM_UP + samples):
        took = sender.round_trip_s()
        if k >= WARM_UP:
            out.round_trips_s.append(took)
    sender.drain(0.1)
    out.jobs_s.append(sender.stream_s(job))


def run_all(
    rounds: int, samples: int, job_count: int, scratch: Path, say: object
) -> dict[str, PathResult]:
    """Every round, both paths in alternating order; the simulator shared by all."""
    assert callable(say)
    results = {path: PathResult() for path in PATHS}
    job = job_lines(job_count)
    sim = SimProcess(scratch, MACHINE)
    try:
        sim.start()
        for number in range(rounds):
            order = PATHS if number % 2 == 0 else PATHS[::-1]
            for path in order:
                if path == "direct":
                    sender = Sender(sim.link)
                    try:
                        measure_path(sender, samples, job, results[path])
                    finally:
                        sender.close()
                else:
                    with proxy_process(scratch, sim.link, number) as link:
                        sender = Sender(link)
                        try:
                            measure_path(sender, samples, job, results[path])
                        finally:
                            sender.close()
                r = results[path]
                say(
                    f"round {number + 1}/{rounds} {path}: round trip median"
                    f" {1000 * statistics.median(r.round_trips_s[-samples:]):.2f} ms,"
                    f" job {r.jobs_s[-1]:.3f} s"
                )
    finally:
        sim.stop()
    return results


def p99(values: Sequence[float]) -> float:
    """The 99th percentile (inclusive method)."""
    return statistics.quantiles(values, n=100, method="inclusive")[98]


def table(results: dict[str, PathResult], job_count: int) -> list[str]:
    """The Markdown table: both paths and the difference."""
    direct, proxy = results["direct"], results["proxy"]

    def ms(value: float) -> str:
        return f"{1000 * value:.2f} ms"

    def jobs(r: PathResult) -> str:
        values = ", ".join(f"{v:.3f}" for v in r.jobs_s)
        return f"{statistics.median(r.jobs_s):.3f} s ({values})"

    rows = [
        "| path | round trip median | round trip p99 | round trip max"
        f" | job of {job_count + 2} lines: median (each round) |",
        "|---|---|---|---|---|",
    ]
    for name, r in (("direct: the simulator's pty", direct), ("through the proxy", proxy)):
        rt = r.round_trips_s
        rows.append(f"| {name} | {ms(statistics.median(rt))} | {ms(p99(rt))} | {ms(max(rt))} |")
        rows[-1] += f" {jobs(r)} |"
    d_med = statistics.median(proxy.round_trips_s) - statistics.median(direct.round_trips_s)
    d_p99 = p99(proxy.round_trips_s) - p99(direct.round_trips_s)
    d_job = statistics.median(proxy.jobs_s) - statistics.median(direct.jobs_s)
    share = 100 * d_job / statistics.median(direct.jobs_s)
    rows.append(
        f"| the proxy adds | {1000 * d_med:+.2f} ms | {1000 * d_p99:+.2f} ms | |"
        f" {d_job:+.3f} s ({share:+.1f} %) |"
    )
    return rows


def report(
    argv: Sequence[str],
    args: argparse.Namespace,
    results: dict[str, PathResult],
    load: tuple[tuple[float, ...], tuple[float, ...]],
    wall_s: float,
) -> list[str]:
    """The whole Markdown report."""
    return [
        "# What the proxy adds for the sender: round trip and job duration",
        "",
        f"Command: `{shlex.join(['python', '-m', 'bench', 'proxy', *argv])}`",
        "",
        f"- Machine: the simulator's Grbl 1.1h, {MACHINE}, as its own process (`python -m"
        " smoothjog sim --machine hobby-router --link PTY`), one for the whole run",
        "- direct: the bench as the sender on the simulator's pty (pyserial, 115200 baud);"
        " proxy: `python -m smoothjog proxy --port <the simulator's pty> --link PTY"
        " --http-port 0` as its own process (SerialLink, the Host with its engine polling as"
        " it does at rest, the pendant's server), the bench as the sender on its pty; a fresh"
        " proxy each round",
        f"- Round trip: `G4P0` to its `ok`, one line in flight, machine at rest; {args.samples}"
        f" per round and path after {WARM_UP} warm-up lines, {args.rounds} rounds pooled"
        f" ({args.samples * args.rounds} per path)",
        f"- Job: {args.job_lines} moves of 0.2 mm along X at F3000 (half out, half back),"
        " between `G21G91` and `G90`, streamed with character counting against 128 bytes;"
        " from the first byte to the first Idle report after the last `ok`",
        f"- Order: direct first in rounds 1, 3, ..., proxy first in 2, 4, ...; {wall_s:.0f} s"
        " in all",
        f"- Code: {code_version()}",
        f"- Computer: {platform.node()}, {os.cpu_count()} CPUs, Python"
        f" {platform.python_version()}, load average {load[0][0]:.2f} before,"
        f" {load[1][0]:.2f} after (three processes in real time on a shared VM: the tails"
        " carry its noise)",
        "",
        *table(results, args.job_lines),
        "",
    ]


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m bench proxy", description=__doc__)
    parser.add_argument("--rounds", type=int, default=3, help="rounds of both paths (3)")
    parser.add_argument("--samples", type=int, default=200, help="round trips a round (200)")
    parser.add_argument("--job-lines", type=int, default=300, help="moves in the job (300)")
    parser.add_argument("--out", default="bench/results", help="where proxy.md goes")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; 0 when every path was measured, 1 with a sentence when one was not."""
    argv = list(sys.argv[2:] if argv is None else argv)
    args = _parser().parse_args(argv)
    if args.rounds < 1 or args.samples < 2 or args.job_lines < 2:
        print("python -m bench proxy: --rounds >= 1, --samples >= 2, --job-lines >= 2")
        return 2
    load_before = os.getloadavg()
    started = time.monotonic()
    try:
        with _sigterm_as_interrupt(), tempfile.TemporaryDirectory(prefix="smoothjog-proxy-") as d:
            results = run_all(
                args.rounds,
                args.samples,
                args.job_lines,
                Path(d),
                lambda line: print(line, file=sys.stderr, flush=True),
            )
    except (BenchError, RigError, serial.SerialException) as exc:
        print(f"python -m bench proxy: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("python -m bench proxy: interrupted; simulator and proxy stopped", file=sys.stderr)
        return 130
    load = (load_before, os.getloadavg())
    text = report(argv, args, results, load, time.monotonic() - started)
    write_report(args.out, "proxy.md", text)
    return 0
