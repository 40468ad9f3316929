"""Tests for core/realtime.py: every byte has Grbl's value, and the tables are complete."""

from __future__ import annotations

import pytest

from smoothjog.core import realtime as rt
from smoothjog.core.realtime import GRBL_REALTIME, GRBLHAL_ALIASES, Realtime

# Values written out again from firmware-facts §5.2 and §7, so a slip in the module shows.
GRBL_VALUES = [
    (rt.RESET, 0x18),
    (rt.STATUS_QUERY, ord("?")),
    (rt.CYCLE_START, ord("~")),
    (rt.FEED_HOLD, ord("!")),
    (rt.SAFETY_DOOR, 0x84),
    (rt.JOG_CANCEL, 0x85),
    (rt.FEED_OVR_RESET, 0x90),
    (rt.FEED_OVR_COARSE_PLUS, 0x91),
    (rt.FEED_OVR_COARSE_MINUS, 0x92),
    (rt.FEED_OVR_FINE_PLUS, 0x93),
    (rt.FEED_OVR_FINE_MINUS, 0x94),
    (rt.RAPID_OVR_RESET, 0x95),
    (rt.RAPID_OVR_MEDIUM, 0x96),
    (rt.RAPID_OVR_LOW, 0x97),
    (rt.SPINDLE_OVR_RESET, 0x99),
    (rt.SPINDLE_OVR_COARSE_PLUS, 0x9A),
    (rt.SPINDLE_OVR_COARSE_MINUS, 0x9B),
    (rt.SPINDLE_OVR_FINE_PLUS, 0x9C),
    (rt.SPINDLE_OVR_FINE_MINUS, 0x9D),
    (rt.SPINDLE_STOP, 0x9E),
    (rt.FLOOD_TOGGLE, 0xA0),
    (rt.MIST_TOGGLE, 0xA1),
]
GRBLHAL_VALUES = [
    (rt.GRBLHAL_STOP, 0x19),
    (rt.GRBLHAL_STATUS_QUERY, 0x80),
    (rt.GRBLHAL_CYCLE_START, 0x81),
    (rt.GRBLHAL_FEED_HOLD, 0x82),
    (rt.GRBLHAL_GCODE_REPORT, 0x83),
    (rt.GRBLHAL_FULL_STATUS, 0x87),
    (rt.GRBLHAL_OPTIONAL_STOP_TOGGLE, 0x88),
    (rt.GRBLHAL_SINGLE_BLOCK_TOGGLE, 0x89),
    (rt.GRBLHAL_MPG_TOGGLE, 0x8B),
    (rt.GRBLHAL_AUTO_REPORT_TOGGLE, 0x8C),
]


@pytest.mark.parametrize(("command", "value"), GRBL_VALUES + GRBLHAL_VALUES)
def test_each_byte_has_its_value(command: bytes, value: int) -> None:
    assert command == bytes((value,))


def test_grbl_table_covers_every_grbl_byte_and_nothing_else() -> None:
    assert set(GRBL_REALTIME) == {value for _, value in GRBL_VALUES}
    assert len(set(GRBL_REALTIME.values())) == len(GRBL_REALTIME)  # one meaning per byte
    # 0x98 (rapid extra low) and 0x9F are not Grbl 1.1h commands (firmware-facts §5.2).
    assert 0x98 not in GRBL_REALTIME
    assert 0x9F not in GRBL_REALTIME


def test_grbl_table_names_match() -> None:
    assert GRBL_REALTIME[rt.JOG_CANCEL[0]] is Realtime.JOG_CANCEL
    assert GRBL_REALTIME[rt.RESET[0]] is Realtime.RESET
    assert GRBL_REALTIME[rt.STATUS_QUERY[0]] is Realtime.STATUS


def test_grblhal_aliases() -> None:
    assert dict(GRBLHAL_ALIASES) == {
        0x80: Realtime.STATUS,
        0x81: Realtime.CYCLE_START,
        0x82: Realtime.FEED_HOLD,
    }


def test_low_and_printable_sets() -> None:
    assert frozenset(b"?!~") == rt.PRINTABLE_REALTIME
    assert frozenset(b"?!~\x18\x19") == rt.LOW_REALTIME
    assert all(byte < rt.EXTENDED_START for byte in rt.LOW_REALTIME)
