"""`smoothjog proxy`: a port for the user's sender in front of the machine, the pendant beside it.

smoothjog owns the controller's port (--port, --connect or --cncjs, or the built-in simulator
when none is named) and offers the sender a port of its own that behaves like the machine: a
pseudo-terminal with a stable symlink (--link) and/or a loopback TCP port (--tcp). The sender
runs its jobs through it as before; the web pendant and the input devices jog whenever the
sender is not running a job, and say why when they may not (docs/proxy.md).
"""

from __future__ import annotations

import argparse
import asyncio
from pathlib import Path
from typing import Any

from smoothjog.cli.pendant import add_session_args, prepare_session, run_session
from smoothjog.proxy import PtySender, SenderProxy, TcpSender


def register(subparsers: Any) -> None:
    """Add `proxy` to the command line."""
    parser = subparsers.add_parser(
        "proxy",
        help="give a desktop sender (UGS, CNCjs, ...) a port in front of the machine, "
        "and jog with the pendant while it is idle",
        description=__doc__,
    )
    ports = parser.add_argument_group("the sender's port (at least one)")
    ports.add_argument(
        "--link",
        type=Path,
        metavar="PATH",
        help="a pseudo-terminal for the sender, with a stable symlink PATH to it, e.g."
        " /tmp/ttyGRBL (pick PATH as the serial port in the sender)",
    )
    ports.add_argument(
        "--tcp",
        type=int,
        metavar="PORT",
        help="also serve the sender on 127.0.0.1:PORT (0 picks a free port and prints it)",
    )
    add_session_args(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run until Ctrl-C or SIGTERM."""
    if args.link is None and args.tcp is None:
        print("smoothjog proxy: give the sender a port: --link PATH (a pty) and/or --tcp PORT")
        return 2
    if args.tcp is not None and not 0 <= args.tcp <= 65535:
        print(f"smoothjog proxy: --tcp {args.tcp} is not a port number (0-65535)")
        return 2
    prepared = prepare_session(args)
    proxy = SenderProxy()

    async def serve_sender() -> None:
        pty = PtySender(proxy, args.link) if args.link is not None else None
        tcp = TcpSender(proxy) if args.tcp is not None else None
        forwarder = asyncio.create_task(proxy.run(), name="smoothjog-proxy")
        try:
            where = []
            if pty is not None:
                where.append(f"pty {pty.open()} (link {args.link})")
            if tcp is not None:
                where.append(f"tcp 127.0.0.1:{await tcp.start(args.tcp)}")
            print(f"smoothjog proxy: the sender's port is {', '.join(where)}", flush=True)
            await forwarder
        finally:
            forwarder.cancel()
            await asyncio.gather(forwarder, return_exceptions=True)
            if pty is not None:
                pty.close()
            if tcp is not None:
                await tcp.close()

    return asyncio.run(run_session(prepared, args, hooks=proxy, side=serve_sender))
