"""`smoothjog jog --replay FILE`: run a script of timed jog intents and print what happened.

`--input-replay FILE --input-kind KIND` plays a recorded device stream instead (evtest text for
evdev devices, `SECONDS HEX` lines for hidraw ones, docs/devices.md) through that kind's decoder
and the arbiter, exactly as the live device would drive the machine.

Without --port or --connect the script runs on the built-in simulator in virtual time (fast and
repeatable; `--realtime` runs it on the wall clock instead). With a controller it runs in real time.
Both are the same runner on the same host; only the event loop's clock differs (vclock.py).
"""

from __future__ import annotations

import argparse
import asyncio
import math
import sys
from dataclasses import dataclass, field
from typing import Any

from smoothjog.authority.gate import MotionGate
from smoothjog.cli.common import (
    add_connection_args,
    config_from_args,
    connection_from_args,
    link_for,
)
from smoothjog.config import Config
from smoothjog.core.engine import EngineEvent, Jogger, JogTuning
from smoothjog.core.errors import SmoothjogError
from smoothjog.core.firmware import FIRMWARE_NAMES
from smoothjog.core.intents import ContinuousIntent, Intent, StopIntent
from smoothjog.core.ledger import ENGINE
from smoothjog.core.machine import UNHOMED_WARNING
from smoothjog.core.units import Vec
from smoothjog.devices import DeviceReplay, load_device_replay
from smoothjog.host import Host
from smoothjog.inputs.kinds import KIND_NAMES
from smoothjog.inputs.replay import ReplayError, TimedIntent, load_replay
from smoothjog.links.base import Link
from smoothjog.links.sim import SimLink
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import available_machine_profiles, get_firmware_profile
from smoothjog.sim.rig import LinkModel, SimRig
from smoothjog.vclock import VirtualClockLoop


def register(subparsers: Any) -> None:
    """Add `jog` to the command line."""
    parser = subparsers.add_parser(
        "jog",
        help="run a replay file of timed jog intents (built-in simulator by default)",
        description=__doc__,
    )
    script = parser.add_mutually_exclusive_group(required=True)
    script.add_argument("--replay", metavar="FILE", help="JSON Lines intents")
    script.add_argument(
        "--input-replay",
        metavar="FILE",
        help="a recorded device stream (evtest text, or SECONDS HEX lines for hidraw)",
    )
    parser.add_argument(
        "--input-kind",
        choices=KIND_NAMES,
        metavar="KIND",
        help=f"the device of --input-replay: {', '.join(KIND_NAMES)}",
    )
    add_connection_args(parser)
    parser.add_argument("--firmware", choices=FIRMWARE_NAMES, help="simulated firmware")
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
    lines_sent: int = 0
    faults: list[str] = field(default_factory=list)
    #: News the engine told that is no fault (a jog clipped at a soft limit), once each.
    notes: list[str] = field(default_factory=list)
    #: Why intents of the script were refused (the controller left Idle mid-script), once each.
    refused: list[str] = field(default_factory=list)
    #: What a replayed device did, in lines (None for a --replay script).
    device: list[str] | None = None

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
            f"  lines sent      {self.lines_sent}",
            f"  stops           {self.stops}",
            f"  tracked - real  {1000 * self.worst_tracking_mm:.2f} µm, "
            f"{self.worst_tracking_steps:.2f} steps (worst axis, worst stop)",
            f"  final state     {self.final_state or 'unknown'} at MPos {pos}",
        ]
        if self.device is not None:
            out += [f"  {line}" for line in self.device]
        if self.notes:
            out.append("  told:")
            out += [f"    - {note}" for note in self.notes]
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
    ] + [f"jog refused: {why}" for why in summary.refused]
    summary.notes = list(
        dict.fromkeys(
            e.text + (f" ({e.hint})" if e.hint else "") for e in events if e.kind == "info"
        )
    )


class JogRefusedError(SmoothjogError):
    """The controller refuses jogging from the start (Alarm, a hold, a door...): nothing runs."""


