"""The contract between the pendant server and whatever drives the machine behind it.

The server (and the arbiter it submits through) calls these methods from the event loop thread.
All but `command` return at once (queue the work, do not wait for the controller); `command` is
awaited in a task of its own and may take as long as the controller does (homing). The jog
session implements it for real; tests implement it with a recorder.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Protocol, runtime_checkable

from smoothjog.authority.gate import StopRecord
from smoothjog.control import CommandResult
from smoothjog.core.intents import Intent
from smoothjog.web.protocol import CommandMessage

#: The keys of the snapshot `PendantBackend.view()` returns; docs/pendant.md explains each one.
VIEW_KEYS: frozenset[str] = frozenset(
    {
        "t_s",
        "firmware",
        "axes",
        "state",
        "substate",
        "link",
        "can_jog",
        "reason",
        "units",
        "mpos",
        "wpos",
        "feed_mm_min",
        "commanded_speed_mm_s",
        "actual_speed_mm_s",
        "stop_point_mpos",
        "queue",
        "fault",
        "stop",
        "warning",
        "envelope",
        "keepouts",
        "max_rate_mm_min",
        "speed_ratios",
        "default_speed",
        "moving",
        "control",
    }
)

#: The keys of the view's "control" object: what machine control the page may offer now.
CONTROL_KEYS: frozenset[str] = frozenset(
    {
        "can_command",
        "reason",
        "commands",
        "offer",
        "running",
        "homing",
        "wcs",
        "wcs_list",
        "offsets",
        "wco",
        "overrides",
        "modal",
        "steps_per_mm",
    }
)


@runtime_checkable
class PendantBackend(Protocol):
    """What the pendant needs from the machine side; every method returns without waiting.

    It is also the arbiter's IntentSink (set_intent, can_jog): the page's intents reach it only
    through the arbiter, which decides who controls and runs the dead-man.
    """

    def add_stop_listener(self, callback: Callable[[StopRecord], None]) -> None:
        """Call callback with every stop of the machine, whoever gave it (every page is told)."""
        ...

    def set_intent(self, intent: Intent) -> None:
        """Take the newest intent; raises JogBuildError in words for one the machine cannot do.

        A held continuous jog arrives on every change and again as the heartbeat (at least
        every 40 ms); a release arrives as a neutral ContinuousIntent or a StopIntent, and a
        StopIntent may come when nothing moves and must then be harmless.
        """
        ...

    def can_jog(self) -> tuple[bool, str | None]:
        """Whether a new jog may start now, and if not why, in words."""
        ...

    def view(self) -> Mapping[str, object]:
        """A JSON-serialisable snapshot with exactly the keys in VIEW_KEYS."""
        ...

    def set_speed_ratios(self, ratios: Mapping[str, float]) -> None:
        """Set the relative top speed of each axis, e.g. {"X": 1, "Y": 1, "Z": 0.25}."""
        ...

    async def command(self, message: CommandMessage) -> CommandResult:
        """Run one machine command (unlock, home, reset, zero, wcs, override, console).

        Raises ControlRefused in words when it cannot run now (the machine moves, another
        command runs) or is malformed; a command the controller rejects returns ok False.
        """
        ...

    def work_zero_targets(self) -> list[dict[str, float]]:
        """The machine positions that lead to work zero, Z first up; raises ControlRefused."""
        ...
