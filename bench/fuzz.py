"""Randomised press/release/reverse/speed-change/step sequences with safety checks on ground truth.

For every sequence: no ghost jog (no motion after a completed stop until the next intent), no
error:15, the soft-limit envelope and the keep-out zones never crossed by the real machine, `$G`
unchanged from start to end, and tracked-minus-real within one step at every stop. Sequences run
back to back on one simulated machine per firmware profile, from a seeded generator.
"""

from __future__ import annotations

import argparse
import logging
import random
import time
from dataclasses import dataclass, field

from smoothjog.core.errors import SmoothjogError
from smoothjog.core.intents import ContinuousIntent, Intent, StepIntent, StopIntent
from smoothjog.core.jogger import EngineEvent
from smoothjog.core.machine import KeepOut
from smoothjog.core.responses import GcodeModes
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import get_firmware_profile
from smoothjog.sim.rig import LinkModel, SimRig
from smoothjog.virtual import VirtualHost

#: A vise near the middle of the hobby router's table, in machine coordinates.
VISE = KeepOut("vise", (-420.0, -420.0, -100.0), (-380.0, -380.0, 0.0))
#: Real positions may sit this far beyond a boundary (float printing of MPos): well under a step.
TOLERANCE_MM = 1e-6


@dataclass
class FuzzReport:
    """Counts over all sequences of one firmware profile."""

    firmware: str
    sequences: int = 0
    stops: int = 0
    ghost_jogs: int = 0
    soft_limit_errors: int = 0
    envelope_crossings: int = 0
    keepout_entries: int = 0
    gcode_state_changed: bool = False
    worst_tracking_steps: float = 0.0
    #: Faults claiming something outside smoothjog stopped or moved the machine: nothing does in
    #: these runs, so each one is a false alarm of the engine.
    false_outside_alarms: int = 0
    faults: list[str] = field(default_factory=list)

    @property
    def clean(self) -> bool:
        """True when every safety check held."""
        return (
            self.ghost_jogs == 0
            and self.soft_limit_errors == 0
            and self.envelope_crossings == 0
            and self.keepout_entries == 0
            and not self.gcode_state_changed
            and self.worst_tracking_steps <= 1.0 + 1e-9
            and self.false_outside_alarms == 0
        )


def _random_intent(rng: random.Random) -> Intent:
    kind = rng.random()
    if kind < 0.12:
        axis = rng.choice("XYZ")
        return StepIntent(axis, rng.choice([-1, 1]) * rng.choice([0.01, 0.1, 1.0, 10.0]), 0.5)
    if kind < 0.2:
        return StopIntent()
    axes = {}
    for axis in rng.sample("XYZ", rng.choice([1, 1, 2, 3])):
        axes[axis] = rng.choice([-1.0, -0.5, -0.1, 0.3, 0.7, 1.0])
    return ContinuousIntent(axes, rng.choice([0.1, 0.3, 0.6, 1.0]))


def _gcode_words(vs: VirtualHost) -> tuple[str, ...]:
    for resp in vs.query_line("$G"):
        if isinstance(resp, GcodeModes):
            return resp.words
    return ()


