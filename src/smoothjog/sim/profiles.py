"""Firmware profiles (Grbl 1.1h, grblHAL, FluidNC) and machine profiles read from TOML files.

A firmware profile pairs a family's row of the firmware table (core/firmware.py: buffers, line
length, jog-cancel and soft-limit behaviour, firmware-facts §7) with what only the simulator needs:
the texts it prints and the timing parameters of the model. A machine profile holds `$` settings and
how the machine starts.
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from smoothjog.core import firmware as firmware_table
from smoothjog.core.defaults import ACCEL_SETTING, MAX_RATE_SETTING, STEPS_PER_MM_SETTING
from smoothjog.core.errors import SimError
from smoothjog.core.firmware import FirmwareFacts
from smoothjog.core.realtime import GRBL_REALTIME, GRBLHAL_ALIASES, Realtime
from smoothjog.sim.settings import GrblSettings


@dataclass(frozen=True)
class FirmwareProfile:
    """A simulated controller family: its firmware facts, its texts, the model's timings."""

    facts: FirmwareFacts
    banner: str
    version_line: str
    #: Received byte value -> realtime meaning; other bytes >= 0x80 are dropped.
    realtime: Mapping[int, Realtime]
    #: Time the main loop spends parsing and planning one line (s); see the profile comments.
    line_time_s: float
    #: Extra settings this family has beyond Grbl's (grblHAL's $40 jog limit).
    extra_settings: dict[int, float] = field(default_factory=dict)
    #: The blocking pause after an ALARM message (firmware-facts §5.3).
    alarm_pause_s: float = 0.5
    #: Integer settings kept in 16 bits rather than one byte (grblHAL's `$10` report mask).
    word_settings: frozenset[int] = frozenset()
    #: The `$10` bit that asks for status reports during homing (grblHAL's bit 12,
    #: `status_report.when_homing`, firmware-facts §5.6a); None: none are made (Grbl 1.1h).
    homing_report_bit: int | None = None

    @property
    def name(self) -> str:
        """The family name (grbl, grblhal, fluidnc)."""
        return self.facts.name

    @property
    def options_line(self) -> str:
        """`$I`'s `[OPT:]` line: variable spindle, usable planner blocks, RX bytes (firmware-facts
        §4.1)."""
        return f"[OPT:V,{self.facts.planner_usable_blocks},{self.facts.rx_buffer_bytes}]"


# Timing parameters (assumptions where the facts are silent):
# - line_time_s: Grbl 1.1h on a 16 MHz AVR needs roughly 1-5 ms to parse and plan a jog line
#   (firmware-facts §9); soft-float parsing of a ~20-char line is about 0.5 ms and the planner's
#   reverse/forward pass over up to 15 blocks about 1 ms, so 1.5 ms is used. The 32-bit
#   controllers (grblHAL, FluidNC) have an FPU and 10x the clock: 0.3 ms.
# - alarm_pause_s: the 500 ms delay after an ALARM message (firmware-facts §5.3).
GRBL = FirmwareProfile(
    facts=firmware_table.GRBL,
    banner="Grbl 1.1h ['$' for help]",
    version_line="[VER:1.1h.20190830:{user}]",
    realtime=dict(GRBL_REALTIME),
    line_time_s=0.0015,
)

# grblHAL's other extra realtime bytes (firmware-facts §7) are not modelled: the simulator drops
# them.
GRBLHAL = FirmwareProfile(
    facts=firmware_table.GRBLHAL,
    banner="GrblHAL 1.1f ['$' or '$HELP' for help]",
    version_line="[VER:1.1f.20260817:{user}]",
    realtime={**GRBL_REALTIME, **GRBLHAL_ALIASES},
    line_time_s=0.0003,
    extra_settings={40: 0},
    word_settings=frozenset({10}),
    homing_report_bit=12,
)

FLUIDNC = FirmwareProfile(
    facts=firmware_table.FLUIDNC,
    banner="Grbl 3.9 [FluidNC v3.9.1 (sim-uart) '$' for help]",
    version_line="[VER:3.9 FluidNC v3.9.1:{user}]",
    realtime=dict(GRBL_REALTIME),
    line_time_s=0.0003,
)

FIRMWARE_PROFILES: dict[str, FirmwareProfile] = {p.name: p for p in (GRBL, GRBLHAL, FLUIDNC)}


def get_firmware_profile(name: str) -> FirmwareProfile:
    """The firmware profile called name (grbl, grblhal, fluidnc)."""
    try:
        return FIRMWARE_PROFILES[name.lower()]
    except KeyError:
        raise SimError(
            f"unknown firmware profile {name!r}; choose one of {', '.join(FIRMWARE_PROFILES)}"
        ) from None


