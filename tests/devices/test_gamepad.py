"""GamepadDecoder: normalisation per driver, the recorded streams, the safety rules, the options."""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from smoothjog.core.errors import ConfigError
from smoothjog.core.intents import ContinuousIntent, StepIntent, StopIntent, validate_intent
from smoothjog.core.options import Table
from smoothjog.inputs.device import (
    EV_ABS,
    EV_KEY,
    EV_MSC,
    EV_REL,
    AbsRange,
    Action,
    DeviceCommand,
    DeviceInfo,
    DeviceNotice,
    EvdevEvent,
    EvdevFrame,
    HidReport,
)
from smoothjog.inputs.gamepad import (
    BUTTON_CODES,
    GamepadDecoder,
    button_code,
    shape_stick,
    shape_trigger,
)
from smoothjog.inputs.recording import load_evtest

FIXTURES = Path(__file__).parent / "fixtures" / "gamepad"
XYZ = ("X", "Y", "Z")
MAX_FEED_MM_MIN = 1000.0

# Codes (linux/input-event-codes.h), written out so a test reads like an evtest line.
ABS_X, ABS_Y, ABS_Z, ABS_RX, ABS_RY, ABS_RZ = 0, 1, 2, 3, 4, 5
ABS_GAS, ABS_BRAKE, ABS_HAT0X, ABS_HAT0Y = 9, 10, 16, 17
BTN_SOUTH, BTN_EAST, BTN_NORTH, BTN_WEST = 0x130, 0x131, 0x133, 0x134
BTN_TL, BTN_TR, BTN_SELECT, BTN_START, BTN_MODE = 0x136, 0x137, 0x13A, 0x13B, 0x13C
BTN_TRIGGER, BTN_0, BTN_DPAD_UP, BTN_TRIGGER_HAPPY1 = 0x120, 0x100, 0x220, 0x2C0
PAD_KEYS = frozenset(range(BTN_SOUTH, 0x13F))

# -- the absinfo sets of devices §8.6 --------------------------------------------------------

STICK_XPAD = AbsRange(0, -32768, 32767, 16, 128)
STICK_NEO = AbsRange(0, -32768, 32767, 255, 4095)
HAT = AbsRange(0, -1, 1)


def _info(name: str, absinfo: Mapping[int, AbsRange], keys: Iterable[int] = PAD_KEYS) -> DeviceInfo:
    return DeviceInfo(name=name, absinfo=dict(absinfo), keys=frozenset(keys))


XPAD_360 = _info(
    "Xbox 360 pad (xpad)",
    {ABS_X: STICK_XPAD, ABS_Y: STICK_XPAD, ABS_RX: STICK_XPAD, ABS_RY: STICK_XPAD}
    | {ABS_Z: AbsRange(0, 0, 255), ABS_RZ: AbsRange(0, 0, 255), ABS_HAT0X: HAT, ABS_HAT0Y: HAT},
)
XPAD_ONE = _info(
    "Xbox One pad (xpad)",
    {ABS_X: STICK_XPAD, ABS_Y: STICK_XPAD, ABS_RX: STICK_XPAD, ABS_RY: STICK_XPAD}
    | {ABS_Z: AbsRange(0, 0, 1023), ABS_RZ: AbsRange(0, 0, 1023), ABS_HAT0X: HAT, ABS_HAT0Y: HAT},
)
XPADNEO = _info(
    "Xbox Wireless Controller (xpadneo)",
    {ABS_X: STICK_NEO._replace(value=4110), ABS_Y: STICK_NEO}
    | {ABS_RX: STICK_NEO, ABS_RY: STICK_NEO, ABS_HAT0X: HAT, ABS_HAT0Y: HAT}
    | {ABS_Z: AbsRange(0, 0, 1023, 3, 63), ABS_RZ: AbsRange(0, 0, 1023, 3, 63)},
)
_GEN = AbsRange(32768, 0, 65535, 255, 4095)
HID_GENERIC = _info(
    "BT pad (hid-generic)",
    {ABS_X: _GEN, ABS_Y: _GEN, ABS_Z: _GEN, ABS_RZ: _GEN, ABS_HAT0X: HAT, ABS_HAT0Y: HAT}
    | {ABS_GAS: AbsRange(0, 0, 1023, 3, 63), ABS_BRAKE: AbsRange(0, 0, 1023, 3, 63)},
)
_PS = AbsRange(128, 0, 255)
PLAYSTATION = _info(
    "DualSense (hid-playstation)",
    {ABS_X: _PS, ABS_Y: _PS, ABS_RX: _PS, ABS_RY: _PS, ABS_HAT0X: HAT, ABS_HAT0Y: HAT}
    | {ABS_Z: AbsRange(0, 0, 255), ABS_RZ: AbsRange(0, 0, 255)},
)
HEADERLESS = DeviceInfo(name="recorded evdev device")

