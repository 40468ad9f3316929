"""Host CPU per second of held jog: `smoothjog jog --port` against `smoothjog sim` on a pty.

Usage: `python -m bench cpu [--speeds 0.5,1.0] [--hold-s 20] [--repeat 3] [--machine hobby-router]
[--src DIR] [--reference-src DIR]`.

The simulator runs as its own process on a pseudo-terminal. Each measurement runs the real
`smoothjog jog --port PTY --replay FILE` twice, once holding the stick for a short time (0.1 s)
and once for a long time (20 s), and takes its CPU time (user + sys, from `os.wait4`). Start-up,
handshake and shutdown cost the same in both runs, so (cpu_long - cpu_short) / (hold_long -
hold_short) is the CPU the host spends per second of held jog. The simulator's CPU over the same
windows (from /proc/PID/stat) is reported beside it for reference. Only the command line is
used, never smoothjog's modules, so the figure stays comparable while the host is rewritten.

The machine is shared and noisy, and noise moves every process at once, so one figure alone is
worth little. With `--reference-src DIR` a second host, `python -m smoothjog` with PYTHONPATH=DIR
(another checkout's src), is measured back to back with the one under test, against the same
simulator and in alternating order, and the ratio under-test / reference is taken per repeat.
`--src DIR` selects the tree under test the same way (default: the installed `smoothjog`).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import platform
import re
import shlex
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType

BAUD = 115200
#: Stick press this long after the replay starts, in both runs, so both see the same start-up.
LEAD_S = 0.2
#: Kept clear of each soft limit, on top of the stopping distance v²/2a at the fastest speed.
MARGIN_MM = 5.0
#: How often the parent looks whether a child has ended: rare enough to cost nothing measurable.
POLL_S = 0.1
#: Beyond hold + settle, how long a jog run may take before it counts as hung (start-up included).
RUN_SLACK_S = 60.0
SIM_READY_S = 15.0
AXES = "XYZABC"
_NUM = r"-?\d+(?:\.\d+)?"


class BenchError(Exception):
    """The benchmark cannot go on; the message says what failed and shows its output."""


@dataclass(frozen=True)
class AxisLimits:
    """One axis as `smoothjog info` reports it."""

    axis: str
    max_rate_mm_min: float
    accel_mm_s2: float
    lo_mm: float
    hi_mm: float
    soft_limits: bool

    def speed_mm_s(self, speed: float) -> float:
        """Feed in mm/s at a stick speed (0..1) with the default speed ratio of 1."""
        return speed * self.max_rate_mm_min / 60.0


@dataclass(frozen=True)
class Controller:
    """What the benchmark learned about the simulated controller before measuring."""

    firmware: str
    limits: AxisLimits
    pos_mm: float


@dataclass(frozen=True)
class Plan:
    """One scripted hold: `legs` equal legs of alternating direction, the first toward `sign`."""

    axis: str
    speed: float
    hold_s: float
    legs: int
    sign: int

    def replay_lines(self) -> list[str]:
        """The JSON Lines replay: press, reverse between legs, release."""
        leg_s = self.hold_s / self.legs
        key = self.axis.lower()
        lines = [
            json.dumps(
                {
                    "t": round(LEAD_S + k * leg_s, 6),
                    "axes": {key: float(self.sign * (-1) ** k)},
                    "speed": self.speed,
                }
            )
            for k in range(self.legs)
        ]
        lines.append(json.dumps({"t": round(LEAD_S + self.hold_s, 6), "axes": {key: 0}}))
        return lines

    def expected_move_mm(self, limits: AxisLimits) -> float:
        """Signed net travel of the hold: the legs cancel in pairs, leaving one leg's distance."""
        v = limits.speed_mm_s(self.speed)
        a = limits.accel_mm_s2
        leg_s = self.hold_s / self.legs
        # A leg shorter than v/a never reaches v: it accelerates and brakes, a·t² in all.
        dist = v * leg_s if leg_s >= v / a else a * leg_s**2
        return self.sign * dist if self.legs % 2 else 0.0

    def excursion_mm(self, limits: AxisLimits) -> float:
        """How far from its start the hold may go, stopping distance included."""
        v = limits.speed_mm_s(self.speed)
        return v * self.hold_s / self.legs + v * v / (2 * limits.accel_mm_s2)


@dataclass(frozen=True)
class Run:
    """One `smoothjog jog` run and what it cost."""

    speed: float
    hold_s: float
    host_cpu_s: float
    sim_cpu_s: float | None
    wall_s: float
    start_mm: float
    end_mm: float
    lines_sent: int | None
    where: str
    role: str = "under test"


