"""3Dconnexion SpaceMouse decoders: both report layouts, shaping, arming, stale axes, buttons."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from smoothjog.core.errors import ConfigError
from smoothjog.core.intents import ContinuousIntent, StopIntent, validate_intent
from smoothjog.core.options import Table
from smoothjog.inputs.device import (
    EV_ABS,
    EV_KEY,
    EV_REL,
    AbsRange,
    Action,
    DeviceCommand,
    DeviceInfo,
    DeviceItem,
    DeviceNotice,
    EvdevEvent,
    EvdevFrame,
    HidReport,
)
from smoothjog.inputs.recording import load_evtest, load_hidraw
from smoothjog.inputs.shaping import expo
from smoothjog.inputs.spacemouse import SpaceMouseDecoder, SpaceMouseEvdevDecoder

FIXTURES = Path(__file__).parent / "fixtures" / "spacemouse"
NAVIGATOR = DeviceInfo("3Dconnexion SpaceNavigator", vendor=0x046D, product=0xC626)
WIRELESS = DeviceInfo("3Dconnexion SpaceMouse Wireless", vendor=0x256F, product=0xC62E)
AXES = ("X", "Y", "Z")
MAX_FEED_MM_MIN = 1000.0
REL_X, REL_Y, REL_Z, REL_RX, REL_RY, REL_RZ = range(6)
BTN_0 = 0x100
LINEAR = {"deadzone": 0.0, "expo": 0.0}


def mouse(
    machine: Sequence[str] = AXES, info: DeviceInfo = NAVIGATOR, **options: Any
) -> SpaceMouseDecoder:
    return SpaceMouseDecoder(info, Table(options, "device", "<test>"), machine)


def evdev_mouse(
    machine: Sequence[str] = AXES, info: DeviceInfo = NAVIGATOR, **options: Any
) -> SpaceMouseEvdevDecoder:
    return SpaceMouseEvdevDecoder(info, Table(options, "device", "<test>"), machine)


def int16s(*values: int) -> bytes:
    return b"".join(v.to_bytes(2, "little", signed=True) for v in values)


def trans(t_s: float, x: int = 0, y: int = 0, z: int = 0) -> HidReport:
    return HidReport(t_s, b"\x01" + int16s(x, y, z))


def rot(t_s: float, rx: int = 0, ry: int = 0, rz: int = 0) -> HidReport:
    return HidReport(t_s, b"\x02" + int16s(rx, ry, rz))


def six(t_s: float, *values: int) -> HidReport:
    return HidReport(t_s, b"\x01" + int16s(*(list(values) + [0] * (6 - len(values)))))


def press(t_s: float, mask: int) -> HidReport:
    return HidReport(t_s, bytes([3, mask & 0xFF, mask >> 8]))


def frame(t_s: float, *events: tuple[int, int, int], resync: bool = False) -> EvdevFrame:
    return EvdevFrame(t_s, tuple(EvdevEvent(*e) for e in events), resync)


def checked(actions: Iterable[Action], axes: Sequence[str] = AXES) -> list[Action]:
    """The actions, each intent having passed validate_intent."""
    out = list(actions)
    for action in out:
        if not isinstance(action, DeviceCommand | DeviceNotice):
            validate_intent(action, axes, MAX_FEED_MM_MIN)
    return out


def feed(decoder: SpaceMouseDecoder | SpaceMouseEvdevDecoder, *items: DeviceItem) -> list[Action]:
    out: list[Action] = []
    for item in items:
        out.extend(checked(decoder.feed(item), decoder.axes))
    return out


def jog(x: float = 0.0, y: float = 0.0, z: float = 0.0, speed: float = 1.0) -> ContinuousIntent:
    return ContinuousIntent({"X": x, "Y": y, "Z": z}, speed)


NEUTRAL = jog()


def armed(decoder: SpaceMouseDecoder) -> SpaceMouseDecoder:
    feed(decoder, trans(0.0), rot(0.008))
    return decoder


# -- devices §8.3: the quoted SpaceNavigator reports and the constructed new layout ----------------

#: What each row of spacenavigator_usbmon.hid gives (defaults: 1 = stop, 2 = dominant).
USBMON_ROWS = [
    [],  # translation, all zero: arms
    [],  # rotation Ry = -30: rotation moves nothing by default
    [StopIntent()],  # button 1 down
    [],  # release
    [DeviceNotice("dominant axis on")],  # button 2 down
    [StopIntent()],  # both buttons: button 1 is the new press
    [],  # LED on (an output report): ignored
    [],  # LED off: ignored
]


def test_the_quoted_spacenavigator_reports() -> None:
    recording = load_hidraw(FIXTURES / "spacenavigator_usbmon.hid")
    decoder = SpaceMouseDecoder(recording.info, Table({}, "d", "<t>"), AXES)
    assert [feed(decoder, r) for r in recording.reports] == USBMON_ROWS
    assert decoder.ignored == 2
    assert decoder.dominant
    assert not decoder.moving


@pytest.mark.parametrize(
    ("options", "expected"),
    [
        ({"axes": {"A": "ry"}}, []),  # -30 of 350 is inside the 0.1 deadzone
        ({"axes": {"A": "ry"}, **LINEAR}, [ContinuousIntent({**NEUTRAL.axes, "A": -30 / 350})]),
        ({"axes": {"A": "-ry"}, **LINEAR}, [ContinuousIntent({**NEUTRAL.axes, "A": 30 / 350})]),
        (LINEAR, []),  # not mapped: ignored however large
    ],
)
def test_rotation_moves_only_when_mapped(options: dict[str, Any], expected: list[Action]) -> None:
    axes = ("X", "Y", "Z", "A")
    decoder = mouse(axes, **options)
    rows = load_hidraw(FIXTURES / "spacenavigator_usbmon.hid").reports
    # Both halves seen at rest first (a rotation mapped is needed known to arm).
    checked(decoder.feed(rows[0]), axes)
    checked(decoder.feed(rot(0.004)), axes)
    assert checked(decoder.feed(rows[1]), axes) == expected


#: What each row of wireless_new_layout.hid gives.
NEW_LAYOUT_ROWS = [
    [],  # at rest
    [jog(x=1.0, z=1.0)],  # X = +350, Z = -350 (Z is -z), Rz = +30 unmapped
    [NEUTRAL],  # release ...
    [],  # ... sent three times: neutral once
    [],
    [jog(x=1.0)],  # X = +498: clamped to full
]


def test_the_new_layout_reports() -> None:
    recording = load_hidraw(FIXTURES / "wireless_new_layout.hid")
    decoder = SpaceMouseDecoder(recording.info, Table({}, "d", "<t>"), AXES)
    assert [feed(decoder, r) for r in recording.reports] == NEW_LAYOUT_ROWS
    assert decoder.model == "SpaceMouse Wireless"


@pytest.mark.parametrize(
    ("raw", "deflection"),
    [
        (0, 0.0),
        (350, 1.0),
        (-350, -1.0),
        (175, 0.5),
        (446, 1.0),  # johnhw/pyspacenavigator#1: x seen up to 446 ...
        (-441, -1.0),  # ... and down to -441
        (498, 1.0),  # y up to 498 (devices §8.6)
        (-471, -1.0),
        (32767, 1.0),
        (-32768, -1.0),
    ],
)
def test_scaled_by_350_and_clamped(raw: int, deflection: float) -> None:
    decoder = armed(mouse(**LINEAR))
    expected = [jog(x=deflection)] if deflection else []
    assert feed(decoder, trans(0.016, x=raw)) == expected


@pytest.mark.parametrize(
    ("channel", "raw", "expected"),
    [
        ("x", 175, jog(x=0.5)),
        ("y", 175, jog(y=-0.5)),  # the cap pulled back (raw +y) is machine -Y
        ("z", 175, jog(z=-0.5)),  # the cap pressed down (raw +z) is machine -Z
        ("z", -175, jog(z=0.5)),
    ],
)
def test_default_axis_signs(channel: str, raw: int, expected: ContinuousIntent) -> None:
    decoder = armed(mouse(**LINEAR))
    assert feed(decoder, trans(0.016, **{channel: raw})) == [expected]


@pytest.mark.parametrize(
    ("raw", "expected_x"),
    [
        (35, 0.0),  # the deadzone's edge: still 0
        (36, expo((36 / 350 - 0.1) / 0.9, 0.2)),  # leaves 0 continuously (tiny)
        (200, expo((200 / 350 - 0.1) / 0.9, 0.2)),
        (350, 1.0),
    ],
)
def test_deadzone_is_rescaled_and_expo_applied(raw: int, expected_x: float) -> None:
    decoder = armed(mouse())
    got = feed(decoder, trans(0.016, x=raw))
    if expected_x == 0.0:
        assert got == []
    else:
        assert got == [jog(x=pytest.approx(expected_x))]
        assert 0.0 < expected_x <= 1.0


def test_push_x_recording_end_to_end() -> None:
    recording = load_hidraw(FIXTURES / "push_x.hid")
    decoder = SpaceMouseDecoder(recording.info, Table({}, "d", "<t>"), AXES)
    got = feed(decoder, *recording.reports)
    assert all(isinstance(a, ContinuousIntent) for a in got)
    *moving, last = got
    assert last == NEUTRAL
    assert got.count(NEUTRAL) == 1
    assert moving
    for intent in moving:
        assert isinstance(intent, ContinuousIntent)
        assert intent.axes["X"] > 0.0
        assert intent.axes["Y"] == intent.axes["Z"] == 0.0
    assert max(i.axes["X"] for i in moving if isinstance(i, ContinuousIntent)) == 1.0
    assert not decoder.moving
    # The neutral comes as the let-go's last report is inside the deadzone (x = 14 of 350),
    # before the device's own zero reports.
    neutral_at = next(
        r.t_s
        for r in recording.reports
        if r.t_s > 1.0 and r.data[0] == 1 and int.from_bytes(r.data[1:3], "little") < 35
    )
    assert neutral_at == pytest.approx(1.152)
    replay = SpaceMouseDecoder(recording.info, Table({}, "d", "<t>"), AXES)
    for report in recording.reports:
        if replay.feed(report) == [NEUTRAL]:
            assert report.t_s == neutral_at
            break
    else:
        pytest.fail("no neutral")


# -- arming: neutral first -------------------------------------------------------------------------


def test_start_up_with_the_cap_deflected_needs_neutral() -> None:
    decoder = mouse()
    assert feed(decoder, trans(0.0, x=300), rot(0.008), trans(0.016, x=300)) == []
    assert not decoder.moving
    assert feed(decoder, trans(0.032, x=0)) == []
    assert feed(decoder, trans(0.048, x=350)) == [jog(x=1.0)]


def test_a_gentle_first_push_arms_even_with_no_deadzone() -> None:
    decoder = mouse(**LINEAR)
    assert feed(decoder, trans(0.0, x=10)) == [jog(x=10 / 350)]
    decoder = mouse(**LINEAR)
    assert feed(decoder, trans(0.0, x=30)) == []  # beyond 5 %: held, not starting


def test_after_a_loss_the_cap_must_be_seen_at_neutral() -> None:
    decoder = armed(mouse())
    feed(decoder, trans(0.016, x=350))
    assert decoder.moving
    assert decoder.lost() == [DeviceNotice("SpaceNavigator lost while jogging: jog stopped")]
    assert not decoder.moving
    assert decoder.lost() == []
    assert feed(decoder, trans(1.0, x=350), rot(1.008)) == []
    assert feed(decoder, trans(1.016), trans(1.032, x=350)) == [jog(x=1.0)]


def test_stop_button_stops_and_the_cap_must_return_to_neutral() -> None:
    decoder = armed(mouse())
    feed(decoder, trans(0.016, x=350))
    assert feed(decoder, press(0.02, 0x01)) == [StopIntent()]
    assert feed(decoder, trans(0.032, x=340), press(0.04, 0)) == []
    assert feed(decoder, trans(0.048), trans(0.064, y=-350)) == [jog(y=1.0)]


def test_stop_at_rest_does_not_block_the_next_push() -> None:
    decoder = armed(mouse())
    assert feed(decoder, press(0.02, 0x01), press(0.03, 0)) == [StopIntent()]
    assert feed(decoder, trans(0.048, x=350)) == [jog(x=1.0)]


def test_old_layout_needs_both_halves_when_a_rotation_is_mapped() -> None:
    axes = ("X", "Y", "Z", "A")
    decoder = SpaceMouseDecoder(NAVIGATOR, Table({"axes": {"A": "rz"}}, "d", "<t>"), axes)
    # Translation at rest but the rotation not yet seen: not armed.
    assert checked(decoder.feed(trans(0.0)), axes) == []
    assert checked(decoder.feed(rot(0.008, rz=300)), axes) == []  # held twisted: still not
    assert checked(decoder.feed(trans(0.016)), axes) == []
    assert checked(decoder.feed(rot(0.024)), axes) == []  # seen at rest: armed
    assert checked(decoder.feed(rot(0.032, rz=350)), axes) == [
        ContinuousIntent({"X": 0.0, "Y": 0.0, "Z": 0.0, "A": 1.0})
    ]


# -- the watchdog (hidraw) -------------------------------------------------------------------------


def test_watchdog_stops_a_jog_the_device_went_silent_in() -> None:
    decoder = armed(mouse())
    feed(decoder, trans(0.016, x=350), rot(0.024))
    assert decoder.deadline_s() == pytest.approx(0.024 + 0.25)
    assert decoder.tick(0.2) == []
    assert decoder.tick(0.274) == [
        StopIntent(),
        DeviceNotice("SpaceNavigator: no report for 250 ms: jog stopped"),
    ]
    assert not decoder.moving
    assert decoder.deadline_s() is None
    # The link comes back with the cap still pushed: no jog until it is seen at rest.
    assert feed(decoder, trans(0.5, x=350), rot(0.508)) == []
    assert feed(decoder, trans(0.516), rot(0.524), trans(0.532, x=350)) == [jog(x=1.0)]


def test_watchdog_off_and_idle() -> None:
    decoder = armed(mouse(watchdog_s=0))
    feed(decoder, trans(0.016, x=350))
    assert decoder.deadline_s() is None
    assert armed(mouse()).deadline_s() is None  # at rest: no timer


# -- dominant, speed, buttons ----------------------------------------------------------------------


def test_dominant_axis_only_the_largest_moves_with_a_margin() -> None:
    decoder = armed(mouse(dominant=True, **LINEAR))
    assert feed(decoder, trans(0.016, x=210, y=-175)) == [jog(x=0.6)]
    assert feed(decoder, trans(0.032, x=210, y=-227)) == []  # Y leads by < 0.1: X keeps it
    assert feed(decoder, trans(0.048, x=210, y=-263)) == [jog(y=263 / 350)]
    assert feed(decoder, trans(0.064, x=245, y=-263)) == []  # X back but not by the margin
    assert feed(decoder, trans(0.08)) == [NEUTRAL]
    assert feed(decoder, trans(0.096, x=70, z=-105)) == [jog(z=0.3)]


def test_dominant_toggle_button_changes_the_held_jog() -> None:
    decoder = armed(mouse(**LINEAR))
    feed(decoder, trans(0.016, x=210, y=-175))
    assert feed(decoder, press(0.02, 0x02)) == [DeviceNotice("dominant axis on"), jog(x=0.6)]
    assert feed(decoder, press(0.03, 0)) == []
    assert feed(decoder, press(0.04, 0x02)) == [
        DeviceNotice("dominant axis off"),
        jog(x=0.6, y=0.5),
    ]


def test_speed_buttons_step_the_speed_and_resend_the_jog() -> None:
    decoder = armed(mouse(buttons={"3": "slower", "4": "faster"}, speed=0.5, **LINEAR))
    assert feed(decoder, trans(0.016, x=350)) == [jog(x=1.0, speed=0.5)]
    assert feed(decoder, press(0.02, 0b100)) == [
        DeviceNotice("SpaceNavigator speed 25%"),
        jog(x=1.0, speed=0.25),
    ]
    for i in range(8):
        feed(decoder, press(0.03 + i / 100, 0), press(0.035 + i / 100, 0b100))
    assert decoder.speed == 1 / 32
    for i in range(8):
        feed(decoder, press(0.2 + i / 100, 0), press(0.205 + i / 100, 0b1000))
    assert decoder.speed == 1.0


@pytest.mark.parametrize(
    ("action", "expected"),
    [
        ("home", [DeviceCommand("home")]),
        ("zero", [DeviceCommand("zero", axes=("X", "Y", "Z"))]),
        ("zero:Z", [DeviceCommand("zero", axes=("Z",))]),
        ("override:feed:reset", [DeviceCommand("override", kind="feed", step="reset")]),
        ("none", []),
    ],
)
def test_command_buttons(action: str, expected: list[Action]) -> None:
    decoder = armed(mouse(buttons={"1": action}))
    assert feed(decoder, press(0.02, 0x01)) == expected


def test_button_reports_of_any_length() -> None:
    decoder = armed(mouse(buttons={"17": "home"}))
    assert feed(decoder, HidReport(0.02, bytes([3, 0, 0, 1, 0, 0, 0]))) == [DeviceCommand("home")]


# -- options ---------------------------------------------------------------------------------------


def test_axes_table_merges_with_the_defaults() -> None:
    decoder = mouse(("X", "Y", "Z", "A"), axes={"a": "rz", "Z": "off"})
    assert decoder.mapping == {"X": (0, 1.0), "Y": (1, -1.0), "A": (5, 1.0)}
    assert "X=x Y=-y A=rz" in decoder.describe()


def test_a_default_axis_the_machine_lacks_is_dropped() -> None:
    decoder = mouse(("X", "Y"))
    assert list(decoder.mapping) == ["X", "Y"]
    armed(decoder)
    assert checked(decoder.feed(trans(0.016, z=-350)), ("X", "Y")) == []


@pytest.mark.parametrize(
    ("options", "key"),
    [
        ({"axes": {"X": "q"}}, "axes.X"),
        ({"axes": {"X": 1}}, "axes.X"),
        ({"axes": {"Q": "x"}}, "axes.Q"),
        ({"axes": {"A": "rz"}}, "axes.A"),  # the machine has no A
        ({"axes": {"X": "y"}}, "axes.Y"),  # y would drive X and Y
        ({"axes": "x"}, "axes"),
        ({"deadzone": 1.0}, "deadzone"),
        ({"deadzone": -0.1}, "deadzone"),
        ({"expo": 2}, "expo"),
        ({"speed": 0}, "speed"),
        ({"dominant": "yes"}, "dominant"),
        ({"buttons": {"0": "stop"}}, "buttons.0"),
        ({"buttons": {"65": "stop"}}, "buttons.65"),
        ({"buttons": {"1": "jump"}}, "buttons.1"),
        ({"buttons": {"1": "zero:A"}}, "buttons.1"),
        ({"buttons": {"1": "override:rapid:10"}}, "buttons.1"),
        ({"watchdog_s": -1}, "watchdog_s"),
        ({"stale_s": 0.05}, "stale_s"),  # an evdev key: unknown on hidraw
        ({"deadzon": 0.1}, "deadzon"),
    ],
)
def test_option_errors_name_the_key(options: dict[str, Any], key: str) -> None:
    with pytest.raises(ConfigError, match=key):
        mouse(**options)


@pytest.mark.parametrize(
    ("options", "key"),
    [({"stale_s": 0}, "stale_s"), ({"stale_s": 2}, "stale_s"), ({"watchdog_s": 1}, "watchdog_s")],
)
def test_evdev_option_errors_name_the_key(options: dict[str, Any], key: str) -> None:
    with pytest.raises(ConfigError, match=key):
        evdev_mouse(**options)


@pytest.mark.parametrize(
    ("info", "hidraw", "evdev"),
    [
        (NAVIGATOR, True, True),
        (DeviceInfo("3Dconnexion SpaceMouse Pro", vendor=0x046D, product=0xC62B), True, True),
        (WIRELESS, True, True),
        (DeviceInfo("3Dconnexion Universal Receiver", vendor=0x256F, product=0xC652), True, True),
        (
            DeviceInfo("3Dconnexion Universal Receiver Mouse", vendor=0x256F, product=0xC652),
            False,
            False,
        ),
        (DeviceInfo("3Dconnexion CadMouse", vendor=0x256F, product=0xC652), False, False),
        (DeviceInfo("3Dconnexion Keyboard", vendor=0x256F, product=0xC652), False, False),
        (
            DeviceInfo("3Dconnexion SpaceMouse", vendor=0x256F, rels=frozenset(range(6))),
            False,
            True,
        ),
        (DeviceInfo("3Dconnexion thing", vendor=0x256F, rels=frozenset({0, 1, 8})), False, False),
        (
            DeviceInfo(
                "3Dconnexion SpaceNavigator", vendor=0x046D, product=0xC626, rels=frozenset({8})
            ),
            True,
            False,
        ),
        (DeviceInfo("Logitech USB Receiver", vendor=0x046D, product=0xC52B), False, False),
    ],
)
def test_matches(info: DeviceInfo, hidraw: bool, evdev: bool) -> None:
    assert SpaceMouseDecoder.matches(info) is hidraw
    assert SpaceMouseEvdevDecoder.matches(info) is evdev


def test_names() -> None:
    assert (SpaceMouseDecoder.name, SpaceMouseDecoder.kind, SpaceMouseDecoder.transport) == (
        "spacemouse",
        "spacemouse",
        "hidraw",
    )
    assert (SpaceMouseEvdevDecoder.name, SpaceMouseEvdevDecoder.transport) == (
        "spacemouse-evdev",
        "evdev",
    )
    assert "check the axis directions" in mouse().describe()


# -- evdev -----------------------------------------------------------------------------------------


def test_the_quoted_spacenavigator_stream_stays_in_the_deadzone() -> None:
    recording = load_evtest(FIXTURES / "spacenavigator.evtest")
    decoder = SpaceMouseEvdevDecoder(recording.info, Table({}, "d", "<t>"), AXES)
    assert feed(decoder, *recording.frames) == []
    assert not decoder.moving


def test_the_quoted_spacenavigator_stream_with_no_deadzone() -> None:
    recording = load_evtest(FIXTURES / "spacenavigator.evtest")
    decoder = SpaceMouseEvdevDecoder(recording.info, Table(dict(LINEAR), "d", "<t>"), AXES)
    rx_only, y_only, rx_again = recording.frames
    assert feed(decoder, rx_only) == []  # translation not yet known: not armed
    assert feed(decoder, y_only) == [jog(y=10 / 350)]  # REL_Y -10 is machine +Y; arms (< 5 %)
    assert feed(decoder, rx_again) == []  # rotation: not mapped
    deadline = decoder.deadline_s()
    assert deadline == pytest.approx(y_only.t_s + 0.05)
    assert checked(decoder.tick(deadline)) == [NEUTRAL]  # the zero the kernel dropped
    assert not decoder.moving


def test_the_quoted_spacemouse_pro_button() -> None:
    recording = load_evtest(FIXTURES / "spacemouse_pro_button.evtest")
    decoder = SpaceMouseEvdevDecoder(recording.info, Table({}, "d", "<t>"), AXES)
    assert feed(decoder, *recording.frames) == [StopIntent()]
    assert decoder.model == "SpaceMouse Pro"


def test_evdev_stale_axis_is_zeroed() -> None:
    decoder = evdev_mouse(**LINEAR)
    assert feed(decoder, frame(0.0, (EV_REL, REL_X, 5))) == [jog(x=5 / 350)]  # no deadzone
    assert decoder.tick(0.05) == [NEUTRAL]  # X and the never-seen rotations: at rest
    assert decoder.deadline_s() is None
    assert feed(decoder, frame(0.1, (EV_REL, REL_X, 10))) == [jog(x=10 / 350)]
    assert feed(decoder, frame(0.116, (EV_REL, REL_X, 175))) == [jog(x=0.5)]
    assert feed(decoder, frame(0.132, (EV_REL, REL_X, 175))) == []  # refreshed, unchanged
    deadline = decoder.deadline_s()
    assert deadline == pytest.approx(0.182)
    assert decoder.tick(0.17) == []
    assert decoder.tick(deadline) == [NEUTRAL]
    assert decoder.deadline_s() is None
    assert decoder.tick(1.0) == []
    # The zero from staleness is a real neutral: the next push moves.
    assert feed(decoder, frame(1.1, (EV_REL, REL_X, 10))) == [jog(x=10 / 350)]


def test_evdev_stale_s_option() -> None:
    decoder = evdev_mouse(stale_s=0.2, **LINEAR)
    feed(decoder, frame(0.0, (EV_REL, REL_X, 5), (EV_REL, REL_RX, 1)))
    feed(decoder, frame(0.016, (EV_REL, REL_X, 175)))
    deadline = decoder.deadline_s()
    assert deadline == pytest.approx(0.2)  # RX, last seen at 0
    assert decoder.tick(deadline) == []
    deadline = decoder.deadline_s()
    assert deadline == pytest.approx(0.216)
    assert decoder.tick(deadline) == [NEUTRAL]


def test_evdev_a_report_with_one_channel_of_a_group_zeroes_the_others() -> None:
    decoder = evdev_mouse(**LINEAR)
    feed(decoder, frame(0.0, (EV_REL, REL_X, 5)), frame(0.016, (EV_REL, REL_X, 175)))
    # Same translation report kind, X absent: the kernel dropped its 0.
    assert feed(decoder, frame(0.032, (EV_REL, REL_Y, -70))) == [jog(y=0.2)]
    # A rotation report says nothing about translation.
    assert feed(decoder, frame(0.04, (EV_REL, REL_RZ, 40))) == []


def test_evdev_start_up_deflected_needs_neutral() -> None:
    decoder = evdev_mouse()
    assert feed(decoder, frame(0.0, (EV_REL, REL_X, 300))) == []
    assert feed(decoder, frame(0.016, (EV_REL, REL_X, 300))) == []
    assert decoder.tick(0.066) == []  # let go: stale, seen at rest now
    assert feed(decoder, frame(0.2, (EV_REL, REL_X, 20)), frame(0.216, (EV_REL, REL_X, 350))) == [
        jog(x=1.0)
    ]


def test_evdev_unknown_channels_become_zero_when_stale() -> None:
    # Translation held at start-up and only rotation frames arrive (the kernel drops zeros).
    decoder = evdev_mouse()
    assert feed(decoder, frame(0.0, (EV_REL, REL_RX, 3))) == []
    assert decoder.deadline_s() == pytest.approx(0.05)
    assert decoder.tick(0.05) == []  # unknown translation presumed at rest: arms
    assert feed(decoder, frame(0.1, (EV_REL, REL_X, 350))) == [jog(x=1.0)]


def test_evdev_abs_axes_hold_their_value() -> None:
    absinfo = {code: AbsRange(0, -350, 350) for code in range(6)}
    info = DeviceInfo(
        "3Dconnexion SpaceMouse Wireless", vendor=0x256F, product=0xC62E, absinfo=absinfo
    )
    decoder = evdev_mouse(info=info, **LINEAR)
    assert feed(decoder, frame(0.0, (EV_ABS, REL_X, 175))) == [jog(x=0.5)]  # armed from absinfo
    assert decoder.deadline_s() is None
    assert decoder.tick(10.0) == []
    assert decoder.moving
    assert feed(decoder, frame(10.1, (EV_ABS, REL_X, 0))) == [NEUTRAL]


def test_evdev_abs_start_up_deflected_needs_neutral() -> None:
    absinfo = {0: AbsRange(300, -350, 350), 1: AbsRange(0, -350, 350), 2: AbsRange(0, -350, 350)}
    info = DeviceInfo("3Dconnexion SpaceMouse", vendor=0x256F, product=0xC62E, absinfo=absinfo)
    decoder = evdev_mouse(info=info)
    assert feed(decoder, frame(0.0, (EV_ABS, REL_X, 310))) == []
    assert feed(decoder, frame(0.1, (EV_ABS, REL_X, 0)), frame(0.2, (EV_ABS, REL_X, 350))) == [
        jog(x=1.0)
    ]


def test_evdev_resync_stops_and_needs_neutral() -> None:
    decoder = evdev_mouse()
    feed(decoder, frame(0.0, (EV_REL, REL_X, 10)), frame(0.016, (EV_REL, REL_X, 350)))
    assert decoder.moving
    assert feed(decoder, frame(0.02, resync=True)) == [
        StopIntent(),
        DeviceNotice("SpaceNavigator: events were lost: jog stopped"),
    ]
    assert feed(decoder, frame(0.032, (EV_REL, REL_X, 350))) == []
    assert feed(decoder, frame(0.048, (EV_REL, REL_X, 350))) == []
    assert decoder.tick(0.098) == []  # let go
    assert feed(decoder, frame(0.2, (EV_REL, REL_X, 350))) == [jog(x=1.0)]


def test_evdev_resync_at_rest_still_needs_the_cap_seen_at_rest() -> None:
    decoder = evdev_mouse()
    feed(decoder, frame(0.0, (EV_REL, REL_X, 3)))
    assert decoder.tick(0.05) == []  # armed, at rest
    assert feed(decoder, frame(0.1, resync=True)) == []  # nothing moving: nothing to stop
    # Pushed while the events were lost: the first frame is no proof of rest.
    assert feed(decoder, frame(0.11, (EV_REL, REL_X, 350))) == []
    assert decoder.tick(0.16) == []
    assert feed(decoder, frame(0.2, (EV_REL, REL_X, 350))) == [jog(x=1.0)]


def test_evdev_buttons_and_what_is_ignored() -> None:
    decoder = evdev_mouse(buttons={"27": "home"})
    feed(decoder, frame(0.0, (EV_REL, REL_X, 1)))
    assert feed(decoder, frame(0.1, (EV_KEY, BTN_0, 2))) == []  # a repeat, not a press
    assert feed(decoder, frame(0.2, (EV_KEY, BTN_0 + 26, 1))) == [DeviceCommand("home")]
    assert feed(decoder, frame(0.3, (0x11, 8, 1), (EV_REL, 9, 5), (EV_KEY, 0x1FF, 1))) == []


def test_the_wrong_item_kind_is_ignored() -> None:
    assert mouse().feed(EvdevFrame(0.0, ())) == []
    assert evdev_mouse().feed(HidReport(0.0, b"\x01" + bytes(6))) == []


# -- properties ------------------------------------------------------------------------------------

OPTIONS = st.sampled_from(
    [{}, {"dominant": True}, LINEAR, {"axes": {"A": "rz"}, "buttons": {"3": "slower"}}]
)
AXES4 = ("X", "Y", "Z", "A")
REPORTS = st.one_of(
    st.builds(
        lambda rid, v: bytes([rid]) + int16s(*v),
        st.sampled_from([1, 2]),
        st.lists(st.integers(-600, 600), min_size=3, max_size=3),
    ),
    st.builds(
        lambda v: b"\x01" + int16s(*v), st.lists(st.integers(-600, 600), min_size=6, max_size=6)
    ),
    st.builds(lambda m: bytes([3, m, 0]), st.integers(0, 7)),
    st.binary(max_size=64),
)


@settings(max_examples=200)
@given(st.lists(st.tuples(REPORTS, st.floats(0, 0.4)), max_size=40), OPTIONS)
def test_arbitrary_reports_never_raise_and_intents_are_valid(
    reports: list[tuple[bytes, float]], options: dict[str, Any]
) -> None:
    decoder = mouse(AXES4, **options)
    t_s = 0.0
    for data, gap_s in reports:
        t_s += gap_s
        deadline = decoder.deadline_s()
        if deadline is not None and deadline <= t_s:
            checked(decoder.tick(deadline), AXES4)
        checked(decoder.feed(HidReport(t_s, data)), AXES4)
    # The device's release: zero reports; after them nothing moves.
    checked(decoder.feed(HidReport(t_s + 0.01, b"\x01" + bytes(12))), AXES4)
    assert not decoder.moving


EVENTS = st.lists(
    st.tuples(
        st.sampled_from([EV_KEY, EV_REL, EV_ABS, 0x04, 0x11]),
        st.integers(0, 6) | st.sampled_from([BTN_0, BTN_0 + 1, BTN_0 + 63, BTN_0 + 64]),
        st.integers(-(2**31), 2**31 - 1) | st.integers(-400, 400) | st.integers(0, 2),
    ),
    max_size=7,
)


@settings(max_examples=200)
@given(st.lists(st.tuples(EVENTS, st.booleans(), st.floats(0, 0.1)), max_size=30), OPTIONS)
def test_evdev_arbitrary_frames_never_raise_and_go_still_when_silent(
    frames: list[tuple[list[tuple[int, int, int]], bool, float]], options: dict[str, Any]
) -> None:
    decoder = evdev_mouse(AXES4, **options)
    t_s = 0.0
    for events, resync, gap_s in frames:
        t_s += gap_s
        while (deadline := decoder.deadline_s()) is not None and deadline <= t_s:
            checked(decoder.tick(deadline), AXES4)
        checked(decoder.feed(frame(t_s, *events, resync=resync)), AXES4)
    # REL axes only: with no more events every channel goes stale and the jog ends.
    if not any(e[0] == EV_ABS for events, _, _ in frames for e in events):
        while (deadline := decoder.deadline_s()) is not None:
            checked(decoder.tick(deadline), AXES4)
        assert not decoder.moving
