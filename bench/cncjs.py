"""S1-S5 in real time through a real CNCjs, beside the direct link to the same simulated machine.

Usage: `python -m bench cncjs [--phases 3] [--scenarios S1,S2,S3,S4,S5] [--out bench/results]`.

Every run starts its own simulator process (`smoothjog sim --machine hobby-router --link PTY
--trace FILE --settings FILE`, Grbl 1.1h, with `$20=0` stored in its EEPROM beforehand: soft
limits off, as in bench/scenarios.py) and, on the CNCjs link, its own CNCjs 1.11.5 (tools/cncjs)
that opens the pty. smoothjog's shipped Host, built as `smoothjog jog` builds it (the default
configuration's tuning and timeouts, the link from cli/common.py's link_for), then plays the
scenario in real time over

* direct: SerialLink straight to the simulator's pty (as `smoothjog jog --port PTY`), or
* CNCjs: CncjsLink through the CNCjs that has the pty open (as `smoothjog jog --cncjs URL
  --cncjs-port PTY`).

When the run is over the simulator is stopped and writes its ground truth, every motion segment
on the monotonic clock the host's event loop runs on; each run is measured on it with
bench/measure.py exactly as bench/scenarios.py defines the metric, from the moments (release,
reversal, death) the bench took on the same clock. S4 through CNCjs has two runs: smoothjog dies
(Host.abandon(): it stops sending and reading, CNCjs keeps the port) and CNCjs dies (SIGKILL of
the CNCjs process; smoothjog keeps running but can no longer reach the machine). Both leave the
controller running out what was queued.

For each release phase and scenario the direct run and the CNCjs runs go back to back (the
direct run first in phases 1, 3, ..., last in 2, 4, ...), and the CNCjs / direct ratio is taken
per phase, so what disturbs both alike cancels: on a shared machine the ratios are the figure to
compare, the absolute numbers carry its noise.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import dataclasses
import functools
import logging
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
from collections.abc import Awaitable, Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from bench import cncjs_rig, measure
from bench import scenarios as sc
from bench.cncjs_rig import CncjsServer, RigError, SimProcess, write_report
from bench.cpu import _sigterm_as_interrupt
from bench.links import cli_tuning, code_version
from smoothjog.cli.common import link_for
from smoothjog.config import Config
from smoothjog.core.engine import Jogger
from smoothjog.core.errors import SmoothjogError
from smoothjog.core.intents import ContinuousIntent
from smoothjog.host import Host
from smoothjog.links.base import Link
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.motion import TraceSegment
from smoothjog.sim.profiles import get_firmware_profile
from smoothjog.sim.rig import SimRig
from smoothjog.sim.serve import read_trace

MACHINE = cncjs_rig.MACHINE
FIRMWARE = "grbl"
SCENARIOS = ("S1", "S2", "S3", "S4", "S5")
DIRECT = "direct"
CNCJS = "CNCjs"
#: How the client dies in S4: smoothjog (Host.abandon()) or, through CNCjs, CNCjs itself.
SMOOTHJOG_DIES = "smoothjog dies"
CNCJS_DIES = "CNCjs dies"
#: From the end of the handshake to the press (bench/scenarios.py waits 50 ms of virtual time;
#: here CNCjs's own start-up chatter, its `$$` and first polls, gets time to pass).
LEAD_S = 0.3
#: After the client died, how long the controller is left to run out its queue before the
#: simulator is stopped (smoothjog queues well under 1 s of motion; a run still moving then fails).
S4_RUN_OUT_S = 3.0
#: After the machine came to rest, before the simulator is stopped (scenarios.py waits 0.5 s).
SETTLE_S = 0.5
IDLE_TIMEOUT_S = 30.0
#: The last motion must have ended this long before the simulator was told to stop, or the
#: trace may miss a segment still under way.
REST_MARGIN_S = 0.1


#: The simulator's last line: what went wrong on its wire (serve.py's summary).
SIM_SUMMARY = re.compile(
    r"stopped on \w+ \((RX bytes dropped \d+; errors sent: .*?; G-code motion blocks \d+)\)"
)
CLEAN_WIRE = "RX bytes dropped 0; errors sent: none; G-code motion blocks 0"


class BenchError(Exception):
    """A run did not give a measurement; the message says why."""


@dataclass(frozen=True)
class Case:
    """One kind of run: a scenario on a link (and for S4, who dies)."""

    scenario: str
    link: str
    dies: str = ""

    @property
    def label(self) -> str:
        """The case in words, for progress lines."""
        return f"{self.scenario} {self.link}" + (f" ({self.dies})" if self.dies else "")


def cases_of(scenario: str) -> list[Case]:
    """The runs of one scenario: direct and CNCjs, and S4 through CNCjs with either dying."""
    if scenario == "S4":
        return [
            Case("S4", DIRECT, SMOOTHJOG_DIES),
            Case("S4", CNCJS, SMOOTHJOG_DIES),
            Case("S4", CNCJS, CNCJS_DIES),
        ]
    return [Case(scenario, DIRECT), Case(scenario, CNCJS)]


def order_of(cases: list[Case], phase: int) -> list[Case]:
    """Phase 0, 2, ...: the direct run first; phase 1, 3, ...: last."""
    direct = [c for c in cases if c.link == DIRECT]
    through = [c for c in cases if c.link != DIRECT]
    return direct + through if phase % 2 == 0 else through + direct


def phase_offsets_s(phases: int) -> list[float]:
    """The middle of each 1/phases of the engine's send cycle, added to every hold (as jog.py)."""
    cycle = cli_tuning().dt_floor_s
    return [cycle * (k + 0.5) / phases for k in range(phases)]


