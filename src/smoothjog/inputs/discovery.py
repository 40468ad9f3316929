"""Finding input devices: what is plugged in, which decoder takes each, and can we open it.

The kernel lists every evdev node under /sys/class/input/eventN and every hidraw node under
/sys/class/hidraw/hidrawN, with the name and USB ids readable by anyone; the /dev node itself
may be closed to us (systemd gives event nodes the `input` group and hidraw nodes root only,
docs/devices.md). So the scan reads sysfs, never opens a device, and says for each node which
decoder would take it and, when it cannot be opened, the one sentence that fixes it.

Capabilities come from the sysfs bitmaps; absolute ranges are only known once a node is opened
(EVIOCGABS), so a scanned node's `absinfo` holds placeholder ranges for the declared axes.
"""

from __future__ import annotations

import os
import re
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Final, Literal

from smoothjog.inputs.device import AbsRange, Decoder, DeviceInfo

#: The udev rules file smoothjog ships (package data) and where it goes.
UDEV_RULES_NAME: Final = "70-smoothjog.rules"
UDEV_RULES_DEST: Final = f"/etc/udev/rules.d/{UDEV_RULES_NAME}"

PERMISSION_FIX: Final = (
    "install smoothjog's udev rule and join the groups it names: "
    f"`smoothjog devices --udev-rules | sudo tee {UDEV_RULES_DEST}`, "
    "`sudo udevadm control --reload-rules && sudo udevadm trigger`, "
    "`sudo usermod -aG input,plugdev $USER`, then log out and in again (docs/devices.md)"
)


@dataclass(frozen=True)
class FoundDevice:
    """One device node and what smoothjog makes of it."""

    path: str
    transport: Literal["evdev", "hidraw"]
    info: DeviceInfo
    #: The decoder's name that takes it by default, or None.
    kind: str | None
    #: Why it cannot be opened, in words with the fix, or None when it can.
    problem: str | None = None

    @property
    def usable(self) -> bool:
        """A decoder takes it and it can be opened."""
        return self.kind is not None and self.problem is None