@dataclass(frozen=True)
class Row:
    """Per speed: the figures of each repeat, as fractions of one core (CPU s per s).

    Everything but the ref_ fields and ratio is of the host under test; with no reference those
    three are empty. ratio[k] = host[k] / ref[k] for the repeats where ref[k] is above zero.
    """

    speed: float
    speed_mm_s: float
    host: list[float]
    sim: list[float]
    lines_per_s: list[float]
    moved_mm: list[float]
    short_cpu_s: list[float]
    ref: list[float] = field(default_factory=list)
    ref_sim: list[float] = field(default_factory=list)
    ratio: list[float] = field(default_factory=list)


def legs_for(hold_s: float, speed_mm_s: float, span_mm: float) -> int:
    """Legs for a hold: one if it fits the span, else an odd number short enough to fit."""
    if span_mm <= 0:
        raise BenchError(f"no usable travel ({span_mm:.1f} mm) once the margins are taken off")
    legs = max(1, math.ceil(hold_s * speed_mm_s / span_mm))
    # Odd, so the hold ends one leg away from its start and the final position proves it moved.
    return legs if legs % 2 else legs + 1


def parse_info(text: str, axis: str) -> Controller:
    """Firmware, the axis's limits and position from `smoothjog info` output."""
    row = re.search(
        rf"^\s*{axis}\s+({_NUM})\s*mm/min\s+({_NUM})\s*mm/s\S*\s+({_NUM})\s*mm", text, re.M
    )
    pos = re.search(rf"^MPos\b.*?\b{axis}\s+({_NUM})", text, re.M)
    if row is None or pos is None:
        raise BenchError(
            f"`smoothjog info` did not show the {axis} axis's max rate, acceleration, travel and"
            f" MPos in the expected form; its output was:\n{_tail(text)}"
        )
    rate, accel, travel = (float(g) for g in row.groups())
    soft = re.search(rf"^Soft limits\s+on\b.*?\b{axis}\s+({_NUM})\.\.({_NUM})", text, re.M)
    # Without soft limits, assume Grbl's default homing toward + ($23=0): machine space -travel..0.
    lo, hi = (float(soft.group(1)), float(soft.group(2))) if soft else (-travel, 0.0)
    firmware = re.search(r"^Controller\s+(.+)$", text, re.M)
    return Controller(
        firmware=firmware.group(1).strip() if firmware else "unknown",
        limits=AxisLimits(axis, rate, accel, lo, hi, soft is not None),
        pos_mm=float(pos.group(1)),
    )


def parse_jog(text: str, axis: str) -> tuple[float, int | None, str]:
    """Final position on the axis, lines sent if printed, and the link from `smoothjog jog`."""
    final = re.search(rf"at MPos\s+({_NUM}(?:\s*,\s*{_NUM})*)", text)
    if final is None:
        raise BenchError(
            f"`smoothjog jog` did not print a final MPos; its output was:\n{_tail(text)}"
        )
    coords = [float(c) for c in final.group(1).split(",")]
    index = AXES.index(axis)
    if index >= len(coords):
        raise BenchError(f"`smoothjog jog` printed no {axis} coordinate: {final.group(0)}")
    # The jog command prints no line count today; a future one may ("lines sent  N").
    sent = re.search(r"lines sent\D*?(\d+)", text)
    where = re.search(r"replay finished on (.+)$", text, re.M)
    return (
        coords[index],
        int(sent.group(1)) if sent else None,
        where.group(1).strip() if where else "unknown",
    )


def _tail(text: str, lines: int = 12) -> str:
    """The last lines of a child's output, indented, for an error message."""
    kept = text.strip().splitlines()[-lines:]
    return "\n".join(f"    {line}" for line in kept) if kept else "    (nothing)"


