"""Read the TOML configuration into frozen dataclasses, checking every value where it is read.

Every key is documented in docs/config.md. A key that nothing reads is an error (most often a
typo), and every error names the file, the section and the key, says what is wrong and how to
fix it. Lengths are machine millimetres, times are seconds, speeds are fractions of the
controller's own maxima (`$110...`).
"""

from __future__ import annotations

import os
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

from smoothjog.core.errors import ConfigError, LinkError
from smoothjog.core.firmware import DEFAULT_BAUD, FIRMWARE_NAMES
from smoothjog.core.machine import KeepOut
from smoothjog.core.options import Table
from smoothjog.core.units import ALL_AXES
from smoothjog.links.cncjs import parse_cncjs_url
from smoothjog.links.tcp import parse_tcp_url

#: Environment variable naming a config file when none is given on the command line.
CONFIG_ENV = "SMOOTHJOG_CONFIG"
#: The pendant's TCP port unless [pendant] port or --http-port says otherwise. It lives here with
#: the other [pendant] defaults, the one module both the CLI and the web server may import.
DEFAULT_HTTP_PORT = 8080
MAX_TIMEOUT_S = 600.0
MAX_LINK_MARGIN_S = 1.0


@dataclass(frozen=True, slots=True)
class ConnectionConfig:
    """Where the controller is: a serial port or a TCP address (neither: the simulator)."""

    port: str | None = None
    baud: int = DEFAULT_BAUD
    connect: str | None = None  # tcp://HOST:PORT
    timeout_s: float = 5.0
    # Through a CNCjs server that owns the port (links/cncjs.py, docs/cncjs.md).
    cncjs: str | None = None  # http://HOST:PORT of CNCjs
    cncjs_port: str | None = None  # the controller's port as CNCjs names it
    cncjs_config: str | None = None  # CNCjs's config file, for its secret (~/.cncrc if None)
    cncjs_token: str | None = None  # a token instead of signing one
    cncjs_user: str | None = None  # the CNCjs user the token names, when users are configured


@dataclass(frozen=True, slots=True)
class JogConfig:
    """How jogs feel: per-axis speed ratios, the starting speed, the link's time margin."""

    # Fraction (0, 1] of each axis's `$11x` maximum rate; axes not listed use 1.
    speed_ratios: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))
    default_speed: float = 0.5  # fraction (0, 1] of the full jog speed at start-up
    link_margin_s: float = 0.0  # queue time added to what the engine measures of the link

    def ratio(self, axis: str) -> float:
        """The speed ratio of one axis (1.0 when not configured)."""
        return self.speed_ratios.get(axis.upper(), 1.0)


@dataclass(frozen=True, slots=True)
class PendantConfig:
    """The web pendant's address."""

    host: str = "127.0.0.1"
    port: int = DEFAULT_HTTP_PORT
    lan: bool = False  # reachable from other devices on the local network


@dataclass(frozen=True, slots=True)
class SimConfig:
    """The built-in simulator used when no controller is given."""

    firmware: str = "grbl"
    machine: str = "hobby-router"


@dataclass(frozen=True, slots=True)
class DeviceConfig:
    """One [[device]] table: which input devices it is for, and its decoder's options.

    The options are read by the decoder (inputs/), which knows its own keys; `table()` gives
    them with this file and section named, so its errors point here.
    """

    kind: str
    match: str | None  # None: every device this kind takes
    options: Mapping[str, Any]
    section: str
    source: str

    def table(self) -> Table:
        """The decoder's options as a Table naming this file and section in its errors."""
        return Table(self.options, self.section, self.source)


