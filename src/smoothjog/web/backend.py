"""The contract between the pendant server and whatever drives the machine behind it.

The server (and the arbiter it submits through) only ever calls these four methods, from the
event loop thread, and never awaits them: each must return quickly (queue the work, do not wait
for the controller). The jog session implements it for real; tests implement it with a recorder.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol, runtime_checkable

from smoothjog.core.intents import Intent

#: The keys of the snapshot `PendantBackend.view()` returns; docs/pendant.md explains each one.
VIEW_KEYS: frozenset[str] = frozenset(
    {
        "t_s",
        "firmware",
        "axes",
        "state",
        "substate",
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
        "envelope",
        "keepouts",
        "max_rate_mm_min",
        "speed_ratios",
        "moving",
    }
)


@runtime_checkable
class PendantBackend(Protocol):
    """What the pendant needs from the machine side; every method returns without waiting.

    It is also the arbiter's IntentSink (set_intent, can_jog): the page's intents reach it only
    through the arbiter, which decides who controls and runs the dead-man.
    """

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
