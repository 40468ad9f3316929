"""`smoothjog pendant` (the default command): a controller, the jog engine and the web pendant.

Without --port, --connect or --cncjs it drives the built-in simulated Grbl machine in real time,
so the pendant can be tried with no machine at all. When the link to a controller is lost (a
CNCjs restart, a cable pulled) the pendant stays up, says so, and connects again every
RECONNECT_S. Ctrl-C stops any jog with the full cancel handshake and shuts down cleanly.

The session itself (the link, the host, the pendant, the devices, the reconnect) is shared:
`add_session_args`, `prepare_session` and `run_session` serve `smoothjog proxy` as well, which
adds its sender ports beside them through `SessionHooks` and a side task.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
import sys
from collections.abc import Callable, Coroutine
from dataclasses import dataclass
from typing import Any, Protocol

from smoothjog.authority.arbiter import Arbiter
from smoothjog.authority.gate import MotionGate
from smoothjog.cli.common import (
    add_connection_args,
    config_from_args,
    connection_from_args,
    link_for,
)
from smoothjog.config import DEFAULT_HTTP_PORT, Config
from smoothjog.core.engine import EngineEvent, JogTuning
from smoothjog.core.errors import SmoothjogError
from smoothjog.core.firmware import FIRMWARE_NAMES
from smoothjog.devices import DeviceManager, MachineCommands, check_device_configs, machine_view
from smoothjog.handshake import format_summary
from smoothjog.host import Host
from smoothjog.links.base import Link
from smoothjog.links.sim import SimLink
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import available_machine_profiles, get_firmware_profile
from smoothjog.web.protocol import PendantError
from smoothjog.web.server import is_loopback, run_pendant
from smoothjog.web.session_backend import SessionBackend

#: Seconds between attempts to open a lost link again.
RECONNECT_S = 2.0


class SessionHooks(Protocol):
    """Something that rides along with every session's host (the proxy's forwarder)."""

    def attach(self, host: Host) -> None:
        """A host was made; called before its start()."""

    def started(self, host: Host) -> None:
        """That host finished its handshake."""

    def gated(self, gate: MotionGate) -> None:
        """The session's motion gate, once (it follows every host)."""


@dataclass
class PreparedSession:
    """What a session command was asked for, checked before the machine is touched."""

    config: Config
    link: Link
    timeout_s: float
    #: A new link to the same controller (None: the built-in simulator, never lost).
    make_link: Callable[[], Link | None] | None


def register(subparsers: Any) -> None:
    """Add `pendant` to the command line."""
    parser = subparsers.add_parser(
        "pendant",
        help="the web pendant on the built-in simulator or a real controller (default command)",
        description=__doc__,
    )
    add_session_args(parser)
    parser.set_defaults(func=run)


def add_session_args(parser: argparse.ArgumentParser) -> None:
    """The controller, built-in simulator, pendant and device options of a session command."""
    add_connection_args(parser)
    sim = parser.add_argument_group("built-in simulator (when no --port/--connect/--cncjs)")
    sim.add_argument("--firmware", choices=FIRMWARE_NAMES)
    sim.add_argument(
        "--machine",
        metavar="PROFILE",
        help=f"one of {', '.join(available_machine_profiles())}, or a .toml path",
    )
    web = parser.add_argument_group("pendant")
    web.add_argument("--host", help="address to serve on (default 127.0.0.1)")
    web.add_argument(
        "--http-port", type=int, metavar="N", help=f"HTTP port (default {DEFAULT_HTTP_PORT})"
    )
    web.add_argument(
        "--lan",
        action="store_true",
        help="serve on the local network too, guarded by a pairing token shown as a QR code",
    )
    devices = parser.add_argument_group("input devices (docs/devices.md)")
    devices.add_argument(
        "--input",
        action="append",
        default=[],
        metavar="NAME",
        help="jog with a device: a kind (gamepad, whb04b, ...), a /dev path, vendor:product, "
        "part of its name, or auto (every device but keyboards); repeatable; "
        "`smoothjog devices` lists them",
    )


def run(args: argparse.Namespace) -> int:
    """Run until Ctrl-C or SIGTERM."""
    return asyncio.run(run_session(prepare_session(args), args))


def prepare_session(args: argparse.Namespace) -> PreparedSession:
    """Read the config and check the options; pick the link (the simulator when none named)."""
    config = config_from_args(args)
    host = args.host or config.pendant.host
    if not (args.lan or config.pendant.lan) and not is_loopback(host):
        # Refused before anything starts: a pendant reachable from the network needs --lan.
        raise PendantError(
            f"refusing to serve the pendant on {host}: anyone on the network could jog the "
            "machine; use --lan, which requires a pairing token, or bind 127.0.0.1"
        )
    connection = connection_from_args(args, config)
    # A bad [[device]] option is refused before the machine is touched.
    check_device_configs(config.devices)
    link = link_for(connection)
    if link is None:
        firmware = args.firmware or config.sim.firmware
        machine = args.machine or config.sim.machine
        # The embedded default runs all day: it keeps no ground-truth trace.
        link = SimLink(GrblFirmware(get_firmware_profile(firmware), machine, keep_trace=False))
        print(
            f"smoothjog: no controller given: using the built-in simulator ({firmware}, {machine})"
        )
        make_link: Callable[[], Link | None] | None = None  # the simulator lives in here
    else:
        make_link = lambda: link_for(connection)  # noqa: E731 - a new token, a new link
    return PreparedSession(config, link, connection.timeout_s, make_link)


