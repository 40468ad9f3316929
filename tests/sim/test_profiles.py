"""Machine and firmware profiles: shipped files load, bad files fail with file and key.

The firmware profiles take their figures from the core firmware table; these tests check the
simulated controller really runs with them.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from smoothjog.core.defaults import GRBL_DEFAULTS
from smoothjog.core.errors import SimError
from smoothjog.core.firmware import FIRMWARE_NAMES, firmware_facts
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import (
    FIRMWARE_PROFILES,
    available_machine_profiles,
    get_firmware_profile,
    load_machine_profile,
)
from smoothjog.sim.settings import Eeprom, GrblSettings, format_grbl_float, load_eeprom

SHIPPED = ["fast", "grbl-defaults", "hobby-router", "slow-machine"]


def test_shipped_profiles_are_listed() -> None:
    assert available_machine_profiles() == SHIPPED


@pytest.mark.parametrize("name", SHIPPED)
def test_each_shipped_profile_boots(name: str) -> None:
    fw = GrblFirmware(machine=name)
    assert fw.state == "Idle"


@pytest.mark.parametrize(
    ("name", "number", "value"),
    [
        ("hobby-router", 110, 5000.0),
        ("hobby-router", 120, 500.0),
        ("hobby-router", 112, 1500.0),
        ("hobby-router", 122, 200.0),
        ("hobby-router", 130, 800.0),
        ("hobby-router", 132, 100.0),
        ("slow-machine", 120, 50.0),
        ("fast", 110, 15000.0),
        ("fast", 120, 2000.0),
        ("grbl-defaults", 100, 250.0),
    ],
)
def test_profile_values(name: str, number: int, value: float) -> None:
    assert GrblFirmware(machine=name).settings[number] == value


def test_hobby_router_starts_homed_at_the_pull_off_corner() -> None:
    fw = GrblFirmware(machine="hobby-router")
    assert fw.mpos_mm() == (-1.0, -1.0, -1.0)
    assert fw.settings.int_value(20) == 1


def test_unknown_profile_lists_the_available_ones() -> None:
    with pytest.raises(SimError, match="hobby-router"):
        load_machine_profile("no-such-machine")


def test_unknown_firmware_lists_the_choices() -> None:
    with pytest.raises(SimError, match="grblhal"):
        get_firmware_profile("marlin")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("spead = 3\n", "unknown key 'spead'"),
        ("[settings]\n110 = 'fast'\n", "settings key '110'"),
        ("[settings]\n999 = 1\n", "settings key '999'"),
        ("[settings]\nabc = 1\n", "settings key 'abc'"),
        ("[settings]\n120 = 0\n", "'120' must be greater than 0"),
        ('start = "sometime"\n', "key 'start'"),
        ("axes = 2\n", "key 'axes'"),
        ("this is not toml", "not valid TOML"),
    ],
)
def test_bad_machine_file_names_file_and_key(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "mine.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(SimError, match=message) as info:
        load_machine_profile(str(path))
    assert str(path) in str(info.value)


def test_user_profile_by_path(tmp_path: Path) -> None:
    path = tmp_path / "mine.toml"
    path.write_text('name = "mine"\n[settings]\n"$110" = 1234\n', encoding="utf-8")
    fw = GrblFirmware(machine=str(path))
    assert fw.settings[110] == 1234.0
    assert fw.machine.name == "mine"


def test_missing_profile_file() -> None:
    with pytest.raises(SimError, match="does not exist"):
        load_machine_profile("/nonexistent/machine.toml")


def test_eeprom_round_trip_and_persistence(tmp_path: Path) -> None:
    path = tmp_path / "eeprom.json"
    saved: list[Eeprom] = []
    fw = GrblFirmware(on_eeprom_write=saved.append)
    fw.receive(b"$110=777\nG10L2P1X3\n", 0.1)
    fw.advance(1.0)
    path.write_text(saved[-1].to_json(), encoding="utf-8")
    image = load_eeprom(path)
    assert image is not None
    again = GrblFirmware(eeprom=image)
    assert again.settings[110] == 777.0
    assert again.parser.coord_systems_mm[0] == (3.0, 0.0, 0.0)


def test_bad_eeprom_file(tmp_path: Path) -> None:
    path = tmp_path / "eeprom.json"
    path.write_text('{"settings": {}}', encoding="utf-8")
    with pytest.raises(SimError, match="coord_systems_mm"):
        load_eeprom(path)


@pytest.mark.parametrize(
    ("value", "decimals", "text"),
    [(1.0005, 3, "1.001"), (-0.0001, 3, "-0.000"), (0.0, 3, "0.000"), (2.5, 0, "3"), (10, 0, "10")],
)
def test_grbl_float_format(value: float, decimals: int, text: str) -> None:
    assert format_grbl_float(value, decimals) == text


def test_settings_for_more_axes() -> None:
    settings = GrblSettings(4)
    assert "$103=250.000" in settings.dollar_lines()


def test_every_family_is_simulated_with_its_table_row() -> None:
    assert sorted(FIRMWARE_PROFILES) == sorted(FIRMWARE_NAMES)
    for name in FIRMWARE_NAMES:
        assert get_firmware_profile(name).facts is firmware_facts(name)


@pytest.mark.parametrize("name", FIRMWARE_NAMES)
def test_simulated_buffers_and_opt_line_follow_the_table(name: str) -> None:
    facts = firmware_facts(name)
    fw = GrblFirmware(get_firmware_profile(name), "grbl-defaults")
    assert fw.rx.size == facts.rx_buffer_bytes
    assert fw.motion.planner_blocks == facts.planner_usable_blocks
    expected = f"[OPT:V,{facts.planner_usable_blocks},{facts.rx_buffer_bytes}]"
    assert get_firmware_profile(name).options_line == expected


def test_default_settings_are_grbls() -> None:
    assert GrblSettings(3).snapshot() == {n: float(v) for n, v in GRBL_DEFAULTS.items()}