# --- the processes of one run -------------------------------------------------------------------


@functools.cache
def soft_limits_off_eeprom(machine: str = MACHINE, firmware: str = FIRMWARE) -> str:
    """The simulator's EEPROM (a `--settings` file) after `$20=0`, stored by the firmware itself."""
    fw = GrblFirmware(get_firmware_profile(firmware), machine)
    rig = SimRig(fw)
    rig.host_send(b"$20=0\n", 0.0)
    replies = [line for _t, line in rig.run_until(1.0) if line == b"ok" or b"error" in line]
    if replies != [b"ok"] or fw.settings[20] != 0:
        raise BenchError(f"the simulator did not take $20=0 (it answered {replies!r})")
    return fw.eeprom().to_json()


class Run:
    """One run's processes: the simulator (and CNCjs) in a scratch folder, and the host's link."""

    def __init__(self, case: Case, root: Path, number: int) -> None:
        """Prepare the scratch folder and the simulator's settings file; start() runs them."""
        self.case = case
        self.dir = root / f"run{number:02d}"
        self.dir.mkdir(parents=True)
        settings = self.dir / "eeprom.json"
        settings.write_text(soft_limits_off_eeprom(), encoding="utf-8")
        self.trace_path = self.dir / "trace.jsonl"
        self.sim = SimProcess(self.dir, MACHINE, trace=self.trace_path, settings=settings)
        self.server = CncjsServer(self.dir, str(self.sim.link)) if case.link == CNCJS else None
        self.stop_asked_s = math.inf

    def start(self) -> None:
        """Start the simulator (and CNCjs) and wait for both."""
        cncjs_rig.start_side_by_side(self.sim, self.server)

    def link(self) -> Link:
        """The host's link, built as the CLI builds it from a [connection]."""
        base = Config().connection
        if self.server is None:
            connection = dataclasses.replace(base, port=str(self.sim.link))
        else:
            connection = dataclasses.replace(
                base,
                cncjs=self.server.url,
                cncjs_port=str(self.sim.link),
                cncjs_config=str(self.server.config_path),
            )
        link = link_for(connection)
        assert link is not None
        return link

    async def kill_cncjs(self) -> None:
        """SIGKILL CNCjs, as when it dies mid-jog (reaped when the run stops, not now: the
        host's loop must not wait for it)."""
        assert self.server is not None
        assert self.server.proc is not None
        cncjs_rig.signal_group(self.server.proc, signal.SIGKILL)

    def finish(self) -> tuple[list[TraceSegment], str]:
        """Stop CNCjs and the simulator; its trace of the whole run and its wire summary."""
        self.close()
        found = SIM_SUMMARY.search(self.sim.log_path.read_text(encoding="utf-8", errors="replace"))
        if found is None:
            raise BenchError(
                f"the simulator did not say how it stopped; its log:\n"
                f"{cncjs_rig.log_tail(self.sim.log_path)}"
            )
        if not self.trace_path.exists():
            raise BenchError(
                f"the simulator wrote no trace to {self.trace_path} when stopped; its log:\n"
                f"{cncjs_rig.log_tail(self.sim.log_path)}"
            )
        trace = read_trace(self.trace_path)
        end = measure.last_motion_end(trace)
        if end > self.stop_asked_s - REST_MARGIN_S:
            raise BenchError(
                f"{self.case.label}: the machine still moved {end - self.stop_asked_s:+.3f} s from"
                " when the simulator was stopped: the trace may miss the end of the motion"
            )
        return trace, found.group(1)

    def close(self) -> None:
        """Stop whatever still runs (harmless twice)."""
        if self.server is not None:
            self.server.stop()
        if self.sim.proc is not None:
            self.stop_asked_s = time.monotonic()
        self.sim.stop()


