"""The WHB04B decoder: the devices §8.1/§8.2 corpus, modes, safety stops, buttons and the LCD."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from smoothjog.core.errors import ConfigError
from smoothjog.core.intents import HandwheelIntent, Intent, StopIntent, validate_intent
from smoothjog.core.options import Table
from smoothjog.inputs.device import (
    DeviceCommand,
    DeviceInfo,
    DeviceNotice,
    DisplayView,
    EvdevEvent,
    EvdevFrame,
    HidReport,
)
from smoothjog.inputs.recording import load_hidraw
from smoothjog.inputs.whb04b import (
    AXIS_CODES,
    FEED_CODES,
    Whb04bDecoder,
    checksum,
    decode_report,
    encode_display,
)

FIXTURES = Path(__file__).parent / "fixtures" / "whb04b"
INFO = DeviceInfo("KTURT.LTD XHC WHB04B", vendor=0x10CE, product=0xEB93)
XYZ = ("X", "Y", "Z")
EMPTY = bytes.fromhex("04ff0000000000ff")
SLEEP = bytes.fromhex("04ffffffffff81ff")
MAX_FEED_MM_MIN = 1000.0
X, Y, Z, A, B, OFF = 0x11, 0x12, 0x13, 0x14, 0x15, 0x06
F001, F01, F1, P60, P100, LEAD, LEAD_6 = 0x0E, 0x0F, 0x10, 0x1A, 0x1B, 0x1C, 0x9B


def pkt(
    delta: int = 0,
    *,
    axis: int = X,
    feed: int = F001,
    key1: int = 0,
    key2: int = 0,
    rnd: int = 0x40,
) -> bytes:
    """A regular report with the checksum a pendant sends for seed 0xFE."""
    return bytes([4, rnd, key1, key2, feed, axis, delta & 0xFF, checksum(rnd, key1)])


def make(axes: Sequence[str] = XYZ, **options: Any) -> Whb04bDecoder:
    return Whb04bDecoder(INFO, Table(options, "device", "<test>"), axes)


def run(dec: Whb04bDecoder, reports: Iterable[bytes], t0_s: float = 0.0) -> list[Any]:
    """Feed reports 50 ms apart; all the actions."""
    actions: list[Any] = []
    for i, data in enumerate(reports):
        actions += dec.feed(HidReport(t0_s + 0.05 * i, data))
    return actions


def wheel(actions: Iterable[Any]) -> list[HandwheelIntent]:
    return [a for a in actions if isinstance(a, HandwheelIntent)]


def stops(actions: Iterable[Any]) -> int:
    return sum(isinstance(a, StopIntent) for a in actions)


def notices(actions: Iterable[Any]) -> list[str]:
    return [a.text for a in actions if isinstance(a, DeviceNotice)]


def check_valid(actions: Iterable[Any], axes: Sequence[str]) -> None:
    for action in actions:
        if isinstance(action, HandwheelIntent | StopIntent):
            intent: Intent = action
            validate_intent(intent, axes, MAX_FEED_MM_MIN)


def pos(axis: str, counts: int, step_mm: float = 0.01) -> HandwheelIntent:
    return HandwheelIntent(axis, counts, step_mm, "position", 0.5)


def moving_x() -> Whb04bDecoder:
    """A decoder that has just sent counts on X at 0.01."""
    dec = make()
    assert wheel(run(dec, [pkt(0), pkt(2)])) == [pos("X", 2)]
    assert dec.moving
    return dec


# -- matching and the corpus ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("vendor", "product", "expected"),
    [
        (0x10CE, 0xEB93, True),
        (0x10CE, 0xEB91, True),
        (0x10CE, 0xEB70, False),
        (0x46D, 0xEB93, False),
    ],
)
def test_matches_the_xhc_dongle_and_the_wmpg6_clone(
    vendor: int, product: int, expected: bool
) -> None:
    info = DeviceInfo("any", vendor=vendor, product=product)
    assert Whb04bDecoder.matches(info) is expected


def _expectations(path: Path) -> list[dict[str, str]]:
    """Each report line's comment before "|": KIND then key=value words."""
    rows = []
    for line in path.read_text().splitlines():
        if line.lstrip().startswith("#") or "#" not in line:
            continue
        words = line.split("#", 1)[1].split("|", 1)[0].split()
        rows.append({"kind": words[0], **dict(w.split("=") for w in words[1:])})
    return rows


