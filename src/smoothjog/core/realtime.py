"""The realtime command bytes of the Grbl family, defined once: their values and what they ask.

A realtime byte is picked out of the serial stream wherever it appears (mid-line, inside a
comment) and never reaches the line buffer (firmware-facts §1.1, §5.2). Values are Grbl 1.1h's
`config.h` CMD_* codes (firmware-facts §5.2) plus grblHAL's additions (firmware-facts §7). Each
constant is the one byte to send; `GRBL_REALTIME` and `GRBLHAL_ALIASES` map received byte values to
their meaning for anything that models a controller.
"""

from __future__ import annotations

from enum import Enum
from types import MappingProxyType
from typing import Final

# --- Grbl 1.1h (firmware-facts §5.2)
# ---------------------------------------------------------------------
RESET: Final = b"\x18"  # Ctrl-X, soft reset (firmware-facts §3.4)
STATUS_QUERY: Final = b"?"
CYCLE_START: Final = b"~"
FEED_HOLD: Final = b"!"
SAFETY_DOOR: Final = b"\x84"
JOG_CANCEL: Final = b"\x85"
FEED_OVR_RESET: Final = b"\x90"  # back to 100 %
FEED_OVR_COARSE_PLUS: Final = b"\x91"  # +10 %
FEED_OVR_COARSE_MINUS: Final = b"\x92"  # -10 %
FEED_OVR_FINE_PLUS: Final = b"\x93"  # +1 %
FEED_OVR_FINE_MINUS: Final = b"\x94"  # -1 %
RAPID_OVR_RESET: Final = b"\x95"  # 100 %
RAPID_OVR_MEDIUM: Final = b"\x96"  # 50 %
RAPID_OVR_LOW: Final = b"\x97"  # 25 %
SPINDLE_OVR_RESET: Final = b"\x99"  # back to 100 %
SPINDLE_OVR_COARSE_PLUS: Final = b"\x9a"  # +10 %
SPINDLE_OVR_COARSE_MINUS: Final = b"\x9b"  # -10 %
SPINDLE_OVR_FINE_PLUS: Final = b"\x9c"  # +1 %
SPINDLE_OVR_FINE_MINUS: Final = b"\x9d"  # -1 %
SPINDLE_STOP: Final = b"\x9e"  # toggle, in Hold only
FLOOD_TOGGLE: Final = b"\xa0"
MIST_TOGGLE: Final = b"\xa1"

# --- grblHAL's additions (firmware-facts §7)
# -------------------------------------------------------------
GRBLHAL_STOP: Final = b"\x19"
GRBLHAL_STATUS_QUERY: Final = b"\x80"  # same as `?`
GRBLHAL_CYCLE_START: Final = b"\x81"  # same as `~`
GRBLHAL_FEED_HOLD: Final = b"\x82"  # same as `!`
GRBLHAL_GCODE_REPORT: Final = b"\x83"
GRBLHAL_FULL_STATUS: Final = b"\x87"
GRBLHAL_OPTIONAL_STOP_TOGGLE: Final = b"\x88"
GRBLHAL_SINGLE_BLOCK_TOGGLE: Final = b"\x89"
GRBLHAL_MPG_TOGGLE: Final = b"\x8b"
GRBLHAL_AUTO_REPORT_TOGGLE: Final = b"\x8c"

#: From this value up every byte is a realtime command or dropped, never part of a line (§5.2).
EXTENDED_START: Final = 0x80
#: Realtime commands that are printable ASCII: inside a line they would act at once instead.
PRINTABLE_REALTIME: Final = frozenset(STATUS_QUERY + FEED_HOLD + CYCLE_START)
#: Every realtime command below EXTENDED_START on any of the three families.
LOW_REALTIME: Final = PRINTABLE_REALTIME | frozenset(RESET + GRBLHAL_STOP)


class Realtime(Enum):
    """What a realtime byte asks of the controller."""

    STATUS = "status"
    CYCLE_START = "cycle_start"
    FEED_HOLD = "feed_hold"
    RESET = "reset"
    SAFETY_DOOR = "safety_door"
    JOG_CANCEL = "jog_cancel"
    FEED_OVR_RESET = "feed_ovr_reset"
    FEED_OVR_COARSE_PLUS = "feed_ovr_coarse_plus"
    FEED_OVR_COARSE_MINUS = "feed_ovr_coarse_minus"
    FEED_OVR_FINE_PLUS = "feed_ovr_fine_plus"
    FEED_OVR_FINE_MINUS = "feed_ovr_fine_minus"
    RAPID_OVR_RESET = "rapid_ovr_reset"
    RAPID_OVR_MEDIUM = "rapid_ovr_medium"
    RAPID_OVR_LOW = "rapid_ovr_low"
    SPINDLE_OVR_RESET = "spindle_ovr_reset"
    SPINDLE_OVR_COARSE_PLUS = "spindle_ovr_coarse_plus"
    SPINDLE_OVR_COARSE_MINUS = "spindle_ovr_coarse_minus"
    SPINDLE_OVR_FINE_PLUS = "spindle_ovr_fine_plus"
    SPINDLE_OVR_FINE_MINUS = "spindle_ovr_fine_minus"
    SPINDLE_STOP = "spindle_stop"
    FLOOD_TOGGLE = "flood_toggle"
    MIST_TOGGLE = "mist_toggle"
    #: A byte >= 0x80 the firmware does not use: dropped without effect.
    DISCARD = "discard"


