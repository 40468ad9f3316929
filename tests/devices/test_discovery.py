"""Finding devices from sysfs (a fake tree here: these machines have no input devices)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from smoothjog.core.options import Table
from smoothjog.inputs import discovery
from smoothjog.inputs.device import Action, Decoder, DeviceInfo, DeviceItem
from smoothjog.inputs.discovery import (
    PERMISSION_FIX,
    FoundDevice,
    choose,
    parse_bitmap,
    scan,
    wanted_by,
)


class _Base(Decoder):
    kind = "handwheel"

    def __init__(self, info: DeviceInfo, options: Table, axes: object) -> None:
        super().__init__(info, options, ("X",))

    def feed(self, item: DeviceItem) -> list[Action]:
        return []

    @property
    def moving(self) -> bool:
        return False

    def lost(self) -> list[Action]:
        return []


class Wheel(_Base):
    name = "whb04b"
    transport = "hidraw"

    @classmethod
    def matches(cls, info: DeviceInfo) -> bool:
        return info.usb_id == "10ce:eb93"


class Shuttle(_Base):
    name = "shuttle"
    transport = "hidraw"

    @classmethod
    def matches(cls, info: DeviceInfo) -> bool:
        return info.usb_id == "0b33:0020"


class ShuttleEv(_Base):
    name = "shuttle-evdev"
    transport = "evdev"

    @classmethod
    def matches(cls, info: DeviceInfo) -> bool:
        return info.usb_id == "0b33:0020"


class Keys(_Base):
    name = "keyboard"
    kind = "keyboard"
    transport = "evdev"

    @classmethod
    def matches(cls, info: DeviceInfo) -> bool:
        return 72 in info.keys  # KEY_KP8


DECODERS = (Wheel, Shuttle, ShuttleEv, Keys)


def _evdev_node(sysfs: Path, n: int, name: str, vid: int, pid: int, key: str = "0") -> None:
    dev = sysfs / "class" / "input" / f"event{n}" / "device"
    (dev / "id").mkdir(parents=True)
    (dev / "capabilities").mkdir()
    (dev / "name").write_text(name + "\n")
    (dev / "id" / "vendor").write_text(f"{vid:04x}\n")
    (dev / "id" / "product").write_text(f"{pid:04x}\n")
    (dev / "id" / "bustype").write_text("0003\n")
    (dev / "capabilities" / "key").write_text(key + "\n")
    (dev / "capabilities" / "rel").write_text("0\n")
    (dev / "capabilities" / "abs").write_text("3\n")


def _hidraw_node(sysfs: Path, n: int, name: str, vid: int, pid: int) -> None:
    dev = sysfs / "class" / "hidraw" / f"hidraw{n}" / "device"
    dev.mkdir(parents=True)
    (dev / "uevent").write_text(
        f"DRIVER=hid-generic\nHID_ID=0003:{vid:08X}:{pid:08X}\nHID_NAME={name}\n"
    )


@pytest.fixture
def tree(tmp_path: Path) -> tuple[Path, Path]:
    sysfs, dev = tmp_path / "sys", tmp_path / "dev"
    (dev / "input").mkdir(parents=True)
    _hidraw_node(sysfs, 0, "KTURT.LTD WHB04B", 0x10CE, 0xEB93)
    _hidraw_node(sysfs, 1, "Contour Design ShuttleXpress", 0x0B33, 0x0020)
    _evdev_node(sysfs, 3, "Contour Design ShuttleXpress", 0x0B33, 0x0020)
    _evdev_node(sysfs, 4, "USB Keypad", 0x1A2C, 0x0E24, key="100 0")  # bit 72 of word 0
    _evdev_node(sysfs, 5, "Power Button", 0, 1)
    for node in ("hidraw0", "hidraw1", "input/event3", "input/event4", "input/event5"):
        (dev / node).write_text("")
    return sysfs, dev


def test_scan_names_each_node_with_the_kind_that_takes_it(tree: tuple[Path, Path]) -> None:
    sysfs, dev = tree
    found = {d.path.removeprefix(str(dev)): d for d in scan(DECODERS, sysfs=sysfs, dev=dev)}
    assert {p: d.kind for p, d in found.items()} == {
        "/input/event3": "shuttle-evdev",
        "/input/event4": "keyboard",
        "/input/event5": None,
        "/hidraw0": "whb04b",
        "/hidraw1": "shuttle",
    }
    assert found["/hidraw0"].info.name == "KTURT.LTD WHB04B"
    assert found["/input/event4"].info.keys == frozenset({72})
    assert set(found["/input/event4"].info.absinfo) == {0, 1}


def test_an_unreadable_node_says_how_to_fix_it(
    tree: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    sysfs, dev = tree
    locked = str(dev / "hidraw0")
    real_access = os.access
    # The suite may run as root, who reads every node: the kernel's answer is stood in for.
    monkeypatch.setattr(
        discovery.os, "access", lambda p, mode: p != locked and real_access(p, mode)
    )
    found = {d.path: d for d in scan(DECODERS, sysfs=sysfs, dev=dev)}
    problem = found[locked].problem
    assert problem is not None
    assert "permission denied" in problem
    assert PERMISSION_FIX in problem
    assert "udev" in PERMISSION_FIX
    assert not found[locked].usable
    assert found[str(dev / "hidraw1")].usable


def test_a_listed_device_without_a_node_is_said(tree: tuple[Path, Path]) -> None:
    sysfs, dev = tree
    (dev / "hidraw1").unlink()
    found = {d.path: d for d in scan(DECODERS, sysfs=sysfs, dev=dev)}
    assert "does not exist" in (found[str(dev / "hidraw1")].problem or "")


def test_an_empty_machine_has_no_devices(tmp_path: Path) -> None:
    assert scan(DECODERS, sysfs=tmp_path, dev=tmp_path) == []


@pytest.mark.parametrize(
    ("text", "bits", "codes"),
    [
        ("0", 64, set()),
        ("3", 64, {0, 1}),
        ("1 0", 64, {64}),
        ("1 0", 32, {32}),
        ("ffff0000 0 0 0", 64, set(range(208, 224))),
        ("120000000000000 0 0 0 0", 64, {256 + 53, 256 + 56}),
    ],
)
def test_capability_bitmaps(text: str, bits: int, codes: set[int]) -> None:
    assert parse_bitmap(text, bits) == frozenset(codes)


def _found(
    path: str, transport: str, kind: str | None, vid: int, pid: int, name: str
) -> FoundDevice:
    return FoundDevice(path, transport, DeviceInfo(name, path, vid, pid), kind)  # type: ignore[arg-type]


SHUTTLE_HID = _found("/dev/hidraw1", "hidraw", "shuttle", 0x0B33, 0x20, "Contour ShuttleXpress")
SHUTTLE_EV = _found(
    "/dev/input/event3", "evdev", "shuttle-evdev", 0x0B33, 0x20, "Contour ShuttleXpress"
)
KEYPAD = _found("/dev/input/event4", "evdev", "keyboard", 0x1A2C, 0x0E24, "USB Keypad")
PAD = _found("/dev/input/event6", "evdev", "gamepad", 0x045E, 0x028E, "Xbox 360 pad")


@pytest.mark.parametrize(
    ("wish", "device", "wanted"),
    [
        ("auto", PAD, True),
        ("auto", KEYPAD, False),  # a keyboard is only grabbed when named
        ("keyboard", KEYPAD, True),
        ("gamepad", PAD, True),
        ("shuttle", SHUTTLE_EV, True),
        ("/dev/input/event6", PAD, True),
        ("045e:028e", PAD, True),
        ("xbox", PAD, True),
        ("XBOX 360", PAD, True),
        ("xbox", KEYPAD, False),
        ("", PAD, False),
    ],
)
def test_what_an_input_wish_names(wish: str, device: FoundDevice, wanted: bool) -> None:
    assert wanted_by(device, wish) is wanted


def test_the_hidraw_node_of_a_device_wins_over_its_event_node() -> None:
    assert choose([SHUTTLE_EV, SHUTTLE_HID, PAD], ["auto"]) == [SHUTTLE_HID, PAD]
    # When the hidraw node cannot be opened, the event node is used.
    locked = FoundDevice(SHUTTLE_HID.path, "hidraw", SHUTTLE_HID.info, "shuttle", "no access")
    assert choose([SHUTTLE_EV, locked], ["shuttle"]) == [SHUTTLE_EV, locked]
