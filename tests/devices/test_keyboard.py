"""The keyboard decoder: the quoted keypad stream, hold-to-jog, taps, NumLock, resync, loss."""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from smoothjog.core.errors import ConfigError
from smoothjog.core.intents import ContinuousIntent, StepIntent, StopIntent, validate_intent
from smoothjog.core.options import Table
from smoothjog.inputs.device import (
    EV_KEY,
    EV_MSC,
    EV_REL,
    Action,
    DeviceCommand,
    DeviceInfo,
    DeviceNotice,
    EvdevEvent,
    EvdevFrame,
    HidReport,
)
from smoothjog.inputs.keyboard import KEY_CODES, KeyboardDecoder, key_code, key_name
from smoothjog.inputs.recording import EvdevRecording, parse_evtest

FIXTURES = Path(__file__).parent / "fixtures" / "keyboard"
AXES = ("X", "Y", "Z")
MAX_FEED_MM_MIN = 1000.0
_HEX_MSC = re.compile(r"\(EV_MSC\).*value\s+-?\d*[a-fA-F]")


def load(name: str, folder: Path = FIXTURES) -> EvdevRecording:
    """A fixture through recording.parse_evtest.

    evtest prints MSC_SCAN values in hex ("value 7005c"), which recording.py does not read yet;
    those lines are left out here (the frame assembler drops EV_MSC anyway).
    """
    path = folder / name
    lines = [line for line in path.read_text().split("\n") if not _HEX_MSC.search(line)]
    return parse_evtest(lines, source=str(path))


def decoder(axes: tuple[str, ...] = AXES, **options: Any) -> KeyboardDecoder:
    """A keyboard decoder with these options on a machine with these axes."""
    return KeyboardDecoder(DeviceInfo("test keypad"), Table(options, "device", "test.toml"), axes)


def keys(t_s: float, *changes: tuple[str, int]) -> EvdevFrame:
    """A frame of EV_KEY changes by key name: ("KP8", 1) presses KP8."""
    return EvdevFrame(t_s, tuple(EvdevEvent(EV_KEY, KEY_CODES[n], v) for n, v in changes))


def press(t_s: float, *names: str) -> EvdevFrame:
    """A frame pressing these keys."""
    return keys(t_s, *((n, 1) for n in names))


def release(t_s: float, *names: str) -> EvdevFrame:
    """A frame releasing these keys."""
    return keys(t_s, *((n, 0) for n in names))


def jog(x: float = 0.0, y: float = 0.0, z: float = 0.0, speed: float = 0.25) -> ContinuousIntent:
    """The ContinuousIntent the default map sends on a 3-axis machine."""
    return ContinuousIntent({"X": x, "Y": y, "Z": z}, speed)


NEUTRAL = jog()


def per_frame(dec: KeyboardDecoder, frames: Iterable[EvdevFrame]) -> list[list[Action]]:
    """The decoder's answer to each frame."""
    return [dec.feed(f) for f in frames]


def intents(actions: Iterable[Action]) -> list[Action]:
    """The actions without the notices."""
    return [a for a in actions if not isinstance(a, DeviceNotice)]


# -- which devices ---------------------------------------------------------------------------

_KEYPAD = frozenset(KEY_CODES[f"KP{n}"] for n in range(10)) | {KEY_CODES["NUMLOCK"]}
_LETTERS = frozenset(KEY_CODES[chr(c)] for c in range(ord("A"), ord("Z") + 1))
_MEDIA = frozenset(KEY_CODES[n] for n in ("MUTE", "VOLUMEUP", "VOLUMEDOWN"))


@pytest.mark.parametrize(
    ("info", "expected"),
    [
        (DeviceInfo("numeric keypad", keys=_KEYPAD), True),
        (DeviceInfo("full keyboard", keys=_LETTERS | {KEY_CODES["ESC"]}), True),
        (DeviceInfo("keyboard with media keys", keys=_LETTERS | _KEYPAD | _MEDIA), True),
        (DeviceInfo("4 keypad keys", keys=frozenset(KEY_CODES[n] for n in ("KP4", "KP6"))), False),
        (DeviceInfo("volume knob", keys=_MEDIA), False),
        (
            DeviceInfo("413d:553a", vendor=0x413D, product=0x553A, keys=_LETTERS | _MEDIA),
            False,
        ),
        (DeviceInfo("gamepad", keys=frozenset({304, 305, 307, 308})), False),
        (DeviceInfo("nothing declared"), False),
    ],
)
def test_matches(info: DeviceInfo, expected: bool) -> None:
    """Keypads and full keyboards are taken; knobs posing as keyboards and others are not."""
    assert KeyboardDecoder.matches(info) is expected


