"""Contour Shuttle decoders: report decoding, ring and wheel intents, enable and centre rules."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from smoothjog.core.errors import ConfigError
from smoothjog.core.intents import (
    ContinuousIntent,
    HandwheelIntent,
    StepIntent,
    StopIntent,
    validate_intent,
)
from smoothjog.core.options import Table
from smoothjog.inputs.device import (
    EV_KEY,
    EV_REL,
    Action,
    DeviceCommand,
    DeviceInfo,
    DeviceItem,
    DeviceNotice,
    EvdevEvent,
    EvdevFrame,
    HidReport,
    parse_command,
)
from smoothjog.inputs.recording import load_evtest, load_hidraw
from smoothjog.inputs.shuttle import (
    ShuttleDecoder,
    ShuttleEvdevDecoder,
    counter_delta,
    parse_report,
)

FIXTURES = Path(__file__).parent / "fixtures" / "shuttle"
XPRESS = DeviceInfo("Contour Design ShuttleXpress", vendor=0x0B33, product=0x0020)
PRO = DeviceInfo("Contour Design ShuttlePRO", vendor=0x05F3, product=0x0240)
PRO2 = DeviceInfo("Contour Design ShuttlePRO v2", vendor=0x0B33, product=0x0030)
AXES = ("X", "Y", "Z")
MAX_FEED_MM_MIN = 1000.0
B1, B2, B3, B4, B5 = 0x0010, 0x0020, 0x0040, 0x0080, 0x0100  # ShuttleXpress buttons 1..5
BTN_4 = 0x104  # ShuttleXpress button 1 on evdev (BTN_0 + bit 4)
REL_DIAL, REL_WHEEL, REL_WHEEL_HI_RES = 7, 8, 11


def shuttle(
    axes: Sequence[str] = AXES, info: DeviceInfo = XPRESS, **options: Any
) -> ShuttleDecoder:
    return ShuttleDecoder(info, Table(options, "device", "<test>"), axes)


def evdev_shuttle(
    axes: Sequence[str] = AXES, info: DeviceInfo = XPRESS, **options: Any
) -> ShuttleEvdevDecoder:
    return ShuttleEvdevDecoder(info, Table(options, "device", "<test>"), axes)


def rep(t_s: float, ring: int = 0, counter: int = 0x2A, buttons: int = 0) -> HidReport:
    return HidReport(t_s, bytes([ring & 0xFF, counter, 0, buttons & 0xFF, buttons >> 8]))


def frame(t_s: float, *events: tuple[int, int, int], resync: bool = False) -> EvdevFrame:
    return EvdevFrame(t_s, tuple(EvdevEvent(*e) for e in events), resync)


def checked(actions: Iterable[Action], axes: Sequence[str] = AXES) -> list[Action]:
    """The actions, each intent having passed validate_intent."""
    out = list(actions)
    for action in out:
        if not isinstance(action, DeviceCommand | DeviceNotice):
            validate_intent(action, axes, MAX_FEED_MM_MIN)
    return out


def feed(decoder: ShuttleDecoder | ShuttleEvdevDecoder, *items: DeviceItem) -> list[Action]:
    out: list[Action] = []
    for item in items:
        out.extend(checked(decoder.feed(item), decoder.axes))
    return out


def intents(actions: Iterable[Action]) -> list[Action]:
    return [a for a in actions if not isinstance(a, DeviceNotice)]


def ring(axis: str, sign: float, speed: float) -> ContinuousIntent:
    return ContinuousIntent({axis: sign}, speed)


def neutral(axis: str = "X") -> ContinuousIntent:
    return ContinuousIntent({axis: 0.0})


def wheel(counts: int, axis: str = "X", step_mm: float = 0.01) -> HandwheelIntent:
    return HandwheelIntent(axis, counts, step_mm, "position", 0.5)


# -- devices §8.4: the constructed ShuttleXpress rows ----------------------------------------------

#: (ring, counter, button mask, detents from the previous row) for each row of the fixture.
ROWS_84 = [
    (0, 0x2A, 0, None),  # first report ever: baseline only
    (0, 0x2B, 0, +1),
    (0, 0x29, 0, -2),
    (5, 0x29, 0, 0),  # shuttle +5
    (-7, 0x29, 0, 0),  # shuttle -7 (CCW extreme)
    (0, 0x29, 0, 0),  # back to centre
    (0, 0x29, 0x0010, 0),  # button-0 down
    (0, 0xFF, 0, -42),  # the constructed jump 0x29 -> 0xff is -42 by the ±128 rule
    (0, 0x01, 0, +2),  # across the wrap
]


def test_the_84_rows_decode_to_ring_counter_buttons_and_detents() -> None:
    reports = load_hidraw(FIXTURES / "xpress_rows.hid").reports
    assert len(reports) == len(ROWS_84)
    previous: int | None = None
    for report, (ring_value, counter, mask, detents) in zip(reports, ROWS_84, strict=True):
        decoded = parse_report(report.data)
        assert decoded is not None
        assert (decoded.ring, decoded.counter, decoded.buttons) == (ring_value, counter, mask)
        got = None if previous is None else counter_delta(previous, decoded.counter)
        assert got == detents
        previous = decoded.counter


#: What the decoder does on each §8.4 row, by enable mode (buttons by default: 1 = X).
ROWS_84_ACTIONS = {
    "select": [[], [], [], [], [], [], [], [wheel(-42)], [wheel(+2)]],
    # Hold: button 1 is released on row 7, so the counts of rows 7 and 8 are dropped.
    "hold": [[], [], [], [], [], [], [], [], []],
}


@pytest.mark.parametrize("enable", ["select", "hold"])
def test_the_84_rows_as_a_stream(enable: str) -> None:
    recording = load_hidraw(FIXTURES / "xpress_rows.hid")
    decoder = ShuttleDecoder(recording.info, Table({"enable": enable}, "d", "<t>"), AXES)
    got = [intents(feed(decoder, r)) for r in recording.reports]
    assert got == ROWS_84_ACTIONS[enable]


@pytest.mark.parametrize(
    ("before", "after", "detents"),
    [
        (0x2A, 0x2B, 1),
        (0x2B, 0x29, -2),
        (0xFF, 0x01, 2),
        (0x01, 0xFF, -2),
        (0x00, 0x7F, 127),
        (0x00, 0x81, -127),
        (0x00, 0x80, 128),
        (0x80, 0x00, -128),
        (-1, 1, 2),  # a driver giving the counter signed: same result
    ],
)
def test_counter_delta_takes_the_short_way_round(before: int, after: int, detents: int) -> None:
    assert counter_delta(before, after) == detents


@given(st.integers(0, 255), st.integers(0, 255))
def test_counter_wrap_is_symmetric_and_lands_on_the_new_value(a: int, b: int) -> None:
    assert counter_delta(a, b) == -counter_delta(b, a)
    assert (a + counter_delta(a, b)) % 256 == b
    assert -128 <= counter_delta(a, b) <= 128


@pytest.mark.parametrize(
    "data",
    [
        b"",
        b"\x00",
        bytes.fromhex("002a0000"),  # short
        bytes.fromhex("002a00000000"),  # long
        bytes.fromhex("082a000000"),  # ring +8
        bytes.fromhex("f82a000000"),  # ring -8
        bytes.fromhex("802a000000"),  # ring -128
    ],
)
def test_wrong_lengths_and_rings_out_of_range_are_ignored(data: bytes) -> None:
    assert parse_report(data) is None
    decoder = shuttle()
    assert decoder.feed(HidReport(0.0, data)) == []
    assert decoder.ignored == 1


# -- the ring --------------------------------------------------------------------------------------

DEFAULT_SPEEDS = [0.01, 0.03, 0.07, 0.15, 0.3, 0.6, 1.0]


@pytest.mark.parametrize(
    ("ring_value", "expected"),
    [(r, ring("X", 1.0, DEFAULT_SPEEDS[r - 1])) for r in range(1, 8)]
    + [(-r, ring("X", -1.0, DEFAULT_SPEEDS[r - 1])) for r in range(1, 8)],
)
def test_the_ring_jogs_the_held_axis_at_the_table_speed(
    ring_value: int, expected: ContinuousIntent
) -> None:
    decoder = shuttle()
    feed(decoder, rep(0.0, buttons=B1))
    assert feed(decoder, rep(0.1, ring_value, buttons=B1)) == [expected]
    assert decoder.moving


def test_ring_back_at_centre_sends_neutral_exactly_once() -> None:
    decoder = shuttle()
    feed(decoder, rep(0.0, buttons=B1), rep(0.1, 5, buttons=B1))
    assert feed(decoder, rep(0.2, 5, buttons=B1)) == []  # a repeat changes nothing
    assert feed(decoder, rep(0.3, 0, buttons=B1)) == [neutral()]
    assert feed(decoder, rep(0.4, 0, buttons=B1), rep(0.5, 0, buttons=B1)) == []
    assert not decoder.moving


def test_invert_and_ring_speeds_options() -> None:
    speeds = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7]
    decoder = shuttle(invert=True, ring_speeds=speeds)
    feed(decoder, rep(0.0, buttons=B1))
    assert feed(decoder, rep(0.1, 3, buttons=B1)) == [ring("X", -1.0, 0.3)]
    assert feed(decoder, rep(0.2, -7, buttons=B1)) == [ring("X", 1.0, 0.7)]


def test_the_ring_hold_recording_end_to_end() -> None:
    recording = load_hidraw(FIXTURES / "ring_hold.hid")
    decoder = ShuttleDecoder(recording.info, Table({}, "d", "<t>"), AXES)
    got = intents(feed(decoder, *recording.reports))
    out_and_back = DEFAULT_SPEEDS + DEFAULT_SPEEDS[-2::-1]
    assert got == [ring("X", 1.0, s) for s in out_and_back] + [neutral()]
    assert not decoder.moving
    assert recording.reports[-1].t_s == pytest.approx(1.9)


# -- hold to enable --------------------------------------------------------------------------------


def test_hold_mode_moves_only_while_an_axis_button_is_held() -> None:
    decoder = shuttle()
    feed(decoder, rep(0.0))
    assert feed(decoder, rep(0.1, 4), rep(0.2, 0)) == []  # ring with no button: nothing
    assert feed(decoder, rep(0.3, buttons=B2)) == []
    assert feed(decoder, rep(0.4, 4, buttons=B2)) == [ring("Y", 1.0, 0.15)]
    assert feed(decoder, rep(0.5, 4)) == [StopIntent()]  # releasing stops, explicitly
    assert not decoder.moving


def test_wheel_counts_while_disabled_are_dropped_never_saved_up() -> None:
    decoder = shuttle()
    feed(decoder, rep(0.0, counter=10))
    assert feed(decoder, rep(0.1, counter=15), rep(0.2, counter=20)) == []  # no button held
    assert feed(decoder, rep(0.3, counter=20, buttons=B1)) == []  # the press brings no counts
    assert feed(decoder, rep(0.4, counter=21, buttons=B1)) == [wheel(1)]
    assert feed(decoder, rep(0.5, counter=25, buttons=0)) == [StopIntent()]  # turned as released
    assert feed(decoder, rep(0.6, counter=30, buttons=B1)) == []


def test_select_mode_keeps_the_axis_after_release() -> None:
    decoder = shuttle(enable="select")
    feed(decoder, rep(0.0), rep(0.1, buttons=B3), rep(0.2))
    assert decoder.active_axis == "Z"
    assert feed(decoder, rep(0.3, 2)) == [ring("Z", 1.0, 0.03)]
    assert feed(decoder, rep(0.4, 0, counter=0x2C)) == [neutral("Z"), wheel(2, "Z")]


def test_two_axis_buttons_held_the_last_pressed_drives() -> None:
    decoder = shuttle()
    feed(decoder, rep(0.0, buttons=B1), rep(0.1, buttons=B1 | B2))
    assert decoder.active_axis == "Y"
    feed(decoder, rep(0.2, buttons=B1))
    assert decoder.active_axis == "X"


# -- re-enable needs the ring at centre ------------------------------------------------------------


def test_re_enable_after_a_release_with_the_ring_deflected_needs_centre() -> None:
    decoder = shuttle()
    feed(decoder, rep(0.0, buttons=B1), rep(0.1, 5, buttons=B1))
    assert feed(decoder, rep(0.2, 5)) == [StopIntent()]
    assert feed(decoder, rep(0.3, 5, buttons=B1), rep(0.4, 6, buttons=B1)) == []
    assert not decoder.moving
    assert feed(decoder, rep(0.5, 0, buttons=B1)) == []
    assert feed(decoder, rep(0.6, 2, buttons=B1)) == [ring("X", 1.0, 0.03)]


def test_start_up_with_the_ring_deflected_needs_centre() -> None:
    decoder = shuttle()
    assert feed(decoder, rep(0.0, 7, buttons=B1), rep(0.1, 7, buttons=B1)) == []
    assert feed(decoder, rep(0.2, 0, buttons=B1), rep(0.3, 1, buttons=B1)) == [ring("X", 1.0, 0.01)]


def test_after_a_loss_the_ring_must_pass_centre_and_the_counter_rebases() -> None:
    decoder = shuttle()
    feed(decoder, rep(0.0, buttons=B1), rep(0.1, 7, buttons=B1))
    assert decoder.moving
    notices = decoder.lost()
    assert not decoder.moving
    assert notices == [DeviceNotice("ShuttleXpress lost while jogging: jog stopped")]
    assert decoder.lost() == []  # nothing moving: nothing to say
    # Replugged with the ring still held and the button down: no jog; the first counter lost.
    assert feed(decoder, rep(1.0, 7, counter=0x50, buttons=B1)) == []
    assert feed(decoder, rep(1.1, 7, counter=0x50, buttons=B1)) == []
    assert feed(decoder, rep(1.2, 0, counter=0x51, buttons=B1)) == [wheel(1)]


def test_stop_button_stops_and_the_ring_must_pass_centre() -> None:
    decoder = shuttle()
    feed(decoder, rep(0.0, buttons=B1), rep(0.1, 3, buttons=B1))
    assert feed(decoder, rep(0.2, 3, buttons=B1 | B5)) == [StopIntent()]
    assert feed(decoder, rep(0.3, 4, buttons=B1)) == []
    assert feed(decoder, rep(0.4, 0, buttons=B1), rep(0.5, 1, buttons=B1)) == [ring("X", 1.0, 0.01)]


def test_stop_is_sent_even_at_rest_and_deselects_in_select_mode() -> None:
    decoder = shuttle(enable="select")
    feed(decoder, rep(0.0), rep(0.1, buttons=B1), rep(0.2))
    assert feed(decoder, rep(0.3, buttons=B5)) == [StopIntent()]
    assert decoder.active_axis is None
    assert feed(decoder, rep(0.4, 3), rep(0.5, 0, counter=0x30)) == []


def test_one_shot_buttons_held_in_the_first_report_do_not_fire() -> None:
    decoder = shuttle()
    assert feed(decoder, rep(0.0, buttons=B5 | B4)) == []
    assert decoder.step_mm == 0.01


# -- axis and step changes, the ring and the wheel together ----------------------------------------


def test_changing_axis_while_counts_run_stops_first() -> None:
    decoder = shuttle()
    feed(decoder, rep(0.0, buttons=B1), rep(0.1, counter=0x2D, buttons=B1))
    assert decoder.moving  # counts may still be running in the engine
    assert feed(decoder, rep(0.2, counter=0x2D, buttons=B1 | B2)) == [StopIntent()]
    assert feed(decoder, rep(0.3, counter=0x2E, buttons=B1 | B2)) == [wheel(1, "Y")]


def test_changing_axis_while_the_ring_jogs_stops_and_needs_centre() -> None:
    decoder = shuttle(enable="select")
    feed(decoder, rep(0.0), rep(0.1, buttons=B1), rep(0.2, 4))
    assert feed(decoder, rep(0.3, 4, buttons=B2)) == [StopIntent()]
    assert feed(decoder, rep(0.4, 4)) == []
    assert feed(decoder, rep(0.5, 0), rep(0.6, -1)) == [ring("Y", -1.0, 0.01)]


def test_step_button_cycles_and_stops_running_counts_first() -> None:
    decoder = shuttle()
    feed(decoder, rep(0.0, buttons=B1), rep(0.1, counter=0x2B, buttons=B1))
    assert feed(decoder, rep(0.2, counter=0x2B, buttons=B1 | B4)) == [
        StopIntent(),
        DeviceNotice("wheel step 0.1 mm"),
    ]
    assert feed(decoder, rep(0.3, counter=0x2C, buttons=B1)) == [wheel(1, step_mm=0.1)]
    steps = []
    for i in range(3):
        feed(decoder, rep(0.4 + i / 10, counter=0x2C, buttons=B1 | B4))
        steps.append(decoder.step_mm)
        feed(decoder, rep(0.45 + i / 10, counter=0x2C, buttons=B1))
    assert steps == [1.0, 0.01, 0.1]


def test_the_ring_owns_the_axis_while_deflected() -> None:
    decoder = shuttle()
    feed(decoder, rep(0.0, buttons=B1), rep(0.1, counter=0x2B, buttons=B1))
    # Counts were running: the ring's jog does not join them, it stops them first.
    assert feed(decoder, rep(0.2, 2, counter=0x2B, buttons=B1)) == [
        StopIntent(),
        ring("X", 1.0, 0.03),
    ]
    assert feed(decoder, rep(0.3, 2, counter=0x30, buttons=B1)) == []  # wheel ignored


@pytest.mark.parametrize(
    ("options", "counts", "expected"),
    [
        ({}, 3, [wheel(3)]),
        ({"wheel_mode": "velocity"}, -2, [HandwheelIntent("X", -2, 0.01, "velocity", 0.5)]),
        ({"wheel": "step", "steps_mm": [0.5]}, 2, [StepIntent("X", 0.5, 0.5)] * 2),
        ({"wheel": "step", "wheel_speed": 0.2}, -1, [StepIntent("X", -0.01, 0.2)]),
        ({"invert_wheel": True, "steps_mm": [0.05, 1]}, 1, [wheel(-1, step_mm=0.05)]),
    ],
)
def test_wheel_modes(options: dict[str, Any], counts: int, expected: list[Action]) -> None:
    decoder = shuttle(**options)
    feed(decoder, rep(0.0, buttons=B1))
    assert feed(decoder, rep(0.1, counter=(0x2A + counts) % 256, buttons=B1)) == expected


# -- buttons, commands, models ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("action", "held", "expected"),
    [
        ("home", 0, [DeviceCommand("home")]),
        ("unlock", B1, [DeviceCommand("unlock")]),
        ("zero", B1, [DeviceCommand("zero", axes=("X",))]),
        ("zero", 0, [DeviceNotice("zero: hold or select an axis first")]),
        ("zero:xy", 0, [DeviceCommand("zero", axes=("X", "Y"))]),
        ("override:feed:+10", 0, [DeviceCommand("override", kind="feed", step="+10")]),
        ("override:rapid:25", 0, [DeviceCommand("override", kind="rapid", step="25")]),
        ("none", 0, []),
    ],
)
def test_command_buttons(action: str, held: int, expected: list[Action]) -> None:
    decoder = shuttle(buttons={"5": action})
    feed(decoder, rep(0.0, buttons=held))
    assert feed(decoder, rep(0.1, buttons=held | B5)) == expected
    assert feed(decoder, rep(0.2, buttons=held)) == []  # a release does nothing


def test_every_override_the_machine_side_sends_is_a_button_command() -> None:
    from smoothjog.core.realtime import OVERRIDES

    for kind, step in OVERRIDES:
        assert parse_command(f"override:{kind}:{step}") == DeviceCommand(
            "override", kind=kind, step=step
        )
    with pytest.raises(ValueError, match="is not an override"):
        parse_command("override:feed:+7")


@pytest.mark.parametrize("text", ["X", "stop", "jump", ""])
def test_parse_command_is_none_for_what_is_not_a_command(text: str) -> None:
    assert parse_command(text) is None


@pytest.mark.parametrize(
    ("info", "mask", "number"),
    [(XPRESS, 0x0010, 1), (XPRESS, 0x0100, 5), (PRO, 0x0001, 1), (PRO2, 0x4000, 15)],
)
def test_button_numbers_follow_the_model(info: DeviceInfo, mask: int, number: int) -> None:
    decoder = shuttle(info=info, buttons={str(number): "home"})
    feed(decoder, rep(0.0))
    assert feed(decoder, rep(0.1, buttons=mask)) == [DeviceCommand("home")]


def test_bits_the_model_has_no_button_for_are_ignored() -> None:
    decoder = shuttle()
    feed(decoder, rep(0.0))
    assert feed(decoder, rep(0.1, 3, buttons=0x000F | 0x8000)) == []
    assert decoder.active_axis is None


def test_a_default_axis_the_machine_lacks_is_left_unmapped() -> None:
    decoder = shuttle(axes=("X", "Y"))
    assert 3 not in decoder.buttons
    feed(decoder, rep(0.0), rep(0.1, buttons=B3))
    assert feed(decoder, rep(0.2, 5, buttons=B3)) == []


@pytest.mark.parametrize(
    ("options", "key"),
    [
        ({"enable": "push"}, "enable"),
        ({"model": "ultra"}, "model"),
        ({"ring_speeds": [0.1] * 6}, "ring_speeds"),
        ({"ring_speeds": [0.5, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9]}, "ring_speeds"),
        ({"ring_speeds": [0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6]}, "ring_speeds"),
        ({"ring_speeds": [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 1.5]}, "ring_speeds"),
        ({"ring_speeds": "fast"}, "ring_speeds"),
        ({"steps_mm": [0.0001]}, "steps_mm"),
        ({"steps_mm": []}, "steps_mm"),
        ({"steps_mm": ["1"]}, "steps_mm"),
        ({"wheel": "spin"}, "wheel"),
        ({"wheel_mode": "fast"}, "wheel_mode"),
        ({"wheel_speed": 0}, "wheel_speed"),
        ({"invert": "yes"}, "invert"),
        ({"buttons": {"6": "X"}}, "buttons.6"),
        ({"buttons": {"one": "X"}}, "buttons.one"),
        ({"buttons": {"1": "Q"}}, "buttons.1"),
        ({"buttons": {"1": "A"}}, "buttons.1"),
        ({"buttons": {"1": 3}}, "buttons.1"),
        ({"buttons": {"1": "override:feed:+5"}}, "buttons.1"),
        ({"buttons": {"1": "home:now"}}, "buttons.1"),
        ({"buttons": {"1": "zero:Q"}}, "buttons.1"),
        ({"buttons": {"1": "zero:A"}}, "buttons.1"),
        ({"buttons": "X"}, "buttons"),
        ({"rings": 1}, "rings"),
        ({"ring_timeout_s": 0.5}, "ring_timeout_s"),  # an evdev key: unknown on hidraw
    ],
)
def test_option_errors_name_the_key(options: dict[str, Any], key: str) -> None:
    with pytest.raises(ConfigError, match=f"'?{key}'?"):
        shuttle(**options)


@pytest.mark.parametrize(
    ("options", "key"),
    [({"ring_timeout_s": 0}, "ring_timeout_s"), ({"centre_gap_s": 1}, "centre_gap_s")],
)
def test_evdev_option_errors_name_the_key(options: dict[str, Any], key: str) -> None:
    with pytest.raises(ConfigError, match=key):
        evdev_shuttle(**options)


def test_buttons_beyond_the_xpress_are_fine_on_a_pro() -> None:
    assert shuttle(info=PRO2, buttons={"15": "home"}).buttons[15].command == DeviceCommand("home")


@pytest.mark.parametrize(
    ("info", "hidraw", "evdev"),
    [
        (XPRESS, True, True),
        (PRO, True, True),
        (PRO2, True, True),
        (DeviceInfo("Contour Design ShuttleXpress"), False, True),
        (DeviceInfo("Shuttle thing", rels=frozenset({REL_DIAL, REL_WHEEL})), False, True),
        (DeviceInfo("Space Shuttle joystick"), False, False),
        (DeviceInfo("Logitech Gamepad F310", vendor=0x046D, product=0xC216), False, False),
    ],
)
def test_matches(info: DeviceInfo, hidraw: bool, evdev: bool) -> None:
    assert ShuttleDecoder.matches(info) is hidraw
    assert ShuttleEvdevDecoder.matches(info) is evdev


def test_names_and_describe() -> None:
    assert (ShuttleDecoder.name, ShuttleDecoder.kind, ShuttleDecoder.transport) == (
        "shuttle",
        "handwheel",
        "hidraw",
    )
    assert (ShuttleEvdevDecoder.name, ShuttleEvdevDecoder.transport) == ("shuttle-evdev", "evdev")
    text = shuttle().describe()
    assert "hold an axis button" in text
    assert "1=X 2=Y 3=Z 4=step 5=stop" in text
    assert "first wheel move after start-up" in text


# -- evdev -----------------------------------------------------------------------------------------


def test_evdev_centre_is_synthesised_from_the_counters_next_event() -> None:
    recording = load_evtest(FIXTURES / "evdev_centre.evtest")
    decoder = ShuttleEvdevDecoder(recording.info, Table({}, "d", "<t>"), AXES)
    got = [(f.t_s, intents(feed(decoder, f))) for f in recording.frames]
    assert [(t, a) for t, a in got if a] == [
        (pytest.approx(0.1), [ring("X", 1.0, 0.01)]),
        (pytest.approx(0.11), [ring("X", 1.0, 0.07)]),
        (pytest.approx(0.12), [ring("X", 1.0, 0.3)]),
        (pytest.approx(0.32), [ring("X", 1.0, 0.03)]),
        (pytest.approx(0.33), [neutral()]),  # the synthesised centre
        (pytest.approx(0.5), [wheel(1)]),
        (pytest.approx(0.7), [StopIntent()]),  # the release stops the counts
    ]


def test_evdev_lost_centre_is_zeroed_by_the_ring_timeout() -> None:
    recording = load_evtest(FIXTURES / "evdev_lost_centre.evtest")
    decoder = ShuttleEvdevDecoder(recording.info, Table({}, "d", "<t>"), AXES)
    *frames, release = recording.frames
    feed(decoder, *frames)
    assert decoder.moving
    deadline = decoder.deadline_s()
    assert deadline == pytest.approx(0.12 + 0.25)
    assert decoder.tick(deadline - 0.01) == []
    assert checked(decoder.tick(deadline)) == [neutral()]
    assert not decoder.moving
    assert decoder.deadline_s() is None
    assert decoder.tick(deadline + 1) == []
    assert feed(decoder, release) == []


def test_evdev_ring_timeout_option_and_repeats_keep_the_jog() -> None:
    decoder = evdev_shuttle(ring_timeout_s=0.1)
    feed(decoder, frame(0.0, (EV_KEY, BTN_4, 1)))
    feed(decoder, frame(0.01, (EV_REL, REL_WHEEL, 6)))
    for i in range(1, 10):  # a ring that repeats its report every 50 ms
        assert feed(decoder, frame(0.01 + 0.05 * i, (EV_REL, REL_WHEEL, 6))) == []
        assert decoder.deadline_s() == pytest.approx(0.11 + 0.05 * i)
    assert decoder.moving
    assert decoder.tick(0.56) == [neutral()]


def test_evdev_a_frame_within_the_centre_gap_is_not_a_centre() -> None:
    decoder = evdev_shuttle()
    feed(decoder, frame(0.0, (EV_KEY, BTN_4, 1)), frame(0.1, (EV_REL, REL_WHEEL, 3)))
    assert feed(decoder, frame(0.103, (EV_REL, REL_DIAL, 9))) == []
    assert decoder.moving
    assert feed(decoder, frame(0.2, (EV_REL, REL_DIAL, 9))) == [neutral()]


def test_evdev_a_key_frame_without_the_ring_is_a_centre_too() -> None:
    decoder = evdev_shuttle(enable="select")
    feed(decoder, frame(0.0, (EV_KEY, BTN_4, 1)), frame(0.05, (EV_KEY, BTN_4, 0)))
    feed(decoder, frame(0.1, (EV_REL, REL_WHEEL, 3)))
    assert feed(decoder, frame(0.3, (EV_KEY, BTN_4 + 1, 1))) == [StopIntent()]  # Y, ring at 0
    assert feed(decoder, frame(0.4, (EV_REL, REL_WHEEL, 2))) == [ring("Y", 1.0, 0.03)]


def test_evdev_counter_passing_zero_never_jumps() -> None:
    recording = load_evtest(FIXTURES / "evdev_dial_wrap.evtest")
    decoder = ShuttleEvdevDecoder(recording.info, Table({}, "d", "<t>"), AXES)
    got = intents(feed(decoder, *recording.frames))
    assert got == [wheel(1), wheel(1), wheel(2), wheel(1), StopIntent()]


def test_evdev_enable_with_the_ring_held_needs_centre() -> None:
    decoder = evdev_shuttle()
    # The kernel sends the held ring's value with the key: the ring is deflected at enable.
    assert feed(decoder, frame(0.0, (EV_KEY, BTN_4, 1), (EV_REL, REL_WHEEL, 4))) == []
    assert feed(decoder, frame(0.02, (EV_REL, REL_WHEEL, 5))) == []
    assert feed(decoder, frame(0.1, (EV_REL, REL_DIAL, 1))) == []  # the centre
    assert feed(decoder, frame(0.2, (EV_REL, REL_WHEEL, 1))) == [ring("X", 1.0, 0.01)]


@pytest.mark.parametrize(
    "event",
    [
        (EV_REL, REL_WHEEL_HI_RES, 600),
        (EV_REL, REL_WHEEL, 9),
        (EV_KEY, BTN_4, 2),
        (EV_KEY, 0x100, 1),  # BTN_0: no ShuttleXpress button
        (EV_REL, 0, 5),
    ],
)
def test_evdev_ignores_what_is_not_the_ring_dial_or_a_button(event: tuple[int, int, int]) -> None:
    decoder = evdev_shuttle()
    assert feed(decoder, frame(0.0, event)) == []
    assert decoder.active_axis is None
    assert not decoder.moving


def test_evdev_resync_stops_and_the_ring_must_be_seen_at_centre() -> None:
    decoder = evdev_shuttle()
    feed(decoder, frame(0.0, (EV_KEY, BTN_4, 1)), frame(0.1, (EV_REL, REL_WHEEL, 5)))
    got = feed(decoder, frame(0.2, (EV_KEY, BTN_4, 1), resync=True))
    assert got == [StopIntent(), DeviceNotice("ShuttleXpress: events were lost: jog stopped")]
    assert decoder.active_axis == "X"
    assert feed(decoder, frame(0.21, (EV_REL, REL_WHEEL, 5))) == []
    assert feed(decoder, frame(0.3, (EV_REL, REL_DIAL, 4))) == []  # centre; counter rebased
    assert feed(decoder, frame(0.4, (EV_REL, REL_WHEEL, 2))) == [ring("X", 1.0, 0.03)]


def test_evdev_resync_without_the_button_disables() -> None:
    decoder = evdev_shuttle()
    feed(decoder, frame(0.0, (EV_KEY, BTN_4, 1)))
    feed(decoder, frame(0.1, (EV_REL, REL_WHEEL, 5)))
    assert feed(decoder, frame(0.2, resync=True)) == [
        StopIntent(),
        DeviceNotice("ShuttleXpress: events were lost: jog stopped"),
    ]
    assert decoder.active_axis is None


def test_the_wrong_item_kind_is_ignored() -> None:
    assert shuttle().feed(EvdevFrame(0.0, ())) == []
    assert evdev_shuttle().feed(HidReport(0.0, b"\x00\x2a\x00\x10\x00")) == []


# -- properties ------------------------------------------------------------------------------------

REPORTS = st.builds(
    lambda ring_value, counter, buttons: bytes(
        [ring_value & 0xFF, counter, 0, buttons & 0xFF, buttons >> 8]
    ),
    st.integers(-7, 7),
    st.integers(0, 255),
    st.sampled_from([0, B1, B2, B3, B4, B5, B1 | B2, B1 | B5, B3 | B4]),
)
OPTIONS = st.sampled_from(
    [{}, {"enable": "select"}, {"wheel": "step"}, {"wheel_mode": "velocity", "invert": True}]
)


@settings(max_examples=200)
@given(st.lists(st.binary(max_size=64), max_size=30), OPTIONS)
def test_arbitrary_bytes_never_raise_and_intents_are_valid(
    chunks: list[bytes], options: dict[str, Any]
) -> None:
    decoder = shuttle(**options)
    for i, data in enumerate(chunks):
        checked(decoder.feed(HidReport(i * 0.01, data)))
    decoder.lost()
    assert not decoder.moving


@settings(max_examples=200)
@given(st.lists(REPORTS, max_size=40))
def test_hold_mode_never_moves_with_no_axis_button_held(reports: list[bytes]) -> None:
    decoder = shuttle(buttons={"4": "home"})
    for i, data in enumerate(reports):
        checked(decoder.feed(HidReport(i * 0.01, data)))
        if not data[3] & (B1 | B2 | B3):
            assert not decoder.moving
            assert decoder.active_axis is None


@settings(max_examples=200)
@given(st.lists(REPORTS, max_size=40))
def test_a_ring_jog_always_ends_with_neutral_or_stop(reports: list[bytes]) -> None:
    decoder = shuttle(enable="select")
    last: Action | None = None
    for i, data in enumerate([*reports, bytes([0, reports[-1][1] if reports else 0, 0, 0, 0])]):
        for action in checked(decoder.feed(HidReport(i * 0.01, data))):
            if isinstance(action, ContinuousIntent | StopIntent):
                last = action
    assert last is None or isinstance(last, StopIntent) or last.is_neutral()


EVENTS = st.lists(
    st.tuples(
        st.sampled_from([EV_KEY, EV_REL, 0x03, 0x04]),
        st.sampled_from([REL_DIAL, REL_WHEEL, REL_WHEEL_HI_RES, 0x100, BTN_4, BTN_4 + 4, 0x10F]),
        st.integers(-(2**31), 2**31 - 1) | st.integers(-8, 8),
    ),
    max_size=6,
)


@settings(max_examples=200)
@given(st.lists(st.tuples(EVENTS, st.booleans(), st.floats(0, 0.5)), max_size=30), OPTIONS)
def test_evdev_arbitrary_frames_and_ticks_never_raise(
    frames: list[tuple[list[tuple[int, int, int]], bool, float]], options: dict[str, Any]
) -> None:
    decoder = evdev_shuttle(**options)
    t_s = 0.0
    for events, resync, gap_s in frames:
        t_s += gap_s
        deadline = decoder.deadline_s()
        if deadline is not None and deadline <= t_s:
            checked(decoder.tick(deadline))
        checked(decoder.feed(frame(t_s, *events, resync=resync)))
    deadline = decoder.deadline_s()
    if deadline is not None:
        checked(decoder.tick(deadline))
        if decoder.enable == "hold" and not decoder.active_axis:
            assert not decoder.moving