#: Per set: the device, its rest value, its sticks (x, y) codes and its (left, right) triggers.
SETS: dict[str, tuple[DeviceInfo, int, tuple[int, int], tuple[int, int], tuple[int, int]]] = {
    "xpad-360": (XPAD_360, 0, (ABS_X, ABS_Y), (ABS_RX, ABS_RY), (ABS_Z, ABS_RZ)),
    "xpad-one": (XPAD_ONE, 0, (ABS_X, ABS_Y), (ABS_RX, ABS_RY), (ABS_Z, ABS_RZ)),
    "xpadneo": (XPADNEO, 4110, (ABS_X, ABS_Y), (ABS_RX, ABS_RY), (ABS_Z, ABS_RZ)),
    "hid-generic": (HID_GENERIC, 32768, (ABS_X, ABS_Y), (ABS_Z, ABS_RZ), (ABS_BRAKE, ABS_GAS)),
    "playstation": (PLAYSTATION, 128, (ABS_X, ABS_Y), (ABS_RX, ABS_RY), (ABS_Z, ABS_RZ)),
    "headerless": (HEADERLESS, 0, (ABS_X, ABS_Y), (ABS_RX, ABS_RY), (ABS_Z, ABS_RZ)),
}


def _range(info: DeviceInfo, code: int, default: AbsRange) -> AbsRange:
    return info.absinfo.get(code, default)


# -- helpers ---------------------------------------------------------------------------------


def make(
    info: DeviceInfo = XPAD_ONE, machine: Sequence[str] = XYZ, **options: Any
) -> GamepadDecoder:
    """A decoder for info on a machine with these axes; options as the config's table."""
    return GamepadDecoder(info, Table(options, "device", "<test>"), machine)


_clock = iter(range(10**9))


def frame(*events: tuple[int, int, int], resync: bool = False) -> EvdevFrame:
    return EvdevFrame(next(_clock) * 0.01, tuple(EvdevEvent(*e) for e in events), resync)


def ab(code: int, value: int) -> tuple[int, int, int]:
    return (EV_ABS, code, value)


def key(code: int, value: int = 1) -> tuple[int, int, int]:
    return (EV_KEY, code, value)


def feed(dec: GamepadDecoder, *events: tuple[int, int, int], resync: bool = False) -> list[Action]:
    out = dec.feed(frame(*events, resync=resync))
    check(out, dec.axes)
    return out


def check(actions: Iterable[Action], axes: Sequence[str]) -> None:
    for a in actions:
        if not isinstance(a, DeviceCommand | DeviceNotice):
            validate_intent(a, axes, MAX_FEED_MM_MIN)


def jogs(actions: Iterable[Action]) -> list[ContinuousIntent]:
    return [a for a in actions if isinstance(a, ContinuousIntent)]


def intents(actions: Iterable[Action]) -> list[Action]:
    return [a for a in actions if not isinstance(a, DeviceNotice)]


def neutral(axes: Sequence[str] = XYZ, speed: float = 0.5) -> ContinuousIntent:
    return ContinuousIntent(dict.fromkeys(axes, 0.0), speed)


def close(got: Sequence[Action], expected: Sequence[Action]) -> bool:
    """The same intents, deflections within 5e-3: a stick at rest is a hair off its centre
    (0 on -32768..32767, 128 on 0..255), which leaks a trace into the other axis."""
    if len(got) != len(expected):
        return False
    for g, e in zip(got, expected, strict=True):
        if isinstance(g, ContinuousIntent) and isinstance(e, ContinuousIntent):
            if g.speed != e.speed or g.axes != pytest.approx(e.axes, abs=5e-3):
                return False
        elif g != e:
            return False
    return True


FULL = 32767  # full deflection on an xpad stick


# -- B. normalisation ------------------------------------------------------------------------


@pytest.mark.parametrize("name", SETS)
def test_rest_values_are_neutral(name: str) -> None:
    info, rest, left, right, _ = SETS[name]
    for x, y in (left, right):
        rng_x = _range(info, x, AbsRange(0, -32768, 32767))
        rng_y = _range(info, y, AbsRange(0, -32768, 32767))
        mid_x, mid_y = (rng_x.min + rng_x.max) // 2, (rng_y.min + rng_y.max) // 2
        # The rest value on one axis, the other centred (xpadneo#77 saw X alone at 4110).
        assert shape_stick(rest, mid_y, rng_x, rng_y, 0.15, 0.3) == (0.0, 0.0)
        assert shape_stick(mid_x, rest, rng_x, rng_y, 0.15, 0.3) == (0.0, 0.0)
    # A decoder opened at rest is ready: the first deflection jogs.
    dec = make(info)
    lo = _range(info, left[0], AbsRange(0, -32768, 32767)).min
    assert jogs(feed(dec, ab(left[0], lo)))[0].axes["X"] == pytest.approx(-1.0, abs=1e-3)


@pytest.mark.parametrize("name", SETS)
def test_full_deflection_and_y_inverted(name: str) -> None:
    info, _, left, right, _ = SETS[name]
    for x, y in (left, right):
        rx = _range(info, x, AbsRange(0, -32768, 32767))
        ry = _range(info, y, AbsRange(0, -32768, 32767))
        cx, cy = (rx.min + rx.max) // 2, (ry.min + ry.max) // 2
        assert shape_stick(rx.max, cy, rx, ry, 0.15, 0.3) == pytest.approx((1.0, 0.0), abs=5e-3)
        assert shape_stick(rx.min, cy, rx, ry, 0.15, 0.3) == pytest.approx((-1.0, 0.0), abs=5e-3)
        # evdev up is the low end of Y: up is positive after shaping.
        assert shape_stick(cx, ry.min, rx, ry, 0.15, 0.3)[1] == pytest.approx(1.0, abs=1e-3)
        assert shape_stick(cx, ry.max, rx, ry, 0.15, 0.3)[1] == pytest.approx(-1.0, abs=1e-3)


