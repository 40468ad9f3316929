"""The virtual-time rig: a simulated controller behind a modelled serial wire, for tests/benches.

The wire serialises bytes one after another in each direction at the link's byte time (115200 8N1:
10 bits per byte, about 86.8 µs) and adds a one-way latency, optionally jittered by a seeded RNG.
Realtime bytes travel in the same byte stream; they only skip the RX line buffer at the far end.
Nothing reads a clock: the caller says what time it is, so two runs of a scenario are identical.
"""

from __future__ import annotations

import random
import re
from bisect import bisect_right
from collections import deque
from dataclasses import dataclass

from smoothjog.core.errors import SimError
from smoothjog.core.firmware import BITS_PER_BYTE_8N1, DEFAULT_BAUD
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.motion import Motion, TraceSegment

# Speed: the comments marked "hot path" here and in firmware.py / motion.py are optimisations that
# keep every result bit for bit (ground-truth traces and the bytes on the wire were compared
# before and after). Measured on `python -m bench sim` (the 60 s jog stream): under callgrind,
# which machine load does not disturb, 1768 M instructions before them and 1325 M after
# (x1.33) for sim/ as a whole; CPU time about 200 ms -> 175 ms; the bench's wall-clock figure,
# runs interleaved with the old code on the 2-core development machine, 169-187x -> 195-314x
# under heavy load (load average 3) and about 300x -> 340x under light load.


@dataclass(frozen=True)
class LinkModel:
    """A serial-like wire: baud rate, bits per byte, latency and its jitter."""

    baud: int = DEFAULT_BAUD
    #: 8N1: one start bit, eight data bits, one stop bit.
    bits_per_byte: int = BITS_PER_BYTE_8N1
    #: One-way latency added to every byte (a USB-serial bridge adds ~1 ms; 0 for a direct line).
    latency_s: float = 0.0
    #: Each chunk's latency is latency_s plus a uniform draw from [0, jitter_s).
    jitter_s: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        """Refuse values the wire cannot have."""
        if self.baud <= 0 or self.bits_per_byte <= 0:
            raise SimError(f"link baud ({self.baud}) and bits per byte must be positive")
        if self.latency_s < 0 or self.jitter_s < 0:
            raise SimError("link latency and jitter cannot be negative")

    @property
    def byte_time_s(self) -> float:
        """Time one byte occupies the wire."""
        return self.bits_per_byte / self.baud


class _Direction:
    """One direction of the wire: serialisation plus (jittered) latency, never reordering."""

    def __init__(self, model: LinkModel, rng: random.Random) -> None:
        self.model = model
        self.rng = rng
        self.free_s = 0.0  # when the transmitter can start the next byte
        self.last_arrival_s = 0.0

    def send(self, nbytes: int, now_s: float) -> list[float]:
        """Arrival times of nbytes sent at now_s, in order."""
        latency = self.model.latency_s
        if self.model.jitter_s > 0.0:
            latency += self.rng.uniform(0.0, self.model.jitter_s)
        byte_s = self.model.byte_time_s
        start = max(now_s, self.free_s)
        # A byte arrives when its stop bit has been received, plus the latency.
        times = [start + (i + 1) * byte_s + latency for i in range(nbytes)]
        # A byte never overtakes the one before it, whatever the jitter drew. The times above
        # never decrease, so that is max(time, last arrival before this call) for every byte,
        # which only changes anything when the first byte would overtake (hot path: one list
        # comprehension instead of a loop with max per byte; see the speed note at the top).
        floor = self.last_arrival_s
        if times and floor > times[0]:
            times = [floor if floor > t else t for t in times]
        if times:
            self.last_arrival_s = times[-1]
        self.free_s = start + nbytes * byte_s
        return times


#: Handed-over bytes are dropped from the rig's input queue once there are more than this many.
_COMPACT_BYTES = 4096


def _line_run_pattern(firmware: GrblFirmware) -> re.Pattern[bytes]:
    """A run that may go to the controller as one chunk: plain line bytes, then one line end.

    The byte classes come from firmware.is_line_byte, which its profile fixes for its lifetime.
    """
    line_bytes = [b for b in range(256) if firmware.is_line_byte(b)]
    plain = b"".join(re.escape(bytes((b,))) for b in line_bytes if b not in (0x0A, 0x0D))
    ends = b"".join(re.escape(bytes((b,))) for b in line_bytes if b in (0x0A, 0x0D))
    pattern = b"[" + plain + b"]+" if plain else b"(?!)"
    if ends:
        pattern += b"[" + ends + b"]?"
    return re.compile(pattern)


