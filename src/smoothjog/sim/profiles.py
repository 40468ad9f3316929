"""Firmware profiles (Grbl 1.1h, grblHAL, FluidNC) and machine profiles read from TOML files.

A firmware profile holds what differs between controller families (facts §7) plus the timing
parameters of the model; a machine profile holds `$` settings and how the machine starts.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from enum import Enum
from importlib import resources
from pathlib import Path
from typing import Any

from smoothjog.core.errors import SimError
from smoothjog.sim.rxbuffer import GRBL_REALTIME, GRBLHAL_EXTRA_REALTIME, Realtime
from smoothjog.sim.settings import GrblSettings


class JogClip(Enum):
    """What a controller does with a jog whose target lies outside the soft limits."""

    #: Grbl 1.1h: error:15, nothing moves (facts §2).
    REJECT = "reject"
    #: grblHAL: clip to the envelope when `$40=1`, otherwise error:15 (facts §7).
    CLIP_IF_40 = "clip_if_40"
    #: FluidNC: clip each axis to its soft limits, never an error (facts §7).
    CLIP_PER_AXIS = "clip_per_axis"


@dataclass(frozen=True)
class FirmwareProfile:
    """What differs between controller families, and the model's timing parameters."""

    name: str
    banner: str
    version_line: str
    options_line: str
    planner_blocks: int
    rx_size: int
    max_line_chars: int
    #: 0x85 empties the RX ring and drops a half-read line, in any state (grblHAL).
    cancel_flushes_rx: bool
    #: A jog line blocked waiting for a planner slot is dropped (answered ok) by a cancel (FluidNC).
    cancel_drops_blocked_jog: bool
    #: `!` in Jog cancels the jog (Grbl, FluidNC); grblHAL ignores it (facts §7, UNCERTAIN there).
    hold_cancels_jog: bool
    jog_clip: JogClip
    realtime: dict[int, Realtime]
    #: Time the main loop spends parsing and planning one line (s); see the profile comments.
    line_time_s: float
    #: Extra settings this family has beyond Grbl's (grblHAL's $40 jog limit).
    extra_settings: dict[int, float] = field(default_factory=dict)
    #: The blocking pause after an ALARM message (facts §5.3).
    alarm_pause_s: float = 0.5
    #: The TX ring: when output does not fit, the main loop waits for it to drain (facts §5.1).
    tx_size: int = 104


# Timing parameters (assumptions where the facts are silent):
# - line_time_s: Grbl 1.1h on a 16 MHz AVR needs roughly 1-5 ms to parse and plan a jog line
#   (facts §9, seed "around 1 to 5 ms"); soft-float parsing of a ~20-char line is about 0.5 ms and
#   the planner's reverse/forward pass over up to 15 blocks about 1 ms, so 1.5 ms is used. The
#   32-bit controllers (grblHAL, FluidNC) have an FPU and 10x the clock: 0.3 ms.
# - alarm_pause_s: the 500 ms delay after an ALARM message (facts §5.3).
# - tx_size: Grbl 1.1h's 104-byte TX ring (facts §5.1). The facts give none for grblHAL and
#   FluidNC; both queue output in buffers of a kilobyte or more, so 1024 is assumed (in effect:
#   their main loop never waits for the wire).
GRBL = FirmwareProfile(
    name="grbl",
    banner="Grbl 1.1h ['$' for help]",
    version_line="[VER:1.1h.20190830:{user}]",
    options_line="[OPT:V,15,128]",
    planner_blocks=15,
    rx_size=128,
    max_line_chars=79,
    cancel_flushes_rx=False,
    cancel_drops_blocked_jog=False,
    hold_cancels_jog=True,
    jog_clip=JogClip.REJECT,
    realtime=dict(GRBL_REALTIME),
    line_time_s=0.0015,
)

GRBLHAL = FirmwareProfile(
    name="grblhal",
    banner="GrblHAL 1.1f ['$' or '$HELP' for help]",
    version_line="[VER:1.1f.20260817:{user}]",
    options_line="[OPT:V,100,1024]",
    planner_blocks=100,
    rx_size=1024,
    max_line_chars=256,
    cancel_flushes_rx=True,
    # The facts find no explicit handling of a blocked jog in grblHAL (UNCERTAIN); Grbl's
    # behaviour (the line is planned after the cancel) is kept.
    cancel_drops_blocked_jog=False,
    hold_cancels_jog=False,
    jog_clip=JogClip.CLIP_IF_40,
    realtime={**GRBL_REALTIME, **GRBLHAL_EXTRA_REALTIME},
    line_time_s=0.0003,
    extra_settings={40: 0},
    tx_size=1024,
)

# FluidNC: 16 planner blocks with Bf = blocks - 1, i.e. 15 usable and reported (facts §7).
FLUIDNC = FirmwareProfile(
    name="fluidnc",
    banner="Grbl 3.9 [FluidNC v3.9.1 (sim-uart) '$' for help]",
    version_line="[VER:3.9 FluidNC v3.9.1:{user}]",
    options_line="[OPT:V,15,256]",
    planner_blocks=15,
    rx_size=256,
    max_line_chars=255,
    cancel_flushes_rx=False,
    cancel_drops_blocked_jog=True,
    hold_cancels_jog=True,
    jog_clip=JogClip.CLIP_PER_AXIS,
    realtime=dict(GRBL_REALTIME),
    line_time_s=0.0003,
    tx_size=1024,
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
    for number in (*range(100, 100 + n_axes), *range(110, 110 + n_axes), *range(120, 120 + n_axes)):
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
