"""The contract between the pendant server and whatever drives the machine behind it.

The server only ever calls these five methods, from its event loop thread, and never awaits
them: each must return quickly (queue the work, do not wait for the controller). The jog engine
and session implement it for real; tests implement it with a recorder.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol, runtime_checkable

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
    """What the pendant needs from the machine side; every method returns without waiting."""

    def jog_continuous(self, axes: Mapping[str, float], speed: float) -> None:
        """Jog by stick deflection per axis in [-1, 1] at a global speed fraction in (0, 1].

        Called on every change of intent and again as the heartbeat (at least every 40 ms)
        while the jog is held; the deflection is already deadzoned and expo-shaped.
        """
        ...

    def jog_step(self, axis: str, dist_mm: float) -> None:
        """Queue an exact relative move of one axis; steps run in the order they arrive."""
        ...

    def stop(self) -> None:
        """Return to neutral: cancel every queued jog with the full cancel handshake."""
        ...

    def view(self) -> Mapping[str, object]:
        """A JSON-serialisable snapshot with exactly the keys in VIEW_KEYS."""
        ...

    def set_speed_ratios(self, ratios: Mapping[str, float]) -> None:
        """Set the relative top speed of each axis, e.g. {"X": 1, "Y": 1, "Z": 0.25}."""
        ...