def test_matches_recorded_keypad_header() -> None:
    """The capabilities read from an evtest header are a keypad's."""
    rec = load("keypad-header.txt")
    assert rec.info.usb_id == "1c4f:0043"
    assert KeyboardDecoder.matches(rec.info)
    dec = KeyboardDecoder(rec.info, Table({}, "device", "<defaults>"), AXES)
    assert per_frame(dec, rec.frames) == [[jog(x=-1.0)], [NEUTRAL]]


def test_identity() -> None:
    """The decoder's names, as the config and the messages use them."""
    assert (KeyboardDecoder.name, KeyboardDecoder.kind, KeyboardDecoder.transport) == (
        "keyboard",
        "keyboard",
        "evdev",
    )
    assert decoder().describe() == "keyboard: jog at 25 %"
    assert decoder(tap_step_mm=0.1).describe() == "keyboard: jog at 25 %, taps of 0.1 mm"


# -- the quoted stream and hold-to-jog -------------------------------------------------------


def test_quoted_keypad_stream() -> None:
    """ev3dev#1043: KP8 down is +Y held, KP8 up is neutral; nothing else."""
    rec = load("keypad-kp8-ev3dev-1043.txt")
    dec = decoder()
    first, second = rec.frames
    assert dec.feed(first) == [jog(y=1.0)]
    assert dec.moving
    assert dec.feed(second) == [NEUTRAL]
    assert not dec.moving


def test_msc_scan_in_a_frame_is_ignored() -> None:
    """A scan code is not a key, even if a frame carries one."""
    dec = decoder()
    scan = EvdevEvent(EV_MSC, 4, 0x70060)
    assert dec.feed(EvdevFrame(0.0, (scan,))) == []
    kp8 = EvdevEvent(EV_KEY, KEY_CODES["KP8"], 1)
    assert dec.feed(EvdevFrame(0.0, (scan, kp8))) == [jog(y=1.0)]


def test_autorepeat_is_one_press() -> None:
    """KP6 held with autorepeat: one start, nothing on the repeats, one neutral."""
    rec = load("kp6-autorepeat.txt")
    answers = per_frame(decoder(), rec.frames)
    assert answers == [[jog(x=1.0)], [], [], [], [], [NEUTRAL]]


def test_autorepeat_never_queues_steps() -> None:
    """In step mode a held key is one step, not one per repeat (devices §3.1)."""
    rec = load("kp6-autorepeat.txt")
    answers = per_frame(decoder(mode="step"), rec.frames)
    assert [a for frame in answers for a in frame] == [StepIntent("X", 0.1, 0.25)]


@pytest.mark.parametrize(
    ("held", "expected"),
    [
        (["KP8", "KP6"], jog(x=1.0, y=1.0)),
        (["KP8", "KP6", "KP9"], jog(x=1.0, y=1.0, z=1.0)),
        (["KP4", "KP2", "KP3"], jog(x=-1.0, y=-1.0, z=-1.0)),
        (["KP8", "UP"], jog(y=1.0)),  # the same direction twice is still full speed
        (["LEFT", "KP6", "KP8"], jog(y=1.0)),  # X cancels, Y stays
        (["PAGEUP", "RIGHT"], jog(x=1.0, z=1.0)),
        (["KP4", "KP6"], None),  # cancels to neutral: nothing to send from rest
    ],
)
def test_held_keys_add_up(held: list[str], expected: ContinuousIntent | None) -> None:
    """Every held key adds its direction; opposite keys on one axis cancel to 0."""
    dec = decoder()
    assert dec.feed(press(0.0, *held)) == ([expected] if expected else [])
    assert dec.moving


def test_diagonal_stream() -> None:
    """KP8, then KP6 added, KP8 let go, KP6 let go: Y, XY, X, neutral."""
    rec = load("diagonal-kp8-kp6.txt")
    answers = per_frame(decoder(), rec.frames)
    assert answers == [[jog(y=1.0)], [jog(x=1.0, y=1.0)], [jog(x=1.0)], [NEUTRAL]]