@pytest.mark.parametrize("name", ["quoted.hid", "constructed.hid"])
def test_every_corpus_packet_decodes_as_its_comment_says(name: str) -> None:
    path = FIXTURES / name
    reports = load_hidraw(path).reports
    rows = _expectations(path)
    assert len(reports) == len(rows) == {"quoted.hid": 10, "constructed.hid": 8}[name]
    for report, row in zip(reports, rows, strict=True):
        decoded = decode_report(report.data)
        assert decoded is not None, row
        assert decoded.kind == row["kind"]
        assert {"ok": True, "bad": False, "-": None}[row["crc"]] is decoded.crc_ok
        if decoded.kind == "regular":
            got = (decoded.key1, decoded.key2, decoded.feed_code, decoded.axis_code, decoded.delta)
            want = tuple(int(row[k], 16) for k in ("key1", "key2", "feed", "axis"))
            assert got == (*want, int(row["delta"]))
        else:
            assert decoded.delta == 0  # the sleep package's 0x81 is no -127


def test_the_quoted_readme_log_through_the_decoder() -> None:
    """LinuxCNC's logged session (devices §8.1), report by report."""
    dec = make()
    reports = load_hidraw(FIXTURES / "quoted.hid").reports
    got = [dec.feed(r) for r in reports]
    assert got == [
        [],  # X at 0.01: state known, nothing moves
        [],  # axis -> Y: a change, but nothing was running, so no stop
        [DeviceCommand("reset")],
        [],  # released
        [pos("Y", 1)],
        [],  # idle
        [StopIntent(), DeviceCommand("hold")],  # feed 0.01 -> 1 while counts may run: stop first
        [],
        [],  # X at 100 %
        [],  # Lead, as this unit codes it
    ]
    assert dec.crc_mismatches == 0


CONSTRUCTED = {r.data.hex(): r.data for r in load_hidraw(FIXTURES / "constructed.hid").reports}


def _corpus(hex_text: str) -> bytes:
    return CONSTRUCTED[hex_text.replace(" ", "")]


@pytest.mark.parametrize(
    ("hex_text", "mode_key", "expected"),
    [
        ("04 5a 00 00 0e 11 fd 5a", None, [pos("X", -3)]),
        ("04 33 00 00 0f 13 05 32", None, [pos("Z", 5, 0.1)]),
        ("04 71 00 00 0d 06 02 70", None, []),  # axis OFF: no motion
        ("04 20 0c 04 0e 11 00 14", None, []),  # Macro-1 does nothing by default
        ("04 44 00 00 1b 11 7f 44", 0x0E, [HandwheelIntent("X", 127, 0.05, "velocity", 1.0)]),
        ("04 45 00 00 1b 11 80 44", 0x0E, [HandwheelIntent("X", -128, 0.05, "velocity", 1.0)]),
    ],
)
def test_constructed_packets_through_the_decoder(
    hex_text: str, mode_key: int | None, expected: list[Any]
) -> None:
    dec = make()
    if mode_key is not None:
        run(dec, [pkt(key1=mode_key, feed=P100), pkt(feed=P100)])
    assert wheel(dec.feed(HidReport(1.0, _corpus(hex_text)))) == expected