class SimRig:
    """A GrblFirmware behind a LinkModel, driven in virtual time."""

    def __init__(
        self,
        firmware: GrblFirmware | None = None,
        link: LinkModel | None = None,
        *,
        clock_ratio: float = 1.0,
    ) -> None:
        """Wire a firmware (default: Grbl 1.1h with default settings) to a link model.

        clock_ratio is how fast the controller's clock runs against the host's: 1.0 for the
        same clock; 1.003 for a controller 0.3 % fast, as a simulator whose clock is only
        roughly real time can be (firmware-facts §0 on grbl-sim). Times the rig takes and gives are
        the host's; the firmware and its trace keep their own.
        """
        if not 0.5 < clock_ratio < 2.0:
            raise SimError(f"clock ratio {clock_ratio} is not a plausible clock error")
        self.clock_ratio = clock_ratio
        self.firmware = firmware if firmware is not None else GrblFirmware()
        self.link = link if link is not None else LinkModel()
        # The controller's UART runs at the wire's rate (in the controller's own clock).
        self.firmware.tx_byte_s = self.link.byte_time_s * clock_ratio
        rng = random.Random(self.link.seed)
        self._up = _Direction(self.link, rng)
        self._down = _Direction(self.link, rng)
        # Bytes on their way to the controller, oldest first, with their arrival times (which
        # never decrease); the first _to_fw_next of them have been handed over already.
        self._to_fw_times: list[float] = []
        self._to_fw_data = bytearray()
        self._to_fw_next = 0
        self._line_run = _line_run_pattern(self.firmware)
        self._to_host: deque[tuple[float, bytes]] = deque()
        self._now_s = self.firmware.now_s / clock_ratio
        self._collect()

    @property
    def now_s(self) -> float:
        """The time the rig has been run to."""
        return self._now_s

    @property
    def motion(self) -> Motion:
        """The firmware's motion model (ground truth)."""
        return self.firmware.motion

    @property
    def trace(self) -> list[TraceSegment]:
        """Ground-truth segments: true position over (host) time."""
        r = self.clock_ratio
        if r == 1.0:
            return self.firmware.trace
        return [
            TraceSegment(seg.t0_s / r, seg.t1_s / r, seg.start_mm, seg.end_mm)
            for seg in self.firmware.trace
        ]

    def host_send(self, data: bytes, now_s: float) -> float:
        """The host writes data at now_s; returns when its last byte reaches the controller."""
        if now_s < self._now_s:
            raise SimError(f"host_send at {now_s} s is before the rig's time {self._now_s} s")
        times = self._up.send(len(data), now_s)
        if self._to_fw_next > _COMPACT_BYTES and self._to_fw_next * 2 > len(self._to_fw_times):
            # Drop the bytes already handed over (amortised: a prefix at a time).
            del self._to_fw_times[: self._to_fw_next]
            del self._to_fw_data[: self._to_fw_next]
            self._to_fw_next = 0
        self._to_fw_times.extend(times)
        self._to_fw_data += data
        return times[-1] if times else now_s

    def send_line(self, text: str, now_s: float) -> float:
        """Send text plus one `\\n`; returns the arrival time of the `\\n`."""
        return self.host_send(text.encode("ascii") + b"\n", now_s)

    def next_event_s(self) -> float | None:
        """The next time anything happens: a byte arrives, the firmware acts, a line lands."""
        times = []
        if self._to_fw_next < len(self._to_fw_times):
            times.append(self._to_fw_times[self._to_fw_next])
        fw_t = self.firmware.next_event_s()
        if fw_t is not None:
            times.append(fw_t / self.clock_ratio)
        if self._to_host:
            times.append(self._to_host[0][0])
        return min(times) if times else None

    def run_until(self, t_s: float) -> list[tuple[float, bytes]]:
        """Run to t_s; the complete lines that reached the host by then, EOL stripped."""
        fw = self.firmware
        r = self.clock_ratio
        to_fw_times = self._to_fw_times
        # The firmware's output is put on the wire once, at the end: the wire back to the host
        # takes the lines in the same order with the same send times (and nothing else draws
        # from the jitter RNG meanwhile), so the arrival times are those of collecting after
        # every event (hot path: one collection per call; see the speed note at the top).
        while True:
            # The next byte due by t_s, if any: the firmware's events before it run first (on a
            # tie the byte goes first), then the byte; with none, every event up to t_s runs.
            byte_t = None
            if self._to_fw_next < len(to_fw_times):
                byte_t = to_fw_times[self._to_fw_next]
                if byte_t > t_s:
                    byte_t = None
            fw_next = fw.run_events(t_s, byte_t, r)
            if byte_t is None:
                break
            fw_t = None if fw_next is None else fw_next / r  # in host time
            arrival, chunk = self._take_line_bytes(min(t_s, fw_t if fw_t is not None else t_s))
            fw.receive(chunk, max(arrival * r, fw.now_s))
        fw.advance(max(t_s * r, fw.now_s))
        self._collect()
        self._now_s = max(self._now_s, t_s)
        delivered = []
        while self._to_host and self._to_host[0][0] <= t_s:
            delivered.append(self._to_host.popleft())
        return delivered

    def run_for(self, dt_s: float) -> list[tuple[float, bytes]]:
        """Run dt_s further."""
        return self.run_until(self._now_s + dt_s)

    def _take_line_bytes(self, limit_s: float) -> tuple[float, bytes]:
        """The next byte, or a run of plain line bytes that all arrive by limit_s.

        Speed-up (the rig must run >= 200x real time): the bytes of a line are handed over
        together at the arrival of the last one taken, and a run stops at the first realtime
        byte and after a line end, so realtime bytes and complete lines act at their exact
        times. Only RX-free counts reported while a line is still arriving can be a little high.

        Hot path (every byte; with firmware.receive's run fast path, 1418 M -> 1325 M
        instructions in bench sim): the run is found by a regular expression
        (plain line bytes, then at most one line end) and cut at the first byte arriving after
        limit_s by bisection, which the arrival times (never decreasing) allow.
        """
        first = self._to_fw_next
        match = self._line_run.match(self._to_fw_data, first)
        end = match.end() if match is not None else first
        if end <= first + 1:
            # A realtime or discarded byte, a line end, or a lone line byte: it goes by itself.
            end = first + 1
        else:
            end = bisect_right(self._to_fw_times, limit_s, first + 1, end)
        self._to_fw_next = end
        return self._to_fw_times[end - 1], bytes(self._to_fw_data[first:end])

    def _collect(self) -> None:
        """Put the firmware's new output on the wire back to the host."""
        for sent_s, data in self.firmware.take_output():
            # The firmware sends whole lines; the host has one once its last byte is in.
            times = self._down.send(len(data), sent_s / self.clock_ratio)
            self._to_host.append((times[-1], data.rstrip(b"\r\n")))