def _read(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8", errors="replace").strip()
    except OSError:
        return ""


def _hex(text: str) -> int:
    try:
        return int(text, 16)
    except ValueError:
        return 0


#: The width of the kernel's unsigned long, in which sysfs prints capability bitmaps: 64 on
#: arm64 and x86-64, 32 on a 32-bit Raspberry Pi OS. Python's own build is the best guess.
LONG_BITS: Final = 64 if sys.maxsize > 2**32 else 32


def parse_bitmap(text: str, long_bits: int = LONG_BITS) -> frozenset[int]:
    """A sysfs capability bitmap ("1 0 ffff0000 0": longs, most significant first) as codes."""
    words = text.split()
    codes: set[int] = set()
    bits = long_bits
    for index, word in enumerate(reversed(words)):
        value = _hex(word)
        base = index * bits
        while value:
            low = value & -value
            codes.add(base + low.bit_length() - 1)
            value ^= low
    return frozenset(codes)


def _evdev_info(node: Path, dev_path: str) -> DeviceInfo:
    device = node / "device"
    caps = device / "capabilities"
    abs_codes = parse_bitmap(_read(caps / "abs"))
    return DeviceInfo(
        name=_read(device / "name") or dev_path,
        path=dev_path,
        vendor=_hex(_read(device / "id" / "vendor")),
        product=_hex(_read(device / "id" / "product")),
        bus=_hex(_read(device / "id" / "bustype")),
        # Ranges are read when the node is opened; presence is what matching needs.
        absinfo={code: AbsRange(0, 0, 0) for code in abs_codes},
        keys=parse_bitmap(_read(caps / "key")),
        rels=parse_bitmap(_read(caps / "rel")),
    )


_HID_ID = re.compile(r"^HID_ID=([0-9A-Fa-f]+):([0-9A-Fa-f]+):([0-9A-Fa-f]+)$", re.MULTILINE)
_HID_NAME = re.compile(r"^HID_NAME=(.*)$", re.MULTILINE)


def _hidraw_info(node: Path, dev_path: str) -> DeviceInfo:
    uevent = _read(node / "device" / "uevent")
    bus = vendor = product = 0
    if m := _HID_ID.search(uevent):
        bus, vendor, product = (_hex(g) for g in m.groups())
    name_match = _HID_NAME.search(uevent)
    name = name_match.group(1).strip() if name_match else dev_path
    return DeviceInfo(name=name, path=dev_path, vendor=vendor, product=product, bus=bus)


def _problem(dev_path: str) -> str | None:
    # Read access is what jogging needs; a display that cannot be written is said on open.
    if not os.path.exists(dev_path):
        return f"{dev_path} does not exist (the kernel lists the device but udev made no node)"
    if not os.access(dev_path, os.R_OK):
        return f"cannot open {dev_path}: permission denied; {PERMISSION_FIX}"
    return None


def classify(info: DeviceInfo, transport: str, decoders: Iterable[type[Decoder]]) -> str | None:
    """The first decoder (in the given order) of this transport that takes the device."""
    for decoder in decoders:
        if decoder.transport == transport and decoder.matches(info):
            return decoder.name
    return None


def scan(
    decoders: Sequence[type[Decoder]],
    *,
    sysfs: str | os.PathLike[str] = "/sys",
    dev: str | os.PathLike[str] = "/dev",
) -> list[FoundDevice]:
    """Every evdev and hidraw node the kernel lists, classified, sorted by path."""
    found: list[FoundDevice] = []
    sys_root = Path(sysfs)
    dev_root = Path(dev)
    for node in sorted((sys_root / "class" / "input").glob("event*")):
        dev_path = str(dev_root / "input" / node.name)
        info = _evdev_info(node, dev_path)
        found.append(
            FoundDevice(
                dev_path,
                "evdev",
                info,
                classify(info, "evdev", decoders),
                _problem(dev_path),
            )
        )
    for node in sorted((sys_root / "class" / "hidraw").glob("hidraw*")):
        dev_path = str(dev_root / node.name)
        info = _hidraw_info(node, dev_path)
        found.append(
            FoundDevice(
                dev_path,
                "hidraw",
                info,
                classify(info, "hidraw", decoders),
                _problem(dev_path),
            )
        )
    return found


#: Kinds that are only opened when named: grabbing a keyboard takes it from the user's console.
NAMED_ONLY_KINDS: Final = frozenset({"keyboard"})


def wanted_by(device: FoundDevice, wish: str) -> bool:
    """Whether `--input wish` names this device: "auto", a kind, a path, vendor:product, or
    part of its name (case does not matter)."""
    text = wish.strip().lower()
    if not text:
        return False
    if text == "auto":
        return device.kind is not None and device.kind not in NAMED_ONLY_KINDS
    if device.kind is not None and text in (device.kind, device.kind.removesuffix("-evdev")):
        return True
    if text == device.path.lower() or text == device.info.usb_id:
        return True
    return text in device.info.name.lower()


def choose(found: Sequence[FoundDevice], wishes: Sequence[str]) -> list[FoundDevice]:
    """The nodes to open for these wishes: one per physical device, hidraw before evdev.

    A Shuttle or a SpaceMouse shows up as a hidraw node and an evdev node; the hidraw one gives
    the ring's and the cap's return to zero, so it wins when it can be opened.
    """
    picked = [d for d in found if d.kind is not None and any(wanted_by(d, w) for w in wishes)]
    hid_ids = {
        (d.info.vendor, d.info.product) for d in picked if d.transport == "hidraw" and d.usable
    }
    return [
        d
        for d in picked
        if d.transport == "hidraw" or (d.info.vendor, d.info.product) not in hid_ids
    ]