@pytest.mark.parametrize("hex_text", ["04 ff 00 00 00 00 00 ff", "04 ff ff ff ff ff 81 ff"])
def test_power_off_packets_stop_and_never_move(hex_text: str) -> None:
    dec = moving_x()
    actions = dec.feed(HidReport(1.0, _corpus(hex_text)))
    assert actions[0] == StopIntent()
    assert wheel(actions) == []
    assert notices(actions)[0].startswith("handwheel switched off or asleep")
    assert not dec.moving
    assert dec.describe() == "WHB04B: asleep"


def test_macro_1_is_a_button_of_the_table() -> None:
    dec = make(buttons={"macro_1": "feed +1"})
    actions = dec.feed(HidReport(0.0, _corpus("04 20 0c 04 0e 11 00 14")))
    assert actions == [DeviceCommand("override", kind="feed", step="+1")]


# -- the LCD ----------------------------------------------------------------------------------

LCD_8_2 = [r.data for r in load_hidraw(FIXTURES / "lcd_8_2.hid").reports]


def test_encode_display_reproduces_devices_8_2() -> None:
    frames = encode_display([1.5, -2.25, 0.0], feed=1000, spindle=12000, mode=1, work_coords=True)
    assert frames == LCD_8_2
    assert all(len(f) == 8 and f[0] == 0x06 for f in frames)


def test_display_shows_the_8_2_view_in_step_mode_with_work_coordinates() -> None:
    dec = make()
    view = DisplayView(
        mpos_mm={"X": 9.0, "Y": 9.0, "Z": 9.0},
        wpos_mm={"X": 1.5, "Y": -2.25, "Z": 0.0},
        feed_mm_min=1000,
        spindle_rpm=12000,
    )
    assert dec.display(view) == LCD_8_2
    assert dec.display(view) == []  # unchanged: nothing to write


def _payload(frames: list[bytes]) -> bytes:
    return b"".join(f[1:] for f in frames)


@pytest.mark.parametrize(
    ("value_mm", "field"),
    [
        (0.0001, "0000 0100"),
        (-0.00001, "0000 0000"),  # rounds to 0: no "-0.0000"
        (1.99996, "0200 0000"),  # the fraction's rounding carries into the whole part
        (-12.3456, "0c00 808d"),
        (70000.0, "ffff 0f27"),  # clamped to 65535.9999
        (-math.inf, "ffff 0fa7"),
        (math.nan, "0000 0000"),
    ],
)
def test_coordinates_are_encoded_and_clamped(value_mm: float, field: str) -> None:
    payload = _payload(encode_display([value_mm, 0.0, 0.0]))
    assert payload[4:8] == bytes.fromhex(field)


@pytest.mark.parametrize(
    ("feed", "spindle", "fields"),
    [(70000.0, -5.0, "ffff 0000"), (math.nan, math.inf, "0000 ffff"), (12.6, 0.4, "0d00 0000")],
)
def test_feed_and_spindle_are_clamped_to_u16(feed: float, spindle: float, fields: str) -> None:
    assert _payload(encode_display([0, 0, 0], feed=feed, spindle=spindle))[16:20] == bytes.fromhex(
        fields
    )


def test_display_rows_mode_flag_and_coordinates_option() -> None:
    view = DisplayView(
        mpos_mm={"X": 1.0, "Y": 2.0, "Z": 3.0, "A": 4.0},
        wpos_mm={"X": 0.0, "Y": 0.0, "Z": 0.0, "A": 5.0},
    )
    dec = make(("X", "Y", "Z", "A"), lcd_coords="machine")
    payload = _payload(dec.display(view))
    assert payload[3] == 0x01  # step mode, machine coordinates
    assert payload[4:16] == bytes.fromhex("0100 0000 0200 0000 0300 0000")
    run(dec, [pkt(axis=A), pkt(axis=A, key1=0x0E)])
    payload = _payload(dec.display(view))
    assert payload[3] == 0x00  # continuous mode
    assert payload[4:16] == bytes.fromhex("0400 0000 0000 0000 0000 0000")  # A, then no B, C


