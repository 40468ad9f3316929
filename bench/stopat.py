"""`python -m bench stopat`: how far the pendant's "Stop at" is from where the machine stops.

The engine's `stop_point_mm()` is what the pendant shows as "Stop at": where the machine would
rest if the jog were released now. This holds an X jog on the built-in simulator (Grbl 1.1h, the
ideal in-process wire, virtual time), reads the prediction at the moment of release, releases,
and compares it with the simulator's ground truth at rest, for each machine profile, speed and
release phase. The figure is the prediction's X minus the rest position's X for a jog toward
-X: negative means the machine stopped short of what was shown, positive that it ran past it.
"""

from __future__ import annotations

import argparse
import statistics

from smoothjog.core.intents import ContinuousIntent
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import get_firmware_profile, load_machine_profile
from smoothjog.sim.rig import SimRig
from smoothjog.virtual import VirtualHost


def release_miss_mm(machine: str, speed: float, hold_s: float) -> float:
    """Predicted X minus rest X (mm) for a jog toward -X released after hold_s."""
    rig = SimRig(GrblFirmware(get_firmware_profile("grbl"), load_machine_profile(machine)))
    vh = VirtualHost(rig)
    try:
        vh.handshake()
        vh.set_intent(ContinuousIntent({"X": -1.0}, speed))
        vh.run_until(vh.now_s + hold_s)
        assert vh.host.engine is not None
        predicted = vh.host.engine.stop_point_mm()
        assert predicted is not None
        vh.set_intent(ContinuousIntent({"X": 0.0}, speed))
        vh.run_until_idle(10.0)
        return predicted[0] - rig.firmware.mpos_mm()[0]
    finally:
        vh.close()


def main(argv: list[str]) -> int:
    """Print the table."""
    parser = argparse.ArgumentParser(prog="python -m bench stopat", description=__doc__)
    parser.add_argument("--machines", default="hobby-router,fast,grbl-defaults,slow-machine")
    parser.add_argument("--speeds", default="1.0,0.5,0.25")
    parser.add_argument("--phases", type=int, default=8, help="release phases per row")
    parser.add_argument("--hold-s", type=float, default=2.5, help="hold before release")
    args = parser.parse_args(argv)
    print("# Stop at: prediction at release against the simulator's rest position")
    print()
    print(
        f"Command: `python -m bench stopat --machines {args.machines} --speeds {args.speeds} "
        f"--phases {args.phases} --hold-s {args.hold_s:g}`; Grbl 1.1h simulator, ideal wire, "
        "virtual time; releases spread over 90 ms after the hold."
    )
    print()
    print("| machine | speed | prediction minus rest (X), median | worst | within 0.5 mm |")
    print("|---|---|---|---|---|")
    worst_all = 0.0
    for machine in args.machines.split(","):
        for speed in (float(s) for s in args.speeds.split(",")):
            errs = [
                release_miss_mm(machine, speed, args.hold_s + k * 0.09 / args.phases)
                for k in range(args.phases)
            ]
            worst = max(errs, key=abs)
            worst_all = max(worst_all, abs(worst))
            within = sum(abs(e) <= 0.5 for e in errs)
            print(
                f"| {machine} | {speed:g} | {statistics.median(errs):+.3f} mm | {worst:+.3f} mm "
                f"| {within}/{len(errs)} |"
            )
    print()
    print(f"Worst: {worst_all:.3f} mm (the pendant's goal: 0.5 mm at full speed).")
    return 0