def run_fuzz(firmware: str, sequences: int, seed: int = 1) -> FuzzReport:
    """Run `sequences` random sequences on one firmware profile and count every violation."""
    rng = random.Random(seed)
    fw = GrblFirmware(get_firmware_profile(firmware), "hobby-router")
    events: list[EngineEvent] = []
    vs = VirtualHost(SimRig(fw, LinkModel()), keepouts=(VISE,), on_event=events.append)
    model = vs.handshake()
    engine = vs.engine
    assert engine is not None
    report = FuzzReport(firmware)
    env = engine.limits.envelope
    gcode_before = _gcode_words(vs)
    checked_upto = 0
    for _ in range(sequences):
        for _ in range(rng.randint(1, 5)):
            try:
                vs.set_intent(_random_intent(rng))
            except SmoothjogError as exc:  # an invalid random intent is a finding, not a crash
                report.faults.append(repr(exc))
            vs.run_until(vs.now_s + rng.choice([0.005, 0.03, 0.1, 0.3, 0.8]))
        vs.set_intent(StopIntent())
        vs.run_until_idle(60.0)
        t_idle = vs.now_s
        vs.run_until(vs.now_s + 0.3)  # anything moving now is a ghost jog
        trace = vs.rig.trace
        for seg in trace[checked_upto:]:
            if seg.t0_s >= t_idle - 1e-9 and seg.speed_mm_s > 0:
                report.ghost_jogs += 1
                break
        for seg in trace[checked_upto:]:
            for p in (seg.start_mm, seg.end_mm):
                if env is not None and not all(
                    lo - TOLERANCE_MM <= x <= hi + TOLERANCE_MM
                    for x, lo, hi in zip(p, env.min_mm, env.max_mm, strict=True)
                ):
                    report.envelope_crossings += 1
            if _enters(VISE, seg.start_mm, seg.end_mm):
                report.keepout_entries += 1
        checked_upto = len(trace)
        report.sequences += 1
        if model.state not in ("Idle", None):
            report.faults.append(f"state {model.state} after a sequence")
            break
    report.stops = len(engine.stats.stops)
    report.soft_limit_errors = engine.stats.soft_limit_errors
    if engine.stats.stops:
        report.worst_tracking_steps = max(s.tracked_error_steps for s in engine.stats.stops)
    report.gcode_state_changed = _gcode_words(vs) != gcode_before
    vs.close()
    faults = [e.text for e in events if e.kind == "fault"]
    report.false_outside_alarms = sum(
        "stopped outside smoothjog" in f or "left the path" in f for f in faults
    )
    report.faults += faults[:5]
    return report


def _enters(zone: KeepOut, a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    """True when the straight move a->b passes through the zone's open interior."""
    shrink = 1e-6
    lo = tuple(v + shrink for v in zone.min_mm)
    hi = tuple(v - shrink for v in zone.max_mm)
    t0, t1 = 0.0, 1.0
    for ai, bi, low, high in zip(a, b, lo, hi, strict=True):
        d = bi - ai
        if d == 0:
            if not low < ai < high:
                return False
            continue
        u0, u1 = (low - ai) / d, (high - ai) / d
        if u0 > u1:
            u0, u1 = u1, u0
        t0, t1 = max(t0, u0), min(t1, u1)
        if t0 >= t1:
            return False
    return True


def main(argv: list[str] | None = None) -> int:
    """Run the fuzz on the three firmware profiles and print one line each."""
    parser = argparse.ArgumentParser(prog="python -m bench fuzz")
    parser.add_argument("--sequences", type=int, default=10_000, help="per firmware profile")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--firmware", default="grbl,grblhal,fluidnc")
    args = parser.parse_args(argv)
    # The host logs every engine fault; the fuzz counts them itself and prints a few.
    logging.getLogger("smoothjog").setLevel(logging.ERROR)
    worst = 0
    print(
        "| firmware | sequences | stops | ghost jogs | error:15 | envelope | keep-out | $G changed"
        " | worst tracked-real (steps) | false outside-stop alarms | wall s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.firmware.split(","):
        t = time.perf_counter()
        r = run_fuzz(name, args.sequences, args.seed)
        print(
            f"| {name} | {r.sequences} | {r.stops} | {r.ghost_jogs} | {r.soft_limit_errors} | "
            f"{r.envelope_crossings} | {r.keepout_entries} | {r.gcode_state_changed} | "
            f"{r.worst_tracking_steps:.2f} | {r.false_outside_alarms} | "
            f"{time.perf_counter() - t:.0f} |",
            flush=True,
        )
        for fault in r.faults[:3]:
            print(f"  fault seen: {fault}")
        worst = worst or (0 if r.clean else 1)
    return worst