def test_no_lcd_writes_while_asleep_and_a_fresh_write_on_waking() -> None:
    dec = make()
    view = DisplayView(mpos_mm={}, wpos_mm={"X": 1.0})
    assert dec.display(view)
    run(dec, [pkt(), EMPTY, SLEEP])
    assert dec.display(view) == []
    run(dec, [pkt()], t0_s=5.0)
    assert dec.display(view)  # unchanged, but the pendant was off: write it again


# -- motion -----------------------------------------------------------------------------------


def test_step_37_recording_is_37_detents_of_001_on_x() -> None:
    rec = load_hidraw(FIXTURES / "step_37.hid")
    dec = Whb04bDecoder(rec.info, Table({}, "device", "<test>"), XYZ)
    actions: list[Any] = []
    for report in rec.reports:
        deadline = dec.deadline_s()
        if deadline is not None and deadline <= report.t_s:
            actions += dec.tick(deadline)
        actions += dec.feed(report)
    intents = wheel(actions)
    assert sum(i.counts for i in intents) == 37
    assert {(i.axis, i.step_mm, i.mode, i.speed) for i in intents} == {("X", 0.01, "position", 0.5)}
    assert {abs(i.counts) for i in intents} <= {1, 2, 3}
    assert stops(actions) == 0
    assert notices(actions) == []
    assert dec.describe() == "WHB04B: axis X, step 0.01 mm, step mode"


def test_velocity_spin_recording_runs_in_continuous_mode_at_100_percent() -> None:
    rec = load_hidraw(FIXTURES / "velocity_spin.hid")
    dec = Whb04bDecoder(rec.info, Table({}, "device", "<test>"), XYZ)
    actions = [a for r in rec.reports for a in dec.feed(r)]
    intents = wheel(actions)
    assert sum(i.counts for i in intents) == -40
    assert {(i.axis, i.step_mm, i.mode, i.speed) for i in intents} == {("X", 0.05, "velocity", 1.0)}
    assert stops(actions) == 0  # the mode and selector changed before anything moved
    assert dec.describe() == "WHB04B: axis X, 100 %, continuous mode"


@pytest.mark.parametrize(
    ("feed", "step_mm", "percent"),
    [(0x0D, 0.001, 2), (F001, 0.01, 5), (F01, 0.1, 10), (F1, 1.0, 30)],
)
def test_selector_positions_in_both_modes(feed: int, step_mm: float, percent: int) -> None:
    dec = make()
    assert wheel(run(dec, [pkt(feed=feed), pkt(4, feed=feed)])) == [pos("X", 4, step_mm)]
    run(dec, [pkt(feed=feed, key1=0x0E), pkt(feed=feed)], t0_s=1.0)
    velocity = HandwheelIntent("X", -4, 0.05, "velocity", percent / 100)
    assert wheel(run(dec, [pkt(-4, feed=feed)], t0_s=2.0)) == [velocity]


@pytest.mark.parametrize("feed", [P60, P100, LEAD, LEAD_6])
def test_step_mode_never_moves_where_the_selector_has_no_step(feed: int) -> None:
    dec = make()
    actions = run(dec, [pkt(feed=feed), pkt(1, feed=feed), pkt(1, feed=feed)])
    assert wheel(actions) == []
    assert len(notices(actions)) == 1  # explained once, not per report


@pytest.mark.parametrize("feed", [LEAD, LEAD_6])
def test_lead_never_moves_in_continuous_mode(feed: int) -> None:
    dec = make()
    assert wheel(run(dec, [pkt(feed=feed, key1=0x0E), pkt(feed=feed), pkt(5, feed=feed)])) == []


def test_mode_keys_take_the_facts_word_over_the_labels() -> None:
    dec = make()
    run(dec, [pkt()])
    assert dec.describe().endswith("step mode")  # from start-up
    run(dec, [pkt(key1=0x0E), pkt()], t0_s=1.0)  # labelled MPG: continuous
    assert dec.describe().endswith("continuous mode")
    assert wheel(run(dec, [pkt(1)], t0_s=2.0))[0].mode == "velocity"
    run(dec, [pkt(key1=0x0F), pkt()], t0_s=3.0)  # labelled STEP: step
    assert dec.describe().endswith("step mode")
    assert wheel(run(dec, [pkt(1)], t0_s=4.0))[0].mode == "position"