# --- the scenarios in real time -----------------------------------------------------------------

#: The moments a scenario took (host clock), and its figures once measured on the trace.
Marks = dict[str, float]


def _stick(speed: float, x: float = sc.DIRECTION) -> ContinuousIntent:
    return ContinuousIntent({"X": x}, speed)


async def _until(host: Host, t_s: float) -> None:
    """Sleep until the host's clock reads t_s."""
    await asyncio.sleep(max(0.0, t_s - host.now_s()))


async def _stop(host: Host, speed: float = 1.0) -> None:
    """Release the stick, wait for rest, then a little more (as scenarios.py)."""
    host.set_intent(_stick(speed, 0.0))
    await host.wait_idle(IDLE_TIMEOUT_S)
    await asyncio.sleep(SETTLE_S)


async def _held(host: Host, ph: sc.Physics, phase_s: float, speed: float = 1.0) -> float:
    """Press toward -X and hold up to the event (hold + phase); the event's time."""
    host.set_intent(_stick(speed))
    await _until(host, host.now_s() + sc._hold_s(ph) + phase_s)
    return host.now_s()


async def drive_release(host: Host, ph: sc.Physics, phase_s: float, speed: float) -> Marks:
    """S1/S5: hold, release; the release's time."""
    t_rel = await _held(host, ph, phase_s, speed)
    await _stop(host, speed)
    return {"t_rel": t_rel}


async def drive_hold(host: Host, ph: sc.Physics, phase_s: float) -> Marks:
    """S2: a 6 s hold at full speed; its measuring window."""
    host.set_intent(_stick(1.0))
    t0 = host.now_s()
    t_end = t0 + max(6.0, 2 * ph.stop_s + 3.0) + phase_s
    await _until(host, t_end)
    # The window ends at the release (a timer may fire a hair early).
    t_end = min(t_end, host.now_s())
    await _stop(host)
    return {"window0": t0 + 1.5 * ph.stop_s + 0.2, "t_end": t_end}


async def drive_reversal(host: Host, ph: sc.Physics, phase_s: float) -> Marks:
    """S3: full speed one way, then through neutral the other way in one instant."""
    t_rev = await _held(host, ph, phase_s)
    host.set_intent(_stick(1.0, 0.0))
    host.set_intent(_stick(1.0, -sc.DIRECTION))
    t_end = t_rev + 4 * ph.stop_s + 2.0
    await _until(host, t_end + 0.1)
    await _stop(host)
    return {"t_rev": t_rev, "t_end": t_end}


