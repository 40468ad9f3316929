"""The controller's serial receive side: the RX ring and the picking of realtime bytes.

Realtime bytes are taken out of the stream at arrival time, wherever they appear, and never reach
the ring (facts §1.1, §5.2); every other byte goes to a fixed-size ring that drops bytes when full,
as the chip's ISR does (facts §5.1).
"""

from __future__ import annotations

from collections import deque
from enum import Enum


class Realtime(Enum):
    """What a realtime byte asks of the controller."""

    STATUS = "status"
    CYCLE_START = "cycle_start"
    FEED_HOLD = "feed_hold"
    RESET = "reset"
    SAFETY_DOOR = "safety_door"
    JOG_CANCEL = "jog_cancel"
    FEED_OVR_RESET = "feed_ovr_reset"
    FEED_OVR_COARSE_PLUS = "feed_ovr_coarse_plus"
    FEED_OVR_COARSE_MINUS = "feed_ovr_coarse_minus"
    FEED_OVR_FINE_PLUS = "feed_ovr_fine_plus"
    FEED_OVR_FINE_MINUS = "feed_ovr_fine_minus"
    RAPID_OVR_RESET = "rapid_ovr_reset"
    RAPID_OVR_MEDIUM = "rapid_ovr_medium"
    RAPID_OVR_LOW = "rapid_ovr_low"
    SPINDLE_OVR_RESET = "spindle_ovr_reset"
    SPINDLE_OVR_COARSE_PLUS = "spindle_ovr_coarse_plus"
    SPINDLE_OVR_COARSE_MINUS = "spindle_ovr_coarse_minus"
    SPINDLE_OVR_FINE_PLUS = "spindle_ovr_fine_plus"
    SPINDLE_OVR_FINE_MINUS = "spindle_ovr_fine_minus"
    SPINDLE_STOP = "spindle_stop"
    FLOOD_TOGGLE = "flood_toggle"
    MIST_TOGGLE = "mist_toggle"
    #: A byte >= 0x80 the firmware does not use: dropped without effect.
    DISCARD = "discard"


#: Grbl 1.1h's realtime bytes (facts §5.2).
GRBL_REALTIME: dict[int, Realtime] = {
    0x18: Realtime.RESET,
    ord("?"): Realtime.STATUS,
    ord("~"): Realtime.CYCLE_START,
    ord("!"): Realtime.FEED_HOLD,
    0x84: Realtime.SAFETY_DOOR,
    0x85: Realtime.JOG_CANCEL,
    0x90: Realtime.FEED_OVR_RESET,
    0x91: Realtime.FEED_OVR_COARSE_PLUS,
    0x92: Realtime.FEED_OVR_COARSE_MINUS,
    0x93: Realtime.FEED_OVR_FINE_PLUS,
    0x94: Realtime.FEED_OVR_FINE_MINUS,
    0x95: Realtime.RAPID_OVR_RESET,
    0x96: Realtime.RAPID_OVR_MEDIUM,
    0x97: Realtime.RAPID_OVR_LOW,
    0x99: Realtime.SPINDLE_OVR_RESET,
    0x9A: Realtime.SPINDLE_OVR_COARSE_PLUS,
    0x9B: Realtime.SPINDLE_OVR_COARSE_MINUS,
    0x9C: Realtime.SPINDLE_OVR_FINE_PLUS,
    0x9D: Realtime.SPINDLE_OVR_FINE_MINUS,
    0x9E: Realtime.SPINDLE_STOP,
    0xA0: Realtime.FLOOD_TOGGLE,
    0xA1: Realtime.MIST_TOGGLE,
}

#: grblHAL's extra aliases for `?`, `~` and `!` (facts §7); its other extras are discarded here.
GRBLHAL_EXTRA_REALTIME: dict[int, Realtime] = {
    0x80: Realtime.STATUS,
    0x81: Realtime.CYCLE_START,
    0x82: Realtime.FEED_HOLD,
}


def classify(byte: int, table: dict[int, Realtime]) -> Realtime | None:
    """The realtime meaning of one received byte, or None when it belongs to a line."""
    kind = table.get(byte)
    if kind is not None:
        return kind
    if byte >= 0x80:
        # Extended-ASCII bytes the firmware does not know are dropped by the ISR (facts §5.2).
        return Realtime.DISCARD
    return None


class RxRing:
    """A fixed-size byte ring; a byte arriving when it is full is lost."""

    def __init__(self, size: int) -> None:
        """An empty ring holding at most size bytes."""
        self.size = size
        self._bytes: deque[int] = deque()
        self.dropped = 0

    def push(self, byte: int) -> bool:
        """Store one byte; False (and the byte lost) when the ring is full."""
        if len(self._bytes) >= self.size:
            self.dropped += 1
            return False
        self._bytes.append(byte)
        return True

    def pop(self) -> int | None:
        """Take the oldest byte, or None when empty."""
        return self._bytes.popleft() if self._bytes else None

    def free(self) -> int:
        """Free bytes, as `Bf:`'s second value reports them (facts §4.4)."""
        return self.size - len(self._bytes)

    def __len__(self) -> int:
        """Bytes waiting."""
        return len(self._bytes)

    def has_line_end(self) -> bool:
        """Whether a complete line (ended by \\n or \\r) is waiting."""
        return 0x0A in self._bytes or 0x0D in self._bytes

    def clear(self) -> None:
        """Drop everything waiting (a soft reset, or grblHAL's 0x85)."""
        self._bytes.clear()
