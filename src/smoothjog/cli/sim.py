"""`smoothjog sim`: serve the simulated controller on a pseudo-terminal and/or a TCP port."""

from __future__ import annotations

import argparse
import asyncio
from pathlib import Path
from typing import Any

from smoothjog.core.firmware import DEFAULT_BAUD
from smoothjog.sim.profiles import FIRMWARE_PROFILES, available_machine_profiles
from smoothjog.sim.serve import ServeOptions, serve_until_signal


def register(subparsers: Any) -> None:
    """Add the `sim` subcommand."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        "sim",
        help="run the simulated Grbl controller on a pseudo-terminal or TCP port",
        description=(
            "Run a simulated Grbl-family controller in real time. Any sender can connect to the"
            " printed pseudo-terminal (or the --link symlink) or to the TCP port as if to a real"
            " machine. Ctrl-C or SIGTERM stops it."
        ),
    )
    parser.add_argument(
        "--firmware",
        choices=sorted(FIRMWARE_PROFILES),
        default="grbl",
        help="controller family to imitate (default: grbl, i.e. Grbl 1.1h)",
    )
    parser.add_argument(
        "--machine",
        default="grbl-defaults",
        metavar="PROFILE",
        help=(
            f"machine profile: one of {', '.join(available_machine_profiles())}, or the path"
            " of your own .toml file (default: grbl-defaults)"
        ),
    )
    parser.add_argument(
        "--settings",
        type=Path,
        metavar="FILE",
        help="keep $x=val, offsets and startup lines in FILE across runs, like EEPROM",
    )
    parser.add_argument(
        "--link", type=Path, metavar="PATH", help="also make a stable symlink PATH to the pty"
    )
    parser.add_argument(
        "--tcp",
        type=int,
        metavar="PORT",
        help="also listen on 127.0.0.1:PORT (0 picks a free port and prints it)",
    )
    parser.add_argument(
        "--no-pty", action="store_true", help="do not open a pseudo-terminal (needs --tcp)"
    )
    parser.add_argument(
        "--trace",
        type=Path,
        metavar="FILE",
        help=(
            "when stopped, write the ground truth to FILE: every motion segment the machine"
            " executed, as JSON Lines {t0_s, t1_s, start_mm, end_mm}, one per segment, in order;"
            " the machine went from start_mm to end_mm (machine coordinates, mm) at constant"
            " speed from t0_s to t1_s, times on this computer's monotonic clock (Python's"
            " time.monotonic())"
        ),
    )
    parser.add_argument(
        "--baud",
        type=int,
        default=DEFAULT_BAUD,
        help=f"modelled wire speed in baud (default {DEFAULT_BAUD}, 8N1)",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Serve until interrupted."""
    if args.no_pty and args.tcp is None:
        print("smoothjog sim: --no-pty leaves nothing to connect to; add --tcp PORT")
        return 2
    if args.no_pty and args.link is not None:
        print("smoothjog sim: --link needs the pty; drop --no-pty")
        return 2
    if args.tcp is not None and not 0 <= args.tcp <= 65535:
        print(f"smoothjog sim: --tcp {args.tcp} is not a port number (0-65535)")
        return 2
    if args.baud <= 0:
        print(f"smoothjog sim: --baud {args.baud} must be positive")
        return 2
    opts = ServeOptions(
        firmware=args.firmware,
        machine=args.machine,
        settings_path=args.settings,
        link_path=args.link,
        pty=not args.no_pty,
        tcp_port=args.tcp,
        baud=args.baud,
        trace_path=args.trace,
    )
    return asyncio.run(serve_until_signal(opts))
