"""The sender's byte stream: lines, realtime bytes, and what goes on the wire for each line."""

from __future__ import annotations

import pytest

from smoothjog.core.machine import MachineModel
from smoothjog.core.responses import ErrorReply, Ok
from smoothjog.proxy import (
    LineAssembler,
    SenderLine,
    SenderRealtime,
    banner_for,
    is_query,
    is_realtime,
    reply_bytes,
    wire_text,
)


def test_lines_end_at_newline_or_return_and_keep_their_order() -> None:
    a = LineAssembler()
    assert a.feed(b"G0X1\nG0") == [SenderLine(b"G0X1")]
    assert a.partial == b"G0"
    assert a.feed(b"Y2\rG4P0\r\n") == [SenderLine(b"G0Y2"), SenderLine(b"G4P0"), SenderLine(b"")]


def test_realtime_bytes_come_out_where_they_were_sent_and_never_in_a_line() -> None:
    a = LineAssembler()
    out = a.feed(b"G1X1?0F100!\n~\x85\x90")
    assert out == [
        SenderRealtime(b"?"),
        SenderRealtime(b"!"),
        SenderLine(b"G1X10F100"),
        SenderRealtime(b"~"),
        SenderRealtime(b"\x85"),
        SenderRealtime(b"\x90"),
    ]


def test_a_reset_byte_drops_the_line_being_read() -> None:
    a = LineAssembler()
    assert a.feed(b"G1X5\x18$X\n") == [SenderRealtime(b"\x18"), SenderLine(b"$X")]


def test_0x19_is_realtime_only_on_grblhal() -> None:
    assert is_realtime(0x19, "grblhal")
    assert not is_realtime(0x19, "grbl")
    assert not is_realtime(0x19, "fluidnc")
    for byte in (0x3F, 0x21, 0x7E, 0x18, 0x80, 0x85, 0xFF):
        assert is_realtime(byte)
    for byte in (0x0A, 0x0D, 0x09, 0x7F, 0x24):
        assert not is_realtime(byte)
    fw = ["grbl"]
    a = LineAssembler(lambda: fw[0])
    assert a.feed(b"\x19\n") == [SenderLine(b"\x19")]
    fw[0] = "grblhal"
    assert a.feed(b"\x19\n") == [SenderRealtime(b"\x19"), SenderLine(b"")]


def test_an_endless_line_is_capped() -> None:
    a = LineAssembler()
    a.feed(b"(" + b"x" * 70000)
    assert len(a.partial) == 65536
    assert a.overflow_bytes == 70001 - 65536


@pytest.mark.parametrize(
    ("raw", "text"),
    [
        (b"G0 X1 ; move", "G0 X1 ; move"),  # as sent: the controller does its own parsing
        (b"g0\tx1", "g0x1"),  # a tab (a control byte) is dropped, as Grbl drops it
        (b"G4P0\x00\x07", "G4P0"),
        (b"G0X1\x7f", "G0X1^"),  # DEL stays a byte Grbl refuses
        (b"", ""),
    ],
)
def test_wire_text(raw: bytes, text: str) -> None:
    assert wire_text(raw) == text


def test_a_line_longer_than_the_rx_buffer_goes_as_grbl_stores_it() -> None:
    raw = b"G4 P0 (" + b"c" * 200 + b") ; and more"
    assert wire_text(raw) == "G4P0"
    overflow = b"G1 " + b"X1" * 100
    text = wire_text(overflow)
    assert len(text) == 80  # one past the 79 Grbl stores: it answers error:11
    assert text.startswith("G1X1X1")


@pytest.mark.parametrize(
    ("raw", "query"),
    [
        (b"$G", True),
        (b"$g", True),
        (b" $ # ", True),
        (b"$$", True),
        (b"$I", True),
        (b"$N", True),
        (b"$", True),
        (b"", True),
        (b"(just a comment)", True),
        (b"$J=G91X1F100", False),
        (b"G0X1", False),
        (b"$X", False),
        (b"$H", False),
        (b"$I=mine", False),
        (b"$N0=G54", False),
        (b"$C", False),
    ],
)
def test_queries_are_told_from_lines_that_act(raw: bytes, query: bool) -> None:
    assert is_query(raw) is query


def test_replies_and_banners_are_printed_as_the_controller_prints_them() -> None:
    assert reply_bytes(Ok()) == b"ok\r\n"
    assert reply_bytes(ErrorReply(20)) == b"error:20\r\n"
    model = MachineModel()
    model.version = "1.1h"
    assert banner_for(model) == b"Grbl 1.1h ['$' for help]"
    model.firmware = "grblhal"
    model.version = "1.1f"
    assert banner_for(model) == b"GrblHAL 1.1f ['$' or '$HELP' for help]"
