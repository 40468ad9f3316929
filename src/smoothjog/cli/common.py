"""Options every subcommand that talks to a controller shares, and picking the link they ask for.

`--port`/`--baud` choose a serial port, `--connect tcp://HOST:PORT` a network controller,
`--cncjs http://HOST:PORT --cncjs-port PATH` a controller behind a running CNCjs server; the
command line wins over the config file's [connection], which wins over the defaults. Neither a
port nor an address means "use the built-in simulator": `open_link` then returns None and the
caller decides (most use `simulator_link`).
"""

from __future__ import annotations

import argparse
from dataclasses import replace

from smoothjog.config import Config, ConnectionConfig, load_config
from smoothjog.core.errors import LinkError
from smoothjog.core.firmware import DEFAULT_BAUD
from smoothjog.links.base import Link
from smoothjog.links.cncjs import CncjsLink, parse_cncjs_url
from smoothjog.links.cncjs_auth import make_token
from smoothjog.links.serial import DEFAULT_WAIT_BANNER_S, SerialLink
from smoothjog.links.sim import SimLink
from smoothjog.links.tcp import TcpLink, parse_tcp_url
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import get_firmware_profile


def _positive_int(text: str) -> int:
    """argparse type: a whole number above zero."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a whole number, e.g. {DEFAULT_BAUD}"
        ) from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"{text} must be above 0, e.g. {DEFAULT_BAUD}")
    return value


def _positive_seconds(text: str) -> float:
    """argparse type: a finite number of seconds above zero."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds, e.g. 5") from None
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"{text} must be a number of seconds above 0, e.g. 5")
    return value


def add_connection_args(parser: argparse.ArgumentParser) -> None:
    """Add --port/--baud, --connect, --timeout and --config to a subcommand's parser."""
    group = parser.add_argument_group("connection (default: the [connection] of the config)")
    where = group.add_mutually_exclusive_group()
    where.add_argument(
        "--port", metavar="PATH", help="serial port of the controller, e.g. /dev/ttyUSB0"
    )
    where.add_argument(
        "--connect",
        metavar="URL",
        help="network controller as tcp://HOST:PORT (FluidNC, ESP32 Grbl, grblHAL telnet)",
    )
    where.add_argument(
        "--cncjs",
        metavar="URL",
        help="a CNCjs server that owns the controller's port, e.g. http://127.0.0.1:8000"
        " (smoothjog joins it as a pendant; see docs/cncjs.md)",
    )
    group.add_argument(
        "--cncjs-port",
        metavar="PATH",
        help="with --cncjs: the controller's port as CNCjs names it, e.g. /dev/ttyUSB0",
    )
    group.add_argument(
        "--cncjs-config",
        metavar="FILE",
        help="with --cncjs: CNCjs's config file, whose secret signs the token (default ~/.cncrc,"
        " or $CNCJS_SECRET)",
    )
    group.add_argument(
        "--cncjs-token", metavar="TOKEN", help="with --cncjs: a token to use instead of signing one"
    )
    group.add_argument(
        "--cncjs-user",
        metavar="NAME",
        help="with --cncjs: the CNCjs user the token names, when CNCjs has users configured",
    )
    group.add_argument(
        "--baud",
        type=_positive_int,
        metavar="N",
        help=f"serial speed in baud (default {DEFAULT_BAUD})",
    )
    group.add_argument(
        "--timeout",
        type=_positive_seconds,
        metavar="S",
        help="seconds to wait for the controller to answer (default 5)",
    )
    group.add_argument(
        "--config",
        metavar="FILE",
        help="TOML config file (default: $SMOOTHJOG_CONFIG, else built-in defaults)",
    )


def config_from_args(args: argparse.Namespace) -> Config:
    """The config file the arguments (or $SMOOTHJOG_CONFIG) name, or the defaults."""
    return load_config(getattr(args, "config", None))


def connection_from_args(
    args: argparse.Namespace, config: Config | None = None
) -> ConnectionConfig:
    """The connection to use: command-line options over the config's [connection]."""
    base = (config if config is not None else config_from_args(args)).connection
    port: str | None = getattr(args, "port", None)
    connect: str | None = getattr(args, "connect", None)
    cncjs: str | None = getattr(args, "cncjs", None)
    if port is not None or connect is not None or cncjs is not None:
        # Naming a controller on the command line replaces the config's choice entirely.
        base = replace(base, port=port, connect=connect, cncjs=cncjs)
    given = []
    for key in ("cncjs_port", "cncjs_config", "cncjs_token", "cncjs_user"):
        value = getattr(args, key, None)
        if value is not None:
            base = replace(base, **{key: value})
            given.append("--" + key.replace("_", "-"))
    if given and base.cncjs is None:
        raise LinkError(
            f"{' and '.join(given)} {'goes' if len(given) == 1 else 'go'} with --cncjs URL (the"
            " CNCjs server that owns the port): add it, or leave them out"
        )
    baud: int | None = getattr(args, "baud", None)
    timeout_s: float | None = getattr(args, "timeout", None)
    if baud is not None:
        base = replace(base, baud=baud)
    if timeout_s is not None:
        base = replace(base, timeout_s=timeout_s)
    return base


def link_for(connection: ConnectionConfig) -> Link | None:
    """The (unopened) link a connection names; None for the built-in simulator.

    A CNCjs link's token is made here, so a missing secret is told before anything connects.
    """
    if connection.cncjs is not None:
        if not connection.cncjs_port:
            raise LinkError(
                "--cncjs needs --cncjs-port: the controller's port as CNCjs names it, e.g."
                " /dev/ttyUSB0 (CNCjs's port list shows it)"
            )
        parse_cncjs_url(connection.cncjs)  # a wrong address is told before a missing secret
        token = make_token(
            token=connection.cncjs_token,
            config_path=connection.cncjs_config,
            user=connection.cncjs_user,
        )
        return CncjsLink(
            connection.cncjs,
            connection.cncjs_port,
            token,
            baud=connection.baud,
            timeout_s=connection.timeout_s,
        )
    if connection.connect is not None:
        host, port = parse_tcp_url(connection.connect)
        return TcpLink(host, port, connect_timeout_s=connection.timeout_s)
    if connection.port is not None:
        return SerialLink(
            connection.port,
            connection.baud,
            wait_banner_s=min(DEFAULT_WAIT_BANNER_S, connection.timeout_s),
        )
    return None


def simulator_link(config: Config) -> Link:
    """A link to the built-in simulator, with the config's [sim] firmware and machine."""
    profile = get_firmware_profile(config.sim.firmware)
    return SimLink(GrblFirmware(profile, config.sim.machine, keep_trace=False))


def open_link(args: argparse.Namespace) -> Link | None:
    """The link the arguments ask for, not yet opened (`async with link:`); None: simulator."""
    return link_for(connection_from_args(args))
