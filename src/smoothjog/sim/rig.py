"""The virtual-time rig: a simulated controller behind a modelled serial wire, for tests/benches.

The wire serialises bytes one after another in each direction at the link's byte time (115200 8N1:
10 bits per byte, about 86.8 µs) and adds a one-way latency, optionally jittered by a seeded RNG.
Realtime bytes travel in the same byte stream; they only skip the RX line buffer at the far end.
Nothing reads a clock: the caller says what time it is, so two runs of a scenario are identical.

Beyond a plain serial line, a LinkModel can describe what sits between the host and the
controller's UART (a USB-serial adapter, a Wi-Fi bridge, or a network stack in the controller
itself): a transport with a latency and a jitter (uniform, or skewed as Wi-Fi's is), that keeps
order (TCP and USB never reorder), can stall (nothing moves either way, then the backlog arrives),
and can hold the controller's bytes back in packets (an FTDI adapter's latency timer). The UART
always sits at the controller's end: host-to-controller bytes cross the transport, then the UART;
controller-to-host bytes cross the UART, then the transport. LINK_MODELS names the links the
benchmark runs on. For fault injection a link can also lose or flip bytes at seeded rates, and
SimRig.inject_stall stalls any link at a given moment.
"""

from __future__ import annotations

import dataclasses
import math
import random
import re
from bisect import bisect_left, bisect_right, insort
from collections import deque
from dataclasses import dataclass, field
from typing import Literal

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

JitterShape = Literal["uniform", "skewed"]

#: The skewed jitter is jitter_s times a Beta(SKEW_ALPHA, SKEW_BETA) draw: bounded to
#: [0, jitter_s] like the stated RTT ranges, most draws near the low end, a long tail to the top
#: (as Wi-Fi latency is: mostly a few ms, now and then a retransmission or a busy channel).
#: Beta(1.3, 4) has its mode at 9 % of the range, median 21 %, 90th percentile 49 %, 99th 72 %.
SKEW_ALPHA = 1.3
SKEW_BETA = 4.0


@dataclass(frozen=True)
class LinkModel:
    """A serial-like wire: baud rate, bits per byte, latency and its jitter, stalls, batching."""

    baud: int = DEFAULT_BAUD
    #: 8N1: one start bit, eight data bits, one stop bit.
    bits_per_byte: int = BITS_PER_BYTE_8N1
    #: One-way latency added to every chunk (a USB-serial bridge adds ~1 ms; 0 for a direct line).
    latency_s: float = 0.0
    #: Each chunk's latency is latency_s plus a draw from [0, jitter_s) shaped by jitter_shape.
    jitter_s: float = 0.0
    seed: int = 0
    #: "uniform" over [0, jitter_s), or "skewed": jitter_s times a Beta(SKEW_ALPHA, SKEW_BETA).
    jitter_shape: JitterShape = "uniform"
    #: Controller-to-host packets of a USB adapter: the adapter keeps the bytes from the
    #: controller until its latency timer (this period; 0: no adapter buffer) expires or
    #: batch_bytes have come in, then sends them on as one packet. The timer restarts at every
    #: packet, a full one included; with nothing to send it still sends its status bytes, so
    #: while idle it simply runs with this period.
    batch_timer_s: float = 0.0
    #: Payload bytes of one adapter packet (an FTDI chip's 64-byte packet minus 2 status bytes).
    batch_bytes: int = 62
    #: Stalls of the transport (a Wi-Fi radio that goes deaf): each lasts stall_s, and the next
    #: starts a uniform draw from stall_gap_s after the start of the one before (the first one a
    #: uniform draw from 0 to the longest gap after time 0, so a scenario meets the schedule at
    #: any phase). Nothing moves either way during a stall; the transport time a chunk still had
    #: left when the stall began is spent after it, so the backlog arrives then.
    stall_s: float = 0.0
    stall_gap_s: tuple[float, float] = (2.5, 3.5)
    #: Line noise, for fault injection: the share of bytes each direction loses (a framing
    #: error: the byte took its wire time but never arrives) or gets with one bit flipped, drawn
    #: per byte from the direction's own seeded RNG. Grbl's protocol has no checksum, so a
    #: flipped bit can make another digit, another command, or a realtime byte.
    drop_to_controller: float = 0.0
    drop_to_host: float = 0.0
    corrupt_to_controller: float = 0.0
    corrupt_to_host: float = 0.0
    #: One line for tables and logs; not part of the model's identity.
    description: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        """Refuse values the wire cannot have."""
        if self.baud <= 0 or self.bits_per_byte <= 0:
            raise SimError(f"link baud ({self.baud}) and bits per byte must be positive")
        if self.latency_s < 0 or self.jitter_s < 0:
            raise SimError("link latency and jitter cannot be negative")
        if self.jitter_shape not in ("uniform", "skewed"):
            raise SimError(f"link jitter shape {self.jitter_shape!r} is not uniform or skewed")
        rates = (
            self.drop_to_controller,
            self.drop_to_host,
            self.corrupt_to_controller,
            self.corrupt_to_host,
        )
        if not all(0.0 <= r < 1.0 for r in rates):
            raise SimError(f"byte drop and corruption rates {rates} must be in [0, 1)")
        if self.batch_timer_s < 0 or self.batch_bytes <= 0:
            raise SimError("an adapter's latency timer cannot be negative nor its packet empty")
        lo, hi = self.stall_gap_s
        if self.stall_s < 0 or (self.stall_s > 0 and not self.stall_s < lo <= hi):
            raise SimError(
                f"link stalls of {self.stall_s} s every {lo}-{hi} s: a stall cannot be negative "
                "and must end before the next one starts"
            )

    @property
    def byte_time_s(self) -> float:
        """Time one byte occupies the wire."""
        return self.bits_per_byte / self.baud

    @property
    def plain(self) -> bool:
        """True for a fixed latency with no jitter, stalls or batching (the fast path)."""
        return self.jitter_s == 0.0 and self.stall_s == 0.0 and self.batch_timer_s == 0.0