def test_nothing_moves_before_the_first_regular_report() -> None:
    dec = make()
    assert dec.describe().startswith("WHB04B: waiting")
    junk = [b"", b"\x04", pkt(5)[:7], b"\x06" + pkt(5)[1:], pkt(5) + b"\x00"]
    assert run(dec, junk) == []
    assert dec.ignored == len(junk)
    assert not dec.moving
    assert wheel(run(dec, [pkt(5)])) == [pos("X", 5)]  # the first report carries its own state


@pytest.mark.parametrize(
    ("axes", "axis", "expected", "explained"),
    [
        (XYZ, OFF, None, 0),  # OFF is the user's choice: silent
        (XYZ, A, None, 1),  # an axis the machine lacks: said once
        (XYZ, B, None, 1),
        (("X", "Y", "Z", "A"), A, "A", 0),
    ],
)
def test_axes_off_or_missing_never_move(
    axes: tuple[str, ...], axis: int, expected: str | None, explained: int
) -> None:
    dec = make(axes)
    actions = run(dec, [pkt(axis=axis), pkt(3, axis=axis), pkt(3, axis=axis)])
    assert [i.axis for i in wheel(actions)] == ([expected] * 2 if expected else [])
    assert len(notices(actions)) == explained
    check_valid(actions, axes)


def test_invert_flips_the_wheel() -> None:
    assert wheel(run(make(invert=True), [pkt(3)])) == [pos("X", -3)]


def test_a_bad_checksum_is_counted_not_dropped() -> None:
    dec = make()
    bad = bytearray(pkt(2))
    bad[7] ^= 0x55
    assert wheel(run(dec, [bytes(bad)])) == [pos("X", 2)]
    assert dec.crc_mismatches == 1


def test_evdev_frames_are_ignored() -> None:
    assert make().feed(EvdevFrame(0.0, (EvdevEvent(2, 8, 1),))) == []


# -- selectors and the counter hazard -----------------------------------------------------------


@given(st.integers(0, 255).filter(lambda code: code not in AXIS_CODES))
def test_an_unknown_axis_code_keeps_the_last_axis(code: int) -> None:
    dec = make()
    run(dec, [pkt(axis=Y)])
    assert wheel(run(dec, [pkt(2, axis=code)], t0_s=1.0)) == []  # a knob in transit: no motion
    assert "axis Y" in dec.describe()
    actions = run(dec, [pkt(2, axis=Y)], t0_s=2.0)
    assert actions == [pos("Y", 2)]  # still Y, and no change, so no stop


@given(st.integers(0, 255).filter(lambda code: code not in FEED_CODES))
def test_an_unknown_feed_code_keeps_the_last_step(code: int) -> None:
    dec = make()
    run(dec, [pkt(feed=F01)])
    assert wheel(run(dec, [pkt(2, feed=code)], t0_s=1.0)) == []
    assert run(dec, [pkt(2, feed=F01)], t0_s=2.0) == [pos("X", 2, 0.1)]


@pytest.mark.parametrize(
    "change",
    [
        pkt(1, axis=Y),  # axis
        pkt(1, axis=OFF),
        pkt(1, feed=F01),  # step size
        pkt(1, feed=P100),
        pkt(1, key1=0x0E),  # mode
    ],
)
def test_a_change_while_counts_may_run_stops_first_and_drops_its_counts(change: bytes) -> None:
    dec = moving_x()
    actions = dec.feed(HidReport(1.0, change))
    assert actions[:1] == [StopIntent()]
    assert wheel(actions) == []  # the accumulator reset: this report's counts are dropped
    assert not dec.moving


