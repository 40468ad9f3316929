"""The dead-man timer: decides when a held jog has gone unheard for too long.

Pure bookkeeping with the time passed in, so it is tested without a clock; the server feeds it
loop.time() and schedules one timer per window to ask `expired`.
"""

from __future__ import annotations

from smoothjog.web.protocol import PendantError


class DeadMan:
    """Arms on a continuous jog, is fed by each heartbeat, expires after window_s of silence."""

    def __init__(self, window_s: float) -> None:
        if not window_s > 0.0:
            raise PendantError(
                f"dead-man window must be positive, got {window_s!r} s; "
                "pass e.g. deadman_s=0.15 to create_app"
            )
        self.window_s = window_s
        self._last_heard_s: float | None = None

    @property
    def armed(self) -> bool:
        """True while a continuous jog is held and watched."""
        return self._last_heard_s is not None

    @property
    def last_heard_s(self) -> float | None:
        """When the last heartbeat arrived, or None when disarmed."""
        return self._last_heard_s

    def feed(self, now_s: float) -> None:
        """Record a heartbeat (a jog message) at now_s; arms the timer if it was disarmed."""
        self._last_heard_s = now_s

    def disarm(self) -> None:
        """Forget the held jog (it was released, stopped, or the timer already fired)."""
        self._last_heard_s = None

    def deadline_s(self) -> float | None:
        """The time at which silence becomes a trip, or None when disarmed."""
        if self._last_heard_s is None:
            return None
        return self._last_heard_s + self.window_s

    def expired(self, now_s: float) -> bool:
        """True when armed and nothing was heard for at least window_s before now_s."""
        deadline = self.deadline_s()
        return deadline is not None and now_s >= deadline