def _link_models() -> dict[str, LinkModel]:
    """The named links of the benchmark and the fuzz."""
    one_way_telnet = (0.0025, 0.0225)  # RTT 5-50 ms: each way 2.5-25 ms
    one_way_bridge = (0.020, 0.040)  # RTT 40-120 ms: each way 20-60 ms
    wifi = LinkModel(
        baud=1_000_000,
        bits_per_byte=8,
        latency_s=one_way_telnet[0],
        jitter_s=one_way_telnet[1],
        jitter_shape="skewed",
        seed=3,
        description="ESP32 / FluidNC telnet over Wi-Fi: RTT 5-50 ms (skewed), in order, "
        "no loss; no UART (the controller's TCP output, taken as 1 Mbit/s)",
    )
    return {
        "ideal": LinkModel(description="115200 baud 8N1 straight into the controller, no latency"),
        "ch340": LinkModel(
            latency_s=0.001,
            jitter_s=0.001,
            seed=1,
            description="CH340 USB-serial at 115200: 1-2 ms each way (USB frames, uniform)",
        ),
        "ftdi": LinkModel(
            jitter_s=0.001,
            batch_timer_s=0.016,
            seed=2,
            description="FTDI USB-serial at 115200: replies held until its 16 ms latency timer "
            "expires or 62 bytes fill a packet; host-to-controller within one 1 ms USB frame",
        ),
        "wifi": wifi,
        "wifi-stalls": dataclasses.replace(
            wifi,
            stall_s=0.200,
            stall_gap_s=(2.5, 3.5),
            seed=4,
            description="the Wi-Fi telnet link with a 200 ms stall every 2.5-3.5 s: nothing "
            "moves either way, then the backlog arrives",
        ),
        "38400": LinkModel(baud=38_400, description="38400 baud 8N1 straight in, no latency"),
        "9600": LinkModel(baud=9_600, description="9600 baud 8N1 straight in, no latency"),
        "wifi-bridge": LinkModel(
            latency_s=one_way_bridge[0],
            jitter_s=one_way_bridge[1],
            jitter_shape="skewed",
            seed=5,
            description="Wi-Fi-to-serial bridge: RTT 40-120 ms (skewed), in order, then "
            "115200 baud 8N1 into the controller",
        ),
    }