async def drive_death(
    host: Host, ph: sc.Physics, phase_s: float, die: Callable[[], Awaitable[None]]
) -> Marks:
    """S4: hold, then the client dies (die()); the controller runs out its queue."""
    await _held(host, ph, phase_s)
    t_kill = host.now_s()
    # What the engine had sent ahead of the machine's last reported position, as it saw it.
    queued_mm = host.view().queued_mm
    await die()
    await asyncio.sleep(S4_RUN_OUT_S)
    return {"t_kill": t_kill, "queued_mm": queued_mm}


async def smoothjog_dies(host: Host) -> None:
    """Host.abandon(), then the link's socket or port closes, as when the process dies: lines
    still in the link's own queue are lost, what reached CNCjs or the port runs on."""
    host.abandon()
    await host.link.close()


def measure_run(scenario: str, trace: Sequence[TraceSegment], marks: Marks) -> dict[str, float]:
    """The scenario's figures from the ground truth, as bench/scenarios.py takes them."""
    ph = sc.physics(MACHINE)
    if scenario in ("S1", "S5"):
        t_rel = marks["t_rel"]
        return {
            "dist_mm": measure.distance_after(trace, t_rel),
            "time_s": max(measure.last_motion_end(trace) - t_rel, 0.0),
            "restarts": float(measure.restarts_after(trace, t_rel)),
        }
    if scenario == "S2":
        w0, t_end = marks["window0"], marks["t_end"]
        share, dips = measure.hold_quality(trace, w0, t_end, ph.speed_mm_s)
        mean = measure.mean_speed(trace, w0, t_end) / ph.speed_mm_s
        return {"within_2pct": share, "dips": float(dips), "mean_of_v": mean}
    if scenario == "S3":
        t_rev = marks["t_rev"]
        took = measure.time_to_velocity(
            trace, t_rev, marks["t_end"], 0, -sc.DIRECTION * ph.speed_mm_s
        )
        return {"time_s": took if took is not None else math.inf}
    t_kill = marks["t_kill"]
    return {
        "dist_mm": measure.distance_after(trace, t_kill),
        "time_s": max(measure.last_motion_end(trace) - t_kill, 0.0),
        "queued_mm": marks["queued_mm"],
    }


async def play(run: Run, phase_s: float) -> Marks:
    """Connect smoothjog's Host as the CLI does and drive the case's scenario."""
    case = run.case
    ph = sc.physics(MACHINE)
    config = Config()
    link = run.link()
    await link.open()
    host = Host(
        link,
        tuning=cli_tuning(),
        keepouts=config.keepouts,
        handshake_timeout_s=config.connection.timeout_s,
    )
    try:
        await host.start()
        if not isinstance(host.driver, Jogger):
            raise BenchError("the host drives no smoothjog engine")
        await asyncio.sleep(LEAD_S)
        drive: Awaitable[Marks]
        if case.scenario == "S1":
            drive = drive_release(host, ph, phase_s, 1.0)
        elif case.scenario == "S5":
            drive = drive_release(host, ph, phase_s, 0.1)
        elif case.scenario == "S2":
            drive = drive_hold(host, ph, phase_s)
        elif case.scenario == "S3":
            drive = drive_reversal(host, ph, phase_s)
        else:
            drive = drive_death(
                host,
                ph,
                phase_s,
                run.kill_cncjs
                if case.dies == CNCJS_DIES
                else functools.partial(smoothjog_dies, host),
            )
        marks = await drive
        if host.error is not None:
            raise BenchError(f"{case.label}: the host failed: {host.error}")
        if host.link_error is not None and case.dies != CNCJS_DIES:
            raise BenchError(f"{case.label}: the link was lost: {host.link_error}")
        return marks
    finally:
        await host.close()