def test_opposite_keys_cancel_and_uncover() -> None:
    """X- then X+ held: neutral; X- let go: X+ again; all let go: one more neutral."""
    dec = decoder()
    frames = [press(0, "KP4"), press(1, "KP6"), release(2, "KP4"), release(3, "KP6")]
    assert per_frame(dec, frames) == [[jog(x=-1.0)], [NEUTRAL], [jog(x=1.0)], [NEUTRAL]]


def test_neutral_is_sent_exactly_once() -> None:
    """Letting go of keys that had already cancelled, or of unknown keys, sends nothing more."""
    dec = decoder()
    frames = [
        press(0, "KP8"),
        press(1, "KP4", "KP6"),
        release(2, "KP8"),  # X still cancelled: neutral
        release(3, "KP4", "KP6"),
        release(4, "KP8", "KP2", "A"),
    ]
    answers = [a for f in per_frame(dec, frames) for a in f]
    assert answers == [jog(y=1.0), NEUTRAL]
    assert not dec.moving


def test_unbound_keys_and_values_do_nothing() -> None:
    """Unbound keys, odd values and other event types are ignored; HID reports too."""
    dec = decoder()
    assert dec.feed(keys(0, ("A", 1), ("KP7", 1), ("KP1", 1), ("KP8", 5), ("KP8", -1))) == []
    assert dec.feed(EvdevFrame(0.1, (EvdevEvent(EV_REL, 0, 5), EvdevEvent(EV_KEY, 9999, 1)))) == []
    assert dec.feed(HidReport(0.2, b"\x00\x00\x60")) == []
    assert not dec.moving


# -- taps ------------------------------------------------------------------------------------


def test_tap_within_the_window_steps() -> None:
    """Released within tap_s: one step of tap_step_mm that way, and no jog."""
    dec = decoder(tap_step_mm=0.1)
    assert dec.feed(press(10.0, "KP4")) == []
    assert dec.moving  # pending: a loss now must still stop
    assert dec.deadline_s() == pytest.approx(10.25)
    assert dec.feed(release(10.1, "KP4")) == [StepIntent("X", -0.1, 0.25)]
    assert dec.deadline_s() is None
    assert not dec.moving


def test_held_past_the_window_jogs() -> None:
    """Still held when tick(tap_s) comes: the continuous jog, then neutral on release."""
    dec = decoder(tap_step_mm=0.1)
    dec.feed(press(10.0, "KP8"))
    assert dec.tick(10.2) == []  # early: still a possible tap
    assert dec.tick(10.25) == [jog(y=1.0)]
    assert dec.deadline_s() is None
    assert dec.feed(release(10.9, "KP8")) == [NEUTRAL]


def test_released_late_without_a_tick_is_no_step() -> None:
    """A release after tap_s is the end of a hold even if no tick came between: no step."""
    dec = decoder(tap_step_mm=0.1)
    dec.feed(press(0.0, "KP6"))
    assert dec.feed(release(0.3, "KP6")) == []
    assert not dec.moving


def test_a_key_joins_a_running_jog_at_once() -> None:
    """With a jog already held, another key makes the diagonal without the tap delay."""
    dec = decoder(tap_step_mm=0.1)
    dec.feed(press(0.0, "KP6"))
    dec.tick(0.25)
    assert dec.feed(press(0.5, "KP8")) == [jog(x=1.0, y=1.0)]
    assert dec.feed(release(0.55, "KP8")) == [jog(x=1.0)]  # no step: it was part of the hold


def test_two_taps_together_are_two_steps() -> None:
    """Keys pressed in one tap window each step when let go in time."""
    dec = decoder(tap_step_mm=0.5, speeds=[0.1, 0.2], speed_index=1)
    dec.feed(press(0.0, "KP6"))
    dec.feed(press(0.05, "KP9"))
    assert dec.feed(release(0.1, "KP6", "KP9")) == [
        StepIntent("X", 0.5, 0.2),
        StepIntent("Z", 0.5, 0.2),
    ]


def test_tap_window_is_configurable() -> None:
    """tap_s moves the deadline."""
    dec = decoder(tap_step_mm=0.1, tap_s=0.5)
    dec.feed(press(1.0, "KP6"))
    assert dec.deadline_s() == pytest.approx(1.5)
    assert dec.feed(release(1.4, "KP6")) == [StepIntent("X", 0.1, 0.25)]