def test_a_change_with_nothing_running_does_not_stop() -> None:
    dec = make()
    assert run(dec, [pkt(), pkt(axis=Y), pkt(feed=F1), pkt(key1=0x0E)]) == []


def test_lead_coded_either_way_is_no_change() -> None:
    dec = make()
    run(dec, [pkt(key1=0x0E), pkt(), pkt(1)])
    assert dec.moving
    assert stops(run(dec, [pkt(feed=LEAD), pkt(feed=LEAD_6), pkt(feed=LEAD)], t0_s=1.0)) == 1


def test_pressing_the_current_mode_key_again_is_no_change() -> None:
    dec = moving_x()
    assert dec.feed(HidReport(1.0, pkt(1, key1=0x0F))) == [pos("X", 1)]


# -- sleep, the watchdog, loss ------------------------------------------------------------------


def test_sleep_stops_once_and_the_first_turn_after_waking_counts() -> None:
    dec = moving_x()
    actions = run(dec, [EMPTY, SLEEP, SLEEP], t0_s=1.0)
    assert stops(actions) == 1
    assert len(notices(actions)) == 1
    assert wheel(actions) == []
    assert dec.deadline_s() is None
    woke = run(dec, [pkt(3, axis=Z)], t0_s=30.0)
    assert notices(woke) == ["handwheel awake"]
    assert wheel(woke) == [pos("Z", 3)]  # a fresh turn: the encoder was off while asleep
    assert stops(woke) == 0


def test_the_watchdog_stops_a_silent_pendant() -> None:
    dec = moving_x()  # last report at 0.05 s
    assert dec.deadline_s() == pytest.approx(2.05)
    assert dec.tick(2.0) == []
    actions = dec.tick(2.05)
    assert actions[0] == StopIntent()
    assert "silent" in notices(actions)[0]
    assert not dec.moving
    assert dec.deadline_s() is None
    assert dec.describe().startswith("WHB04B: silent")
    back = dec.feed(HidReport(9.0, pkt(4)))
    assert notices(back) == ["handwheel reports again"]
    assert wheel(back) == []  # counts from across the gap are dropped
    assert wheel(dec.feed(HidReport(9.05, pkt(4)))) == [pos("X", 4)]


def test_a_report_after_the_deadline_stops_even_without_tick() -> None:
    dec = moving_x()
    actions = dec.feed(HidReport(5.0, pkt(2)))
    assert actions[0] == StopIntent()
    assert wheel(actions) == []


def test_the_watchdog_option_and_idle_reports() -> None:
    dec = make(watchdog_s=0.5)
    assert dec.deadline_s() is None  # nothing running: no timer
    run(dec, [pkt(), pkt(1)])
    assert dec.deadline_s() == pytest.approx(0.55)
    run(dec, [pkt()], t0_s=0.5)  # an idle report is a sign of life
    assert dec.deadline_s() == pytest.approx(1.0)


def test_lost_forgets_everything() -> None:
    dec = moving_x()
    run(dec, [pkt(key1=0x0E), pkt()], t0_s=1.0)
    assert notices(dec.lost())[0].startswith("handwheel lost")
    assert not dec.moving
    assert dec.deadline_s() is None
    assert dec.describe().startswith("WHB04B: waiting")
    assert wheel(run(dec, [pkt(1)], t0_s=3.0)) == [pos("X", 1)]  # step mode again