# --- the whole benchmark ------------------------------------------------------------------------


@dataclass(frozen=True)
class Measured:
    """One run's figures."""

    case: Case
    phase: int
    metrics: dict[str, float]
    wall_s: float
    #: The simulator's summary of its wire (CLEAN_WIRE when nothing went wrong).
    wire: str = CLEAN_WIRE


def run_one(case: Case, phase: int, phase_s: float, root: Path, number: int) -> Measured:
    """Start the processes, play the scenario, stop them and measure the trace."""
    started = time.monotonic()
    run = Run(case, root, number)
    try:
        run.start()
        marks = asyncio.run(play(run, phase_s))
        trace, wire = run.finish()
    except TimeoutError:
        raise BenchError(
            f"phase {phase + 1} {case.label}: the machine did not come to rest within"
            f" {IDLE_TIMEOUT_S:g} s (logs in {run.dir})"
        ) from None
    finally:
        run.close()
    metrics = measure_run(case.scenario, trace, marks)
    return Measured(case, phase, metrics, time.monotonic() - started, wire)


def progress(m: Measured, phases: int) -> str:
    """One line on stderr per run."""
    r = m.metrics
    if m.case.scenario in ("S1", "S4", "S5"):
        figure = f"{r['dist_mm']:.3f} mm, {1000 * r['time_s']:.0f} ms"
    elif m.case.scenario == "S2":
        figure = f"{100 * r['within_2pct']:.1f} % within 2 %, {int(r['dips'])} dips"
    else:
        figure = _num(r["time_s"], 3, " s")
    wire = "" if m.wire == CLEAN_WIRE else f"; simulator: {m.wire}"
    return f"phase {m.phase + 1}/{phases} {m.case.label}: {figure} (run {m.wall_s:.1f} s){wire}"


def run_all(
    scenarios: Sequence[str], phases: int, root: Path, log: Callable[[str], None]
) -> list[Measured]:
    """Every case of every scenario, phase by phase, the direct and CNCjs runs back to back."""
    results: list[Measured] = []
    offsets = phase_offsets_s(phases)
    for k in range(phases):
        for scenario in scenarios:
            for case in order_of(cases_of(scenario), k):
                m = run_one(case, k, offsets[k], root, len(results))
                results.append(m)
                log(progress(m, phases))
    return results


#: Each scenario's headline figure, for the CNCjs / direct ratio.
HEADLINE = {
    "S1": ("dist_mm", "S1 distance after the release"),
    "S2": ("within_2pct", "S2 share within 2 % of v"),
    "S3": ("time_s", "S3 time to full speed the other way"),
    "S4": ("dist_mm", "S4 distance after the death"),
    "S5": ("dist_mm", "S5 distance after the release"),
}


def _num(value: float, digits: int, unit: str = "") -> str:
    return "never" if math.isinf(value) else f"{value:.{digits}f}{unit}"


def _spread(
    values: Sequence[float], digits: int, scale: float = 1.0, unit: str = "", note: str = ""
) -> str:
    """Median and range, `9.37 mm (9.02-9.72)`, with a note in the same brackets if given.

    The range is left out when it shows as one number (a single run, or all runs alike).
    """
    med = statistics.median(values) * scale
    lo, hi = _num(min(values) * scale, digits), _num(max(values) * scale, digits)
    inside = [f"{lo}-{hi}"] if lo != hi else []
    inside += [note] if note else []
    return _num(med, digits, unit) + (f" ({'; '.join(inside)})" if inside else "")