def test_taps_off_jogs_at_once() -> None:
    """Without tap_step_mm a press jogs at once and needs no timer."""
    dec = decoder()
    assert dec.feed(press(0.0, "KP6")) == [jog(x=1.0)]
    assert dec.deadline_s() is None
    assert dec.feed(release(0.05, "KP6")) == [NEUTRAL]  # a short press is no step


def test_stop_cancels_a_pending_tap() -> None:
    """Stop during the tap window: the stop, and no step on the release."""
    dec = decoder(tap_step_mm=0.1)
    dec.feed(press(0.0, "KP6"))
    assert dec.feed(press(0.05, "ESC")) == [StopIntent()]
    assert dec.feed(release(0.1, "KP6")) == []
    assert dec.tick(1.0) == []


# -- NumLock ---------------------------------------------------------------------------------


def test_injected_numlock_is_ignored() -> None:
    """NUMLOCK around KP2 (hid-remapper#164): -Y held, then neutral, nothing else."""
    rec = load("numlock-injected.txt")
    answers = [a for f in per_frame(decoder(), rec.frames) for a in f]
    assert answers == [jog(y=-1.0), NEUTRAL]


@pytest.mark.parametrize("name", ["numlock", "KEY_NUMLOCK"])
def test_numlock_cannot_be_bound(name: str) -> None:
    """Binding NumLock is refused in words naming the key."""
    with pytest.raises(ConfigError, match=rf"keys\.{name} cannot be bound"):
        decoder(keys={name: "X+"})


# -- resync and loss -------------------------------------------------------------------------


def test_resync_stops_and_a_still_held_key_does_not_restart() -> None:
    """SYN_DROPPED with KP8 held: neutral; KP8's repeats and release do nothing; a new press jogs.

    The key may have been let go and pressed again in the gap, and the jog ran blind meanwhile:
    after a resync only a key pressed anew moves the machine.
    """
    rec = load("syn-dropped-while-held.txt")
    assert rec.dropped == 1
    assert [f.resync for f in rec.frames] == [False, True, False, False, False, False]
    dec = decoder()
    held, resync, repeat, up, down, up_again = per_frame(dec, rec.frames)
    assert held == [jog(y=1.0)]
    assert resync[0] == NEUTRAL
    assert isinstance(resync[1], DeviceNotice)
    assert "lost" in resync[1].text
    assert (repeat, up) == ([], [])
    assert down == [jog(y=1.0)]
    assert up_again == [NEUTRAL]


def test_resync_releases_keys_it_does_not_list() -> None:
    """Keys held before a resync that lists none are up: neutral, not moving."""
    dec = decoder()
    dec.feed(press(0.0, "KP8", "KP6"))
    answer = dec.feed(EvdevFrame(1.0, (), resync=True))
    assert answer[0] == NEUTRAL
    assert not dec.moving
    assert dec.feed(press(2.0, "KP6")) == [jog(x=1.0)]


def test_resync_at_rest_ignores_keys_pressed_in_the_gap() -> None:
    """A key first seen held in a resync never starts motion; its release is no news."""
    dec = decoder()
    kp8 = EvdevEvent(EV_KEY, KEY_CODES["KP8"], 1)
    assert dec.feed(EvdevFrame(0.0, (kp8,), resync=True)) == []
    assert not dec.moving
    assert dec.feed(keys(0.1, ("KP8", 2))) == []
    assert dec.feed(release(0.2, "KP8")) == []


def test_resync_drops_a_pending_tap() -> None:
    """A tap window open at a resync ends with no step and no jog."""
    dec = decoder(tap_step_mm=0.1)
    dec.feed(press(0.0, "KP6"))
    dec.feed(EvdevFrame(0.1, (EvdevEvent(EV_KEY, KEY_CODES["KP6"], 1),), resync=True))
    assert dec.deadline_s() is None
    assert dec.tick(1.0) == []
    assert dec.feed(release(1.1, "KP6")) == []