@dataclass(frozen=True)
class MachineProfile:
    """A machine: its `$` settings and how it starts."""

    name: str
    description: str
    n_axes: int
    settings: dict[int, float]
    #: "power-up": MPos 0 and Alarm if $22=1 (HOMING_INIT_LOCK); "homed": Idle at the pull-off
    #: corner, as if `$H` had just run, so jogs work at once.
    start: str
    source: str

    def apply(self, settings: GrblSettings) -> None:
        """Write this profile's settings over the defaults."""
        for number, value in self.settings.items():
            settings.force(number, value)


_MACHINE_KEYS = frozenset({"name", "description", "axes", "start", "settings"})
_STARTS = ("power-up", "homed")


def _machines_dir() -> Any:
    """The packaged folder of machine profiles."""
    return resources.files("smoothjog").joinpath("data", "machines")


def available_machine_profiles() -> list[str]:
    """Names of the machine profiles shipped with smoothjog."""
    names = [
        entry.name.removesuffix(".toml")
        for entry in _machines_dir().iterdir()
        if entry.name.endswith(".toml")
    ]
    return sorted(names)


def load_machine_profile(name_or_path: str | Path) -> MachineProfile:
    """A shipped profile by name, or a user's TOML file by path."""
    text_path = str(name_or_path)
    if text_path.endswith(".toml") or "/" in text_path or isinstance(name_or_path, Path):
        path = Path(name_or_path)
        if not path.is_file():
            raise SimError(f"machine profile file {path} does not exist")
        return parse_machine_profile(path.read_text(encoding="utf-8"), str(path))
    entry = _machines_dir().joinpath(f"{text_path}.toml")
    if not entry.is_file():
        raise SimError(
            f"unknown machine profile {text_path!r}; available: "
            f"{', '.join(available_machine_profiles())} (or give the path of a .toml file)"
        )
    return parse_machine_profile(entry.read_text(encoding="utf-8"), f"{text_path}.toml")


def parse_machine_profile(text: str, source: str) -> MachineProfile:
    """Parse and check one machine profile's TOML text; errors name source and key."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SimError(f"{source}: not valid TOML ({exc})") from None
    for key in data:
        if key not in _MACHINE_KEYS:
            raise SimError(
                f"{source}: unknown key {key!r};"
                f" allowed keys are {', '.join(sorted(_MACHINE_KEYS))}"
            )
    name = data.get("name", Path(source).stem)
    description = data.get("description", "")
    if not isinstance(name, str) or not isinstance(description, str):
        raise SimError(f"{source}: 'name' and 'description' must be strings")
    n_axes = data.get("axes", 3)
    if not isinstance(n_axes, int) or isinstance(n_axes, bool) or not 3 <= n_axes <= 6:
        raise SimError(f"{source}: key 'axes' must be an integer from 3 to 6, not {n_axes!r}")
    start = data.get("start", "power-up")
    if start not in _STARTS:
        raise SimError(f"{source}: key 'start' must be one of {', '.join(_STARTS)}, not {start!r}")
    raw_settings = data.get("settings", {})
    if not isinstance(raw_settings, dict):
        raise SimError(f"{source}: 'settings' must be a table of $number = value")
    valid = GrblSettings(n_axes)
    settings: dict[int, float] = {}
    for key, value in raw_settings.items():
        number_text = key.removeprefix("$")
        if not number_text.isdigit():
            raise SimError(f"{source}: settings key {key!r} is not a setting number like 110")
        number = int(number_text)
        try:
            valid[number]
        except KeyError:
            raise SimError(
                f"{source}: settings key {key!r} is not a setting of a {n_axes}-axis Grbl"
            ) from None
        if isinstance(value, bool) or not isinstance(value, int | float) or value < 0:
            raise SimError(f"{source}: settings key {key!r} must be a number >= 0, not {value!r}")
        settings[number] = float(value)
    # A zero steps/mm, rate or acceleration would divide by zero in the planner model.
    for group in (STEPS_PER_MM_SETTING, MAX_RATE_SETTING, ACCEL_SETTING):
        for number in range(group, group + n_axes):
            if settings.get(number, 1.0) <= 0.0:
                raise SimError(f"{source}: settings key '{number}' must be greater than 0")
    return MachineProfile(
        name=name,
        description=description,
        n_axes=n_axes,
        settings=settings,
        start=start,
        source=source,
    )
