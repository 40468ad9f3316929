"""`smoothjog devices`: the input devices this machine has, what each is taken for, and access.

Nothing is opened: the list comes from sysfs, which anyone may read. A device that cannot be
opened is listed with the one sentence that fixes it; `--udev-rules` prints the rules file that
does (docs/devices.md).
"""

from __future__ import annotations

import argparse
from importlib import resources
from typing import Any

from smoothjog.inputs.discovery import UDEV_RULES_NAME, FoundDevice, choose, scan
from smoothjog.inputs.kinds import DECODERS, KIND_NAMES

#: The serial side: FTDI adapters hand on received bytes within 1 ms instead of 16 ms.
FTDI_LATENCY_RULES_NAME = "99-smoothjog-ftdi-latency.rules"


def register(subparsers: Any) -> None:
    """Add `devices` to the command line."""
    parser = subparsers.add_parser(
        "devices",
        help="list the input devices smoothjog can see and whether it can open them",
        description=__doc__,
    )
    parser.add_argument(
        "--udev-rules",
        action="store_true",
        help=f"print the udev rules file ({UDEV_RULES_NAME}) that gives access to the devices"
        f" and sets FTDI serial adapters' latency timer to 1 ms ({FTDI_LATENCY_RULES_NAME})",
    )
    parser.add_argument("--all", action="store_true", help="also list nodes no decoder takes")
    parser.add_argument("--sysfs", default="/sys", help=argparse.SUPPRESS)
    parser.add_argument("--dev", default="/dev", help=argparse.SUPPRESS)
    parser.set_defaults(func=run)


def udev_rules() -> str:
    """The shipped rules files' text: the input devices' access, then the FTDI latency timer."""
    folder = resources.files("smoothjog").joinpath("data", "udev")
    return "\n".join(
        folder.joinpath(name).read_text(encoding="utf-8")
        for name in (UDEV_RULES_NAME, FTDI_LATENCY_RULES_NAME)
    )


def _line(device: FoundDevice, chosen: bool) -> list[str]:
    info = device.info
    kind = device.kind or "-"
    access = "yes" if device.problem is None else "no"
    head = f"{device.path:<20} {kind:<16} {info.usb_id:<10} {access:<5} {info.name}"
    out = [head]
    if device.kind is not None and not chosen and device.problem is None:
        out.append("    (also seen through its other node; `--input auto` uses the hidraw one)")
    if device.problem is not None:
        out.append(f"    {device.problem}")
    return out


def run(args: argparse.Namespace) -> int:
    """Print the list (or the udev rules); 0 always: no device is not an error."""
    if args.udev_rules:
        print(udev_rules(), end="")
        return 0
    found = scan(DECODERS, sysfs=args.sysfs, dev=args.dev)
    shown = found if args.all else [d for d in found if d.kind is not None]
    if not found:
        print(
            "no input devices found: this machine lists no /dev/input/event* or /dev/hidraw* "
            "nodes (plug a device in, or check that the kernel sees it with `dmesg`)"
        )
        return 0
    if not shown:
        print(
            f"{len(found)} input node(s) found, none of a kind smoothjog drives "
            f"({', '.join(KIND_NAMES)}); `--all` lists them"
        )
        return 0
    chosen = {d.path for d in choose(found, ["auto", "keyboard"])}
    print(f"{'node':<20} {'taken for':<16} {'usb id':<10} {'open':<5} name")
    for device in shown:
        print("\n".join(_line(device, device.path in chosen)))
    print(
        "\nUse one with `smoothjog --input KIND|NAME|PATH` (repeatable; `--input auto` takes "
        "every device above but keyboards, which are only used when named)."
    )
    return 0