def test_loss_while_held_leaves_the_stop_to_the_device_input() -> None:
    """Held key: moving, so the DeviceInput stops; after lost() nothing moves until a new press."""
    dec = decoder()
    dec.feed(press(0.0, "KP8"))
    assert dec.moving
    assert dec.lost() == []
    assert not dec.moving
    assert dec.feed(keys(0.5, ("KP8", 2))) == []
    assert dec.feed(release(0.6, "KP8")) == []
    assert dec.feed(press(1.0, "KP8")) == [jog(y=1.0)]


def test_loss_during_a_tap_window() -> None:
    """A pending tap counts as moving; after the loss it neither steps nor jogs."""
    dec = decoder(tap_step_mm=0.1)
    dec.feed(press(0.0, "KP6"))
    assert dec.moving
    dec.lost()
    assert (dec.moving, dec.deadline_s()) == (False, None)
    assert dec.tick(1.0) == []
    assert dec.feed(release(0.1, "KP6")) == []


def test_loss_forgets_speed_and_mode() -> None:
    """lost() forgets all state: speed and mode go back to the configured ones."""
    dec = decoder(keys={"kpasterisk": "step"})
    dec.feed(press(0.0, "KPPLUS", "KPASTERISK"))
    dec.lost()
    assert dec.describe() == "keyboard: jog at 25 %"


# -- speed, stop, modes, commands ------------------------------------------------------------


def test_speed_keys_while_jogging() -> None:
    """KPPLUS while holding re-sends the jog faster; repeats ignored; clamped at the ends."""
    dec = decoder()
    dec.feed(press(0.0, "KP8"))
    assert intents(dec.feed(press(0.1, "KPPLUS"))) == [jog(y=1.0, speed=0.5)]
    assert dec.feed(keys(0.2, ("KPPLUS", 2))) == []
    dec.feed(release(0.3, "KPPLUS"))
    assert intents(dec.feed(press(0.4, "KPPLUS"))) == [jog(y=1.0, speed=1.0)]
    assert dec.feed(keys(0.5, ("KPPLUS", 0), ("KPPLUS", 1))) == []  # already at the top
    for t_s in (0.6, 0.7, 0.8, 0.9):
        dec.feed(keys(t_s, ("KPMINUS", 1), ("KPMINUS", 0)))
    assert dec.speed == 0.1


def test_speed_change_at_rest_is_only_a_notice() -> None:
    """At rest a speed key says the new speed; the next jog uses it."""
    dec = decoder(speeds=[0.2, 0.8], speed_index=0)
    answer = dec.feed(press(0.0, "KPPLUS"))
    assert answer == [DeviceNotice("keyboard jog speed 80 %")]
    assert dec.feed(press(0.1, "KP2")) == [jog(y=-1.0, speed=0.8)]


@pytest.mark.parametrize("stop_key", ["KP5", "KP0", "ESC"])
def test_stop_keys_stop_and_forget_held_keys(stop_key: str) -> None:
    """Stop while holding: StopIntent, no neutral after it, the held key must be pressed anew."""
    dec = decoder()
    dec.feed(press(0.0, "KP8"))
    assert dec.feed(press(0.1, stop_key)) == [StopIntent()]
    assert not dec.moving
    assert dec.feed(release(0.2, stop_key, "KP8")) == []
    assert dec.feed(press(0.3, "KP8")) == [jog(y=1.0)]


def test_step_mode_toggle() -> None:
    """The "step" action: neutral, then one step per press; jogging again needs new presses."""
    dec = decoder(keys={"kpasterisk": "step"}, step_mm=0.05)
    dec.feed(press(0.0, "KP8"))
    answer = dec.feed(press(0.1, "KPASTERISK"))
    assert NEUTRAL in answer
    assert "step of 0.05 mm" in dec.describe()
    assert dec.feed(release(0.2, "KP8", "KPASTERISK")) == []
    assert dec.feed(press(0.3, "KP6")) == [StepIntent("X", 0.05, 0.25)]
    assert dec.moving  # held: a loss during a long step still stops
    assert intents(dec.feed(press(0.4, "KPASTERISK"))) == []
    assert dec.feed(release(0.5, "KP6", "KPASTERISK")) == []
    assert dec.feed(press(0.6, "KP6")) == [jog(x=1.0)]