def _moves(intent: Intent) -> bool:
    """True for an intent that asks for motion (not a stop or a released stick)."""
    if isinstance(intent, StopIntent):
        return False
    if isinstance(intent, ContinuousIntent):
        return not intent.is_neutral()
    return True


def _refuse_at_start(gate: MotionGate) -> None:
    """Raise JogRefusedError, in the gate's words, when no jog may start on this controller;
    warn on stderr about a machine that looks unhomed (soft limits then count from power-up)."""
    host = gate.host
    why = gate.jog_refusal()
    if why is not None and host.model.state is not None:
        raise JogRefusedError(f"jogging refused, the script was not run: {why}")
    if host.model.state == "Idle" and host.model.looks_unhomed():
        print(f"smoothjog: warning: {UNHOMED_WARNING}", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    """Run the replay; 0 when it ended idle with no fault."""
    config = config_from_args(args)
    script: list[TimedIntent] | DeviceReplay
    if args.input_replay is not None:
        if args.input_kind is None:
            raise ReplayError(
                "--input-replay needs --input-kind, the kind of device recorded: "
                + ", ".join(KIND_NAMES)
            )
        script = load_device_replay(args.input_replay, args.input_kind, config.devices)
    else:
        if args.input_kind is not None:
            raise ReplayError("--input-kind goes with --input-replay, not --replay")
        script = load_replay(args.replay)
    connection = connection_from_args(args, config)
    link = link_for(connection)
    firmware = args.firmware or config.sim.firmware
    machine = args.machine or config.sim.machine
    if link is None:
        fw = GrblFirmware(get_firmware_profile(firmware), machine)
        sim_link = SimLink(rig=SimRig(fw, LinkModel()))
        runner = _run(sim_link, script, config, connection.timeout_s, args.settle)
        if args.realtime:
            where = sim_link.describe()
            summary = asyncio.run(runner)
        else:
            where = f"the built-in simulator ({firmware}, {machine}, virtual time)"
            loop = VirtualClockLoop()
            try:
                summary = loop.run_until_complete(runner)
            finally:
                loop.close()
    else:
        where = link.describe()
        summary = asyncio.run(_run(link, script, config, connection.timeout_s, args.settle))
    print("\n".join(summary.lines(where)))
    return 0 if summary.idle and not summary.faults else 1


async def _run(
    link: Link,
    script: list[TimedIntent] | DeviceReplay,
    config: Config,
    timeout_s: float,
    settle_s: float,
) -> Summary:
    """Start a host on link, play the script on the loop's clock, wait for rest, summarise."""
    events: list[EngineEvent] = []
    async with link:
        host = Host(
            link,
            tuning=_tuning(config),
            keepouts=config.keepouts,
            handshake_timeout_s=timeout_s,
            on_event=events.append,
        )
        await host.start()
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        # The simulator's trace runs on its own clock (the same as the loop's in virtual time).
        rig_t0 = link.rig.now_s if isinstance(link, SimLink) else 0.0
        summary = Summary()
        try:
            gate = MotionGate(host)
            _refuse_at_start(gate)
            if isinstance(script, DeviceReplay):
                summary.device = await script.play(host)
            else:
                for item in script:
                    await asyncio.sleep(max(t0 + item.t_s - loop.time(), 0.0))
                    if _moves(item.intent):
                        why = gate.jog_refusal()
                        if why is not None and why not in summary.refused:
                            summary.refused.append(why)
                    host.set_intent(item.intent)
            try:
                await host.wait_idle(settle_s)
                summary.idle = True
            except TimeoutError:
                summary.idle = False
            summary.duration_s = loop.time() - t0
            if isinstance(link, SimLink):
                summary.distance_mm = sum(
                    math.dist(s.start_mm, s.end_mm) for s in link.rig.trace if s.t0_s >= rig_t0
                )
            assert host.engine is not None
            _fill(summary, host.engine, events)
            summary.lines_sent = host.ledger.stats.lines[ENGINE]
        finally:
            await host.close()
    return summary
