"""Tests for core/firmware.py: the firmware table holds the facts, and the lookups behave."""

from __future__ import annotations

import pytest

from smoothjog.core.errors import CoreError
from smoothjog.core.firmware import (
    BITS_PER_BYTE_8N1,
    DEFAULT_BAUD,
    FIRMWARE_NAMES,
    FIRMWARES,
    FLUIDNC,
    GRBL,
    GRBLHAL,
    FirmwareFacts,
    JogClip,
    firmware_facts,
    for_model,
    named_by_info,
    named_by_version,
)
from smoothjog.core.machine import MachineModel

# The figures written out again here, from firmware-facts §4.1, §5.1 and §7, so a slip in the table
# shows. (family, max line, planner blocks, hidden, usable, RX bytes, TX bytes)
FIGURES = [
    ("grbl", 79, 15, 0, 15, 128, 104),
    ("grblhal", 256, 100, 0, 100, 1024, 1024),
    ("fluidnc", 255, 16, 1, 15, 256, 1024),
]


@pytest.mark.parametrize(
    ("name", "line_chars", "blocks", "hidden", "usable", "rx_bytes", "tx_bytes"), FIGURES
)
def test_figures(
    name: str, line_chars: int, blocks: int, hidden: int, usable: int, rx_bytes: int, tx_bytes: int
) -> None:
    facts = FIRMWARES[name]
    assert facts.name == name
    assert facts.max_line_chars == line_chars
    assert facts.planner_blocks == blocks
    assert facts.planner_blocks_hidden == hidden
    assert facts.planner_usable_blocks == usable
    assert facts.rx_buffer_bytes == rx_bytes
    assert facts.tx_buffer_bytes == tx_bytes


# (family, RX flushed by 0x85, blocked jog dropped, `!` cancels a jog, soft-limit jog)
CANCELS = [
    (GRBL, False, False, True, JogClip.REJECT),
    (GRBLHAL, True, False, False, JogClip.CLIP_IF_40),
    (FLUIDNC, False, True, True, JogClip.CLIP_PER_AXIS),
]


@pytest.mark.parametrize(("facts", "flushes", "drops", "hold", "clip"), CANCELS)
def test_jog_cancel_and_clip(
    facts: FirmwareFacts, flushes: bool, drops: bool, hold: bool, clip: JogClip
) -> None:
    assert facts.jog_cancel.flushes_rx is flushes
    assert facts.jog_cancel.drops_blocked_jog is drops
    assert facts.jog_cancel.feed_hold_cancels is hold
    assert facts.jog_clip is clip


def test_the_wire() -> None:
    # 115200 baud 8N1 (firmware-facts §0, §5.1): one byte takes about 87 µs (firmware-facts §6).
    assert DEFAULT_BAUD == 115200
    byte_s = BITS_PER_BYTE_8N1 / DEFAULT_BAUD
    assert byte_s == pytest.approx(86.8e-6, rel=1e-3)


def test_names_in_order() -> None:
    assert FIRMWARE_NAMES == ("grbl", "grblhal", "fluidnc")
    assert tuple(FIRMWARES) == FIRMWARE_NAMES


@pytest.mark.parametrize("name", ["grbl", "GrblHAL", "FLUIDNC"])
def test_lookup_ignores_case(name: str) -> None:
    assert firmware_facts(name) is FIRMWARES[name.lower()]


def test_unknown_name_is_a_clear_error() -> None:
    with pytest.raises(CoreError, match=r"firmware 'marlin': choose one of grbl, grblhal, fluidnc"):
        firmware_facts("marlin")


@pytest.mark.parametrize("facts", [GRBL, GRBLHAL, FLUIDNC])
def test_for_model(facts: FirmwareFacts) -> None:
    assert for_model(MachineModel(firmware=facts.name)) is facts


@pytest.mark.parametrize(
    ("version", "name"),
    [("3.7 FluidNC v3.7.8", "fluidnc"), ("1.1h", None), ("1.1f", None), ("", None)],
)
def test_named_by_version(version: str, name: str | None) -> None:
    assert named_by_version(version) == name


@pytest.mark.parametrize(
    ("text", "name"),
    [("FIRMWARE:grblHAL", "grblhal"), ("firmware:GRBLHAL", "grblhal"), ("NEWOPT:ENUMS", None)],
)
def test_named_by_info(text: str, name: str | None) -> None:
    assert named_by_info(text) == name