#: Every named link model, seeded; the benchmark and the fuzz run on these by name.
LINK_MODELS: dict[str, LinkModel] = _link_models()


class _Stalls:
    """A link's stalls, the same for both directions: its schedule (drawn lazily) and any added."""

    def __init__(self, model: LinkModel) -> None:
        self.duration_s = model.stall_s
        self.gap_s = model.stall_gap_s
        # Its own RNG, so the schedule does not depend on the traffic.
        self.rng = random.Random(f"stalls:{model.seed}")
        #: (start, end) of every stall drawn or added so far, by start.
        self.spans: list[tuple[float, float]] = []
        self._longest_s = model.stall_s
        # The start of the last scheduled stall drawn (none are drawn for a link without any).
        self._drawn_to_s = -math.inf if model.stall_s > 0 else math.inf

    def _draw(self, t_s: float) -> None:
        """Draw the scheduled stalls that start by t_s."""
        while self._drawn_to_s <= t_s:
            if self._drawn_to_s == -math.inf:
                self._drawn_to_s = self.rng.uniform(0.0, self.gap_s[1])
            else:
                self._drawn_to_s += self.rng.uniform(*self.gap_s)
            insort(self.spans, (self._drawn_to_s, self._drawn_to_s + self.duration_s))

    def add(self, start_s: float, duration_s: float) -> None:
        """One more stall (an injected one); it may overlap the schedule's."""
        insort(self.spans, (start_s, start_s + duration_s))
        self._longest_s = max(self._longest_s, duration_s)

    def arrival_s(self, depart_s: float, transit_s: float) -> float:
        """When a chunk that leaves at depart_s and needs transit_s of moving time arrives."""
        t = depart_s
        left = transit_s
        spans = self.spans
        # The first stall that can still be running at depart_s.
        i = bisect_left(spans, (depart_s - self._longest_s, -math.inf))
        while True:
            self._draw(t + left)
            if i >= len(spans) or spans[i][0] >= t + left:
                return t + left
            s0, s1 = spans[i]
            if s1 > t:
                if t < s0:
                    left -= s0 - t
                t = s1
            i += 1


class _Batcher:
    """A USB adapter's receive buffer: bytes leave in packets when the timer expires or it fills."""

    def __init__(self, model: LinkModel, rng: random.Random) -> None:
        self.period_s = model.batch_timer_s
        self.size = model.batch_bytes
        # The timer's phase at power-up is unknown: a seeded draw. Expiry k is anchor + k x period.
        self._anchor_s = rng.uniform(0.0, self.period_s) - self.period_s
        self._k = 1
        self._times: list[float] = []  # when each byte not yet sent on reached the adapter
        self._base = 0  # how many bytes were sent on before _times[0]
        self._entered = 0  # the first _entered of _times are in the buffer
        self._lines: deque[tuple[int, bytes]] = deque()  # (absolute end index, chunk) not yet out

    def push(self, times: list[float], chunk: bytes) -> None:
        """A line's bytes reach the adapter at times (never before the bytes pushed earlier)."""
        self._times.extend(times)
        self._lines.append((self._base + len(self._times), chunk))

    def _expiry_s(self, k: int) -> float:
        """When the timer expires for the k-th time since it last restarted."""
        return self._anchor_s + k * self.period_s

    def _idle_periods(self, k: int, limit_s: float) -> int:
        """How many further expiries after the k-th fall by limit_s (with an empty buffer)."""
        n = max(math.floor((limit_s - self._expiry_s(k)) / self.period_s), 0)
        while n > 0 and self._expiry_s(k + n) > limit_s:
            n -= 1
        return n

    def run(self, until_s: float) -> list[tuple[float, list[bytes]]]:
        """The packets sent by until_s: their send times and the lines (as sent) they complete."""
        out: list[tuple[float, list[bytes]]] = []
        while True:
            expiry = self._expiry_s(self._k)
            nxt = self._times[self._entered] if self._entered < len(self._times) else None
            # On a tie the timer goes first: the byte waits for the next packet.
            if nxt is not None and nxt < expiry:
                if nxt > until_s:
                    break
                self._entered += 1
                if self._entered == self.size:
                    out.append((nxt, self._flush()))
                    self._anchor_s, self._k = nxt, 1
                continue
            if expiry > until_s:
                break
            if self._entered:
                out.append((expiry, self._flush()))
            else:
                # Nothing to send: skip the empty periods up to the next byte (or until_s).
                self._k += self._idle_periods(
                    self._k, until_s if nxt is None else min(nxt, until_s)
                )
            self._k += 1
        return out

    def next_packet_s(self) -> float | None:
        """When the next packet goes if no more bytes come (None: no line waits)."""
        if not self._lines:
            return None
        k = self._k
        i = self._entered
        while True:
            expiry = self._expiry_s(k)
            nxt = self._times[i] if i < len(self._times) else None
            if nxt is not None and nxt < expiry:
                i += 1
                if i == self.size:
                    return nxt
                continue
            if i > 0:
                return expiry
            # A line waits, so a byte does: the timer runs on empty until it has come in.
            assert nxt is not None
            k += self._idle_periods(k, nxt) + 1

    def _flush(self) -> list[bytes]:
        """Send the buffer on; the lines whose last byte went with it."""
        n = self._entered
        del self._times[:n]
        self._base += n
        self._entered = 0
        done = []
        while self._lines and self._lines[0][0] <= self._base:
            done.append(self._lines.popleft()[1])
        return done