def _print_notice(text: str, arbiter: Arbiter) -> None:
    """A device's sentence: on stderr, and on every page of the pendant."""
    print(f"smoothjog: {text}", file=sys.stderr, flush=True)
    arbiter.announce(text)


def _print_event(event: EngineEvent) -> None:
    if event.kind == "fault":
        hint = f" ({event.hint})" if event.hint else ""
        print(f"smoothjog: {event.text}{hint}", file=sys.stderr, flush=True)


def _make_host(link: Link, config: Config, timeout_s: float) -> Host:
    return Host(
        link,
        tuning=JogTuning(
            speed_ratios=dict(config.jog.speed_ratios),
            link_margin_s=config.jog.link_margin_s,
        ),
        keepouts=config.keepouts,
        handshake_timeout_s=timeout_s,
        on_event=_print_event,
    )


async def _keep_connected(
    backend: SessionBackend,
    arbiter: Arbiter,
    make_link: Callable[[], Link | None],
    config: Config,
    timeout_s: float,
    hooks: SessionHooks | None,
) -> None:
    """Open the link again whenever it is lost, and hand the pendant the new session."""
    while True:
        session = backend.session
        await session.wait_lost()
        why = session.link_error or session.error
        arbiter.machine_lost()
        print(f"smoothjog: {why}; connecting again every {RECONNECT_S:g} s", file=sys.stderr)
        await session.close()
        last = ""
        while True:
            await asyncio.sleep(RECONNECT_S)
            link = make_link()
            if link is None:
                return
            try:
                await link.open()
                fresh = _make_host(link, config, timeout_s)
                if hooks is not None:
                    hooks.attach(fresh)
                await fresh.start()
            except (SmoothjogError, OSError) as exc:
                with contextlib.suppress(SmoothjogError, OSError):
                    await link.close()
                if str(exc) != last:  # said once, not every attempt
                    print(f"smoothjog: not connected yet: {exc}", file=sys.stderr, flush=True)
                    last = str(exc)
                continue
            backend.attach(fresh)
            if hooks is not None:
                hooks.started(fresh)
            print(f"smoothjog: connected again to {link.describe()}", file=sys.stderr, flush=True)
            arbiter.announce(f"connected again to {link.describe()}")
            break


async def run_session(
    prepared: PreparedSession,
    args: argparse.Namespace,
    *,
    hooks: SessionHooks | None = None,
    side: Callable[[], Coroutine[Any, Any, None]] | None = None,
) -> int:
    """The session until Ctrl-C or SIGTERM: host, pendant, devices, reconnect.

    hooks see every host (the first and each one after a lost link); side runs as one more
    task once the first host has started (the proxy's ports), and its failure ends the session.
    """
    config, link, timeout_s = prepared.config, prepared.link, prepared.timeout_s
    make_link = prepared.make_link
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop.set)
    async with link:
        session = _make_host(link, config, timeout_s)
        if hooks is not None:
            hooks.attach(session)
        model = await session.start()
        if hooks is not None:
            hooks.started(session)
        print(format_summary(model), flush=True)
        backend = SessionBackend(
            session,
            speed_ratios=config.jog.speed_ratios,
            default_speed=config.jog.default_speed,
        )
        if hooks is not None:
            hooks.gated(backend.gate)
        # One arbiter for the session: every input (the pages now, devices beside them) asks
        # it for control, and it owns the dead-man lease and the stop when an input goes away.
        arbiter = Arbiter(backend)
        host = args.host or config.pendant.host
        port = args.http_port if args.http_port is not None else config.pendant.port
        lan = bool(args.lan or config.pendant.lan)
        server = asyncio.create_task(
            run_pendant(backend, host=host, port=port, lan=lan, arbiter=arbiter)
        )
        waiter = asyncio.create_task(stop.wait())
        tasks = [server, waiter]
        ends = {server, waiter}  # any of these ending ends the session
        if side is not None:
            side_task = asyncio.create_task(side())
            tasks.append(side_task)
            ends.add(side_task)
        if make_link is not None:
            tasks.append(
                asyncio.create_task(
                    _keep_connected(backend, arbiter, make_link, config, timeout_s, hooks)
                )
            )
        if args.input or config.devices:
            manager = DeviceManager(
                arbiter,
                wishes=args.input,
                configs=config.devices,
                axes=lambda: backend.session.model.axis_letters,
                commands=MachineCommands(backend.control),
                view=machine_view(backend.control),
                notices=lambda text: _print_notice(text, arbiter),
            )
            tasks.append(asyncio.create_task(manager.run()))
        try:
            await asyncio.wait(ends, return_when=asyncio.FIRST_COMPLETED)
            if waiter.done():
                # Ctrl-C or SIGTERM: a stop like any other, whatever moves (a console line, a
                # sender's job, homing), before the session lets go of the machine.
                backend.gate.stop("a signal to smoothjog (Ctrl-C or SIGTERM)")
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            await backend.session.close()  # always: stop any jog with the handshake, let go
        for task in ends:
            if task.done() and not task.cancelled() and task.exception() is not None:
                raise task.exception()  # type: ignore[misc]  # e.g. the PendantError sentence
    print("smoothjog: stopped", flush=True)
    return 0
