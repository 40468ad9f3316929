"""`smoothjog devices`: plain words on a machine with no devices, a table when there are some."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import pytest

from smoothjog.cli import main


def test_a_machine_with_no_input_devices_says_so(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    assert main(["devices", "--sysfs", str(tmp_path), "--dev", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("no input devices found")


def test_this_machine_runs_it_whatever_it_has(capsys: pytest.CaptureFixture[str]) -> None:
    # The CI machines have no /dev/input; a developer's may. Either way: no traceback, exit 0.
    assert main(["devices"]) == 0
    assert capsys.readouterr().out.strip()


def test_the_list_names_kind_access_and_the_hidraw_node_first(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    sysfs, dev = tmp_path / "sys", tmp_path / "dev"
    hid = sysfs / "class" / "hidraw" / "hidraw1" / "device"
    hid.mkdir(parents=True)
    (hid / "uevent").write_text(
        "HID_ID=0003:00000B33:00000020\nHID_NAME=Contour Design ShuttleXpress\n"
    )
    ev = sysfs / "class" / "input" / "event3" / "device"
    (ev / "id").mkdir(parents=True)
    (ev / "capabilities").mkdir()
    (ev / "name").write_text("Contour Design ShuttleXpress\n")
    for key, value in (("vendor", "0b33"), ("product", "0020"), ("bustype", "0003")):
        (ev / "id" / key).write_text(value + "\n")
    for key, value in (("key", "1f 0 0 0 0"), ("rel", "180"), ("abs", "0")):
        (ev / "capabilities" / key).write_text(value + "\n")
    (dev / "input").mkdir(parents=True)
    (dev / "hidraw1").write_text("")
    assert main(["devices", "--sysfs", str(sysfs), "--dev", str(dev)]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert lines[0].split()[:5] == ["node", "taken", "for", "usb", "id"]
    hid_line = next(line for line in lines if "hidraw1" in line)
    assert hid_line.split()[1:4] == ["shuttle", "0b33:0020", "yes"]
    ev_line = next(line for line in lines if "event3" in line)
    assert ev_line.split()[1:4] == ["shuttle-evdev", "0b33:0020", "no"]
    assert "does not exist" in out  # event3 has no /dev node in this tree


def test_udev_rules_cover_every_raw_device(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["devices", "--udev-rules"]) == 0
    rules = capsys.readouterr().out
    for vid, pid in (("10ce", "eb93"), ("10ce", "eb91"), ("0b33", "0020"), ("05f3", "0240")):
        assert f'ATTRS{{idVendor}}=="{vid}", ATTRS{{idProduct}}=="{pid}"' in rules
    assert 'ATTRS{idVendor}=="256f"' in rules
    assert 'GROUP="plugdev"' in rules


FTDI_LATENCY_RULE = 'SUBSYSTEM=="usb-serial", DRIVER=="ftdi_sio", ATTR{latency_timer}="1"'


def test_udev_rules_set_the_ftdi_latency_timer(capsys: pytest.CaptureFixture[str]) -> None:
    """The printed rules end with the FTDI one (16 ms late replies otherwise), which also ships
    as its own file."""
    assert main(["devices", "--udev-rules"]) == 0
    rules = capsys.readouterr().out
    assert FTDI_LATENCY_RULE in rules.splitlines()
    assert 'GROUP="plugdev"' in rules  # the input devices' rules are still there, first
    assert rules.index('GROUP="plugdev"') < rules.index(FTDI_LATENCY_RULE)
    shipped = resources.files("smoothjog").joinpath(
        "data", "udev", "99-smoothjog-ftdi-latency.rules"
    )
    rule_lines = [
        line for line in shipped.read_text(encoding="utf-8").splitlines() if line and line[0] != "#"
    ]
    assert rule_lines == [FTDI_LATENCY_RULE]
