"""load_config: defaults, every section, bounds, unknown keys, file and syntax errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from smoothjog.config import (
    CONFIG_ENV,
    DEFAULT_HTTP_PORT,
    Config,
    ConnectionConfig,
    JogConfig,
    PendantConfig,
    SimConfig,
    load_config,
    parse_config,
)
from smoothjog.core.errors import ConfigError
from smoothjog.core.machine import KeepOut, MachineModel
from smoothjog.core.responses import parse_response

FULL = """
[connection]
port = "/dev/ttyUSB0"
baud = 250000
timeout_s = 2.5

[jog]
speed_ratios = { x = 1, y = 0.8, Z = 0.25 }
default_speed = 0.3
link_margin_s = 0.05

[[keepout]]
name = "vise"
min_mm = [-120, -80, -60]
max_mm = [-40, -20, 0]

[[keepout]]
name = "probe dock"
min_mm = [-5.5, -300]
max_mm = [0, -280]

[pendant]
host = "0.0.0.0"
port = 8899
lan = true

[sim]
firmware = "fluidnc"
machine = "hobby-router"
"""


def write(tmp_path: Path, text: str, name: str = "smoothjog.toml") -> Path:
    """Write a config file and return its path."""
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_no_file_gives_the_defaults() -> None:
    """No path and no environment variable: every default."""
    config = load_config(None, environ={})
    assert config == Config()
    assert config.connection == ConnectionConfig(None, 115200, None, 5.0)
    assert config.jog.ratio("x") == 1.0
    assert config.source is None


def test_every_key_is_read(tmp_path: Path) -> None:
    """A full file lands in the dataclasses, axis letters upper-cased."""
    path = write(tmp_path, FULL)
    config = load_config(path, environ={})
    assert config.source == path
    assert config.connection == ConnectionConfig("/dev/ttyUSB0", 250000, None, 2.5)
    assert dict(config.jog.speed_ratios) == {"X": 1.0, "Y": 0.8, "Z": 0.25}
    assert config.jog.ratio("z") == 0.25
    assert config.jog.ratio("A") == 1.0
    assert (config.jog.default_speed, config.jog.link_margin_s) == (0.3, 0.05)
    assert config.keepouts == (
        KeepOut("vise", (-120.0, -80.0, -60.0), (-40.0, -20.0, 0.0)),
        KeepOut("probe dock", (-5.5, -300.0), (0.0, -280.0)),
    )
    assert config.pendant == PendantConfig("0.0.0.0", 8899, True)
    assert config.sim == SimConfig("fluidnc", "hobby-router")


def test_pendant_port_defaults_to_the_one_constant() -> None:
    """An empty [pendant] and no [pendant] at all both serve on DEFAULT_HTTP_PORT (8080)."""
    assert DEFAULT_HTTP_PORT == 8080
    assert parse_config("").pendant.port == DEFAULT_HTTP_PORT
    assert parse_config("[pendant]\n").pendant.port == DEFAULT_HTTP_PORT
    assert PendantConfig().port == DEFAULT_HTTP_PORT


@pytest.mark.parametrize("firmware", ["grbl", "grblhal", "fluidnc"])
def test_every_known_firmware_is_accepted(firmware: str) -> None:
    assert parse_config(f"[sim]\nfirmware = {firmware!r}\n").sim.firmware == firmware


def test_cncjs_connection(tmp_path: Path) -> None:
    """A CNCjs server, its port and where its secret is."""
    text = (
        "[connection]\ncncjs = 'http://pi.local:8000'\ncncjs_port = '/dev/ttyACM0'\n"
        "cncjs_config = '/home/pi/.cncrc'\ncncjs_user = 'alice'\n"
    )
    connection = load_config(write(tmp_path, text)).connection
    assert connection.cncjs == "http://pi.local:8000"
    assert connection.cncjs_port == "/dev/ttyACM0"
    assert connection.cncjs_config == "/home/pi/.cncrc"
    assert connection.cncjs_user == "alice"


def test_tcp_connection(tmp_path: Path) -> None:
    """A connect URL is kept as written."""
    config = load_config(write(tmp_path, '[connection]\nconnect = "tcp://cnc.local:23"\n'))
    assert config.connection.connect == "tcp://cnc.local:23"
    assert config.connection.port is None


def test_environment_variable_names_the_file(tmp_path: Path) -> None:
    """$SMOOTHJOG_CONFIG is used when no path is given, and a path given wins over it."""
    env_file = write(tmp_path, "[connection]\nbaud = 9600\n", "env.toml")
    arg_file = write(tmp_path, "[connection]\nbaud = 38400\n", "arg.toml")
    assert load_config(None, environ={CONFIG_ENV: str(env_file)}).connection.baud == 9600
    assert load_config(arg_file, environ={CONFIG_ENV: str(env_file)}).connection.baud == 38400


def test_missing_file_given_explicitly(tmp_path: Path) -> None:
    """A named file that does not exist is an error naming it."""
    missing = tmp_path / "nope.toml"
    with pytest.raises(ConfigError, match=r"nope\.toml \(given with --config\) does not exist"):
        load_config(missing, environ={})
    with pytest.raises(ConfigError, match=r"named by \$SMOOTHJOG_CONFIG\) does not exist"):
        load_config(None, environ={CONFIG_ENV: str(missing)})


def test_directory_is_not_a_config(tmp_path: Path) -> None:
    """A directory given as the config is refused clearly."""
    with pytest.raises(ConfigError, match="is a directory"):
        load_config(tmp_path, environ={})


def test_syntax_error_names_file_and_line(tmp_path: Path) -> None:
    """A TOML syntax error gives the file and the line."""
    path = write(tmp_path, "[connection]\nbaud = 115200\nport = /dev/ttyUSB0\n")
    with pytest.raises(ConfigError, match=r"smoothjog\.toml: not valid TOML: .*line 3"):
        load_config(path, environ={})


def test_not_utf8(tmp_path: Path) -> None:
    """A file that is not UTF-8 is refused with a fix."""
    path = tmp_path / "latin1.toml"
    path.write_bytes(b'[pendant]\nhost = "caf\xe9"\n')
    with pytest.raises(ConfigError, match="not UTF-8"):
        load_config(path, environ={})


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[conection]\nport = 'x'\n", "unknown section 'conection'"),
        ("[connection]\nbuad = 9600\n", r"unknown key 'buad' in \[connection\]"),
        ("[jog]\ndefault_sped = 0.5\n", r"unknown key 'default_sped' in \[jog\]"),
        ("[pendant]\nlan = true\nwan = true\n", r"unknown key 'wan' in \[pendant\]"),
        ("[sim]\nfirmwear = 'grbl'\n", r"unknown key 'firmwear' in \[sim\]"),
        ("[[keepout]]\nname='a'\nmin_mm=[0]\nmax_mm=[1]\ncolour='red'\n",
         r"unknown key 'colour' in \[keepout 'a'\]"),
        ("connection = 3\n", "must be a section"),
        ("[connection]\nbaud = 0\n", r"\[connection\] baud = 0 must be from 1"),
        ("[connection]\nbaud = -9600\n", "baud = -9600 must be from 1"),
        ("[connection]\nbaud = 'fast'\n", "baud = 'fast' is not a whole number"),
        ("[connection]\nbaud = 115200.0\n", "is not a whole number"),
        ("[connection]\ntimeout_s = 0\n", r"timeout_s = 0 must be above 0"),
        ("[connection]\ntimeout_s = nan\n", "not a finite number"),
        ("[connection]\ntimeout_s = true\n", "is not a number"),
        ("[connection]\nport = ''\n", "port is empty"),
        ("[connection]\nport = 3\n", "port = 3 is not a string"),
        ("[connection]\nport = 'a'\nconnect = 'tcp://h:23'\n", "both set"),
        ("[connection]\ncncjs = 'http://h:8000'\n", "cncjs needs cncjs_port"),
        ("[connection]\ncncjs = 'h:8000'\ncncjs_port = 'p'\n", "cncjs is wrong: .*CNCjs address"),
        ("[connection]\ncncjs = 'http://h'\ncncjs_port = 'p'\nport = 'a'\n", "beside port"),
        ("[connection]\nconnect = 'http://h:80'\n", r"connect is wrong: .*not a tcp:// address"),
        ("[connection]\nconnect = 'tcp://h:99999'\n", "port '99999'"),
        ("[jog]\nspeed_ratios = { x = 0 }\n", r"speed_ratios\.x = 0 must be above 0"),
        ("[jog]\nspeed_ratios = { y = 1.5 }\n", r"speed_ratios\.y = 1\.5 must be at most 1"),
        ("[jog]\nspeed_ratios = { q = 0.5 }\n", r"speed_ratios\.q names no axis"),
        ("[jog]\nspeed_ratios = { x = 0.5, X = 0.4 }\n", "given twice"),
        ("[jog]\nspeed_ratios = 0.5\n", "is not a table"),
        ("[jog]\ndefault_speed = 0\n", "default_speed = 0 must be above 0"),
        ("[jog]\ndefault_speed = 1.01\n", "must be at most 1"),
        ("[jog]\nlink_margin_s = -0.01\n", "must be at least 0"),
        ("[[keepout]]\nmin_mm=[0]\nmax_mm=[1]\n", r"\[keepout #1\] name is missing"),
        ("[[keepout]]\nname='v'\nmax_mm=[1]\n", "min_mm is missing"),
        ("[[keepout]]\nname='v'\nmin_mm=[0, 0]\nmax_mm=[1]\n", "has 1 numbers but min_mm has 2"),
        ("[[keepout]]\nname='v'\nmin_mm=[0, 5]\nmax_mm=[1, 5]\n", "axis Y .* not below max_mm"),
        ("[[keepout]]\nname='v'\nmin_mm=[]\nmax_mm=[]\n", "not a list of 1 to 9 numbers"),
        ("[[keepout]]\nname='v'\nmin_mm=['a']\nmax_mm=[1]\n", "is not a number"),
        ("[[keepout]]\nname='v'\nmin_mm=[0]\nmax_mm=[1]\n[[keepout]]\nname='v'\nmin_mm=[0]\n"
         "max_mm=[1]\n", "used twice"),
        ("keepout = 3\n", r"written as \[\[keepout\]\]"),
        ("[pendant]\nport = 70000\n", "port = 70000 must be from 1 to 65535"),
        ("[pendant]\nlan = 'yes'\n", "lan = 'yes' is not true or false"),
        ("[sim]\nfirmware = 'marlin'\n", "'marlin' is not one of grbl, grblhal, fluidnc"),
    ],
)  # fmt: skip
def test_bad_values_name_file_section_and_key(tmp_path: Path, text: str, message: str) -> None:
    """Every bad value is a ConfigError naming the file and what is wrong."""
    path = write(tmp_path, text)
    with pytest.raises(ConfigError, match=message) as info:
        load_config(path, environ={})
    assert str(info.value).startswith(str(path))


def test_bounds_are_inclusive_where_documented() -> None:
    """The edges that are allowed are accepted."""
    config = parse_config(
        "[jog]\nspeed_ratios = { x = 1 }\ndefault_speed = 1\nlink_margin_s = 0\n"
        "[pendant]\nport = 65535\n[connection]\nbaud = 1\n"
    )
    assert config.jog == JogConfig(
        speed_ratios=config.jog.speed_ratios, default_speed=1.0, link_margin_s=0.0
    )
    assert config.pendant.port == 65535
    assert config.connection.baud == 1


def test_config_is_frozen() -> None:
    """The dataclasses cannot be changed after loading."""
    config = parse_config("")
    with pytest.raises(AttributeError):
        config.connection.baud = 9600  # type: ignore[misc]
    with pytest.raises(TypeError):
        config.jog.speed_ratios["X"] = 0.5  # type: ignore[index]


def test_a_keepout_remembers_where_it_was_written(tmp_path: Path) -> None:
    """Each zone carries its file and section, for messages only: equality ignores it."""
    path = write(tmp_path, FULL)
    vise, dock = load_config(path, environ={}).keepouts
    assert (vise.source, dock.source) == (str(path), str(path))
    assert dock.where == f"{path}: [keepout 'probe dock']"
    assert dock == KeepOut("probe dock", (-5.5, -300.0), (0.0, -280.0))


@pytest.mark.parametrize(
    ("min_mm", "max_mm", "accepted"),
    [
        ("[-120, -80]", "[-40, -20]", True),  # X and Y only: every Z height is blocked
        ("[-120]", "[-40]", True),
        ("[-120, -80, -60]", "[-40, -20, 0]", True),
        ("[-120, -80, -60, 0]", "[-40, -20, 0, 90]", False),  # an A the machine lacks
    ],
)
def test_keepout_axes_are_checked_against_the_machine_at_start_up(
    tmp_path: Path, min_mm: str, max_mm: str, accepted: bool
) -> None:
    """A zone may name fewer axes than the machine; one it lacks is refused naming file and key."""
    path = write(tmp_path, f"[[keepout]]\nname = 'vise'\nmin_mm = {min_mm}\nmax_mm = {max_mm}\n")
    zones = load_config(path, environ={}).keepouts
    model = MachineModel()
    model.apply(parse_response("<Idle|MPos:0.000,0.000,0.000|FS:0,0>"))
    if accepted:
        model.set_keep_outs(zones)
        assert model.keep_outs == zones
        return
    with pytest.raises(ConfigError) as info:
        model.set_keep_outs(zones)
    message = str(info.value)
    assert message.startswith(f"{path}: [keepout 'vise'] min_mm")
    assert "4 numbers" in message
    assert "3 axes (X Y Z)" in message
