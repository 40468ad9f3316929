"""The controller families smoothjog drives, as one table of the firmware facts a jog host needs.

One row per family: Grbl 1.1h, grblHAL and FluidNC. Each holds the numbers a host must respect
(longest line, planner blocks, RX and TX buffers; firmware-facts §4.1, §5.1, §7), what a jog cancel
does there (§3.1, §3.2, §7), what a jog outside the soft limits does (§2, §7), and how `$I` names
the family. The buffer figures are the firmware's defaults: a controller's own `[OPT:]` line wins
over them (`MachineModel` does that). `DEFAULT_BAUD` is the serial speed all three ship with.
Everything else (the engine, the machine model, the simulator's profiles) reads these rows
instead of restating the numbers.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from types import MappingProxyType
from typing import Final, Literal, Protocol

from smoothjog.core.errors import CoreError

FirmwareName = Literal["grbl", "grblhal", "fluidnc"]

#: Serial speed of the default builds (Grbl's `config.h` BAUD_RATE, firmware-facts §0, §5.1), sent
#: 8N1.
DEFAULT_BAUD: Final = 115200
#: Bits on the wire per byte at 8N1: a start bit, eight data bits, a stop bit.
BITS_PER_BYTE_8N1: Final = 10


class JogClip(Enum):
    """What a controller does with a jog whose target lies outside the soft limits."""

    #: Grbl 1.1h: error:15, nothing moves (firmware-facts §2).
    REJECT = "reject"
    #: grblHAL: clip to the envelope when `$40=1`, otherwise error:15 (firmware-facts §7).
    CLIP_IF_40 = "clip_if_40"
    #: FluidNC: clip each axis to its soft limits, never an error (firmware-facts §7).
    CLIP_PER_AXIS = "clip_per_axis"


@dataclass(frozen=True, slots=True)
class JogCancel:
    """What ending a jog with 0x85 (or `!`) leaves behind on one firmware.

    On all three families 0x85 stops motion only while the state is Jog (firmware-facts §3.1, §7);
    these flags say what else happens.
    """

    #: 0x85 empties the serial RX buffer and drops a half-read line, in any state (grblHAL).
    #: False: complete `$J=` lines still waiting there run after the cancel as new jogs.
    flushes_rx: bool
    #: A jog line already parsed and waiting for a planner slot is dropped (and answered `ok`)
    #: by the cancel (FluidNC). False: it is planned after the cancel and travels in full.
    drops_blocked_jog: bool
    #: A feed hold `!` sent in Jog cancels the jog exactly like 0x85 (Grbl, FluidNC).
    feed_hold_cancels: bool
    #: A 0x85 landing in a cancel's last moments leaves the controller suspended in Idle, taking
    #: no line until `~` (Grbl 1.1h, firmware-facts §3.8; not checked on grblHAL and FluidNC).
    late_cancel_suspends: bool = False


@dataclass(frozen=True, slots=True)
class FirmwareFacts:
    """One controller family: its limits and buffers (defaults) and its jog behaviour."""

    name: FirmwareName
    #: Longest line the controller stores, in characters (Grbl: 79; one more is error:11).
    max_line_chars: int
    #: Planner size as the firmware states it by default (`[OPT:]` or its own config).
    planner_blocks: int
    #: Blocks the host can never fill: `Bf` shows planner_blocks minus this when empty.
    planner_blocks_hidden: int
    #: Serial receive buffer in bytes (`Bf`'s second value when empty, `[OPT:]`'s third).
    rx_buffer_bytes: int
    #: Serial transmit buffer in bytes; when an answer does not fit, the main loop waits.
    tx_buffer_bytes: int
    jog_cancel: JogCancel
    jog_clip: JogClip
    #: Text in `$I`'s `[VER:...]` line that names this family, if it prints one.
    version_marker: str | None = None
    #: An `$I` feedback line (without brackets, any case) that names this family, if any.
    info_line: str | None = None
    #: `ALARM:N` codes after which the controller reads no line until a reset (its critical
    #: event loop, firmware-facts §5.6a); Grbl 1.1h's hard and soft limit by default.
    critical_alarms: frozenset[int] = frozenset({1, 2})

    @property
    def planner_usable_blocks(self) -> int:
        """Blocks a host can fill by default: what `Bf` shows with the planner empty."""
        return self.planner_blocks - self.planner_blocks_hidden


# TX buffers: Grbl 1.1h's ring is 104 bytes (firmware-facts §5.1). The facts give no figure for
# grblHAL and FluidNC; both queue output in buffers of a kilobyte or more, so 1024 is assumed
# (in effect their main loop never waits for the wire).
GRBL: Final = FirmwareFacts(
    name="grbl",
    max_line_chars=79,
    # [OPT:] already counts usable blocks: 15 of a 16-slot ring (firmware-facts §4.1).
    planner_blocks=15,
    planner_blocks_hidden=0,
    rx_buffer_bytes=128,
    tx_buffer_bytes=104,
    jog_cancel=JogCancel(
        flushes_rx=False,
        drops_blocked_jog=False,
        feed_hold_cancels=True,
        late_cancel_suspends=True,
    ),
    jog_clip=JogClip.REJECT,
)

GRBLHAL: Final = FirmwareFacts(
    name="grblhal",
    max_line_chars=256,
    planner_blocks=100,  # `$398`; every block is usable
    planner_blocks_hidden=0,
    rx_buffer_bytes=1024,
    tx_buffer_bytes=1024,
    # A blocked jog line during a cancel: no handling found (UNCERTAIN), so Grbl's is assumed.
    # `!` in Jog: the state machine appears to ignore it (UNCERTAIN; use 0x85).
    jog_cancel=JogCancel(flushes_rx=True, drops_blocked_jog=False, feed_hold_cancels=False),
    jog_clip=JogClip.CLIP_IF_40,
    info_line="FIRMWARE:grblHAL",
    # Hard and soft limit, E-stop, motor fault, I/O expander failure (alarms.h:alarm_is_critical).
    critical_alarms=frozenset({1, 2, 10, 17, 20}),
)

FLUIDNC: Final = FirmwareFacts(
    name="fluidnc",
    max_line_chars=255,
    planner_blocks=16,  # `planner_blocks` in config.yaml
    planner_blocks_hidden=1,  # Bf = planner_blocks - 1
    rx_buffer_bytes=256,
    tx_buffer_bytes=1024,
    jog_cancel=JogCancel(flushes_rx=False, drops_blocked_jog=True, feed_hold_cancels=True),
    jog_clip=JogClip.CLIP_PER_AXIS,
    version_marker="FluidNC",
)

#: Every family by name, in the order smoothjog lists them.
FIRMWARES: Final[MappingProxyType[str, FirmwareFacts]] = MappingProxyType(
    {facts.name: facts for facts in (GRBL, GRBLHAL, FLUIDNC)}
)
#: The family names, for option choices and config checks.
FIRMWARE_NAMES: Final[tuple[FirmwareName, ...]] = tuple(f.name for f in FIRMWARES.values())


class _RunsFirmware(Protocol):
    """Anything that knows which family its controller is (a MachineModel)."""

    @property
    def firmware(self) -> str:
        """The family name."""
        ...


def firmware_facts(name: str) -> FirmwareFacts:
    """The row of the family called name (grbl, grblhal, fluidnc; any case)."""
    facts = FIRMWARES.get(name.lower())
    if facts is None:
        raise CoreError(
            f"unknown controller firmware {name!r}: choose one of {', '.join(FIRMWARE_NAMES)}"
        )
    return facts


def for_model(model: _RunsFirmware) -> FirmwareFacts:
    """The row of the family a machine model's controller runs."""
    return firmware_facts(model.firmware)


def named_by_version(version: str) -> FirmwareName | None:
    """The family whose marker is in `$I`'s version text, or None (Grbl and grblHAL have none)."""
    for facts in FIRMWARES.values():
        if facts.version_marker is not None and facts.version_marker in version:
            return facts.name
    return None


def named_by_info(text: str) -> FirmwareName | None:
    """The family an `$I` feedback line such as `[FIRMWARE:grblHAL]` names, or None."""
    lowered = text.lower()
    for facts in FIRMWARES.values():
        if facts.info_line is not None and facts.info_line.lower() == lowered:
            return facts.name
    return None
