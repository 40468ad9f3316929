"""`smoothjog jog --replay FILE`: run a script of timed jog intents and print what happened.

Without --port or --connect the script runs on the built-in simulator in virtual time (fast and
repeatable; `--realtime` runs it on the wall clock instead). With a controller it runs in real time.
"""

from __future__ import annotations

import argparse
import asyncio
import math
from dataclasses import dataclass, field
from typing import Any

from smoothjog.cli.common import (
    add_connection_args,
    config_from_args,
    connection_from_args,
    link_for,
)
from smoothjog.config import Config
from smoothjog.core.jogger import EngineEvent, Jogger, JogTuning
from smoothjog.core.units import Vec
from smoothjog.inputs.replay import TimedIntent, load_replay
from smoothjog.links.base import Link
from smoothjog.links.sim import SimLink
from smoothjog.session import JogSession
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import available_machine_profiles, get_firmware_profile
from smoothjog.sim.rig import LinkModel, SimRig
from smoothjog.vsession import VirtualSession


def register(subparsers: Any) -> None:
    """Add `jog` to the command line."""
    parser = subparsers.add_parser(
        "jog",
        help="run a replay file of timed jog intents (built-in simulator by default)",
        description=__doc__,
    )
    parser.add_argument("--replay", required=True, metavar="FILE", help="JSON Lines intents")
    add_connection_args(parser)
    parser.add_argument(
        "--firmware", choices=("grbl", "grblhal", "fluidnc"), help="simulated firmware"
    )
    parser.add_argument(
        "--machine",
        metavar="PROFILE",
        help=f"simulated machine: {', '.join(available_machine_profiles())} or a .toml path",
    )
    parser.add_argument(
        "--realtime", action="store_true", help="run the simulator on the wall clock"
    )
    parser.add_argument(
        "--settle", type=float, default=30.0, metavar="S", help="max seconds to wait for idle"
    )
    parser.set_defaults(func=run)


@dataclass
class Summary:
    """What a replay did."""

    duration_s: float = 0.0
    distance_mm: float | None = None
    stops: int = 0
    worst_tracking_mm: float = 0.0
    worst_tracking_steps: float = 0.0
    final_mpos: Vec | None = None
    final_state: str | None = None
    idle: bool = False
    faults: list[str] = field(default_factory=list)

    def lines(self, where: str) -> list[str]:
        """The readable summary."""
        pos = ", ".join(f"{v:.3f}" for v in self.final_mpos) if self.final_mpos else "unknown"
        out = [
            f"replay finished on {where}",
            f"  duration        {self.duration_s:.3f} s",
        ]
        if self.distance_mm is not None:
            out.append(f"  distance        {self.distance_mm:.3f} mm (simulator ground truth)")
        out += [
            f"  stops           {self.stops}",
            f"  tracked - real  {1000 * self.worst_tracking_mm:.2f} µm, "
            f"{self.worst_tracking_steps:.2f} steps (worst axis, worst stop)",
            f"  final state     {self.final_state or 'unknown'} at MPos {pos}",
        ]
        if self.faults:
            out.append("  faults:")
            out += [f"    - {f}" for f in self.faults]
        else:
            out.append("  faults          none")
        return out


def _tuning(config: Config) -> JogTuning:
    return JogTuning(
        speed_ratios=dict(config.jog.speed_ratios), link_margin_s=config.jog.link_margin_s
    )


def _fill(summary: Summary, engine: Jogger, events: list[EngineEvent]) -> None:
    summary.stops = len(engine.stats.stops)
    if engine.stats.stops:
        summary.worst_tracking_mm = max(s.tracked_error_mm for s in engine.stats.stops)
        summary.worst_tracking_steps = max(s.tracked_error_steps for s in engine.stats.stops)
    summary.final_mpos = engine.model.mpos_mm
    summary.final_state = engine.model.state
    summary.faults = [
        e.text + (f" ({e.hint})" if e.hint else "") for e in events if e.kind == "fault"
    ]


def run(args: argparse.Namespace) -> int:
    """Run the replay; 0 when it ended idle with no fault."""
    config = config_from_args(args)
    script = load_replay(args.replay)
    connection = connection_from_args(args, config)
    link = link_for(connection)
    firmware = args.firmware or config.sim.firmware
    machine = args.machine or config.sim.machine
    if link is None and not args.realtime:
        summary = _run_virtual(script, config, firmware, machine, args.settle)
        where = f"the built-in simulator ({firmware}, {machine}, virtual time)"
    else:
        if link is None:
            link = SimLink(GrblFirmware(get_firmware_profile(firmware), machine))
        where = link.describe()
        summary = asyncio.run(_run_real(link, script, config, connection.timeout_s, args.settle))
    print("\n".join(summary.lines(where)))
    return 0 if summary.idle and not summary.faults else 1


def _run_virtual(
    script: list[TimedIntent], config: Config, firmware: str, machine: str, settle_s: float
) -> Summary:
    fw = GrblFirmware(get_firmware_profile(firmware), machine)
    vs = VirtualSession(SimRig(fw, LinkModel()), tuning=_tuning(config), keepouts=config.keepouts)
    vs.handshake()
    engine = vs.engine
    assert engine is not None
    t0 = vs.now_s
    events: list[EngineEvent] = []
    for item in script:
        vs.run_until(t0 + item.t_s)
        vs.set_intent(item.intent)
        events += engine.events
        engine.events.clear()
    summary = Summary()
    summary.idle = vs.run_until_idle(settle_s)
    events += engine.events
    summary.duration_s = vs.now_s - t0
    summary.distance_mm = sum(math.dist(s.start_mm, s.end_mm) for s in fw.trace if s.t0_s >= t0)
    _fill(summary, engine, events)
    return summary


async def _run_real(
    link: Link, script: list[TimedIntent], config: Config, timeout_s: float, settle_s: float
) -> Summary:
    events: list[EngineEvent] = []
    async with link:
        session = JogSession(
            link,
            tuning=_tuning(config),
            keepouts=config.keepouts,
            handshake_timeout_s=timeout_s,
            on_event=events.append,
        )
        await session.start()
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        summary = Summary()
        try:
            for item in script:
                await asyncio.sleep(max(t0 + item.t_s - loop.time(), 0.0))
                session.set_intent(item.intent)
            try:
                await session.wait_idle(settle_s)
                summary.idle = True
            except TimeoutError:
                summary.idle = False
            summary.duration_s = loop.time() - t0
            assert session.engine is not None
            _fill(summary, session.engine, events)
        finally:
            await session.close()
    return summary
