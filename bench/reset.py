"""Someone else resets a machine at rest just as a press goes out: how far do the lines run?

`python -m bench reset [--firmware grbl,grblhal,fluidnc] [--links all] [--delays-ms 0,5,20]`

Another sender writes a soft reset (0x18) on the same wire while the hobby router stands Idle;
`delay` ms later smoothjog's stick is pressed at full speed (before the banner can come back),
held 0.3 s and released. The jog lines written before the banner reached smoothjog arrive at
the restarted controller and start it (firmware-facts §3.4). The table gives the distance the
machine ran after the reset, on the simulator in virtual time, per firmware profile and link.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time

from bench import links, measure
from bench import scenarios as sc
from bench.hosts import Shipped
from smoothjog.core.intents import StopIntent
from smoothjog.core.realtime import RESET
from smoothjog.sim.profiles import FIRMWARE_PROFILES
from smoothjog.sim.rig import LINK_MODELS

DEFAULT_DELAYS_MS = (0.0, 5.0, 20.0)
#: How long the stick is held after the press.
HOLD_S = 0.3


def ghost_mm(firmware: str, link_name: str, delay_s: float) -> float:
    """Distance (mm) the machine ran after the reset, the press delay_s after it."""
    vs, _t0 = sc._session(
        Shipped(links.cli_tuning()), links.LINK_MACHINE, firmware, LINK_MODELS[link_name]
    )
    try:
        t_reset = vs.now_s

        async def another_sender_resets() -> None:
            vs.link.send_realtime(RESET)

        vs.loop.run_until_complete(another_sender_resets())
        vs.run_until(t_reset + delay_s)
        vs.set_intent(sc._stick(1.0))
        vs.run_until(t_reset + delay_s + HOLD_S)
        vs.set_intent(StopIntent())
        vs.run_until(t_reset + delay_s + HOLD_S + 3.0)
        return measure.distance_after(vs.rig.trace, t_reset)
    finally:
        vs.close()


def _firmwares(text: str) -> list[str]:
    """The firmware profiles named (comma-separated, or 'all'); SystemExit for an unknown one."""
    known = list(FIRMWARE_PROFILES)
    names = known if text == "all" else [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        named = ", ".join(unknown) if unknown else repr(text)
        raise SystemExit(f"unknown firmware {named}: use {', '.join(known)}")
    return names


def _delays(text: str) -> list[float]:
    try:
        delays = [float(part) for part in text.split(",") if part.strip()]
    except ValueError:
        delays = []
    if not delays or any(d < 0 for d in delays):
        raise argparse.ArgumentTypeError(
            f"--delays-ms takes one or more delays of 0 ms or more, like 0,5,20: {text!r}"
        )
    return delays


def main(argv: list[str] | None = None) -> int:
    """Print the distance after the reset per firmware, link and press delay."""
    parser = argparse.ArgumentParser(
        prog="python -m bench reset", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--firmware", default="all", help="profiles, comma-separated, or 'all'")
    parser.add_argument("--links", default="all", help="link models, comma-separated, or 'all'")
    parser.add_argument(
        "--delays-ms",
        type=_delays,
        default=list(DEFAULT_DELAYS_MS),
        help="press this long after the reset (default: 0,5,20)",
    )
    args = parser.parse_args(argv)
    firmwares = _firmwares(args.firmware)
    names = links.parse_names(args.links)
    if not names:
        raise SystemExit("python -m bench reset: no link to run")
    # Each run's reset is a fault the host logs; the table says what came of it.
    logging.getLogger("smoothjog").setLevel(logging.CRITICAL)
    started = time.monotonic()
    print(
        f"{links.LINK_MACHINE}, idle; another sender's 0x18, then a full-speed press held"
        f" {HOLD_S:g} s; mm run after the reset (simulated, virtual time)"
    )
    print()
    head = " | ".join(f"press {d:g} ms after" for d in args.delays_ms)
    print(f"| firmware | link | {head} |")
    print("|---|---|" + "---|" * len(args.delays_ms))
    for firmware in firmwares:
        for name in names:
            cells = [f"{ghost_mm(firmware, name, d / 1000.0):.2f}" for d in args.delays_ms]
            print(f"| {firmware} | {name} | " + " | ".join(cells) + " |", flush=True)
    print()
    print(f"Wall time: {time.monotonic() - started:.1f} s", file=sys.stderr)
    return 0
