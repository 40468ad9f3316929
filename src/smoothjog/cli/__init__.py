"""The command line: the only place that picks concrete links, inputs and the simulator.

Each subcommand lives in its own module of this package and exposes
`register(subparsers) -> None`, which adds its parser and sets `func(args) -> int` on it.
Adding a command means adding a module and naming it in SUBCOMMANDS.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from smoothjog import __version__
from smoothjog.core.errors import SmoothjogError

#: Subcommand modules, in the order `--help` lists them.
SUBCOMMANDS: tuple[str, ...] = ("pendant", "proxy", "info", "devices", "sim", "jog")

#: The subcommand that runs when none is given (the README's main job).
DEFAULT_COMMAND: str | None = "pendant"


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one sentence and exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"smoothjog: {message} (see `smoothjog --help`)\n")


def build_parser() -> argparse.ArgumentParser:
    """The full parser with every subcommand registered."""
    parser = _Parser(
        prog="smoothjog",
        description="Smooth, low-latency, safe jogging for Grbl-family CNC controllers.",
    )
    parser.add_argument("--version", action="version", version=f"smoothjog {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in SUBCOMMANDS:
        module = importlib.import_module(f"smoothjog.cli.{name}")
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the process exit code."""
    args_list = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    if (
        DEFAULT_COMMAND is not None
        and not any(a in SUBCOMMANDS for a in args_list)
        and not {"-h", "--help", "--version"} & set(args_list)
    ):
        args_list.insert(0, DEFAULT_COMMAND)
    args = parser.parse_args(args_list)
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help()
        return 0
    try:
        code: int = func(args)
    except SmoothjogError as exc:
        print(f"smoothjog: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("smoothjog: interrupted", file=sys.stderr)
        return 130
    return code