def _by_value(rows: tuple[tuple[bytes, Realtime], ...]) -> MappingProxyType[int, Realtime]:
    """A received-byte-value -> meaning table from (command byte, meaning) rows."""
    return MappingProxyType({command[0]: meaning for command, meaning in rows})


#: Grbl 1.1h's realtime bytes by value; any other byte >= 0x80 is dropped (firmware-facts §5.2).
GRBL_REALTIME: Final = _by_value(
    (
        (RESET, Realtime.RESET),
        (STATUS_QUERY, Realtime.STATUS),
        (CYCLE_START, Realtime.CYCLE_START),
        (FEED_HOLD, Realtime.FEED_HOLD),
        (SAFETY_DOOR, Realtime.SAFETY_DOOR),
        (JOG_CANCEL, Realtime.JOG_CANCEL),
        (FEED_OVR_RESET, Realtime.FEED_OVR_RESET),
        (FEED_OVR_COARSE_PLUS, Realtime.FEED_OVR_COARSE_PLUS),
        (FEED_OVR_COARSE_MINUS, Realtime.FEED_OVR_COARSE_MINUS),
        (FEED_OVR_FINE_PLUS, Realtime.FEED_OVR_FINE_PLUS),
        (FEED_OVR_FINE_MINUS, Realtime.FEED_OVR_FINE_MINUS),
        (RAPID_OVR_RESET, Realtime.RAPID_OVR_RESET),
        (RAPID_OVR_MEDIUM, Realtime.RAPID_OVR_MEDIUM),
        (RAPID_OVR_LOW, Realtime.RAPID_OVR_LOW),
        (SPINDLE_OVR_RESET, Realtime.SPINDLE_OVR_RESET),
        (SPINDLE_OVR_COARSE_PLUS, Realtime.SPINDLE_OVR_COARSE_PLUS),
        (SPINDLE_OVR_COARSE_MINUS, Realtime.SPINDLE_OVR_COARSE_MINUS),
        (SPINDLE_OVR_FINE_PLUS, Realtime.SPINDLE_OVR_FINE_PLUS),
        (SPINDLE_OVR_FINE_MINUS, Realtime.SPINDLE_OVR_FINE_MINUS),
        (SPINDLE_STOP, Realtime.SPINDLE_STOP),
        (FLOOD_TOGGLE, Realtime.FLOOD_TOGGLE),
        (MIST_TOGGLE, Realtime.MIST_TOGGLE),
    )
)

#: grblHAL's alternative bytes for `?`, `~` and `!` (firmware-facts §7), by value.
GRBLHAL_ALIASES: Final = _by_value(
    (
        (GRBLHAL_STATUS_QUERY, Realtime.STATUS),
        (GRBLHAL_CYCLE_START, Realtime.CYCLE_START),
        (GRBLHAL_FEED_HOLD, Realtime.FEED_HOLD),
    )
)


# --- overrides by name (what a page or a device button asks for)
# ---------------------------------------------------------------------
#: (kind, step) -> the byte: the feed and rapid overrides every Grbl 1.1 has.
OVERRIDES: Final = MappingProxyType(
    {
        ("feed", "reset"): FEED_OVR_RESET,
        ("feed", "+10"): FEED_OVR_COARSE_PLUS,
        ("feed", "-10"): FEED_OVR_COARSE_MINUS,
        ("feed", "+1"): FEED_OVR_FINE_PLUS,
        ("feed", "-1"): FEED_OVR_FINE_MINUS,
        ("rapid", "100"): RAPID_OVR_RESET,
        ("rapid", "50"): RAPID_OVR_MEDIUM,
        ("rapid", "25"): RAPID_OVR_LOW,
    }
)
OVERRIDE_KINDS: Final = tuple(sorted({kind for kind, _ in OVERRIDES}))
#: kind -> its steps, in the order above.
OVERRIDE_STEPS: Final = MappingProxyType(
    {kind: tuple(step for k, step in OVERRIDES if k == kind) for kind in OVERRIDE_KINDS}
)
