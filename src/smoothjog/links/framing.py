"""Turn the byte stream a controller sends into lines, whatever the read boundaries.

Grbl ends every line it sends with `\\r\\n` (firmware-facts §5.3); some firmware and terminals send
a bare `\\n` or a bare `\\r`. All three end a line, and `\\r\\n` counts as one end, even when the
`\\r` and the `\\n` arrive in different reads. A line that never ends (noise from a wrong baud rate,
a peer that is not a controller) is cut at `max_line_bytes` so memory stays bounded.
"""

from __future__ import annotations

import re

#: Longest line kept whole; Grbl's longest reply (`$$` lines, `[GC:...]`) is under 100 bytes and
#: grblHAL/FluidNC stay well under 1 KiB, so anything longer is noise or a runaway peer.
DEFAULT_MAX_LINE_BYTES = 1024

_EOL = re.compile(rb"\r\n|\r|\n")


class LineFramer:
    """A push parser: feed it bytes, get back the complete lines without their end-of-line."""

    def __init__(self, max_line_bytes: int = DEFAULT_MAX_LINE_BYTES) -> None:
        """Create a framer that cuts lines longer than max_line_bytes."""
        if max_line_bytes < 1:
            raise ValueError(f"max_line_bytes must be at least 1, not {max_line_bytes}")
        self.max_line_bytes = max_line_bytes
        self._partial = bytearray()
        # A `\r` ended the previous read: a `\n` opening the next read belongs to that same EOL.
        self._skip_lf = False
        # The current line already overflowed and was emitted; drop bytes until its EOL.
        self._discarding = False
        self.overflowed_lines = 0

    @property
    def pending_bytes(self) -> int:
        """Bytes of an unfinished line held back until its end arrives."""
        return len(self._partial)

    def feed(self, data: bytes) -> list[bytes]:
        """Take the next bytes of the stream; return every line they complete, in order."""
        if (
            data.endswith(b"\r\n")
            and not self._partial
            and not self._skip_lf
            and not self._discarding
        ):
            # The usual read: whole lines in Grbl's own `\r\n`, nothing held over from before.
            lines = data[:-2].split(b"\r\n")
            if all(
                b"\r" not in line and b"\n" not in line and len(line) <= self.max_line_bytes
                for line in lines
            ):
                return lines
        lines = []
        start = 0
        if self._skip_lf and data:
            if data[:1] == b"\n":
                start = 1
            self._skip_lf = False
        for match in _EOL.finditer(data, start):
            self._append(data[start : match.start()], lines)
            if self._discarding:
                self._discarding = False
            else:
                lines.append(bytes(self._partial))
            self._partial.clear()
            start = match.end()
        if start < len(data):
            self._append(data[start:], lines)
        elif data and data[-1:] == b"\r":
            self._skip_lf = True
        return lines

    def clear(self) -> None:
        """Forget any unfinished line (after a reconnect or a controller reset)."""
        self._partial.clear()
        self._skip_lf = False
        self._discarding = False

    def _append(self, chunk: bytes, lines: list[bytes]) -> None:
        """Add bytes of the current line, emitting it cut short if it grows past the cap."""
        if self._discarding or not chunk:
            return
        self._partial += chunk
        if len(self._partial) > self.max_line_bytes:
            lines.append(bytes(self._partial[: self.max_line_bytes]))
            self._partial.clear()
            self._discarding = True
            self.overflowed_lines += 1