def _proc_cpu_s(pid: int) -> float | None:
    """utime + stime of a running process from /proc, in seconds; None without /proc."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text(encoding="ascii")
    except OSError:
        return None
    # Fields after the parenthesised command name: state is field 3, utime 14, stime 15.
    fields = stat.rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _child_env() -> dict[str, str]:
    """The environment without a user config, so the defaults (speed ratio 1) apply."""
    env = dict(os.environ)
    env.pop("SMOOTHJOG_CONFIG", None)
    return env


@dataclass(frozen=True)
class Host:
    """One way of starting smoothjog: a role in the report, a command, and the tree it imports."""

    role: str
    cmd: tuple[str, ...]
    #: The folder put on PYTHONPATH (a checkout's src); None runs the installed command as is.
    src: Path | None = None
    #: How the report names a host that is not smoothjog (the streaming floor).
    label: str | None = None

    def env(self) -> dict[str, str]:
        """The environment of its runs: no user config, PYTHONPATH set to src when there is one."""
        env = _child_env()
        if self.src is not None:
            env["PYTHONPATH"] = str(self.src)
        return env

    def shown(self, args: str) -> str:
        """The command line of `smoothjog ARGS` as the report writes it."""
        if self.label is not None:
            return f"`{self.label} {args}`"
        if self.src is None:
            return f"`smoothjog {args}`"
        return f"`python -m smoothjog {args}` with PYTHONPATH={self.src}"


def _imported_from(env: dict[str, str]) -> Path:
    """The folder of the smoothjog package this interpreter imports with env; BenchError if none."""
    cmd = [sys.executable, "-c", "import smoothjog, sys; print(smoothjog.__file__)"]
    try:
        done = subprocess.run(
            cmd, capture_output=True, text=True, env=env, timeout=RUN_SLACK_S, check=False
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise BenchError(f"`{shlex.join(cmd)}` did not run: {exc}") from None
    if done.returncode != 0:
        raise BenchError(
            f"`{shlex.join(cmd)}` with PYTHONPATH={env.get('PYTHONPATH', '')} failed (exit"
            f" {done.returncode}): smoothjog does not import; its stderr ended:\n"
            f"{_tail(done.stderr)}"
        )
    return Path(done.stdout.strip()).resolve().parent


def host_from_src(src: str, role: str) -> Host:
    """`python -m smoothjog` importing from src; BenchError unless smoothjog comes from there."""
    folder = Path(src).resolve()
    if not (folder / "smoothjog").is_dir():
        raise BenchError(
            f"{src} ({role}) has no smoothjog package folder: give a checkout's src folder,"
            " the one that holds smoothjog/"
        )
    host = Host(role, (sys.executable, "-m", "smoothjog"), folder)
    found = _imported_from(host.env())
    if found != folder / "smoothjog":
        # An installed copy or the working folder can shadow PYTHONPATH; its figures would lie.
        raise BenchError(
            f"with PYTHONPATH={folder}, {sys.executable} imports smoothjog from {found}, not from"
            f" {folder / 'smoothjog'}; the {role} tree would not be the one measured. Run the"
            " benchmark from a folder without its own smoothjog package, or check the path"
        )
    return host


def floor_host() -> Host:
    """The streaming floor (bench/cpu_floor.py): the same traffic with no engine behind it."""
    top = Path(__file__).resolve().parent.parent
    cmd = (sys.executable, "-m", "bench.cpu_floor")
    return Host("floor", cmd, top, "python -m bench.cpu_floor")


def find_smoothjog() -> str:
    """The `smoothjog` script beside this interpreter, else the one on PATH."""
    beside = Path(sys.executable).parent / "smoothjog"
    if beside.exists():
        return str(beside)
    found = shutil.which("smoothjog")
    if found is None:
        raise BenchError("no `smoothjog` command: install the project (pip install -e .) first")
    return found


class Bench:
    """The simulator process, its pty and a scratch folder, all removed by close()."""

    def __init__(self, host: Host, machine: str, firmware: str, axis: str) -> None:
        """Prepare; start() launches the simulator with the host's tree."""
        self.host = host
        self.machine = machine
        self.firmware = firmware
        self.axis = axis
        self._tmp = tempfile.TemporaryDirectory(prefix="smoothjog-bench-cpu-")
        self.dir = Path(self._tmp.name)
        self.pty = self.dir / "pty"
        self.sim: subprocess.Popen[bytes] | None = None
        self.child: subprocess.Popen[bytes] | None = None
        self.sim_ready = ""
        self._runs = 0

    def __enter__(self) -> Bench:
        """Start the simulator."""
        try:
            self.start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *_exc: object) -> None:
        """Stop every process and remove the scratch folder."""
        self.close()

    def _sim_output(self) -> tuple[str, str]:
        """What the simulator printed so far: stdout, stderr."""
        return (
            (self.dir / "sim.out").read_text(encoding="utf-8", errors="replace"),
            (self.dir / "sim.err").read_text(encoding="utf-8", errors="replace"),
        )

    def start(self) -> None:
        """Launch `smoothjog sim --link PTY` and wait until the pty exists and it says so."""
        cmd = [
            *self.host.cmd,
            "sim",
            "--firmware",
            self.firmware,
            "--machine",
            self.machine,
            "--link",
            str(self.pty),
            "--baud",
            str(BAUD),
        ]
        with (
            (self.dir / "sim.out").open("wb") as out,
            (self.dir / "sim.err").open("wb") as err,
        ):
            # Own session: a Ctrl-C reaches only the benchmark, which then stops it in order.
            self.sim = subprocess.Popen(
                cmd,
                stdout=out,
                stderr=err,
                stdin=subprocess.DEVNULL,
                env=self.host.env(),
                start_new_session=True,
            )
        deadline = time.monotonic() + SIM_READY_S
        while True:
            out_text, err_text = self._sim_output()
            if self.sim.poll() is not None:
                raise BenchError(
                    f"`{' '.join(cmd)}` exited with code {self.sim.returncode} before serving;"
                    f" its stderr ended:\n{_tail(err_text or out_text)}"
                )
            if self.pty.exists() and "smoothjog sim:" in out_text:
                self.sim_ready = out_text.strip().splitlines()[0]
                return
            if time.monotonic() > deadline:
                raise BenchError(
                    f"`{' '.join(cmd)}` made no pty at {self.pty} within {SIM_READY_S:.0f} s;"
                    f" its stderr ended:\n{_tail(err_text or out_text)}"
                )
            time.sleep(POLL_S)

    def _check_sim(self) -> int:
        """The simulator's pid; BenchError if it has died."""
        assert self.sim is not None
        if self.sim.poll() is not None:
            out_text, err_text = self._sim_output()
            raise BenchError(
                f"`smoothjog sim` died (exit {self.sim.returncode}) during the benchmark;"
                f" its stderr ended:\n{_tail(err_text or out_text)}"
            )
        return self.sim.pid

    def run_cli(
        self, args: list[str], timeout_s: float, host: Host | None = None
    ) -> tuple[int, str, str, float, float]:
        """Run `smoothjog ARGS` (host default: the bench's): exit, stdout, stderr, CPU s, wall s."""
        host = host or self.host
        self._check_sim()
        self._runs += 1
        out_path = self.dir / f"run{self._runs}.out"
        err_path = self.dir / f"run{self._runs}.err"
        with out_path.open("wb") as out, err_path.open("wb") as err:
            started = time.monotonic()
            self.child = subprocess.Popen(
                [*host.cmd, *args],
                stdout=out,
                stderr=err,
                stdin=subprocess.DEVNULL,
                env=host.env(),
                start_new_session=True,
            )
            pid = self.child.pid
            while True:
                # wait4, not wait(): it hands back the child's own rusage, exact to the µs.
                done, status, usage = os.wait4(pid, os.WNOHANG)
                if done:
                    break
                if time.monotonic() - started > timeout_s:
                    raise BenchError(
                        f"{host.shown(' '.join(args))} ({host.role}) still ran after"
                        f" {timeout_s:.0f} s;"
                        f" its output ended:\n{_tail(out_path.read_text(errors='replace'))}"
                    )
                time.sleep(POLL_S)
            wall_s = time.monotonic() - started
        self.child.returncode = os.waitstatus_to_exitcode(status)
        self.child = None
        return (
            os.waitstatus_to_exitcode(status),
            out_path.read_text(encoding="utf-8", errors="replace"),
            err_path.read_text(encoding="utf-8", errors="replace"),
            usage.ru_utime + usage.ru_stime,
            wall_s,
        )

    def info(self) -> Controller:
        """`smoothjog info --port PTY`, parsed."""
        code, out, err, _cpu, _wall = self.run_cli(
            ["info", "--port", str(self.pty), "--baud", str(BAUD)], RUN_SLACK_S
        )
        if code != 0:
            raise BenchError(
                f"`smoothjog info --port {self.pty}` failed (exit {code});"
                f" its stderr ended:\n{_tail(err or out)}"
            )
        return parse_info(out, self.axis)

    def jog(
        self, lines: list[str], settle_s: float, what: str, host: Host | None = None
    ) -> tuple[str, float, float, float]:
        """Run one replay on the pty: stdout, host CPU s, simulator CPU s (nan: unknown), wall s."""
        host = host or self.host
        replay = self.dir / "replay.jsonl"
        replay.write_text("\n".join(lines) + "\n", encoding="utf-8")
        args = [
            "jog",
            "--port",
            str(self.pty),
            "--baud",
            str(BAUD),
            "--replay",
            str(replay),
            "--settle",
            f"{settle_s:g}",
        ]
        sim_pid = self._check_sim()
        sim_before = _proc_cpu_s(sim_pid)
        code, out, err, cpu_s, wall_s = self.run_cli(args, RUN_SLACK_S + LEAD_S + settle_s, host)
        sim_after = _proc_cpu_s(sim_pid)
        if code != 0:
            raise BenchError(
                f"{host.shown(' '.join(args))} ({what}) failed with exit {code}; its output"
                f" ended:\n{_tail(out)}\nand its stderr:\n{_tail(err)}"
            )
        sim_cpu = (
            sim_after - sim_before if sim_before is not None and sim_after is not None else math.nan
        )
        return out, cpu_s, sim_cpu, wall_s

    def close(self) -> None:
        """Stop the jog child and the simulator (SIGTERM, then SIGKILL) and remove the files."""
        for proc in (self.child, self.sim):
            if proc is None or proc.poll() is not None:
                continue
            proc.terminate()
            try:
                proc.wait(5.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        self.child = None
        self._tmp.cleanup()


def _usable(limits: AxisLimits, fastest_mm_s: float) -> tuple[float, float]:
    """The part of the axis a hold may use: soft limits less the margin and a stopping distance."""
    margin = MARGIN_MM + fastest_mm_s**2 / (2 * limits.accel_mm_s2)
    return limits.lo_mm + margin, limits.hi_mm - margin


class Runner:
    """Runs planned holds on a Bench within [lo_mm, hi_mm], keeping track of where the axis is."""

    def __init__(
        self, bench: Bench, controller: Controller, lo_mm: float, hi_mm: float, log: bool
    ) -> None:
        """Start from the position `smoothjog info` reported."""
        self.bench = bench
        self.limits = controller.limits
        self.pos_mm = controller.pos_mm
        self.lo_mm = lo_mm
        self.hi_mm = hi_mm
        self.log = log

    def _say(self, text: str) -> None:
        """A progress line on stderr, unless quiet."""
        if self.log:
            print(text, file=sys.stderr, flush=True)

    def _goto(self, target_mm: float) -> None:
        """Move the axis to target at full speed (not measured)."""
        key = self.limits.axis.lower()
        line = json.dumps({"t": 0.0, "goto": {key: round(target_mm, 3)}, "speed": 1.0})
        travel_s = abs(target_mm - self.pos_mm) / self.limits.speed_mm_s(1.0)
        out, *_ = self.bench.jog([line], 10.0 + 2 * travel_s, f"move {self.limits.axis} to start")
        self.pos_mm, _sent, _where = parse_jog(out, self.limits.axis)
        self._say(f"  moved {self.limits.axis} to {self.pos_mm:.1f} mm to make room")

    def measure(self, speed: float, hold_s: float, legs: int, host: Host | None = None) -> Run:
        """One measured hold by host (default: the bench's), first toward the end with more room."""
        host = host or self.bench.host
        sign = -1 if self.pos_mm - self.lo_mm >= self.hi_mm - self.pos_mm else 1
        plan = Plan(self.limits.axis, speed, hold_s, legs, sign)
        room = self.pos_mm - self.lo_mm if sign < 0 else self.hi_mm - self.pos_mm
        if plan.excursion_mm(self.limits) > room:
            self._goto(self.hi_mm)
            plan = Plan(self.limits.axis, speed, hold_s, legs, -1)
        start = self.pos_mm
        settle_s = 10.0 + 2 * self.limits.speed_mm_s(speed) / self.limits.accel_mm_s2
        what = f"{hold_s:g} s hold at speed {speed:g}, {host.role}"
        out, cpu_s, sim_s, wall_s = self.bench.jog(plan.replay_lines(), settle_s, what, host)
        end, sent, where = parse_jog(out, self.limits.axis)
        self.pos_mm = end
        expected = plan.expected_move_mm(self.limits)
        moved = end - start
        # Well under what was scripted means the host idled: its CPU figure would be meaningless.
        if legs % 2 and not moved * plan.sign >= 0.3 * abs(expected):
            raise BenchError(
                f"the {what} moved {self.limits.axis} by {moved:+.2f} mm where about"
                f" {expected:+.2f} mm was scripted: the jog did not run; its output:\n{_tail(out)}"
            )
        self._say(
            f"  {what}: host {cpu_s:.3f} s CPU, simulator {sim_s:.3f} s, wall {wall_s:.1f} s,"
            f" {self.limits.axis} {start:.1f} -> {end:.1f} mm"
        )
        sim_cpu_s = None if math.isnan(sim_s) else sim_s
        return Run(speed, hold_s, cpu_s, sim_cpu_s, wall_s, start, end, sent, where, host.role)


def measure_all(
    bench: Bench,
    controller: Controller,
    speeds: list[float],
    short_s: float,
    hold_s: float,
    repeat: int,
    *,
    reference: Host | None = None,
    log: bool = True,
) -> tuple[list[Row], list[Run], int]:
    """Interleaved short and long holds per repeat, speed and host; per-speed rows, the runs, legs.

    With a reference, both hosts run back to back for each repeat and speed, against the same
    simulator; repeats 1, 3, 5, ... start with the host under test, 2, 4, ... with the reference,
    so neither always meets the machine in the same state.
    """
    limits = controller.limits
    fastest = limits.speed_mm_s(max(speeds))
    lo, hi = _usable(limits, fastest)
    legs = legs_for(hold_s, fastest, hi - lo)
    runner = Runner(bench, controller, lo, hi, log)
    runs: list[Run] = []
    under: dict[float, list[tuple[Run, Run]]] = {s: [] for s in speeds}
    ref: dict[float, list[tuple[Run, Run]]] = {s: [] for s in speeds}
    for k in range(repeat):
        for speed in speeds:
            if log:
                print(f"repeat {k + 1}/{repeat}, speed {speed:g}", file=sys.stderr, flush=True)
            order = [(bench.host, under)]
            if reference is not None:
                order.insert(1 - k % 2, (reference, ref))
            for host, pairs in order:
                short = runner.measure(speed, short_s, 1, host)
                long = runner.measure(speed, hold_s, legs, host)
                runs += [short, long]
                pairs[speed].append((short, long))
    dt = hold_s - short_s
    rows = [build_row(speed, limits, dt, under[speed], ref[speed]) for speed in speeds]
    return rows, runs, legs


def build_row(
    speed: float,
    limits: AxisLimits,
    dt_s: float,
    under: list[tuple[Run, Run]],
    ref: list[tuple[Run, Run]],
) -> Row:
    """One speed's row from its (short, long) run pairs, repeat k at index k; ref may be empty."""

    def each(pairs: list[tuple[Run, Run]], of: Callable[[Run], float | None]) -> list[float]:
        """(long - short) / dt per repeat, leaving out repeats where the figure is unknown."""
        got = [(of(sh), of(lg)) for sh, lg in pairs]
        return [(lg - sh) / dt_s for sh, lg in got if sh is not None and lg is not None]

    host = each(under, lambda r: r.host_cpu_s)
    ref_host = each(ref, lambda r: r.host_cpu_s)
    # Per repeat, not median over median: a burst of noise moves both hosts of one repeat alike.
    # A reference figure at or below zero (noise swamping a tiny cost) gives no ratio.
    ratio = [h / r for h, r in zip(host, ref_host, strict=True) if r > 0] if ref else []
    return Row(
        speed=speed,
        speed_mm_s=limits.speed_mm_s(speed),
        host=host,
        sim=each(under, lambda r: r.sim_cpu_s),
        lines_per_s=each(under, lambda r: r.lines_sent),
        moved_mm=[abs(lg.end_mm - lg.start_mm) for _sh, lg in under],
        short_cpu_s=[sh.host_cpu_s for sh, _lg in under],
        ref=ref_host,
        ref_sim=each(ref, lambda r: r.sim_cpu_s),
        ratio=ratio,
    )


def _spread(values: list[float], scale: float, unit: str, digits: int = 1) -> str:
    """Median and range, e.g. `15.6 % (15.1-16.0)`; `n/a` for no values."""
    if not values:
        return "n/a"
    med = statistics.median(values) * scale
    lo, hi = min(values) * scale, max(values) * scale
    if len(values) == 1:
        return f"{med:.{digits}f}{unit}"
    return f"{med:.{digits}f}{unit} ({lo:.{digits}f} to {hi:.{digits}f})"


def table(rows: list[Row], axis: str) -> list[str]:
    """The Markdown table: one row per speed; the reference's columns only if one was measured."""
    with_ref = any(row.ref for row in rows)
    heads = [
        "stick speed",
        "feed",
        "host CPU per s of held jog, % of one core",
        "host, least disturbed (min of repeats)",
        *(
            [
                "reference host, % of one core",
                "under test / reference, per repeat",
                "simulator, % of one core",
                "simulator during the reference's runs",
            ]
            if with_ref
            else ["simulator, % of one core"]
        ),
        "host lines/s",
        "host CPU of a short run",
        "net move per long hold",
    ]
    out = ["| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
    for row in rows:
        lines = (
            _spread(row.lines_per_s, 1.0, "", 0)
            if row.lines_per_s
            else "not printed by `smoothjog jog`"
        )
        least = f"{100 * min(row.host):.1f} %" if row.host else "n/a"
        sims = (
            [
                _spread(row.ref, 100.0, " %"),
                _spread(row.ratio, 1.0, "", 2),
                _spread(row.sim, 100.0, " %"),
                _spread(row.ref_sim, 100.0, " %"),
            ]
            if with_ref
            else [_spread(row.sim, 100.0, " %")]
        )
        cells = [
            f"{100 * row.speed:.0f} %",
            f"{row.speed_mm_s:.1f} mm/s",
            _spread(row.host, 100.0, " %"),
            least,
            *sims,
            lines,
            _spread(row.short_cpu_s, 1.0, " s", 2),
            f"{axis} {_spread(row.moved_mm, 1.0, ' mm', 0)}",
        ]
        out.append("| " + " | ".join(cells) + " |")
    return out


def _floats(text: str) -> list[float]:
    """argparse type: stick speeds as a comma list, each in (0, 1]."""
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma list, e.g. 0.5,1.0") from None
    if not values or not all(0.0 < v <= 1.0 for v in values):
        raise argparse.ArgumentTypeError(f"{text!r}: each speed must be in (0, 1], e.g. 0.5,1.0")
    return values


def _positive(text: str) -> float:
    """argparse type: a finite number above zero."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0.0 < value < math.inf:
        raise argparse.ArgumentTypeError(f"{text} must be above 0")
    return value


def _parser() -> argparse.ArgumentParser:
    """The command line of `python -m bench cpu`."""
    parser = argparse.ArgumentParser(
        prog="python -m bench cpu",
        description="Host CPU per second of held jog, smoothjog jog against smoothjog sim.",
    )
    parser.add_argument("--speeds", type=_floats, default=[0.5, 1.0], help="default 0.5,1.0")
    parser.add_argument("--hold-s", type=_positive, default=20.0, help="long hold (default 20)")
    parser.add_argument("--short-s", type=_positive, default=0.1, help="short hold (default 0.1)")
    parser.add_argument("--repeat", type=int, default=3, help="measurements per speed (default 3)")
    parser.add_argument("--machine", default="hobby-router", help="sim machine profile")
    parser.add_argument("--firmware", default="grbl", help="sim firmware (default grbl)")
    parser.add_argument("--axis", default="X", choices=list("XYZ"), type=str.upper)
    parser.add_argument("--out", default="bench/results", help="folder for cpu.md")
    tree = parser.add_mutually_exclusive_group()
    tree.add_argument("--smoothjog", help="the smoothjog command (default: beside python)")
    tree.add_argument(
        "--src",
        metavar="DIR",
        help="the tree under test: a checkout's src, run as python -m smoothjog with PYTHONPATH=DIR"
        " (default: the installed smoothjog); the simulator runs from it too",
    )
    reference = parser.add_mutually_exclusive_group()
    reference.add_argument(
        "--reference-src",
        metavar="DIR",
        help="a second checkout's src, measured back to back with the host under test",
    )
    reference.add_argument(
        "--floor",
        action="store_true",
        help="measure bench/cpu_floor.py back to back as the reference: the same lines and"
        " polls with no engine, the event loop's and the kernel's share alone",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    parser.add_argument("--note", help="a line for the report, e.g. which tree was measured")
    return parser


def report(
    argv: list[str],
    args: argparse.Namespace,
    bench: Bench,
    controller: Controller,
    rows: list[Row],
    runs: list[Run],
    legs: int,
    load: tuple[tuple[float, ...], tuple[float, ...]],
    reference: Host | None = None,
) -> list[str]:
    """The whole Markdown report."""
    lim = controller.limits
    fastest = lim.speed_mm_s(max(args.speeds))
    lo, hi = _usable(lim, fastest)
    leg_s = args.hold_s / legs
    if legs > 1:
        pattern = (
            f"{args.hold_s:g} s at {fastest:.1f} mm/s ({args.hold_s * fastest:.0f} mm) exceeds the"
            f" {hi - lo:.0f} mm of usable {lim.axis} travel, so the long hold goes back and forth:"
            f" {legs} legs of {leg_s:.2f} s, reversing every {leg_s:.2f} s (at every speed, so"
            f" each long hold has {legs - 1} reversals). Each hold starts toward the end with"
            " more room."
        )
    else:
        pattern = (
            f"the long hold fits the {hi - lo:.0f} mm of usable {lim.axis} travel in one"
            " direction, toward the end with more room."
        )
    limits = (
        f"soft limits {lim.lo_mm:g}..{lim.hi_mm:g} mm"
        if lim.soft_limits
        else f"no soft limits; travel assumed {lim.lo_mm:g}..{lim.hi_mm:g} mm"
    )
    # The scratch pty's path changes every run; the report names it PTY.
    wheres = sorted({r.where.replace(str(bench.pty), "PTY") for r in runs})
    banner = re.search(r"^smoothjog sim: (.+?) on pty", bench.sim_ready)
    jog_args = f"jog --port PTY --baud {BAUD} --replay FILE"
    sim_args = f"sim --firmware {args.firmware} --machine {args.machine} --link PTY --baud {BAUD}"
    if reference is None:
        hosts = [
            f"- Host: {bench.host.shown(jog_args)}, default config; one process per run,"
            " CPU = user + sys from os.wait4",
            f"- Source: {_tree(bench.host)}",
        ]
        figure = f"median of {args.repeat} (range in brackets)"
    else:
        hosts = [
            f"- Host under test: {bench.host.shown(jog_args)}; source: {_tree(bench.host)}",
            f"- Reference host: {reference.shown(jog_args)}; source: {_tree(reference)}",
            "- Both hosts: default config; one process per run, CPU = user + sys from os.wait4;"
            " for every repeat and speed both are measured back to back against the same"
            " simulator process, the host under test first in repeats 1, 3, 5, ... and the"
            " reference first in repeats 2, 4, ...",
        ]
        figure = (
            f"median of {args.repeat} (range in brackets); the ratio is computed per repeat,"
            " the host under test's figure divided by the reference's from the same repeat and"
            " speed, and the table gives the median and range of those ratios, so noise that"
            " moves both hosts alike cancels"
        )
    return [
        "# CPU benchmark: host CPU while a jog is held",
        "",
        f"Command: `{shlex.join(['python', '-m', 'bench', 'cpu', *argv])}`",
        "",
        f"- Simulator: {bench.host.shown(sim_args)} in its own process (the tree under test),"
        " serving"
        f" {banner.group(1) if banner else bench.sim_ready}",
        f"- Controller: {controller.firmware}; machine {args.machine}; {lim.axis} max rate"
        f" {lim.max_rate_mm_min:g} mm/min, {lim.accel_mm_s2:g} mm/s², {limits}",
        f"- Link: pseudo-terminal, {BAUD} baud (jog reported: {', '.join(wheres)})",
        *hosts,
        f"- Stick: {lim.axis} axis at full deflection, speed as below; press {LEAD_S:g} s into"
        f" the replay, release after the hold; holds of {args.short_s:g} s and {args.hold_s:g} s;"
        f" {pattern}",
        f"- Figure: (CPU of the {args.hold_s:g} s run - CPU of the {args.short_s:g} s run) /"
        f" {args.hold_s - args.short_s:g} s; {figure}; least disturbed = the lowest of the"
        " repeats, since noise here only ever adds CPU time; simulator CPU from /proc/PID/stat"
        " over the same runs",
        f"- Machine: {platform.node()}, {os.cpu_count()} CPUs, Python"
        f" {platform.python_version()}, load average {load[0][0]:.2f} before,"
        f" {load[1][0]:.2f} after (shared and noisy: compare medians, mind the ranges)",
        *([f"- Note: {args.note}"] if args.note else []),
        "",
        *table(rows, lim.axis),
        "",
    ]


def _git(folder: Path, *args: str) -> str:
    """Output of a read-only git command run in folder."""
    return subprocess.run(
        ["git", "-C", str(folder), *args], capture_output=True, text=True, check=True
    ).stdout.strip()


def _tree(host: Host) -> str:
    """Which smoothjog the host's runs import, and its commit: a PYTHONPATH may pick a copy."""
    if host.label is not None:
        return "bench/cpu_floor.py (streaming only: no engine, ledger or tracker)"
    try:
        package = _imported_from(host.env())
    except BenchError:
        return "unknown (smoothjog does not import)"
    # A src on PYTHONPATH sits in a checkout: its parent is the checkout's top (or within it).
    where = host.src.parent if host.src is not None else package
    try:
        head = _git(where, "rev-parse", "--short", "HEAD")
        dirty = _git(package, "status", "--porcelain", "--untracked-files=no", "--", ".")
    except (OSError, subprocess.CalledProcessError):
        return f"smoothjog from {package} (not a git checkout)"
    changed = " with uncommitted changes" if dirty else ""
    return f"smoothjog from {package}, commit {head}{changed}"


@contextlib.contextmanager
def _sigterm_as_interrupt() -> Iterator[None]:
    """Turn SIGTERM into KeyboardInterrupt so the cleanup runs; restores the old handler."""

    def handler(_sig: int, _frame: FrameType | None) -> None:
        raise KeyboardInterrupt

    old = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def main(argv: list[str] | None = None) -> int:
    """Run the CPU benchmark; 0 when every run jogged, 1 with a sentence when one failed."""
    argv = list(sys.argv[2:] if argv is None else argv)
    args = _parser().parse_args(argv)
    if args.repeat < 1:
        print("python -m bench cpu: --repeat must be 1 or more", file=sys.stderr)
        return 2
    if args.hold_s <= args.short_s:
        print("python -m bench cpu: --hold-s must be longer than --short-s", file=sys.stderr)
        return 2
    load_before = os.getloadavg()
    try:
        with _sigterm_as_interrupt():
            under = (
                host_from_src(args.src, "under test")
                if args.src
                else Host("under test", (args.smoothjog or find_smoothjog(),))
            )
            reference = (
                host_from_src(args.reference_src, "reference")
                if args.reference_src
                else (floor_host() if args.floor else None)
            )
            with Bench(under, args.machine, args.firmware, args.axis) as bench:
                controller = bench.info()
                rows, runs, legs = measure_all(
                    bench,
                    controller,
                    args.speeds,
                    args.short_s,
                    args.hold_s,
                    args.repeat,
                    reference=reference,
                    log=not args.quiet,
                )
                load = (load_before, os.getloadavg())
                text = report(argv, args, bench, controller, rows, runs, legs, load, reference)
    except BenchError as exc:
        print(f"python -m bench cpu: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("python -m bench cpu: interrupted; simulator and jog stopped", file=sys.stderr)
        return 130
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "cpu.md").write_text("\n".join(text) + "\n", encoding="utf-8")
    print("\n".join(text))
    return 0