@pytest.mark.parametrize(
    ("action", "expected"),
    [
        ("home", DeviceCommand("home")),
        ("Unlock", DeviceCommand("unlock")),
        ("goto_zero", DeviceCommand("goto_zero")),
        ("hold", DeviceCommand("hold")),
        ("zero", DeviceCommand("zero", axes=("X", "Y", "Z"))),
        ("zero:xy", DeviceCommand("zero", axes=("X", "Y"))),
        ("override:feed:+10", DeviceCommand("override", kind="feed", step="+10")),
        ("override:rapid:25", DeviceCommand("override", kind="rapid", step="25")),
    ],
)
def test_machine_commands(action: str, expected: DeviceCommand) -> None:
    """A key bound to a machine command asks for it on the press only."""
    dec = decoder(keys={"f1": action})
    assert dec.feed(press(0.0, "F1")) == [expected]
    assert dec.feed(keys(0.1, ("F1", 2), ("F1", 0))) == []


def test_keymap_merges_over_the_defaults() -> None:
    """keys adds and overrides bindings; "none" unbinds; any spelling of a key name works."""
    dec = decoder(keys={"kp4": "none", "KEY_KP7": "z+", "Kp1": "Z-", "f": "X+"})
    assert dec.feed(press(0.0, "KP4")) == []
    assert dec.feed(press(0.1, "KP7")) == [jog(z=1.0)]
    assert dec.feed(press(0.2, "F")) == [jog(x=1.0, z=1.0)]
    assert dec.feed(press(0.3, "KP1")) == [jog(x=1.0)]
    assert dec.feed(press(0.4, "LEFT")) == [jog()]  # the arrows keep their defaults


def test_axes_the_machine_lacks_are_dropped() -> None:
    """On an XY machine the Z keys do nothing and the intents name X and Y only."""
    dec = decoder(axes=("X", "Y"), keys={"a": "A+"})
    assert dec.feed(press(0.0, "PAGEUP", "KP9", "A")) == []
    assert dec.feed(press(0.1, "KP6")) == [ContinuousIntent({"X": 1.0, "Y": 0.0}, 0.25)]


# -- key names -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "code"),
    [
        ("KEY_KP4", 75),
        ("kp4", 75),
        (" Key_Kp4 ", 75),
        ("left", 105),
        ("PAGEDOWN", 109),
        ("f12", 88),
        ("1", 2),
        ("BTN_0", 256),
        ("kp44", None),
        ("", None),
    ],
)
def test_key_names(name: str, code: int | None) -> None:
    """Key names with or without KEY_, in any case."""
    assert key_code(name) == code


def test_key_name_for_messages() -> None:
    """Codes back to the kernel's names."""
    assert (key_name(75), key_name(256), key_name(999)) == ("KEY_KP4", "BTN_0", "key 999")


def test_key_codes_agree_with_the_kernel_headers() -> None:
    """Every name in the table has python-evdev's code (linux/input-event-codes.h)."""
    ecodes = pytest.importorskip("evdev.ecodes")
    for name, code in KEY_CODES.items():
        full = name if name.startswith("BTN_") else f"KEY_{name}"
        assert ecodes.ecodes[full] == code, full


# -- options ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("options", "key"),
    [
        ({"keys": {"kp44": "X+"}}, "keys.kp44"),
        ({"keys": {"kp4": "Q+"}}, "keys.kp4"),
        ({"keys": {"kp4": 3}}, "keys.kp4"),
        ({"keys": {"kp4": " "}}, "keys.kp4"),
        ({"keys": {"f1": "zero:XQ"}}, "keys.f1"),
        ({"keys": {"f1": "override:spindle:+10"}}, "keys.f1"),
        ({"keys": {"f1": "override:feed"}}, "keys.f1"),
        ({"keys": {"f1": "home:now"}}, "keys.f1"),
        ({"keys": "kp4"}, "keys"),
        ({"speeds": []}, "speeds"),
        ({"speeds": "fast"}, "speeds"),
        ({"speeds": [0.0, 1.0]}, "speeds"),
        ({"speeds": [0.5, 1.5]}, "speeds"),
        ({"speeds": [0.5, "max"]}, "speeds"),
        ({"speeds": [0.5] * 21}, "speeds"),
        ({"speed_index": 4}, "speed_index"),
        ({"speeds": [0.5], "speed_index": 1}, "speed_index"),
        ({"speed_index": 1.5}, "speed_index"),
        ({"tap_step_mm": 0}, "tap_step_mm"),
        ({"tap_step_mm": 500}, "tap_step_mm"),
        ({"tap_step_mm": "0.1"}, "tap_step_mm"),
        ({"tap_s": 0}, "tap_s"),
        ({"tap_s": 10}, "tap_s"),
        ({"step_mm": -1}, "step_mm"),
        ({"mode": "walk"}, "mode"),
        ({"tap_stepmm": 0.1}, "'tap_stepmm'"),
    ],
)
def test_option_errors_name_the_key(options: dict[str, Any], key: str) -> None:
    """Each bad option is refused with the file, the section and the key."""
    with pytest.raises(ConfigError) as err:
        decoder(**options)
    assert "test.toml" in str(err.value)
    assert key in str(err.value)


