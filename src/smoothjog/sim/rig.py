"""The virtual-time rig: a simulated controller behind a modelled serial wire, for tests/benches.

The wire serialises bytes one after another in each direction at the link's byte time (115200 8N1:
10 bits per byte, about 86.8 µs) and adds a one-way latency, optionally jittered by a seeded RNG.
Realtime bytes travel in the same byte stream; they only skip the RX line buffer at the far end.
Nothing reads a clock: the caller says what time it is, so two runs of a scenario are identical.
"""

from __future__ import annotations

import random
from collections import deque
from dataclasses import dataclass

from smoothjog.core.errors import SimError
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.motion import Motion, TraceSegment


@dataclass(frozen=True)
class LinkModel:
    """A serial-like wire: baud rate, bits per byte, latency and its jitter."""

    baud: int = 115200
    #: 8N1: one start bit, eight data bits, one stop bit.
    bits_per_byte: int = 10
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
        times = []
        for i in range(nbytes):
            # A byte arrives when its stop bit has been received, plus the latency; a byte
            # never overtakes the one before it, whatever the jitter drew.
            arrival = max(start + (i + 1) * byte_s + latency, self.last_arrival_s)
            self.last_arrival_s = arrival
            times.append(arrival)
        self.free_s = start + nbytes * byte_s
        return times


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
        roughly real time can be (facts §0 on grbl-sim). Times the rig takes and gives are
        the host's; the firmware and its trace keep their own.
        """
        if not 0.5 < clock_ratio < 2.0:
            raise SimError(f"clock ratio {clock_ratio} is not a plausible clock error")
        self.clock_ratio = clock_ratio
        self.firmware = firmware if firmware is not None else GrblFirmware()
        self.link = link if link is not None else LinkModel()
        rng = random.Random(self.link.seed)
        self._up = _Direction(self.link, rng)
        self._down = _Direction(self.link, rng)
        self._to_fw: deque[tuple[float, int]] = deque()
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
        self._to_fw.extend(zip(times, data, strict=True))
        return times[-1] if times else now_s

    def send_line(self, text: str, now_s: float) -> float:
        """Send text plus one `\\n`; returns the arrival time of the `\\n`."""
        return self.host_send(text.encode("ascii") + b"\n", now_s)

    def next_event_s(self) -> float | None:
        """The next time anything happens: a byte arrives, the firmware acts, a line lands."""
        times = []
        if self._to_fw:
            times.append(self._to_fw[0][0])
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
        while True:
            byte_t = self._to_fw[0][0] if self._to_fw else None
            fw_next = fw.next_event_s()
            fw_t = None if fw_next is None else fw_next / r  # in host time
            if byte_t is not None and byte_t <= t_s and (fw_t is None or byte_t <= fw_t):
                arrival, chunk = self._take_line_bytes(min(t_s, fw_t if fw_t is not None else t_s))
                fw.receive(chunk, max(arrival * r, fw.now_s))
            elif fw_next is not None and fw_t is not None and fw_t <= t_s:
                fw.advance(max(fw_next, fw.now_s))
            else:
                break
            self._collect()
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
        """
        arrival, byte = self._to_fw.popleft()
        run = bytearray((byte,))
        is_line = self.firmware.is_line_byte
        if not is_line(byte) or byte in (0x0A, 0x0D):
            return arrival, bytes(run)
        while self._to_fw:
            t, nxt = self._to_fw[0]
            if t > limit_s or not is_line(nxt):
                break
            self._to_fw.popleft()
            run.append(nxt)
            arrival = t
            if nxt in (0x0A, 0x0D):
                break
        return arrival, bytes(run)

    def _collect(self) -> None:
        """Put the firmware's new output on the wire back to the host."""
        for sent_s, data in self.firmware.take_output():
            # The firmware sends whole lines; the host has one once its last byte is in.
            times = self._down.send(len(data), sent_s / self.clock_ratio)
            self._to_host.append((times[-1], data.rstrip(b"\r\n")))