@pytest.mark.parametrize("name", SETS)
def test_monotonic_and_continuous_through_the_deadzone_edge(name: str) -> None:
    info, _, (x, y), _, _ = SETS[name]
    rx = _range(info, x, AbsRange(0, -32768, 32767))
    ry = _range(info, y, AbsRange(0, -32768, 32767))
    cy = (ry.min + ry.max) // 2
    span = rx.max - rx.min
    raws = range(rx.min, rx.max + 1, max(1, span // 4096))
    outs = [shape_stick(v, cy, rx, ry, 0.15, 0.3)[0] for v in raws]
    assert outs == sorted(outs)
    # No jump anywhere, the deadzone edge included: the slope is bounded by
    # (2 / span) * 1 / (1 - dz) * max expo slope (1 + 2k).
    step = (raws[1] - raws[0]) * 2 / span / 0.85 * 1.6
    assert max(b - a for a, b in itertools.pairwise(outs)) <= step + 1e-12
    leaving = [o for o in outs if o > 0.0]
    assert leaving[0] <= step + 1e-12


@pytest.mark.parametrize("name", SETS)
def test_triggers_are_one_sided(name: str) -> None:
    info, _, _, _, (lt, rt) = SETS[name]
    for code in (lt, rt):
        rng = _range(info, code, AbsRange(0, 0, 1023))
        outs = [shape_trigger(v, rng, 0.15, 0.3) for v in range(rng.min, rng.max + 1)]
        assert outs[0] == 0.0
        assert outs[-1] == pytest.approx(1.0)
        assert outs == sorted(outs)
        assert shape_trigger(rng.min - 50, rng, 0.15, 0.3) == 0.0  # undershoot is rest


@pytest.mark.parametrize("name", SETS)
def test_trigger_pair_drives_an_axis(name: str) -> None:
    info, _, _, _, (lt, rt) = SETS[name]
    dec = make(info, axes={"Z": "right_trigger-left_trigger"})
    top = _range(info, rt, AbsRange(0, 0, 1023)).max
    assert close(jogs(feed(dec, ab(rt, top))), [ContinuousIntent({"Z": 1.0}, 0.5)])
    out = feed(dec, ab(rt, 0), ab(lt, top))
    assert close(jogs(out), [ContinuousIntent({"Z": -1.0}, 0.5)])


@given(
    name=st.sampled_from(sorted(SETS)),
    x=st.integers(-(2**31), 2**31 - 1),
    y=st.integers(-(2**31), 2**31 - 1),
    dz=st.floats(0.0, 0.9),
    k=st.floats(0.0, 1.0),
)
def test_shaped_values_always_in_unit_range(name: str, x: int, y: int, dz: float, k: float) -> None:
    info, _, (cx, cy), _, (lt, _) = SETS[name]
    rx = _range(info, cx, AbsRange(0, -32768, 32767))
    ry = _range(info, cy, AbsRange(0, -32768, 32767))
    sx, sy = shape_stick(x, y, rx, ry, dz, k)
    assert -1.0 <= sx <= 1.0
    assert -1.0 <= sy <= 1.0
    assert 0.0 <= shape_trigger(x, _range(info, lt, AbsRange(0, 0, 1023)), dz, k) <= 1.0


@given(a=st.integers(-40000, 40000), b=st.integers(-40000, 40000))
def test_stick_is_monotonic(a: int, b: int) -> None:
    lo, hi = sorted((a, b))
    x_lo = shape_stick(lo, 0, STICK_NEO, STICK_NEO, 0.15, 0.3)[0]
    x_hi = shape_stick(hi, 0, STICK_NEO, STICK_NEO, 0.15, 0.3)[0]
    assert x_lo <= x_hi


@pytest.mark.parametrize(
    ("info", "event", "expected"),
    [
        # xpad: the right stick is RX/RY, Z/RZ are triggers (not mapped by default).
        (XPAD_ONE, ab(ABS_RY, -FULL), {"X": 0.0, "Y": 0.0, "Z": 1.0}),
        (XPAD_ONE, ab(ABS_RZ, 1023), None),
        # hid-generic: the right stick is Z/RZ (0..65535, up = 0).
        (HID_GENERIC, ab(ABS_RZ, 0), {"X": 0.0, "Y": 0.0, "Z": 1.0}),
        (HID_GENERIC, ab(ABS_RY, 0), None),
        (HID_GENERIC, ab(ABS_X, 65535), {"X": 1.0, "Y": 0.0, "Z": 0.0}),
        (PLAYSTATION, ab(ABS_Y, 0), {"X": 0.0, "Y": 1.0, "Z": 0.0}),
        (PLAYSTATION, ab(ABS_RY, 255), {"X": 0.0, "Y": 0.0, "Z": -1.0}),
        # No header: xpad's layout and the documented default ranges.
        (HEADERLESS, ab(ABS_X, 32767), {"X": 1.0, "Y": 0.0, "Z": 0.0}),
        (HEADERLESS, ab(ABS_RY, 32767), {"X": 0.0, "Y": 0.0, "Z": -1.0}),
    ],
)
def test_layout_by_capabilities(
    info: DeviceInfo, event: tuple[int, int, int], expected: dict[str, float] | None
) -> None:
    dec = make(info)
    got = jogs(feed(dec, event))
    assert close(got, [] if expected is None else [ContinuousIntent(expected, 0.5)])


# -- recorded streams ------------------------------------------------------------------------


def test_xpadneo_return_to_rest_ends_at_neutral() -> None:
    rec = load_evtest(FIXTURES / "xpadneo-return-to-rest.evtest")
    dec = GamepadDecoder(rec.info, Table({}, "device", "<defaults>"), XYZ)
    out: list[Action] = []
    for f in rec.frames:
        out.extend(dec.feed(f))
    check(out, XYZ)
    sent = jogs(out)
    assert len(sent) >= 3
    xs = [j.axes["X"] for j in sent[:-1]]
    assert all(x > 0.0 for x in xs)
    assert xs == sorted(xs, reverse=True)  # easing off, never a jump back
    assert all(abs(j.axes["Y"]) < 1e-3 and j.axes["Z"] == 0.0 for j in sent)
    assert sent[-1] == neutral()  # and only the last one is neutral
    assert [j.is_neutral() for j in sent].count(True) == 1
    assert not dec.moving


def test_xpadneo_stream_opened_deflected_needs_neutral_first() -> None:
    """Opened with the stick at 6126 (absinfo's value): no jog until it has been at rest."""
    rec = load_evtest(FIXTURES / "xpadneo-return-to-rest.evtest")
    absinfo = dict(rec.info.absinfo) | {ABS_X: rec.info.absinfo[ABS_X]._replace(value=7000)}
    info = DeviceInfo(name=rec.info.name, absinfo=absinfo, keys=rec.info.keys)
    dec = GamepadDecoder(info, Table({}, "device", "<defaults>"), XYZ)
    out = [a for f in rec.frames for a in dec.feed(f)]
    assert intents(out) == []
    assert any("centre" in n.text for n in out if isinstance(n, DeviceNotice))
    # Now at rest (4110): the next push jogs.
    assert jogs(feed(dec, ab(ABS_X, 20000)))


@pytest.mark.parametrize(
    ("options", "expected"),
    [
        ({}, [StepIntent("X", -1.0, 0.5)]),
        ({"hat_step_mm": 0.1, "speed_index": 0}, [StepIntent("X", -0.1, 0.1)]),
        (
            {"hat": "slow", "hat_speed": 0.2},
            [ContinuousIntent({"X": -1.0, "Y": 0.0, "Z": 0.0}, 0.2), neutral()],
        ),
        ({"hat": "off"}, []),
        ({"buttons": {"south": "home"}}, [StepIntent("X", -1.0, 0.5), DeviceCommand("home")]),
        (
            {"buttons": {"BTN_SOUTH": "zero"}},
            [StepIntent("X", -1.0, 0.5), DeviceCommand("zero", XYZ)],
        ),
    ],
)
def test_hat_and_button_stream(options: dict[str, Any], expected: list[Action]) -> None:
    rec = load_evtest(FIXTURES / "hat-and-button.evtest")
    dec = GamepadDecoder(rec.info, Table(options, "device", "<test>"), XYZ)
    out = [a for f in rec.frames for a in dec.feed(f)]
    check(out, XYZ)
    assert close(intents(out), expected)
    assert not dec.moving


def test_syn_dropped_while_jogging_stops_and_needs_neutral() -> None:
    rec = load_evtest(FIXTURES / "xpad-syn-dropped.evtest")
    assert rec.dropped == 1
    dec = GamepadDecoder(rec.info, Table({}, "device", "<defaults>"), XYZ)
    per_frame = [intents(dec.feed(f)) for f in rec.frames]
    first, resync, still_deflected, centred, pushed = per_frame
    assert jogs(first)[0].axes["X"] > 0.5
    assert resync == [neutral()]  # the resync shows a deflected stick: stop, wait for neutral
    assert still_deflected == []
    assert centred == []
    assert jogs(pushed)[0].axes["X"] > 0.5


def test_autorepeat_is_ignored() -> None:
    rec = load_evtest(FIXTURES / "xpad-autorepeat.evtest")
    dec = GamepadDecoder(rec.info, Table({}, "device", "<defaults>"), XYZ)
    out = [a for f in rec.frames for a in dec.feed(f)]
    assert intents(out) == [StepIntent("Y", 1.0, 0.5)]  # TRIGGER_HAPPY3 is D-pad up on xpad
    assert dec.speed == 1.0  # one BTN_TR press, however long held
    assert [n.text for n in out if isinstance(n, DeviceNotice)] == ["gamepad speed 100 %"]


# -- C. safety rules -------------------------------------------------------------------------


def test_deadman_release_sends_an_explicit_stop() -> None:
    dec = make(deadman="tl")
    assert intents(feed(dec, ab(ABS_X, FULL))) == []  # not held: nothing moves
    feed(dec, ab(ABS_X, 0))
    feed(dec, key(BTN_TL, 1))
    assert jogs(feed(dec, ab(ABS_X, FULL)))[0].axes["X"] == pytest.approx(1.0)
    assert dec.moving
    assert intents(feed(dec, key(BTN_TL, 0))) == [StopIntent()]
    assert not dec.moving
    assert intents(feed(dec, ab(ABS_X, FULL - 100))) == []  # stick still held: nothing


def test_deadman_release_after_a_step_stops_too() -> None:
    dec = make(deadman="tl")
    feed(dec, key(BTN_TL, 1))
    assert intents(feed(dec, ab(ABS_HAT0Y, -1))) == [StepIntent("Y", 1.0, 0.5)]
    assert intents(feed(dec, key(BTN_TL, 0))) == [StopIntent()]


def test_deadman_release_without_motion_sends_nothing() -> None:
    dec = make(deadman="tl")
    feed(dec, key(BTN_TL, 1))
    assert intents(feed(dec, key(BTN_TL, 0))) == []


def test_deadman_reenable_needs_neutral() -> None:
    dec = make(deadman="tl")
    feed(dec, key(BTN_TL, 1))
    feed(dec, ab(ABS_X, FULL))
    feed(dec, key(BTN_TL, 0))
    # Pressed again with the stick still out: no motion, whatever the stick does out there.
    assert intents(feed(dec, key(BTN_TL, 1))) == []
    assert intents(feed(dec, ab(ABS_X, 20000))) == []
    # Back inside the deadzone, then out again: jogs.
    assert intents(feed(dec, ab(ABS_X, 1000))) == []
    assert jogs(feed(dec, ab(ABS_X, FULL)))[0].axes["X"] == pytest.approx(1.0)


def test_deadman_neutral_must_be_seen_while_held() -> None:
    dec = make(deadman="tl")
    feed(dec, key(BTN_TL, 1))
    feed(dec, ab(ABS_X, FULL))
    feed(dec, key(BTN_TL, 0))
    feed(dec, ab(ABS_X, 0))  # centred while released ...
    feed(dec, ab(ABS_X, FULL))  # ... then pushed before the dead-man is pressed
    assert intents(feed(dec, key(BTN_TL, 1))) == []


def test_deadman_gates_steps_and_moving_commands() -> None:
    dec = make(deadman="tl", buttons={"start": "home", "select": "unlock"})
    assert intents(feed(dec, ab(ABS_HAT0X, 1))) == []
    feed(dec, ab(ABS_HAT0X, 0))
    out = feed(dec, key(BTN_START, 1))
    assert intents(out) == []
    assert [n.text for n in out if isinstance(n, DeviceNotice)] == ["gamepad: hold BTN_TL to home"]
    assert intents(feed(dec, key(BTN_SELECT, 1))) == [DeviceCommand("unlock")]
    assert intents(feed(dec, key(BTN_EAST, 1))) == [StopIntent()]  # stop never needs it
    feed(dec, key(BTN_TL, 1))
    assert intents(feed(dec, key(BTN_START, 0), key(BTN_START, 1))) == [DeviceCommand("home")]


def test_startup_deflected_needs_neutral_without_deadman() -> None:
    info = _info("pad", dict(XPAD_ONE.absinfo) | {ABS_X: STICK_XPAD._replace(value=30000)})
    dec = make(info)
    assert intents(feed(dec, ab(ABS_X, 31000))) == []
    assert intents(feed(dec, ab(ABS_X, 0))) == []
    assert jogs(feed(dec, ab(ABS_X, 31000)))


def test_startup_deflected_right_stick_blocks_the_left() -> None:
    info = _info("pad", dict(XPAD_ONE.absinfo) | {ABS_RY: STICK_XPAD._replace(value=-30000)})
    dec = make(info)
    assert intents(feed(dec, ab(ABS_X, FULL))) == []  # Z is deflected: not neutral
    feed(dec, ab(ABS_X, 0), ab(ABS_RY, 0))
    assert jogs(feed(dec, ab(ABS_X, FULL)))


def test_resync_neutral_while_jogging_stops_then_jogs_again() -> None:
    dec = make()
    feed(dec, ab(ABS_X, FULL))
    out = feed(dec, ab(ABS_X, 0), ab(ABS_Y, 0), resync=True)
    assert intents(out) == [neutral()]
    assert jogs(feed(dec, ab(ABS_X, FULL)))


def test_resync_releasing_the_deadman_stops() -> None:
    dec = make(deadman="tl")
    feed(dec, key(BTN_TL, 1))
    feed(dec, ab(ABS_X, FULL))
    out = feed(dec, ab(ABS_X, 0), resync=True)  # BTN_TL not listed: it is up
    assert intents(out) == [StopIntent()]
    assert not dec.moving


def test_resync_replays_only_a_stop_press() -> None:
    dec = make(buttons={"start": "home"})
    feed(dec, ab(ABS_HAT0X, 0))
    out = feed(dec, ab(ABS_HAT0X, 1), key(BTN_START, 1), key(BTN_TR, 1), resync=True)
    assert intents(out) == []  # no step, no home, no speed change from a resync
    assert dec.speed == 0.5
    assert intents(feed(dec, key(BTN_EAST, 1), resync=True)) == [StopIntent()]


def test_lost_forgets_and_needs_every_stick_back() -> None:
    dec = make()
    feed(dec, ab(ABS_X, FULL))
    assert dec.moving
    notes = dec.lost()
    assert notes
    assert all(isinstance(n, DeviceNotice) for n in notes)
    assert not dec.moving
    # Values are unknown now: an unrelated frame does not count as the sticks at rest ...
    assert intents(feed(dec, key(BTN_SOUTH, 1))) == []
    assert intents(feed(dec, ab(ABS_X, FULL))) == []
    # ... nor does one stick reported at rest while the other has not been heard from.
    feed(dec, ab(ABS_X, 0), ab(ABS_Y, 0))
    assert intents(feed(dec, ab(ABS_X, FULL))) == []
    # A full state at rest (as a resync gives) makes it ready again.
    feed(dec, ab(ABS_X, 0), ab(ABS_Y, 0), ab(ABS_RX, 0), ab(ABS_RY, 0), resync=True)
    assert jogs(feed(dec, ab(ABS_X, FULL)))


def test_stop_button_while_jogging_needs_neutral_before_jogging_again() -> None:
    dec = make()
    feed(dec, ab(ABS_X, FULL))
    assert intents(feed(dec, key(BTN_EAST, 1))) == [StopIntent()]
    assert not dec.moving
    assert intents(feed(dec, ab(ABS_X, 30000))) == []
    feed(dec, ab(ABS_X, 0))
    assert jogs(feed(dec, ab(ABS_X, 30000)))


@pytest.mark.parametrize("command", ["hold", "reset"])
def test_hold_and_reset_end_the_jog(command: str) -> None:
    dec = make(buttons={"start": command})
    feed(dec, ab(ABS_X, FULL))
    assert intents(feed(dec, key(BTN_START, 1))) == [DeviceCommand(command), neutral()]
    assert intents(feed(dec, ab(ABS_X, 30000))) == []


# -- emission, speed, buttons, D-pad ---------------------------------------------------------


def test_emits_only_on_change_and_neutral_once() -> None:
    dec = make()
    first = jogs(feed(dec, ab(ABS_X, FULL)))
    assert len(first) == 1
    assert jogs(feed(dec, ab(ABS_X, FULL))) == []  # same value: nothing new
    assert jogs(feed(dec, key(BTN_SOUTH, 1))) == []
    assert jogs(feed(dec, ab(ABS_X, 1000))) == [neutral()]
    assert jogs(feed(dec, ab(ABS_X, 500))) == []  # still in the deadzone
    assert jogs(feed(dec, ab(ABS_X, 0))) == []


def test_speed_buttons_step_through_the_list() -> None:
    dec = make(speeds=[0.1, 0.3, 1.0], speed_index=0)
    assert dec.describe() == "gamepad: speed 10 %, no dead-man"
    feed(dec, ab(ABS_X, FULL))
    assert close(jogs(feed(dec, key(BTN_TR, 1))), [ContinuousIntent({"X": 1, "Y": 0, "Z": 0}, 0.3)])
    feed(dec, key(BTN_TR, 0))
    feed(dec, key(BTN_TR, 1))
    feed(dec, key(BTN_TR, 0))
    assert jogs(feed(dec, key(BTN_TR, 1))) == []  # already at the top
    assert dec.speed == 1.0
    feed(dec, key(BTN_TL, 1))
    assert dec.speed == 0.3
    assert jogs(feed(dec, ab(ABS_X, 0))) == [neutral(speed=0.3)]  # neutral is exact
    feed(dec, key(BTN_TL, 0))
    feed(dec, key(BTN_TL, 1))
    assert dec.speed == 0.1
    assert jogs(feed(dec, key(BTN_TL, 0), key(BTN_TL, 1))) == []  # neutral: nothing to resend


@pytest.mark.parametrize(
    ("buttons", "code", "expected"),
    [
        ({}, BTN_EAST, [StopIntent()]),
        ({}, BTN_SOUTH, []),
        ({"east": "none"}, BTN_EAST, []),
        ({"BTN_START": "home"}, BTN_START, [DeviceCommand("home")]),
        ({"select": "unlock"}, BTN_SELECT, [DeviceCommand("unlock")]),
        ({"Mode": "reset"}, BTN_MODE, [DeviceCommand("reset")]),
        ({"north": "zero"}, BTN_NORTH, [DeviceCommand("zero", XYZ)]),
        ({"west": "goto_zero"}, BTN_WEST, [DeviceCommand("goto_zero")]),
        ({"x": "hold"}, BTN_NORTH, [DeviceCommand("hold")]),
        ({"y": "Resume"}, BTN_WEST, [DeviceCommand("resume")]),
        ({"south": "stop"}, BTN_SOUTH, [StopIntent()]),
    ],
)
def test_button_commands(buttons: dict[str, str], code: int, expected: list[Action]) -> None:
    dec = make(buttons=buttons)
    assert intents(feed(dec, key(code, 1))) == expected
    assert intents(feed(dec, key(code, 2))) == []  # autorepeat
    assert intents(feed(dec, key(code, 0))) == []  # release


def test_dpad_buttons_and_xpad_trigger_happy() -> None:
    dec = make()  # XPAD_ONE has hat axes: TRIGGER_HAPPY1 is a plain button there
    assert intents(feed(dec, key(BTN_DPAD_UP, 1))) == [StepIntent("Y", 1.0, 0.5)]
    assert intents(feed(dec, key(BTN_TRIGGER_HAPPY1, 1))) == []
    no_hat = _info("xpad wireless", {c: r for c, r in XPAD_ONE.absinfo.items() if c < ABS_HAT0X})
    dec = make(no_hat)
    assert intents(feed(dec, key(BTN_TRIGGER_HAPPY1, 1))) == [StepIntent("X", -1.0, 0.5)]
    assert dec.moving  # held after a step: a loss now stops it
    feed(dec, key(BTN_TRIGGER_HAPPY1, 0))
    assert not dec.moving


def test_hat_step_per_press_and_diagonal() -> None:
    dec = make(speed_index=3, hat_step_mm=0.5)
    assert intents(feed(dec, ab(ABS_HAT0X, 1), ab(ABS_HAT0Y, 1))) == [
        StepIntent("X", 0.5, 1.0),
        StepIntent("Y", -0.5, 1.0),  # HAT0Y +1 is down
    ]
    assert intents(feed(dec, ab(ABS_HAT0X, 1))) == []  # unchanged
    assert intents(feed(dec, ab(ABS_HAT0X, -1))) == [StepIntent("X", -0.5, 1.0)]


def test_slow_hat_takes_over_from_the_stick() -> None:
    dec = make(hat="slow")
    feed(dec, ab(ABS_X, FULL))
    assert jogs(feed(dec, ab(ABS_HAT0Y, -1))) == [
        ContinuousIntent({"X": 0.0, "Y": 1.0, "Z": 0.0}, 0.1)
    ]
    assert dec.moving
    back = jogs(feed(dec, ab(ABS_HAT0Y, 0)))
    assert close(back, [ContinuousIntent({"X": 1.0, "Y": 0.0, "Z": 0.0}, 0.5)])


@pytest.mark.parametrize(
    ("mapping", "machine", "event", "expected"),
    [
        ({"X": "-left_x"}, XYZ, ab(ABS_X, FULL), {"X": -1.0}),
        ({"x": "right_x", "y": "right_y"}, XYZ, ab(ABS_RX, FULL), {"X": 1.0, "Y": 0.0}),
        ({"X": "left_x", "Z": "right_y"}, ("X", "Y"), ab(ABS_RY, -FULL), None),  # no Z: dropped
        ({"A": "left_trigger"}, ("X", "Y", "Z", "A"), ab(ABS_Z, 1023), {"A": 1.0}),
        ({"Z": "-right_trigger-left_trigger"}, XYZ, ab(ABS_RZ, 1023), {"Z": -1.0}),
    ],
)
def test_axes_mapping(
    mapping: dict[str, str],
    machine: tuple[str, ...],
    event: tuple[int, int, int],
    expected: dict[str, float] | None,
) -> None:
    dec = make(machine=machine, axes=mapping)
    got = jogs(feed(dec, event))
    assert close(got, [] if expected is None else [ContinuousIntent(expected, 0.5)])


def test_default_mapping_on_a_machine_without_z() -> None:
    dec = make(machine=("X", "Y"))
    assert close(jogs(feed(dec, ab(ABS_Y, -FULL))), [ContinuousIntent({"X": 0.0, "Y": 1.0}, 0.5)])


def test_hidraw_reports_are_ignored() -> None:
    assert make().feed(HidReport(0.0, b"\x01\x02")) == []


@pytest.mark.parametrize(
    ("info", "expected"),
    [
        (XPAD_ONE, True),
        (HID_GENERIC, True),
        (PLAYSTATION, True),
        (_info("flight stick", {ABS_X: STICK_XPAD, ABS_Y: STICK_XPAD}, {BTN_TRIGGER}), True),
        (_info("no buttons", XPAD_ONE.absinfo, ()), False),
        (_info("SpaceMouse-like", {ABS_X: STICK_XPAD, ABS_Y: STICK_XPAD}, {BTN_0}), False),
        (_info("keyboard", {}, {30, 31, 32}), False),
        (_info("only X", {ABS_X: STICK_XPAD}, PAD_KEYS), False),
        (HEADERLESS, False),
    ],
)
def test_matches(info: DeviceInfo, expected: bool) -> None:
    assert GamepadDecoder.matches(info) is expected


def test_class_identity_and_describe() -> None:
    assert (GamepadDecoder.name, GamepadDecoder.kind, GamepadDecoder.transport) == (
        "gamepad",
        "gamepad",
        "evdev",
    )
    assert make(deadman="BTN_TL").describe() == "gamepad: speed 50 %, dead-man BTN_TL"
    assert make().describe() == "gamepad: speed 50 %, no dead-man"


def test_button_names_agree_with_the_kernel() -> None:
    from evdev import ecodes

    for name, code in BUTTON_CODES.items():
        assert ecodes.ecodes[f"BTN_{name.upper()}"] == code, name
    assert button_code("BTN_EAST") == button_code("east") == button_code(" East ") == BTN_EAST
    assert button_code("BTN_NOPE") is None


def test_defaults_give_way_to_explicit_bindings() -> None:
    dec = make(deadman="tl")  # speed_down's default is BTN_TL
    assert dec.speed_down is None
    assert dec.deadman == BTN_TL
    dec = make(speed_up="east")  # east's default stop gives way
    assert intents(feed(dec, key(BTN_EAST, 1))) == []
    assert dec.speed == 1.0
    dec = make(speed_up="none", speed_down="none")
    feed(dec, key(BTN_TR, 1))
    assert dec.speed == 0.5


# -- options errors --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("options", "key"),
    [
        ({"deadzone": 1.5}, "deadzone"),
        ({"deadzone": "big"}, "deadzone"),
        ({"expo": -0.1}, "expo"),
        ({"hat": "fast"}, "hat"),
        ({"hat_step_mm": 0.0}, "hat_step_mm"),
        ({"hat_speed": 0}, "hat_speed"),
        ({"hat_speed": 2}, "hat_speed"),
        ({"speeds": []}, "speeds"),
        ({"speeds": "fast"}, "speeds"),
        ({"speeds": [0.5, 0.0]}, "speeds"),
        ({"speeds": [0.5, "x"]}, "speeds"),
        ({"speed_index": 4}, "speed_index"),
        ({"speeds": [0.5], "speed_index": 1}, "speed_index"),
        ({"deadman": "nosuch"}, "deadman"),
        ({"deadman": 3}, "deadman"),
        ({"speed_up": "BTN_NOPE"}, "speed_up"),
        ({"deadman": "tr", "speed_up": "tr"}, "speed_up"),
        ({"deadman": "east", "buttons": {"east": "stop"}}, "buttons.east"),
        ({"buttons": {"nosuch": "stop"}}, "buttons.nosuch"),
        ({"buttons": {"east": "explode"}}, "buttons.east"),
        ({"buttons": {"east": "override"}}, "buttons.east"),
        ({"buttons": {"east": 1}}, "buttons.east"),
        ({"buttons": "stop"}, "buttons"),
        ({"axes": {"Q": "left_x"}}, "axes.Q"),
        ({"axes": {"X": "left_z"}}, "axes.X"),
        ({"axes": {"X": "left_x-right_x"}}, "axes.X"),
        ({"axes": {"X": 1}}, "axes.X"),
        ({"axes": {"X": "left_x", "x": "left_y"}}, "axes.x"),
        ({"axes": "left"}, "axes"),
        ({"deadzon": 0.1}, "deadzon"),
    ],
)
def test_option_errors_name_the_key(options: dict[str, Any], key: str) -> None:
    with pytest.raises(ConfigError) as err:
        make(**options)
    assert f"{key} " in str(err.value) or f"'{key}'" in str(err.value)


# -- property tests --------------------------------------------------------------------------

_CODES = [ABS_X, ABS_Y, ABS_Z, ABS_RX, ABS_RY, ABS_RZ, ABS_GAS, ABS_BRAKE, ABS_HAT0X, ABS_HAT0Y]
_KEYS = [BTN_SOUTH, BTN_EAST, BTN_TL, BTN_TR, BTN_START, BTN_DPAD_UP, BTN_TRIGGER_HAPPY1]
_events = st.one_of(
    st.tuples(
        st.just(EV_ABS),
        st.sampled_from(_CODES),
        st.one_of(st.integers(-70000, 70000), st.integers(-(2**31), 2**31 - 1)),
    ),
    st.tuples(st.just(EV_KEY), st.sampled_from(_KEYS), st.integers(-1, 3)),
    st.tuples(
        st.sampled_from([EV_REL, EV_MSC, EV_KEY, EV_ABS, 17]),
        st.integers(0, 0x2FF),
        st.integers(-(2**31), 2**31 - 1),
    ),
)
_frames = st.lists(
    st.tuples(st.lists(_events, max_size=6), st.booleans()),
    max_size=40,
)
_options = st.sampled_from(
    [
        {},
        {"deadman": "tl"},
        {"hat": "slow"},
        {"hat": "off", "deadman": "south"},
        {"axes": {"X": "right_trigger-left_trigger", "Y": "-left_y", "A": "right_x"}},
    ]
)


def _deadman_held(
    held: bool, code: int | None, events: list[tuple[int, int, int]], resync: bool
) -> bool:
    if code is None:
        return True
    if resync:
        return any(t == EV_KEY and c == code and v for t, c, v in events)
    for t, c, v in events:
        if t == EV_KEY and c == code and v in (0, 1):
            held = v == 1
    return held


@settings(max_examples=300, deadline=None)
@given(
    info=st.sampled_from([XPAD_ONE, XPADNEO, HID_GENERIC, PLAYSTATION, HEADERLESS]),
    options=_options,
    frames=_frames,
)
def test_arbitrary_frames_never_raise_and_give_valid_intents(
    info: DeviceInfo, options: dict[str, Any], frames: list[tuple[list[tuple[int, int, int]], bool]]
) -> None:
    dec = make(info, **options)
    held = False
    last_jog: ContinuousIntent | None = None  # the last continuous intent not undone by a stop
    for events, resync in frames:
        out = dec.feed(frame(*events, resync=resync))
        check(out, XYZ)
        held = _deadman_held(held, dec.deadman, events, resync)
        for a in out:
            if isinstance(a, StopIntent):
                last_jog = None
            elif isinstance(a, ContinuousIntent):
                # Only on change, and a neutral only to end a jog.
                assert a != last_jog
                assert not a.is_neutral() or (last_jog is not None and not last_jog.is_neutral())
                assert set(a.axes) <= set(XYZ)
                last_jog = None if a.is_neutral() else a
                # No motion without the dead-man, held both before and after the frame
                # (a press and a release in one frame allow none).
                if not a.is_neutral():
                    assert held
            elif isinstance(a, StepIntent):
                assert held
        if last_jog is not None:
            assert dec.moving
    dec.lost()
    assert not dec.moving


@settings(max_examples=100, deadline=None)
@given(frames=_frames)
def test_after_lost_nothing_moves_until_a_neutral_state(
    frames: list[tuple[list[tuple[int, int, int]], bool]],
) -> None:
    dec = make(XPAD_ONE)
    feed(dec, ab(ABS_X, FULL))
    dec.lost()
    # Only deflected stick values (and buttons) from here: no jog may start.
    for events, _ in frames:
        deflected = [
            (t, c, 30000) if t == EV_ABS and c == ABS_X else (t, c, v) for t, c, v in events
        ]
        deflected = [e for e in deflected if e[0] != EV_ABS or e[1] == ABS_X]
        out = dec.feed(frame(*deflected))
        assert not [a for a in out if isinstance(a, ContinuousIntent) and not a.is_neutral()]