# -- buttons ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("key1", "key2", "expected"),
    [
        (0x01, 0, [DeviceCommand("reset")]),
        (0x01, 0x01, [DeviceCommand("reset")]),  # the same key in both bytes is one press
        (0x02, 0, [StopIntent()]),
        (0x0C, 0x02, [StopIntent()]),  # STOP stops with Fn held too
        (0x03, 0, [DeviceCommand("hold")]),
        (0x04, 0, [DeviceCommand("override", kind="feed", step="+10")]),
        (0x05, 0, [DeviceCommand("override", kind="feed", step="-10")]),
        (0x08, 0, [DeviceCommand("home")]),
        (0x0A, 0, [DeviceCommand("goto_zero")]),
        (0x0C, 0x0A, [DeviceCommand("zero", axes=("Y",))]),  # Fn + W-HOME: zero the selected axis
        (0x0A, 0x0C, [DeviceCommand("zero", axes=("Y",))]),  # either byte may hold Fn
        (0x0C, 0x08, [DeviceCommand("zero", axes=XYZ)]),  # Fn + M-HOME: zero every axis
        (0x06, 0, []),
        (0x07, 0, []),
        (0x09, 0, []),
        (0x0B, 0, []),
        (0x0D, 0, []),
        (0x10, 0, []),
        (0x0C, 0, []),  # Fn alone is a modifier
        (0x11, 0, []),  # no such key
        (0xFF, 0x80, []),
    ],
)
def test_each_button_acts_once_per_press(key1: int, key2: int, expected: list[Any]) -> None:
    dec = make()
    run(dec, [pkt(axis=Y)])
    held = pkt(axis=Y, key1=key1, key2=key2)
    actions = run(dec, [held, held, held, pkt(axis=Y)], t0_s=1.0)  # press, held, release
    assert actions == expected
    check_valid(actions, XYZ)


def test_fn_pressed_after_the_key_fires_nothing_more() -> None:
    dec = make()
    actions = run(dec, [pkt(key1=0x0A), pkt(key1=0x0A, key2=0x0C), pkt(key1=0x0C), pkt()])
    assert actions == [DeviceCommand("goto_zero")]


def test_zero_axis_needs_an_axis() -> None:
    dec = make()
    actions = run(dec, [pkt(axis=OFF, key1=0x0C, key2=0x0A)])
    assert not [a for a in actions if isinstance(a, DeviceCommand)]
    assert "axis" in notices(actions)[0]


def test_stop_drops_the_counts_of_its_report() -> None:
    dec = moving_x()
    assert dec.feed(HidReport(1.0, pkt(5, key1=0x02))) == [StopIntent()]
    assert not dec.moving


@pytest.mark.parametrize(
    ("state", "expected"),
    [
        ("Hold:0", "resume"),
        ("Door:0", "resume"),
        ("Run", "hold"),
        ("Jog", "hold"),
        ("Idle", "hold"),
    ],
)
def test_start_pause_follows_the_machine_state(state: str, expected: str) -> None:
    dec = make()
    dec.display(DisplayView(mpos_mm={}, wpos_mm={}, state=state))
    press = [pkt(key1=0x03), pkt()]
    assert run(dec, press + press) == [DeviceCommand(expected)] * 2


def test_start_pause_alternates_from_hold_when_the_state_is_unknown() -> None:
    dec = make()
    press = [pkt(key1=0x03), pkt()]
    assert run(dec, press * 3) == [DeviceCommand(n) for n in ("hold", "resume", "hold")]


def test_the_buttons_table_remaps_and_accepts_macro_names() -> None:
    dec = make(buttons={"macro_10": "unlock", "macro_7": "none", "reset": "stop", "stop": "stop"})
    assert run(dec, [pkt(key1=0x10), pkt()]) == [DeviceCommand("unlock")]
    assert run(dec, [pkt(key1=0x0C, key2=0x0A), pkt()], t0_s=1.0) == []
    assert run(dec, [pkt(key1=0x01), pkt()], t0_s=2.0) == [StopIntent()]