class _ByteFaults:
    """Line noise on one direction: bytes lost or with one bit flipped, at seeded rates."""

    def __init__(self, drop: float, corrupt: float, rng: random.Random) -> None:
        self.drop = drop
        self.corrupt = corrupt
        self.rng = rng
        self.dropped = 0
        self.corrupted = 0

    @classmethod
    def of(cls, drop: float, corrupt: float, seed: int, direction: str) -> _ByteFaults | None:
        """The noise of one direction, with its own RNG; None for a clean one."""
        if not drop and not corrupt:
            return None
        return cls(drop, corrupt, random.Random(f"noise-{direction}:{seed}"))

    def apply(self, data: bytes, times: list[float] | None = None) -> tuple[bytes, list[float]]:
        """What is left of data (and of its arrival times, if given) after the noise."""
        out = bytearray()
        kept: list[float] = []
        rnd = self.rng.random
        for i, sent in enumerate(data):
            if rnd() < self.drop:
                self.dropped += 1
                continue
            got = sent
            if rnd() < self.corrupt:
                got ^= 1 << self.rng.randrange(8)
                self.corrupted += 1
            out.append(got)
            if times is not None:
                kept.append(times[i])
        return bytes(out), kept


class _Direction:
    """One direction of the wire: transport and UART in their order, never reordering."""

    def __init__(
        self,
        model: LinkModel,
        rng: random.Random,
        *,
        to_controller: bool,
        stalls: _Stalls | None = None,
    ) -> None:
        self.model = model
        self.rng = rng
        self.to_controller = to_controller
        self.stalls = stalls
        self.plain = model.plain
        self.free_s = 0.0  # when the UART can start the next byte
        self.last_arrival_s = 0.0  # the latest chunk out of the transport
        self.batcher = (
            _Batcher(model, rng) if model.batch_timer_s > 0 and not to_controller else None
        )

    def add_stalls(self, stalls: _Stalls) -> None:
        """From now on the transport can stall (an injected stall): leave the fast path."""
        self.stalls = stalls
        if self.plain:
            self.plain = False
            if self.to_controller:
                # The fast path keeps the UART's time at the host's end, before the latency.
                self.free_s += self.model.latency_s

    def _transit_s(self) -> float:
        """One chunk's time in the transport: latency plus its jitter draw."""
        m = self.model
        if m.jitter_s == 0.0:
            return m.latency_s
        if m.jitter_shape == "uniform":
            return m.latency_s + self.rng.uniform(0.0, m.jitter_s)
        return m.latency_s + m.jitter_s * self.rng.betavariate(SKEW_ALPHA, SKEW_BETA)

    def transport(self, depart_s: float) -> float:
        """When a chunk that enters the transport at depart_s leaves it (in order)."""
        transit = self._transit_s()
        if self.stalls is None:
            arrival = depart_s + transit
        else:
            arrival = self.stalls.arrival_s(depart_s, transit)
        # A chunk never overtakes the one before it, whatever the jitter drew (TCP, USB).
        arrival = max(arrival, self.last_arrival_s)
        self.last_arrival_s = arrival
        return arrival

    def uart(self, nbytes: int, start_s: float) -> list[float]:
        """When each of nbytes, offered to the UART at start_s, has its stop bit received."""
        byte_s = self.model.byte_time_s
        start = max(start_s, self.free_s)
        self.free_s = start + nbytes * byte_s
        return [start + (i + 1) * byte_s for i in range(nbytes)]

    def to_controller_s(self, nbytes: int, now_s: float) -> list[float]:
        """When each of nbytes the host writes at now_s reaches the controller, in order."""
        if self.plain:
            # Hot path (the ideal wire): a fixed latency before or after the UART is the same.
            latency = self.model.latency_s
            byte_s = self.model.byte_time_s
            start = max(now_s, self.free_s)
            self.free_s = start + nbytes * byte_s
            return [start + (i + 1) * byte_s + latency for i in range(nbytes)]
        # Through the transport as one chunk, then out of the far end's UART.
        return self.uart(nbytes, self.transport(now_s))

    def to_host_s(self, nbytes: int, sent_s: float) -> float:
        """When a line of nbytes the controller sends at sent_s is all at the host.

        Not for a link with an adapter buffer: its lines go through the batcher.
        """
        if self.plain:
            byte_s = self.model.byte_time_s
            start = max(sent_s, self.free_s)
            self.free_s = start + nbytes * byte_s
            return start + nbytes * byte_s + self.model.latency_s
        # Out of the controller's UART, then through the transport as one chunk.
        return self.transport(self.uart(nbytes, sent_s)[-1])


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
        # One RNG per direction (and the stalls their own), so what either direction draws does
        # not depend on how the other's traffic interleaves with it, nor on how the rig is run.
        stalls = _Stalls(self.link) if self.link.stall_s > 0 else None
        self._up = _Direction(
            self.link, random.Random(self.link.seed), to_controller=True, stalls=stalls
        )
        self._down = _Direction(
            self.link,
            random.Random(f"to-host:{self.link.seed}"),
            to_controller=False,
            stalls=stalls,
        )
        # Bytes on their way to the controller, oldest first, with their arrival times (which
        # never decrease); the first _to_fw_next of them have been handed over already.
        self._to_fw_times: list[float] = []
        self._to_fw_data = bytearray()
        self._to_fw_next = 0
        self._line_run = _line_run_pattern(self.firmware)
        self._to_host: deque[tuple[float, bytes]] = deque()
        self._stalls = stalls
        # Line noise (fault injection), each direction with its own RNG; None on a clean wire.
        m = self.link
        self._noise_up = _ByteFaults.of(m.drop_to_controller, m.corrupt_to_controller, m.seed, "up")
        self._noise_down = _ByteFaults.of(m.drop_to_host, m.corrupt_to_host, m.seed, "down")
        # With noise toward the host, lines are found again in what arrives, as a host does: a
        # lost `\n` joins two lines, a flipped bit can split one.
        self._host_partial = bytearray()
        self._now_s = self.firmware.now_s / clock_ratio
        self._collect()

    @property
    def noise_counts(self) -> tuple[int, int, int, int]:
        """Bytes dropped and corrupted so far: (to controller, to host) each."""
        up, down = self._noise_up, self._noise_down
        return (
            up.dropped if up else 0,
            down.dropped if down else 0,
            up.corrupted if up else 0,
            down.corrupted if down else 0,
        )

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
        """The host writes data at now_s; returns when its last byte reaches the controller.

        (As scheduled now: a stall injected later moves it, and noise may lose the byte.)
        """
        if now_s < self._now_s:
            raise SimError(f"host_send at {now_s} s is before the rig's time {self._now_s} s")
        times = self._up.to_controller_s(len(data), now_s)
        last_s = times[-1] if times else now_s
        if self._noise_up is not None:
            data, times = self._noise_up.apply(data, times)
        if self._to_fw_next > _COMPACT_BYTES and self._to_fw_next * 2 > len(self._to_fw_times):
            # Drop the bytes already handed over (amortised: a prefix at a time).
            del self._to_fw_times[: self._to_fw_next]
            del self._to_fw_data[: self._to_fw_next]
            self._to_fw_next = 0
        self._to_fw_times.extend(times)
        self._to_fw_data += data
        return last_s

    def inject_stall(self, duration_s: float, now_s: float) -> None:
        """The transport stalls for duration_s from now_s, both ways (fault injection).

        What is still on its way after now_s arrives duration_s later; what is sent during the
        stall waits for its end. The adapter of a batching link and the controller's UART keep
        their own timing; only the transport stops.
        """
        if now_s < self._now_s:
            raise SimError(f"a stall at {now_s} s is before the rig's time {self._now_s} s")
        if duration_s <= 0:
            return
        if self._stalls is None:
            self._stalls = _Stalls(dataclasses.replace(self.link, stall_s=0.0))
        self._stalls.add(now_s, duration_s)
        for direction in (self._up, self._down):
            direction.add_stalls(self._stalls)
            if direction.last_arrival_s > now_s:
                direction.last_arrival_s += duration_s
        if self._up.free_s > now_s:
            self._up.free_s += duration_s
        times = self._to_fw_times
        first = bisect_right(times, now_s, self._to_fw_next)
        for i in range(first, len(times)):
            times[i] += duration_s
        self._to_host = deque(
            (t + duration_s if t > now_s else t, line) for t, line in self._to_host
        )
        if self._to_host:
            self._down.last_arrival_s = max(self._down.last_arrival_s, self._to_host[-1][0])

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
        batcher = self._down.batcher
        if batcher is not None:
            packet_s = batcher.next_packet_s()
            if packet_s is not None:
                times.append(packet_s)
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
        if self._down.batcher is not None:
            self._send_packets(t_s)
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
        down = self._down
        batcher = down.batcher
        noise = self._noise_down
        for sent_s, data in self.firmware.take_output():
            # The firmware sends whole lines; the host has one once its last byte is in.
            if noise is None and batcher is None:
                arrival = down.to_host_s(len(data), sent_s / self.clock_ratio)
                self._to_host.append((arrival, data.rstrip(b"\r\n")))
                continue
            # A lost byte took its wire time all the same; the line's time is its last byte's.
            if batcher is None:
                arrival = down.to_host_s(len(data), sent_s / self.clock_ratio)
                assert noise is not None
                self._deliver(arrival, noise.apply(data)[0])
            else:
                times = down.uart(len(data), sent_s / self.clock_ratio)
                if noise is None:
                    batcher.push(times, data)
                else:
                    left, left_times = noise.apply(data, times)
                    batcher.push(left_times, left)

    def _deliver(self, arrival_s: float, chunk: bytes) -> None:
        """Bytes that reached the host at arrival_s: the complete lines among them, EOL stripped."""
        if self._noise_down is None:
            self._to_host.append((arrival_s, chunk.rstrip(b"\r\n")))
            return
        buf = self._host_partial
        buf += chunk
        while (end := buf.find(b"\n")) >= 0:
            self._to_host.append((arrival_s, bytes(buf[:end]).rstrip(b"\r")))
            del buf[: end + 1]

    def _send_packets(self, until_s: float) -> None:
        """Move the adapter's packets sent by until_s through the transport to the host.

        A packet sent by until_s is final: a byte that could still have filled it earlier would
        have reached the adapter by then, and the firmware has been run to until_s.
        """
        assert self._down.batcher is not None
        for sent_s, chunks in self._down.batcher.run(until_s):
            arrival = self._down.transport(sent_s)
            for chunk in chunks:
                self._deliver(arrival, chunk)