def cell(scenario: str, runs: Sequence[Measured], ph: sc.Physics) -> str:
    """One table cell: the medians over the phases with their ranges."""
    if not runs:
        return "-"

    def values(key: str) -> list[float]:
        return [m.metrics[key] for m in runs]

    def median(key: str) -> float:
        return statistics.median(values(key))

    if scenario in ("S1", "S4"):
        stop = f"{median('dist_mm') / ph.stop_mm:.2f}x v²/2a"
        text = (
            f"{_spread(values('dist_mm'), 2, unit=' mm', note=stop)} /"
            f" {_spread(values('time_s'), 3, unit=' s')}"
        )
        if scenario == "S4":
            text += f"; queued {_spread(values('queued_mm'), 2, unit=' mm')}"
    elif scenario == "S5":
        text = (
            f"{_spread(values('dist_mm'), 3, unit=' mm')} /"
            f" {_spread(values('time_s'), 0, 1000.0, ' ms')}"
        )
    elif scenario == "S2":
        return (
            f"{_spread(values('within_2pct'), 1, 100.0, ' %')} /"
            f" {_spread(values('dips'), 0, unit=' dips')}"
            f" (mean {_spread(values('mean_of_v'), 1, 100.0, ' %')} of v)"
        )
    else:
        twice = f"{_num(median('time_s') / (2 * ph.stop_s), 2)}x 2v/a"
        return _spread(values("time_s"), 3, unit=" s", note=twice)
    if scenario != "S4" and any(m.metrics["restarts"] for m in runs):
        text += f", restarts {'/'.join(str(int(m.metrics['restarts'])) for m in runs)}"
    return text


#: The table's rows: a label and which runs fill it (S4 through CNCjs: one row per death).
ROWS = (
    ("direct: SerialLink to the pty", DIRECT, SMOOTHJOG_DIES),
    ("through CNCjs: CncjsLink (S4: smoothjog dies)", CNCJS, SMOOTHJOG_DIES),
    ("through CNCjs, S4: CNCjs dies (SIGKILL)", CNCJS, CNCJS_DIES),
)
COLUMNS = {
    "S1": "S1 release at full speed: distance (x v²/2a) / time",
    "S2": "S2 6 s hold: within 2 % / dips (mean speed)",
    "S3": "S3 reversal: time to full speed the other way",
    "S4": "S4 client dies: distance (x v²/2a) / time; the engine's queue at the death",
    "S5": "S5 10 % release: distance / time",
}


def _runs_of(results: Sequence[Measured], scenario: str, link: str, dies: str) -> list[Measured]:
    return [
        m
        for m in results
        if m.case.scenario == scenario
        and m.case.link == link
        and (scenario != "S4" or m.case.dies == dies)
    ]


def table(results: Sequence[Measured], scenarios: Sequence[str]) -> list[str]:
    """Markdown: one row per link (S4 through CNCjs in two), one column per scenario."""
    ph = sc.physics(MACHINE)
    out = [
        "| link | " + " | ".join(COLUMNS[s] for s in scenarios) + " |",
        "|---|" + "---|" * len(scenarios),
    ]
    for full, link, dies in ROWS:
        if "S4" not in scenarios and dies == CNCJS_DIES:
            continue
        label = full if "S4" in scenarios else full.split(" (S4:")[0]
        cells = []
        for s in scenarios:
            runs = _runs_of(results, s, link, dies)
            only_s4 = dies == CNCJS_DIES and s != "S4"
            cells.append("-" if only_s4 else cell(s, runs, ph))
        out.append(f"| {label} | " + " | ".join(cells) + " |")
    return out


def ratios(results: Sequence[Measured], scenario: str, dies: str) -> list[float]:
    """CNCjs / direct of the scenario's headline figure, per phase (both runs of that phase)."""
    key = HEADLINE[scenario][0]
    direct = {m.phase: m.metrics[key] for m in _runs_of(results, scenario, DIRECT, SMOOTHJOG_DIES)}
    out = []
    for m in _runs_of(results, scenario, CNCJS, dies):
        base = direct.get(m.phase)
        if base is None or base == 0 or math.isinf(base):
            continue
        out.append(m.metrics[key] / base)
    return out


