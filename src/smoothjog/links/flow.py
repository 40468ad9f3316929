"""Character-counting flow control: never more unanswered bytes than the controller's RX buffer.

Grbl answers every line with one `ok` or `error:N`, in order, and drops bytes that arrive when its
RX ring is full (facts §5.1). The host therefore counts the bytes of every unanswered line, each
with its single `\\n`, keeps the total within the RX size (128 on Grbl 1.1h, more on grblHAL and
FluidNC: read it from `$I`), and releases the oldest line on each reply.
"""

from __future__ import annotations

import collections

from smoothjog.core.errors import LinkError

#: Grbl 1.1h's usable RX ring (`[OPT:V,15,128]`, facts §5.1).
GRBL_RX_BUFFER_BYTES = 128


class FlowError(LinkError):
    """The character count and the controller's replies disagree."""


class UnexpectedAckError(FlowError):
    """An ok or error arrived while no line was waiting for one: a protocol fault."""


class OverfillError(FlowError):
    """A line was counted as sent although it did not fit in the controller's RX buffer."""


def line_cost_bytes(line: str) -> int:
    """RX-buffer bytes a line takes: its ASCII bytes plus the one `\\n` the link appends."""
    return len(line.encode("ascii", errors="replace")) + 1


class CharCounter:
    """Bytes of sent-but-unanswered lines, and the lines themselves, oldest first."""

    def __init__(self, capacity_bytes: int = GRBL_RX_BUFFER_BYTES) -> None:
        """Create an empty counter for a controller whose RX buffer holds capacity_bytes."""
        if capacity_bytes < 2:
            raise FlowError(
                f"an RX buffer of {capacity_bytes} bytes cannot hold any line:"
                " the controller reported an impossible size"
            )
        self.capacity_bytes = capacity_bytes
        self._outstanding: collections.deque[str] = collections.deque()
        self._in_flight_bytes = 0

    @property
    def in_flight_bytes(self) -> int:
        """Bytes sent and not yet answered."""
        return self._in_flight_bytes

    @property
    def free_bytes(self) -> int:
        """Bytes that may still be sent before a reply is needed."""
        return self.capacity_bytes - self._in_flight_bytes

    @property
    def outstanding(self) -> tuple[str, ...]:
        """The unanswered lines, oldest first."""
        return tuple(self._outstanding)

    def fits(self, line: str) -> bool:
        """True when line can be sent now without overrunning the RX buffer."""
        return line_cost_bytes(line) <= self.free_bytes

    def sent(self, line: str) -> None:
        """Count line as sent; raises OverfillError if it did not fit (nothing is counted)."""
        cost = line_cost_bytes(line)
        if cost > self.free_bytes:
            raise OverfillError(
                f"line {line!r} needs {cost} bytes but only {self.free_bytes} of the"
                f" controller's {self.capacity_bytes}-byte RX buffer are free:"
                " check fits() before sending"
            )
        self._outstanding.append(line)
        self._in_flight_bytes += cost

    def acknowledged(self) -> str:
        """Release the oldest unanswered line on an ok or error, and return it."""
        if not self._outstanding:
            raise UnexpectedAckError(
                "the controller answered (ok/error) although no line was waiting for an"
                " answer: another program may be sending on the same port, or lines were"
                " sent around the flow control; reset the controller and reconnect"
            )
        line = self._outstanding.popleft()
        self._in_flight_bytes -= line_cost_bytes(line)
        return line

    def clear(self) -> None:
        """Forget every unanswered line (after a controller reset empties its RX buffer)."""
        self._outstanding.clear()
        self._in_flight_bytes = 0