@dataclass(frozen=True, slots=True)
class Config:
    """The whole configuration; `source` is the file it came from (None: built-in defaults)."""

    connection: ConnectionConfig = field(default_factory=ConnectionConfig)
    jog: JogConfig = field(default_factory=JogConfig)
    keepouts: tuple[KeepOut, ...] = ()
    pendant: PendantConfig = field(default_factory=PendantConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    devices: tuple[DeviceConfig, ...] = ()
    source: Path | None = None


def _connection(table: Table) -> ConnectionConfig:
    """Read [connection]."""
    port = table.text("port", None)
    connect = table.text("connect", None)
    cncjs = table.text("cncjs", None)
    if port is not None and connect is not None:
        raise table.error("connect", "and port are both set: keep the one you use")
    if cncjs is not None and (port is not None or connect is not None):
        raise table.error("cncjs", "is set beside port or connect: keep the one you use")
    if connect is not None:
        try:
            parse_tcp_url(connect)
        except LinkError as exc:
            raise table.error("connect", f"is wrong: {exc}") from None
    if cncjs is not None:
        try:
            parse_cncjs_url(cncjs)
        except LinkError as exc:
            raise table.error("cncjs", f"is wrong: {exc}") from None
    baud = table.integer("baud", DEFAULT_BAUD, at_least=1, at_most=10_000_000)
    timeout_s = table.number("timeout_s", 5.0, above=0.0, at_most=MAX_TIMEOUT_S)
    cncjs_port = table.text("cncjs_port", None)
    cncjs_config = table.text("cncjs_config", None)
    cncjs_user = table.text("cncjs_user", None)
    if cncjs is not None and cncjs_port is None:
        raise table.error("cncjs", "needs cncjs_port: the controller's port as CNCjs names it")
    table.finish()
    return ConnectionConfig(
        port=port,
        baud=baud,
        connect=connect,
        timeout_s=timeout_s,
        cncjs=cncjs,
        cncjs_port=cncjs_port,
        cncjs_config=cncjs_config,
        cncjs_user=cncjs_user,
    )


def _jog(table: Table) -> JogConfig:
    """Read [jog]."""
    ratios: dict[str, float] = {}
    raw_ratios = table.table("speed_ratios")
    for axis, value in raw_ratios.items():
        letter = axis.upper()
        key = f"speed_ratios.{axis}"
        if letter not in ALL_AXES:
            raise table.error(key, f"names no axis: use one of {', '.join(ALL_AXES)}")
        if letter in ratios:
            raise table.error(key, "is given twice (letters are not case-sensitive)")
        ratios[letter] = table.check_number(key, value, above=0.0, at_most=1.0)
    default_speed = table.number("default_speed", 0.5, above=0.0, at_most=1.0)
    link_margin_s = table.number("link_margin_s", 0.0, at_least=0.0, at_most=MAX_LINK_MARGIN_S)
    table.finish()
    return JogConfig(
        speed_ratios=MappingProxyType(ratios),
        default_speed=default_speed,
        link_margin_s=link_margin_s,
    )


def _keepouts(value: Any, source: str) -> tuple[KeepOut, ...]:
    """Read the [[keepout]] array."""
    if not isinstance(value, list):
        raise ConfigError(f"{source}: keepout must be written as [[keepout]] tables")
    zones: list[KeepOut] = []
    for index, item in enumerate(value, start=1):
        section = f"keepout #{index}"
        if not isinstance(item, dict):
            raise ConfigError(f"{source}: [{section}] is not a table: write it as [[keepout]]")
        table = Table(item, section, source)
        name = table.text("name", None)
        if name is None:
            raise table.error("name", 'is missing: give every zone a name, e.g. name = "vise"')
        table.section = f"keepout {name!r}"
        if any(zone.name == name for zone in zones):
            raise table.error("name", f"= {name!r} is used twice: give each zone its own name")
        min_mm = table.numbers("min_mm")
        max_mm = table.numbers("max_mm")
        if len(min_mm) != len(max_mm):
            raise table.error(
                "max_mm",
                f"has {len(max_mm)} numbers but min_mm has {len(min_mm)}: give both"
                " corners the same axes",
            )
        for axis, lo, hi in zip(ALL_AXES, min_mm, max_mm, strict=False):
            if not lo < hi:
                raise table.error(
                    "min_mm", f"on axis {axis} ({lo:g}) is not below max_mm ({hi:g}): swap them"
                )
        table.finish()
        # Whether the machine has every axis the zone names is known only after the connect
        # handshake; MachineModel.set_keep_outs checks it then, naming this file and the key.
        zones.append(KeepOut(name, min_mm, max_mm, source=source))
    return tuple(zones)


def _devices(value: Any, source: str) -> tuple[DeviceConfig, ...]:
    """Read the [[device]] array (the decoders check their own options when they are built)."""
    if not isinstance(value, list):
        raise ConfigError(f"{source}: device must be written as [[device]] tables")
    devices: list[DeviceConfig] = []
    for index, item in enumerate(value, start=1):
        section = f"device #{index}"
        if not isinstance(item, dict):
            raise ConfigError(f"{source}: [{section}] is not a table: write it as [[device]]")
        table = Table(item, section, source)
        kind = table.text("kind", None)
        if kind is None:
            raise table.error(
                "kind", 'is missing: say which kind of device this is, e.g. kind = "gamepad"'
            )
        match = table.text("match", None)
        options = {k: v for k, v in item.items() if k not in ("kind", "match")}
        devices.append(DeviceConfig(kind, match, options, f"{section} ({kind})", source))
    return tuple(devices)


def _pendant(table: Table) -> PendantConfig:
    """Read [pendant]."""
    host = table.text("host", "127.0.0.1")
    assert host is not None  # a default is given
    port = table.integer("port", DEFAULT_HTTP_PORT, at_least=1, at_most=65535)
    lan = table.flag("lan", False)
    table.finish()
    return PendantConfig(host=host, port=port, lan=lan)


def _sim(table: Table) -> SimConfig:
    """Read [sim]."""
    firmware = table.choice("firmware", "grbl", FIRMWARE_NAMES)
    machine = table.text("machine", "hobby-router")
    assert machine is not None  # a default is given
    table.finish()
    return SimConfig(firmware=firmware, machine=machine)


_SECTIONS = ("connection", "device", "jog", "keepout", "pendant", "sim")


def parse_config(text: str, source: str = "<config>") -> Config:
    """Parse TOML text into a Config; source names the file in messages."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: not valid TOML: {exc}") from None
    for key, value in data.items():
        if key not in _SECTIONS:
            raise ConfigError(
                f"{source}: unknown section {key!r}: the sections are {', '.join(_SECTIONS)}"
                " (check the spelling)"
            )
        if key not in ("keepout", "device") and not isinstance(value, dict):
            raise ConfigError(f"{source}: {key} must be a section, written [{key}]")

    def section(name: str) -> Table:
        return Table(data.get(name, {}), name, source)

    return Config(
        connection=_connection(section("connection")),
        jog=_jog(section("jog")),
        keepouts=_keepouts(data.get("keepout", []), source),
        pendant=_pendant(section("pendant")),
        sim=_sim(section("sim")),
        devices=_devices(data.get("device", []), source),
    )


def load_config(
    path: str | os.PathLike[str] | None = None,
    *,
    environ: Mapping[str, str] | None = None,
) -> Config:
    """Load the config file at path, else the one $SMOOTHJOG_CONFIG names, else the defaults."""
    env = os.environ if environ is None else environ
    origin = "given with --config"
    if path is None and env.get(CONFIG_ENV):
        path = env[CONFIG_ENV]
        origin = f"named by ${CONFIG_ENV}"
    if path is None:
        return Config()
    file = Path(path)
    try:
        raw = file.read_bytes()
    except FileNotFoundError:
        raise ConfigError(
            f"config file {file} ({origin}) does not exist: check the path, or leave it out to"
            " use the defaults"
        ) from None
    except IsADirectoryError:
        raise ConfigError(
            f"config file {file} ({origin}) is a directory: name a .toml file"
        ) from None
    except OSError as exc:
        raise ConfigError(f"cannot read config file {file} ({origin}): {exc.strerror}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{file}: not UTF-8 text (byte {exc.start}): save it as UTF-8") from None
    return replace(parse_config(text, str(file)), source=file)