def ratio_table(results: Sequence[Measured], scenarios: Sequence[str]) -> list[str]:
    """Markdown: CNCjs / direct per scenario, median and range over the phases."""
    out = [
        "| ratio, per phase | " + " | ".join(HEADLINE[s][1] for s in scenarios) + " |",
        "|---|" + "---|" * len(scenarios),
    ]
    for full, dies in (
        ("CNCjs / direct (S4: smoothjog dies)", SMOOTHJOG_DIES),
        ("CNCjs dies / direct (S4 only)", CNCJS_DIES),
    ):
        if "S4" not in scenarios and dies == CNCJS_DIES:
            continue
        label = full if "S4" in scenarios else full.split(" (S4:")[0]
        cells = []
        for s in scenarios:
            if dies == CNCJS_DIES and s != "S4":
                cells.append("-")
                continue
            rs = ratios(results, s, dies)
            cells.append(_spread(rs, 2) if rs else "n/a")
        out.append(f"| {label} | " + " | ".join(cells) + " |")
    return out


def _node_version() -> str:
    node = shutil.which("node")
    if node is None:
        return "node not found"
    try:
        done = subprocess.run([node, "--version"], capture_output=True, text=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        return "node (version unknown)"
    return f"node {done.stdout.strip()}"


def report(
    argv: Sequence[str],
    args: argparse.Namespace,
    results: Sequence[Measured],
    load: tuple[tuple[float, ...], tuple[float, ...]],
    wall_s: float,
) -> list[str]:
    """The whole Markdown report."""
    ph = sc.physics(MACHINE)
    tuning = cli_tuning()
    fw = GrblFirmware(get_firmware_profile(FIRMWARE), MACHINE)
    scenarios = args.scenarios
    runs = len(results)
    dirty = [m for m in results if m.wire != CLEAN_WIRE]
    wire = (
        f"every run ended with {CLEAN_WIRE}"
        if not dirty
        else "; ".join(f"phase {m.phase + 1} {m.case.label}: {m.wire}" for m in dirty)
        + f"; every other run: {CLEAN_WIRE}"
    )
    plural = "s" if args.phases != 1 else ""
    return [
        "# The jog scenarios through a real CNCjs, beside the direct link",
        "",
        f"Command: `{shlex.join(['python', '-m', 'bench', 'cncjs', *argv])}`",
        "",
        f"- Machine: {MACHINE}, v = {ph.speed_mm_s:.1f} mm/s and a = {ph.accel_mm_s2:g} mm/s²"
        f" along X, v²/2a = {ph.stop_mm:.2f} mm, v/a = {1000 * ph.stop_s:.0f} ms; the stick"
        " toward -X from the homed + corner, as bench/scenarios.py",
        f"- Firmware: the simulator's {fw.profile.banner.split(' [')[0]} as its own process,"
        " `python -m smoothjog sim --machine hobby-router --link PTY --trace FILE --settings"
        " FILE`, with `$20=0` stored in its EEPROM before the run (soft limits off, as in"
        " bench/scenarios.py); a fresh simulator (and CNCjs) for every run",
        "- Links: direct = SerialLink on the simulator's pty at 115200 baud (as `smoothjog jog"
        f" --port PTY`); CNCjs = CncjsLink through CNCjs {cncjs_rig.cncjs_version()}"
        f" ({_node_version()}) on 127.0.0.1, which opened the pty at 115200 baud as Grbl (as"
        " `smoothjog jog --cncjs URL --cncjs-port PTY`)",
        "- Host: smoothjog's Host, built as `smoothjog jog` builds it from the default"
        f" configuration (JogTuning with link margin {1000 * tuning.link_margin_s:g} ms, the"
        " byte time from the link); S4: smoothjog dies = Host.abandon() and its link closed at"
        " once, as a process's socket and port close when it dies (nothing more sent or read;"
        " lines still in the link's own queue are lost; CNCjs keeps the port and writes what"
        " it already has), CNCjs dies = SIGKILL of the CNCjs process; then"
        f' {S4_RUN_OUT_S:g} s to run out the queue; "queued" is the distance the engine had'
        " sent ahead of the machine's last reported position at the death, as it saw it",
        f"- Code: {code_version()}",
        "- Ground truth: every motion segment the simulator executed (`--trace`, on the"
        " monotonic clock the host runs on), measured with bench/measure.py as"
        " bench/scenarios.py defines each figure",
        f"- Runs: {args.phases} release phase{plural} per scenario (every hold lengthened by"
        " the middle of each 1/N of the engine's send cycle); per phase and scenario the"
        " direct run and the CNCjs runs back to back, the direct run first in phases 1, 3,"
        f" ... and last in 2, 4, ...; {runs} runs, {wall_s:.0f} s in all",
        "- Figures: medians over the phases, lowest-highest in brackets; the ratios are"
        " CNCjs / direct per phase, from the two runs of that phase",
        f"- The simulator's own summary of its wire (as it prints when stopped): {wire}",
        f"- Machine: {platform.node()}, {os.cpu_count()} CPUs, Python"
        f" {platform.python_version()}, load average {load[0][0]:.2f} before,"
        f" {load[1][0]:.2f} after (real time on a shared 2-core VM: compare ratios, mind the"
        " ranges)",
        "",
        *table(results, scenarios),
        "",
        *ratio_table(results, scenarios),
        "",
    ]


def _scenarios(text: str) -> list[str]:
    """argparse type: a comma list of S1..S5."""
    names = [n.strip().upper() for n in text.split(",") if n.strip()]
    bad = [n for n in names if n not in SCENARIOS]
    if not names or bad:
        raise argparse.ArgumentTypeError(
            f"{text!r}: name scenarios from {', '.join(SCENARIOS)}, e.g. S1,S4"
        )
    return [s for s in SCENARIOS if s in names]


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m bench cncjs",
        description="S1-S5 in real time through a real CNCjs and straight to the simulator's"
        " pty, measured on the simulator's ground truth.",
    )
    parser.add_argument("--phases", type=int, default=3, help="release phases (default 3)")
    parser.add_argument(
        "--scenarios",
        type=_scenarios,
        default=list(SCENARIOS),
        help="which of S1,S2,S3,S4,S5 (default all)",
    )
    parser.add_argument("--out", default="bench/results", help="folder for cncjs.md")
    parser.add_argument("--keep", action="store_true", help="keep the runs' logs and traces")
    return parser


