"""The recording formats `jog --input-replay` reads: evtest text and hidraw SECONDS HEX lines."""

from __future__ import annotations

import contextlib
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from smoothjog.inputs.device import EV_ABS, EV_KEY, AbsRange, EvdevEvent, HidReport
from smoothjog.inputs.recording import (
    RecordingError,
    load_evtest,
    load_hidraw,
    parse_evtest,
    parse_hidraw,
)

HEADER = """\
Input driver version is 1.0.1
Input device ID: bus 0x5 vendor 0x45e product 0x2fd version 0x903
Input device name: "Xbox Wireless Controller"
Supported events:
  Event type 0 (EV_SYN)
  Event type 1 (EV_KEY)
    Event code 304 (BTN_SOUTH)
  Event type 3 (EV_ABS)
    Event code 0 (ABS_X)
      Value   4110
      Min   -32768
      Max    32767
      Fuzz     255
      Flat    4095
  Event type 4 (EV_MSC)
    Event code 4 (MSC_SCAN)
Key repeat handling:
  Repeat type 20 (EV_REP)
    Repeat code 0 (REP_DELAY)
      Value    250
Properties:
Testing ... (interrupt to exit)
"""


def test_the_evtest_header_gives_the_device_and_its_ranges() -> None:
    rec = parse_evtest(
        (HEADER + "Event: time 1.5, type 1 (EV_KEY), code 304 (BTN_SOUTH), value 1\n").split("\n")
    )
    info = rec.info
    assert (info.name, info.bus, info.usb_id) == ("Xbox Wireless Controller", 5, "045e:02fd")
    assert info.absinfo == {0: AbsRange(4110, -32768, 32767, 255, 4095)}
    assert info.keys == frozenset({304})
    assert [f.events for f in rec.frames] == [(EvdevEvent(EV_KEY, 304, 1),)]
    assert rec.frames[0].t_s == 0.0


def test_frames_close_on_syn_report_or_a_new_time_and_scan_codes_in_hex_are_dropped() -> None:
    lines = [
        "Event: time 10.000000, type 4 (EV_MSC), code 4 (MSC_SCAN), value 7005c",
        "Event: time 10.000000, type 3 (EV_ABS), code 0 (ABS_X), value 5",
        "Event: time 10.000000, type 3 (EV_ABS), code 1 (ABS_Y), value -5",
        "Event: time 10.000000, -------------- SYN_REPORT ------------",
        "Event: time 10.250000, type 3 (EV_ABS), code 0 (ABS_X), value 6",
        "Event: time 10.500000, type 3 (EV_ABS), code 0 (ABS_X), value 7",
    ]
    rec = parse_evtest(lines)
    assert [(f.t_s, f.events) for f in rec.frames] == [
        (0.0, (EvdevEvent(EV_ABS, 0, 5), EvdevEvent(EV_ABS, 1, -5))),
        (0.25, (EvdevEvent(EV_ABS, 0, 6),)),
        (0.5, (EvdevEvent(EV_ABS, 0, 7),)),
    ]


@pytest.mark.parametrize(
    "dropped_line",
    [
        "Event: time 1.1, >>>>>>>>>>>>>> SYN_DROPPED <<<<<<<<<<<<",  # as evtest prints it
        "Event: time 1.1, -------------- SYN_DROPPED ------------",
    ],
)
def test_syn_dropped_gives_a_resync_frame_of_the_state_seen(dropped_line: str) -> None:
    lines = [
        "Event: time 1.0, type 3 (EV_ABS), code 0 (ABS_X), value 100",
        "Event: time 1.0, type 1 (EV_KEY), code 304 (BTN_SOUTH), value 1",
        "Event: time 1.0, -------------- SYN_REPORT ------------   # a comment",
        dropped_line,
        "Event: time 1.1, type 3 (EV_ABS), code 0 (ABS_X), value 999",
        "Event: time 1.1, -------------- SYN_REPORT ------------",
    ]
    rec = parse_evtest(lines)
    assert rec.dropped == 1
    last = rec.frames[-1]
    assert last.resync
    assert last.events == (EvdevEvent(EV_ABS, 0, 100), EvdevEvent(EV_KEY, 304, 1))


@pytest.mark.parametrize(
    ("lines", "message"),
    [
        ([], "nothing to replay"),
        (["hello"], "<evtest>:1: not an evtest line"),
        (
            ["Event: time 2.0, type 1 (EV_KEY), code 1 (KEY_ESC), value 1", "junk"],
            "<evtest>:2: expected an evtest 'Event: time",
        ),
        (
            [
                "Event: time 2.0, type 1 (EV_KEY), code 1 (KEY_ESC), value 1",
                "Event: time 1.0, type 1 (EV_KEY), code 1 (KEY_ESC), value 0",
            ],
            "goes back",
        ),
    ],
)
def test_evtest_errors_name_the_line(lines: list[str], message: str) -> None:
    with pytest.raises(RecordingError, match=message):
        parse_evtest(lines)


def test_hidraw_lines_and_hid_recorder_lines() -> None:
    rec = parse_hidraw(
        [
            "# a WHB04B, X at 0.01",
            "N: KTURT.LTD WHB04B",
            "I: 3 10ce eb93",
            "R: 46 06 00 ff",
            "5.000  04 ba 00 00 0e 11 00 ba   # idle",
            "5.016 049d00000e12019c",
            "E: 000005.100000 8 04 82 01 00 0e 12 00 81",
            "",
        ]
    )
    assert (rec.info.name, rec.info.usb_id, rec.info.bus) == ("KTURT.LTD WHB04B", "10ce:eb93", 3)
    assert rec.reports == (
        HidReport(0.0, bytes.fromhex("04ba00000e1100ba")),
        HidReport(0.016, bytes.fromhex("049d00000e12019c")),
        HidReport(0.1, bytes.fromhex("048201000e120081")),
    )


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("0.1 04 b", "odd number of hex digits"),
        ("0.1 zz", "expected 'SECONDS HEX BYTES'"),
        ("E: 0.1 3 04 05", "the line says 3 bytes but holds 2"),
        ("x 04", "expected 'SECONDS HEX BYTES'"),
    ],
)
def test_hidraw_errors_name_the_line(line: str, message: str) -> None:
    with pytest.raises(RecordingError, match=rf"<hidraw>:2: {message}"):
        parse_hidraw(["0.0 04", line])


def test_missing_and_unreadable_files_are_said(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="does not exist"):
        load_hidraw(tmp_path / "nope.hid")
    with pytest.raises(RecordingError, match="is a directory"):
        load_evtest(tmp_path)
    (tmp_path / "bin").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(RecordingError, match="cannot read"):
        load_evtest(tmp_path / "bin")


@given(st.lists(st.text(max_size=60), max_size=8))
def test_any_text_is_a_recording_or_a_recording_error(lines: list[str]) -> None:
    for parse in (parse_evtest, parse_hidraw):
        with contextlib.suppress(RecordingError):
            parse(lines)
