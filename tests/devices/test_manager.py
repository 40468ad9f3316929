"""The session's device manager: open what is wished for, stop on loss, reopen on replug."""

from __future__ import annotations

import asyncio
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from smoothjog.authority.arbiter import Arbiter
from smoothjog.config import parse_config
from smoothjog.core.errors import ConfigError
from smoothjog.core.intents import HandwheelIntent, Intent, StopIntent
from smoothjog.devices import DeviceManager, check_device_configs
from smoothjog.inputs import discovery
from smoothjog.inputs.device import HidReport
from smoothjog.inputs.devinput import RecordedSource
from smoothjog.inputs.discovery import FoundDevice

X_AT_001 = bytes.fromhex("04ba00000e1100ba")  # WHB04B: X selected, 0.01 mm, wheel still
PLUS_ONE = bytes.fromhex("049d00000e11019c")  # one detent +1


@dataclass
class Sink:
    intents: list[Intent] = field(default_factory=list)

    def set_intent(self, intent: Intent) -> None:
        self.intents.append(intent)

    def can_jog(self) -> tuple[bool, str | None]:
        return True, None


def _whb_node(sysfs: Path, dev: Path) -> Path:
    node = sysfs / "class" / "hidraw" / "hidraw0" / "device"
    node.mkdir(parents=True)
    (node / "uevent").write_text("HID_ID=0003:000010CE:0000EB93\nHID_NAME=KTURT.LTD WHB04B\n")
    dev.mkdir(exist_ok=True)
    (dev / "hidraw0").write_text("")
    return node.parent


async def _until(check: Callable[[], bool], timeout_s: float = 3.0) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout_s
    while not check():
        assert loop.time() < end, "timed out"
        await asyncio.sleep(0.01)


async def test_a_wished_device_is_opened_stopped_when_lost_and_opened_again(
    tmp_path: Path,
) -> None:
    sysfs, dev = tmp_path / "sys", tmp_path / "dev"
    node = _whb_node(sysfs, dev)
    opened: list[str] = []

    def opener(found: FoundDevice) -> RecordedSource:
        opened.append(found.path)
        # Two detents, then the stream ends mid-motion: the device is gone.
        reports = [HidReport(0.0, X_AT_001), HidReport(0.02, PLUS_ONE), HidReport(0.04, PLUS_ONE)]
        return RecordedSource(found.info, reports)

    sink = Sink()
    told: list[str] = []
    manager = DeviceManager(
        Arbiter(sink),
        wishes=["whb04b"],
        axes=lambda: ("X", "Y", "Z"),
        notices=told.append,
        sysfs=str(sysfs),
        dev=str(dev),
        rescan_s=0.05,
        opener=opener,
    )
    task = asyncio.create_task(manager.run())
    try:
        await _until(lambda: len(opened) >= 2)
        wheel = [i for i in sink.intents if isinstance(i, HandwheelIntent)]
        assert wheel[:2] == [HandwheelIntent("X", 1, 0.01, "position", 0.5)] * 2
        # The loss stopped the machine before the device was opened again.
        first_stop = sink.intents.index(StopIntent())
        assert first_stop == 2
        assert any("ready" in t for t in told)
        # Unplugged for good: the node goes, nothing more is opened.
        for child in sorted(node.rglob("*"), reverse=True):
            child.unlink() if child.is_file() else child.rmdir()
        node.rmdir()
        await asyncio.sleep(0.2)
        count = len(opened)
        await asyncio.sleep(0.2)
        assert len(opened) == count
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


async def test_an_unopenable_device_and_an_unmatched_wish_are_told_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    sysfs, dev = tmp_path / "sys", tmp_path / "dev"
    _whb_node(sysfs, dev)
    locked = str(dev / "hidraw0")
    real_access = os.access
    monkeypatch.setattr(discovery.os, "access", lambda p, m: p != locked and real_access(p, m))
    told: list[str] = []
    manager = DeviceManager(
        Arbiter(Sink()),
        wishes=["whb04b", "gamepad"],
        axes=lambda: ("X", "Y", "Z"),
        notices=told.append,
        sysfs=str(sysfs),
        dev=str(dev),
        rescan_s=0.01,
        opener=lambda found: pytest.fail("a locked device must not be opened"),
    )
    for _ in range(5):
        manager.scan_once()
    assert len([t for t in told if "permission denied" in t]) == 1
    assert "udev" in next(t for t in told if "permission denied" in t)
    assert len([t for t in told if "--input gamepad" in t]) == 1
    assert not any("--input whb04b" in t for t in told)


def test_a_bad_device_option_is_refused_at_start_naming_the_key() -> None:
    config = parse_config('[[device]]\nkind = "whb04b"\nwatchdog_s = -1\n', "pi.toml")
    with pytest.raises(ConfigError, match=r"pi.toml: \[device #1 \(whb04b\)\] watchdog_s"):
        check_device_configs(config.devices)
    config = parse_config('[[device]]\nkind = "joystick"\n', "pi.toml")
    with pytest.raises(ConfigError, match="unknown device kind 'joystick'"):
        check_device_configs(config.devices)
    config = parse_config('[[device]]\nkind = "keyboard"\n', "pi.toml")
    with pytest.raises(ConfigError, match="a keyboard table must name its device"):
        check_device_configs(config.devices)
    with pytest.raises(ConfigError, match="kind is missing"):
        parse_config('[[device]]\nmatch = "pad"\n', "pi.toml")


async def test_a_configured_device_needs_no_wish_and_gets_its_options(tmp_path: Path) -> None:
    sysfs, dev = tmp_path / "sys", tmp_path / "dev"
    _whb_node(sysfs, dev)
    config = parse_config('[[device]]\nkind = "whb04b"\nstep_speed = 0.25\n', "pi.toml")
    sink = Sink()
    manager = DeviceManager(
        Arbiter(sink),
        wishes=[],
        configs=config.devices,
        axes=lambda: ("X", "Y", "Z"),
        sysfs=str(sysfs),
        dev=str(dev),
        opener=lambda found: RecordedSource(
            found.info, [HidReport(0.0, X_AT_001), HidReport(0.01, PLUS_ONE)]
        ),
    )
    manager.scan_once()
    started = manager.started
    assert len(started) == 1
    await asyncio.wait_for(asyncio.gather(*asyncio.all_tasks() - {asyncio.current_task()}), 2.0)
    wheel = [i for i in sink.intents if isinstance(i, HandwheelIntent)]
    assert wheel == [HandwheelIntent("X", 1, 0.01, "position", 0.25)]
