"""The lead sweep: what a shorter queue would buy (S1, S4) and cost (S2 dips), link by link.

`python -m bench lead [--links wifi-bridge,ch340] [--cut-ms 0,5,10,15,20] [--phases 5]`

The engine queues the stopping distance v²/2a plus a lead: the committed step segments, the
time a new line needs to reach the planner over the link, how late the host wakes, and the
configured link margin. This runs the shipped engine with that margin lowered by each cut (a
negative `link_margin_s`, which no configuration allows) and measures, on the simulator in
virtual time at the same release phases as the links table:

- S1, the release at full speed, as a multiple of one long jog + 0x85 on the same link;
- S2, a 6 s hold at full speed: share within 2 % of v and dips;
- S4, a client that dies mid-jog, as a multiple of v²/2a.

A cut that lowers S1 or S4 and leaves S2 at 100 % / 0 dips is lead the engine did not need; a
cut that brings dips is lead the link needs. A figure from a cut is an experiment, not what
smoothjog ships.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import time
from dataclasses import dataclass

from bench import links
from bench import scenarios as sc
from bench.hosts import REFERENCE_FACTORIES, Shipped
from smoothjog.core.engine import JogTuning
from smoothjog.sim.rig import LINK_MODELS

#: The links whose targets the engine misses by the least: the bridge's S1 and CH340's S4.
DEFAULT_LINKS = ("wifi-bridge", "ch340")
DEFAULT_CUTS_MS = (0.0, 5.0, 10.0, 15.0, 20.0)


@dataclass(frozen=True)
class Point:
    """The medians over the phases of one link at one cut of the lead."""

    link: str
    cut_ms: float
    s1_mm: float
    long_s1_mm: float
    s2_within: float
    s2_dips: float
    s4_mm: float


def _median(values: list[float]) -> float:
    return statistics.median(values)


def sweep(names: list[str], cuts_ms: list[float], phases: int) -> list[Point]:
    """Run S1, S2 and S4 per link and cut (and the long jog's S1 once per link)."""
    base_tuning = links.cli_tuning()
    long_factory = REFERENCE_FACTORIES[links.LONG_JOG]
    machine, firmware = links.LINK_MACHINE, "grbl"
    points: list[Point] = []
    for name in names:
        base = LINK_MODELS[name]
        long_cycle = links.cycle_on_link_s(long_factory, base)
        long_s1 = _median(
            [
                sc.release(
                    long_factory,
                    machine,
                    firmware,
                    long_cycle * (k + 0.5) / phases,
                    1.0,
                    link=links.phase_link(base, k),
                ).metrics["dist_mm"]
                for k in range(phases)
            ]
        )
        for cut_ms in cuts_ms:
            tuning = dataclasses.replace(
                base_tuning, link_margin_s=base_tuning.link_margin_s - cut_ms / 1000.0
            )
            method = Shipped(tuning)
            cycle = links.cycle_on_link_s(method, base)
            s1, within, dips, s4 = [], [], [], []
            for k in range(phases):
                off = cycle * (k + 0.5) / phases
                link = links.phase_link(base, k)
                s1.append(
                    sc.release(method, machine, firmware, off, 1.0, link=link).metrics["dist_mm"]
                )
                held = sc.hold(method, machine, firmware, off, link=link).metrics
                within.append(held["within_2pct"])
                dips.append(held["dips"])
                s4.append(
                    sc.client_dies(method, machine, firmware, off, link=link).metrics["dist_mm"]
                )
            points.append(
                Point(
                    name,
                    cut_ms,
                    _median(s1),
                    long_s1,
                    _median(within),
                    _median(dips),
                    _median(s4),
                )
            )
            print(f"  {name}, lead cut by {cut_ms:g} ms: done", flush=True)
    return points


def table(points: list[Point], stop_mm: float) -> list[str]:
    """Markdown: one row per link and cut."""
    out = [
        "| link | lead cut | S1 release (x one long jog) | S2 6 s hold: within 2 % / dips"
        " | S4 client dies (x v²/2a) |",
        "|---|---|---|---|---|",
    ]
    for p in points:
        out.append(
            f"| {p.link} | {p.cut_ms:g} ms | {p.s1_mm:.2f} mm ({p.s1_mm / p.long_s1_mm:.3f})"
            f" | {100 * p.s2_within:.1f} % / {p.s2_dips:g} | {p.s4_mm:.2f} mm"
            f" ({p.s4_mm / stop_mm:.3f}x) |"
        )
    return out


def _cuts(text: str) -> list[float]:
    try:
        cuts = [float(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--cut-ms takes numbers in ms, like 0,5,10: {text!r}"
        ) from None
    if not cuts or any(c < 0 for c in cuts):
        raise argparse.ArgumentTypeError(
            f"--cut-ms takes one or more cuts of 0 ms or more: {text!r}"
        )
    return cuts


def _phases(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"--phases takes a whole number of 1 or more: {text!r}")
    return n


def main(argv: list[str] | None = None) -> int:
    """Print the sweep's table for the links asked."""
    parser = argparse.ArgumentParser(
        prog="python -m bench lead", description=__doc__.split("\n")[0]
    )
    parser.add_argument(
        "--links",
        default=",".join(DEFAULT_LINKS),
        help="comma-separated link models, or 'all' (default: %(default)s)",
    )
    parser.add_argument(
        "--cut-ms",
        type=_cuts,
        default=list(DEFAULT_CUTS_MS),
        help="how much to take off the engine's lead, in ms (default: 0,5,10,15,20)",
    )
    parser.add_argument(
        "--phases", type=_phases, default=5, help="release phases per figure (default: 5)"
    )
    args = parser.parse_args(argv)
    names = links.parse_names(args.links)
    if not names:
        print("python -m bench lead: no link to run", file=sys.stderr)
        return 2
    started = time.monotonic()
    ph = sc.physics(links.LINK_MACHINE)
    points = sweep(names, args.cut_ms, args.phases)
    print()
    print(
        f"{links.LINK_MACHINE}, Grbl 1.1h profile, simulated in virtual time; CLI defaults"
        f" ({JogTuning.__name__} link margin {1000 * links.cli_tuning().link_margin_s:g} ms)"
        f" less each cut; medians over {args.phases} release phases;"
        f" v²/2a = {ph.stop_mm:.2f} mm"
    )
    print()
    print("\n".join(table(points, ph.stop_mm)))
    print()
    print(f"Wall time: {time.monotonic() - started:.1f} s")
    return 0
