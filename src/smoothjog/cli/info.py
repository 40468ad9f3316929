"""`smoothjog info`: connect to a controller, run the handshake and print what it is."""

from __future__ import annotations

import argparse
import asyncio
from typing import Any

from smoothjog.cli.common import (
    add_connection_args,
    config_from_args,
    connection_from_args,
    link_for,
    simulator_link,
)
from smoothjog.core.errors import LinkError
from smoothjog.handshake import format_summary, handshake
from smoothjog.links.base import Link


def register(subparsers: Any) -> None:
    """Add the `info` subcommand."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        "info",
        help="connect to a controller and describe it",
        description=(
            "Connect to a Grbl-family controller, ask it $I, $$, $G, $# and ?, and print its"
            " firmware, buffers, axis limits, soft limits, state and position. Nothing moves."
            " Without --port or --connect it describes the built-in simulator."
        ),
    )
    add_connection_args(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print the controller summary; exit 0."""
    config = config_from_args(args)
    connection = connection_from_args(args, config)
    # No controller named: describe the built-in simulator, so the command always shows something.
    link = link_for(connection) or simulator_link(config)
    summary = asyncio.run(_describe(link, connection.timeout_s))
    print(summary)
    return 0


async def _describe(link: Link, timeout_s: float) -> str:
    """Open the link, run the handshake, close, and return the summary."""
    try:
        async with link:
            model = await handshake(link, timeout_s=timeout_s)
    except OSError as exc:
        # Anything the links did not translate still becomes one sentence, never a traceback.
        raise LinkError(f"{link.describe()}: {exc.strerror or exc}") from None
    return f"{'Link':14}{link.describe()}\n{format_summary(model)}"
