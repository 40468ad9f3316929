"""The machine-command catalogue: each command once, with what it sends and when it may run.

The page's buttons, a device's buttons, the console and the proxy's view of the machine all
name commands from here; MachineControl runs them and the gate decides when each may run.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from smoothjog.core import realtime

#: A line that ends quickly; a longer wait means the controller is stuck or the line a dwell.
LINE_TIMEOUT_S: Final = 30.0
#: A homing cycle seeks the whole travel at `$25` and then creeps at `$24`; two minutes covers
#: an 800 mm router at 2000 mm/min with room to spare. Its `ok` comes when homing ends.
HOME_TIMEOUT_S: Final = 120.0

#: "Go to work zero" runs at this fraction of the top jog speed (a page's or a device's).
GOTO_SPEED: Final = 0.5

#: Re-read after a command: nothing, the parser modes and offsets, or the settings.
NOTHING, MODES, SETTINGS = "", "modes", "settings"


@dataclass(frozen=True)
class Command:
    """One machine command: its line or byte, the states it runs in, what it re-reads."""

    name: str
    #: Shown while it runs ("homing").
    doing: str
    #: The line it sends (None: a realtime byte, or a line built from its arguments).
    line: str | None = None
    byte: bytes | None = None
    #: The controller states it may run in (None: any; a console line follows the line table).
    states: frozenset[str] | None = None
    #: It may run while another program holds the machine (it cannot change that job).
    locked_ok: bool = False
    #: It may run while the machine moves or another command runs (a realtime byte).
    always: bool = False
    rereads: str = NOTHING
    timeout_s: float = LINE_TIMEOUT_S


_REST: Final = frozenset({"Idle"})
_REST_OR_ALARM: Final = frozenset({"Idle", "Alarm"})

CATALOGUE: Final[dict[str, Command]] = {
    c.name: c
    for c in (
        Command("unlock", "unlocking", line="$X", states=_REST_OR_ALARM),
        Command(
            "home",
            "homing",
            line="$H",
            states=_REST_OR_ALARM,
            rereads=MODES,
            timeout_s=HOME_TIMEOUT_S,
        ),
        Command("reset", "resetting", byte=realtime.RESET, locked_ok=True, always=True),
        Command("zero", "setting work zero", states=_REST, rereads=MODES),
        Command("wcs", "selecting a coordinate system", states=_REST, rereads=MODES),
        Command("override", "changing an override", locked_ok=True, always=True),
        # `!` in Idle would freeze the controller in Hold:0 with nothing to hold (§3.2).
        Command(
            "hold",
            "holding",
            byte=realtime.FEED_HOLD,
            states=frozenset({"Run", "Jog"}),
            locked_ok=True,
            always=True,
        ),
        Command(
            "resume",
            "resuming",
            byte=realtime.CYCLE_START,
            states=frozenset({"Hold", "Door"}),
            locked_ok=True,
            always=True,
        ),
        Command("console", "a console line", rereads=MODES),
        Command("goto_zero", "going to work zero", states=_REST),
    )
}

#: The commands a page or a device may name, in the order the page lists them.
COMMAND_NAMES: Final = tuple(CATALOGUE)


def command(name: str) -> Command:
    """The catalogue entry of name; KeyError for a name it lacks."""
    return CATALOGUE[name]


__all__ = [
    "CATALOGUE",
    "COMMAND_NAMES",
    "GOTO_SPEED",
    "HOME_TIMEOUT_S",
    "LINE_TIMEOUT_S",
    "Command",
    "command",
]
