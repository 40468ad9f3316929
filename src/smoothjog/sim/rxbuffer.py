"""The controller's serial receive side: the RX ring and the picking of realtime bytes.

Realtime bytes are taken out of the stream at arrival time, wherever they appear, and never reach
the ring (firmware-facts §1.1, §5.2); every other byte goes to a fixed-size ring that drops bytes
when full, as the chip's ISR does (firmware-facts §5.1).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping

from smoothjog.core.realtime import EXTENDED_START, Realtime


def classify(byte: int, table: Mapping[int, Realtime]) -> Realtime | None:
    """The realtime meaning of one received byte, or None when it belongs to a line."""
    kind = table.get(byte)
    if kind is not None:
        return kind
    if byte >= EXTENDED_START:
        # Extended-ASCII bytes the firmware does not know are dropped by the ISR (firmware-facts
        # §5.2).
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
        """Free bytes, as `Bf:`'s second value reports them (firmware-facts §4.4)."""
        return self.size - len(self._bytes)

    def __len__(self) -> int:
        """Bytes waiting."""
        return len(self._bytes)

    def has_line_end(self) -> bool:
        """Whether a complete line (ended by \\n or \\r) is waiting."""
        return 0x0A in self._bytes or 0x0D in self._bytes

    def line_ends(self) -> int:
        """How many line ends (\\n or \\r) are waiting."""
        return sum(1 for byte in self._bytes if byte in (0x0A, 0x0D))

    def clear(self) -> None:
        """Drop everything waiting (a soft reset, or grblHAL's 0x85)."""
        self._bytes.clear()