@pytest.mark.parametrize(
    ("options", "words"),
    [
        ({"buttons": {"start": "hold"}}, "buttons.start is not a WHB04B button"),
        ({"buttons": {"reset": "explode"}}, "buttons.reset = 'explode' is not one of"),
        ({"buttons": {"reset": 3}}, "buttons.reset = 3 is not one of"),
        ({"buttons": {"stop": "none"}}, "buttons.stop = 'none': the STOP key always stops"),
        ({"buttons": {"macro_7": "none", "fn_w_home": "home"}}, "buttons.fn_w_home names the same"),
        ({"buttons": "reset"}, "buttons = 'reset' is not a table"),
        ({"step_speed": 0}, "step_speed = 0 must be above 0"),
        ({"step_speed": 1.5}, "step_speed = 1.5 must be at most 1"),
        ({"velocity_step_mm": 0.0001}, "velocity_step_mm = 0.0001 must be at least 0.001"),
        ({"watchdog_s": 0}, "watchdog_s = 0 must be above 0"),
        ({"invert": "yes"}, "invert = 'yes' is not true or false"),
        ({"lcd_coords": "both"}, "lcd_coords = 'both' is not one of work, machine"),
        ({"wachdog_s": 1.0}, "unknown key 'wachdog_s'"),
    ],
)
def test_option_errors_name_the_key(options: dict[str, Any], words: str) -> None:
    with pytest.raises(ConfigError) as info:
        make(**options)
    assert words in str(info.value)


# -- properties ---------------------------------------------------------------------------------


@given(st.binary(min_size=0, max_size=64))
def test_arbitrary_bytes_never_raise(data: bytes) -> None:
    report = decode_report(data)
    assert (report is None) == (len(data) != 8 or data[0] != 4)
    dec = make()
    check_valid(dec.feed(HidReport(0.0, data)), XYZ)
    dec.describe()


_FIELD = st.integers(0, 255)
_REPORT = st.one_of(
    st.builds(lambda k1, k2, f, a, d, r: bytes([4, r, k1, k2, f, a, d, 0]), *[_FIELD] * 6),
    st.builds(
        lambda f, a, d: pkt(d, feed=f, axis=a),
        st.sampled_from([F001, F01, F1, P60, P100, LEAD, LEAD_6, 0x0D, 0x00]),
        st.sampled_from([OFF, X, Y, Z, A, B, 0x16, 0x00]),
        st.integers(-128, 127),
    ),
    st.sampled_from([EMPTY, SLEEP, b"\x04", b""]),
)


@given(
    st.lists(st.tuples(_REPORT, st.floats(0.0, 3.0)), max_size=40),
    st.sampled_from([XYZ, ("X", "Y", "Z", "A")]),
)
def test_any_report_stream_gives_only_valid_intents(
    stream: list[tuple[bytes, float]], axes: tuple[str, ...]
) -> None:
    dec = make(axes)
    t = 0.0
    for data, gap in stream:
        t += gap
        deadline = dec.deadline_s()
        actions = dec.tick(t) if deadline is not None and deadline <= t else []
        actions += dec.feed(HidReport(t, data))
        check_valid(actions, axes)
        decoded = decode_report(data)
        if decoded is None or decoded.kind != "regular":
            assert wheel(actions) == []
        dec.display(DisplayView(mpos_mm={}, wpos_mm={"X": t}))
        dec.describe()


@given(st.lists(st.one_of(st.integers(-128, 127), st.sampled_from([EMPTY, SLEEP])), max_size=60))
def test_the_decoded_counts_sum_byte_6_over_regular_reports_only(
    stream: list[int | bytes],
) -> None:
    reports = [item if isinstance(item, bytes) else pkt(item) for item in stream]
    decoded = [decode_report(r) for r in reports]
    regular_byte6 = [
        int.from_bytes(r[6:7], signed=True)
        for r, d in zip(reports, decoded, strict=True)
        if d is not None and d.kind == "regular"
    ]
    assert sum(d.delta for d in decoded if d is not None) == sum(regular_byte6)
    dec = make()
    intents = wheel(a for i, r in enumerate(reports) for a in dec.feed(HidReport(0.05 * i, r)))
    assert sum(i.counts for i in intents) == sum(regular_byte6)
    assert all(i.axis == "X" and i.step_mm == 0.01 for i in intents)