def test_one_speed_needs_no_index() -> None:
    """A single speed is used as it is; the default index follows the list."""
    dec = decoder(speeds=[0.6])
    assert dec.feed(press(0.0, "KP6")) == [jog(x=1.0, speed=0.6)]


def test_every_default_is_usable() -> None:
    """The defaults table gives a working decoder."""
    dec = KeyboardDecoder(DeviceInfo("k"), Table({}, "device", "<defaults>"), AXES)
    assert dec.speed == 0.25
    assert dec.feed(press(0.0, "KP8")) == [jog(y=1.0)]


# -- properties ------------------------------------------------------------------------------

_CODES = sorted(KEY_CODES.values())
_EVENTS = st.builds(
    EvdevEvent,
    st.sampled_from([EV_KEY, EV_KEY, EV_KEY, EV_REL, EV_MSC, 0, 3, 17]) | st.integers(0, 0xFFFF),
    st.sampled_from(_CODES) | st.integers(0, 0x2FF),
    st.sampled_from([0, 1, 1, 2]) | st.integers(-(2**31), 2**31 - 1),
)
_STEPS = st.lists(
    st.tuples(
        st.floats(0.0, 0.4),  # time to the next frame
        st.lists(_EVENTS, max_size=6),
        st.sampled_from([False, False, False, True]),  # a resync frame (rarer)
        st.integers(0, 30),  # 0: the device is lost before this frame
    ),
    max_size=40,
)
_OPTIONS = st.fixed_dictionaries(
    {},
    optional={
        "tap_step_mm": st.sampled_from([0.01, 0.1, 1.0]),
        "mode": st.sampled_from(["jog", "step"]),
        "speed_index": st.integers(0, 3),
        "keys": st.just({"kpasterisk": "step", "f1": "home", "f2": "zero:X"}),
    },
)


@settings(max_examples=300, deadline=None)
@given(options=_OPTIONS, steps=_STEPS)
def test_arbitrary_frames_never_raise_and_never_leave_a_jog_behind(
    options: dict[str, Any], steps: list[tuple[float, list[EvdevEvent], bool, int]]
) -> None:
    """Any events: no exception, every intent valid, no repeated neutral, no jog while idle.

    The last invariant is the safety one: whenever the decoder says it is not moving, the last
    continuous intent it sent is neutral (or a stop came after it).
    """
    dec = decoder(**options)
    jogging = False
    last: ContinuousIntent | None = None
    t_s = 0.0

    def check(actions: list[Action]) -> None:
        nonlocal jogging, last
        for action in actions:
            if isinstance(action, DeviceNotice | DeviceCommand):
                continue
            validate_intent(action, AXES, MAX_FEED_MM_MIN)
            if isinstance(action, StopIntent):
                jogging, last = False, None
            elif isinstance(action, ContinuousIntent):
                assert set(action.axes.values()) <= {-1.0, 0.0, 1.0}
                assert action != last, "the same intent sent twice"
                assert not (action.is_neutral() and not jogging), "neutral sent twice"
                jogging, last = not action.is_neutral(), action
        assert dec.moving or not jogging, "a jog left running with no key held"

    for dt_s, events, resync, lose in steps:
        t_s += dt_s
        deadline = dec.deadline_s()
        if deadline is not None and deadline <= t_s:
            check(dec.tick(deadline))
        if lose == 0:
            dec.lost()
            assert (dec.moving, dec.deadline_s()) == (False, None)
            jogging, last = False, None  # the DeviceInput stopped it
        check(dec.feed(EvdevFrame(t_s, tuple(events), resync=resync)))
        if resync:
            assert not jogging, "a resync must stop the jog"
        dec.describe()