@contextlib.contextmanager
def _scratch(keep: bool) -> Iterator[Path]:
    """A scratch folder for the runs, removed afterwards unless keep (then its path is told)."""
    path = Path(tempfile.mkdtemp(prefix="smoothjog-bench-cncjs-"))
    try:
        yield path
    finally:
        if keep:
            print(f"python -m bench cncjs: logs and traces kept in {path}", file=sys.stderr)
        else:
            shutil.rmtree(path, ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; 0 when every run was measured, 1 with a sentence when one was not."""
    argv = list(sys.argv[2:] if argv is None else argv)
    args = _parser().parse_args(argv)
    if args.phases < 1:
        print("python -m bench cncjs: --phases must be 1 or more", file=sys.stderr)
        return 2
    # The host logs the lost link of "CNCjs dies" as an error: expected here, not news.
    logging.getLogger("smoothjog").setLevel(logging.CRITICAL)
    load_before = os.getloadavg()
    started = time.monotonic()
    try:
        with _sigterm_as_interrupt(), _scratch(args.keep) as root:
            results = run_all(
                args.scenarios,
                args.phases,
                root,
                lambda line: print(line, file=sys.stderr, flush=True),
            )
    except (BenchError, RigError, SmoothjogError) as exc:
        print(f"python -m bench cncjs: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("python -m bench cncjs: interrupted; simulator and CNCjs stopped", file=sys.stderr)
        return 130
    load = (load_before, os.getloadavg())
    text = report(argv, args, results, load, time.monotonic() - started)
    write_report(args.out, "cncjs.md", text)
    return 0
