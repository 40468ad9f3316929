"""The four reference jog methods, each built from its published description, plus smoothjog.

Every method keeps the engine contract of `smoothjog.host.JogEngine` (set_intent, on_reply,
on_response, poll, next_deadline_s, busy), so the one host drives them all, on the same simulator
and through the same line ledger, exactly as it drives smoothjog's own engine. The reference
methods are written as their authors describe them, flaws included; none of them is smoothjog.

- PendantPost150: the pendant post's smooth multi-axis jogging: a `$J=G91` increment worth 150 ms
  of travel every 150 ms (the second one after 100 ms), axis speeds split by the ratio diagonal,
  F = the largest ratio times the speed; no jog cancel: on release it simply stops sending. Its
  timer fires 0.6 ms late each time, as a real-time sender's does (see the class).
- WikiJog(corrected=False): Grbl's jogging doc: one short G91 jog at a time, the next sent on each
  `ok`, `dt = v²/(2a(N−1))` exactly as printed (v in mm/s, a the smallest axis acceleration, at
  least 10 ms), and 0x85 as soon as the stick returns to neutral.
- WikiJog(corrected=True): the same with the dimensionally correct `dt = v/(2a(N−1))`.
- LongJog: one jog to the edge of the travel, cancelled with 0x85 on release (what many senders do).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from smoothjog.core.engine import EngineLimits, JogTuning, Output, SendLine, SendRealtime
from smoothjog.core.intents import ContinuousIntent, Intent
from smoothjog.core.jogline import build_jog_line
from smoothjog.core.ledger import ENGINE, Entry, Ledger
from smoothjog.core.machine import MachineModel
from smoothjog.core.realtime import JOG_CANCEL, STATUS_QUERY
from smoothjog.core.responses import ErrorReply, Ok, Response
from smoothjog.core.units import mm_min_to_mm_s
from smoothjog.host import EngineFactory

#: Status polling of the reference senders (Grbl's docs: no more than 5 Hz).
STATUS_INTERVAL_S = 0.2


class _Host:
    """Shared plumbing: the machine model, the ledger's room check, and the held stick."""

    #: The host's own send cycle, used to place releases at several phases of it.
    cycle_s = 0.010
    name = "host"

    def __init__(self, model: MachineModel, ledger: Ledger) -> None:
        self.model = model
        self.ledger = ledger
        self.limits = EngineLimits.from_model(model)
        self.max_feed_mm_min = max(self.limits.max_rate_mm_min)
        self.stick: ContinuousIntent | None = None
        self.outbox: list[Output] = []
        self._last_status_s = -1.0
        self._now_s = 0.0

    # JogEngine ---------------------------------------------------------------------------
    def set_intent(self, intent: Intent, now_s: float) -> None:
        """Take the stick; reference methods know only continuous jogging."""
        if isinstance(intent, ContinuousIntent) and not intent.is_neutral():
            self.press(intent, now_s)
        else:
            self.release(now_s)

    def on_reply(self, entry: Entry, resp: Ok | ErrorReply, now_s: float) -> bool:
        """One of this method's lines was answered; poll the method at once."""
        self.on_line_reply(entry.text, resp, now_s)
        return True

    def on_response(self, resp: Response, now_s: float) -> bool:
        """Other lines: the host has folded them into the model already; poll at once."""
        return True

    def poll(self, now_s: float) -> list[Output]:
        """Give the method a chance to act, then hand over what it queued."""
        self._now_s = now_s
        if now_s - self._last_status_s >= STATUS_INTERVAL_S:
            # Every sender polls the position; 5 Hz is what Grbl's interface doc recommends.
            self._last_status_s = now_s
            self.realtime(STATUS_QUERY)
        self.tick(now_s)
        out, self.outbox = self.outbox, []
        return out

    def next_deadline_s(self, now_s: float) -> float:
        """Hosts tick every 5 ms."""
        return now_s + 0.005

    def busy(self) -> bool:
        """True while the stick is held or lines await an answer."""
        return self.stick is not None or self.ledger.waiting(ENGINE) > 0

    def reset_outputs(self) -> list[Output]:
        """A reset: the reference methods send nothing of their own."""
        return []

    def restart_outputs(self, now_s: float) -> list[Output]:
        """A reset: the reference methods watch for nothing before the settings are read."""
        return []

    def restart_settled(self) -> bool:
        """A reset: the reference methods read the settings again at once."""
        return True

    def restart_wire_clear(self, now_s: float) -> None:
        """A reset: the reference methods count nothing from the wire."""

    def reset_machine(self, limits: EngineLimits) -> None:
        """A reset: the reference methods simply carry on with the new limits."""
        self.limits = limits

    # for the methods ---------------------------------------------------------------------
    def press(self, intent: ContinuousIntent, now_s: float) -> None:
        """The stick left neutral or changed."""
        self.stick = intent

    def release(self, now_s: float) -> None:
        """The stick returned to neutral."""
        self.stick = None

    def tick(self, now_s: float) -> None:
        """Periodic work."""

    def on_line_reply(self, line: str, resp: Ok | ErrorReply, now_s: float) -> None:
        """A line was answered."""

    def send(self, line: str) -> bool:
        """Queue a line if the RX buffer has room for it (character counting, by the ledger)."""
        if not self.ledger.fits(line):
            return False
        self.ledger.record_line(ENGINE, line, self._now_s)
        self.outbox.append(SendLine(line))
        return True

    def realtime(self, byte: bytes) -> None:
        """Queue a realtime byte."""
        self.outbox.append(SendRealtime(byte))

    def axis_speeds_mm_min(self, intent: ContinuousIntent) -> dict[str, float]:
        """Per-axis speeds the stick asks for (deflection times the speed setting)."""
        base = self.max_feed_mm_min * intent.speed
        return {a: v * base for a, v in intent.axes.items() if v != 0.0}

    def vector_speed_mm_s(self, intent: ContinuousIntent) -> tuple[float, float]:
        """The requested vector speed (mm/s) and the smallest acceleration of the moving axes."""
        speeds = self.axis_speeds_mm_min(intent)
        v = mm_min_to_mm_s(math.sqrt(sum(s * s for s in speeds.values())))
        accel = min(self.limits.accel_mm_s2[self.limits.axes.index(a)] for a in speeds)
        return v, accel


class PendantPost150(_Host):
    """The pendant post: 150 ms of travel every 150 ms, no jog cancel.

    The post paces its lines by a timer, and the real-firmware figures were measured with a
    sender running in real time, where a timer never fires on time. This host's timer fires
    TIMER_LATE_S after it is due and is re-armed from when it fired (as a chain of
    `setTimeout` calls or `sleep` loops does), so the sender drifts behind the controller's
    clock by that much per line. The drift is what makes this method dip on the real firmware
    (S2): the post queues only 50 ms more than holding speed needs, which is about what Grbl
    commits ahead in step segments, so a few milliseconds of accumulated lateness are enough.
    """

    name = "fixed 150 ms, no cancel"
    cycle_s = 0.150
    interval_s = 0.150
    first_interval_s = 0.100
    #: How late the sender's timer fires, every time (see the class note and bench/README).
    timer_late_s = 0.0006

    def __init__(self, model: MachineModel, ledger: Ledger) -> None:
        super().__init__(model, ledger)
        self.fire_s: float | None = None
        self.sent_count = 0

    def press(self, intent: ContinuousIntent, now_s: float) -> None:
        first = self.stick is None
        self.stick = intent
        if first:
            # The first line goes out with the press itself, not on the timer.
            self.sent_count = 0
            self.fire_s = now_s

    def release(self, now_s: float) -> None:
        self.stick = None
        self.fire_s = None

    def next_deadline_s(self, now_s: float) -> float:
        """Wake exactly when the timer fires (and at least every 5 ms for status polls)."""
        if self.fire_s is not None and self.fire_s > now_s:
            return min(now_s + 0.005, self.fire_s)
        return now_s + 0.005

    def tick(self, now_s: float) -> None:
        if self.stick is None or self.fire_s is None or now_s < self.fire_s:
            return
        intent = self.stick
        # The post's math: speeds split over the ratio diagonal D, F = the largest ratio x speed.
        ratios = {a: abs(v) for a, v in intent.axes.items() if v != 0.0}
        diag = math.sqrt(sum(r * r for r in ratios.values()))
        speed_mm_min = self.max_feed_mm_min * intent.speed
        moves = {
            a: speed_mm_min * math.copysign(1.0, intent.axes[a]) * r / diag * self.interval_s / 60
            for a, r in ratios.items()
        }
        feed = max(ratios.values()) * speed_mm_min
        line = build_jog_line(moves=moves, feed_mm_min=round(feed, 3), axes=self.limits.axes)
        self.send(line)
        self.sent_count += 1
        step = self.first_interval_s if self.sent_count == 1 else self.interval_s
        self.fire_s = now_s + step + self.timer_late_s


class WikiJog(_Host):
    """Grbl's jogging doc: one jog in flight, next on ok, 0x85 on release."""

    def __init__(self, model: MachineModel, ledger: Ledger, *, corrected: bool) -> None:
        super().__init__(model, ledger)
        self.corrected = corrected
        self.name = "wiki, dt corrected" if corrected else "wiki, dt as printed"
        self.in_flight = False
        self.cycle_s = 0.010

    def dt_s(self, intent: ContinuousIntent) -> float:
        """The doc's dt: the printed form or the corrected one, never under 10 ms."""
        v, a = self.vector_speed_mm_s(intent)
        n = self.limits.planner_blocks
        dt = v / (2 * a * (n - 1)) if self.corrected else v * v / (2 * a * (n - 1))
        return max(dt, 0.010)

    def press(self, intent: ContinuousIntent, now_s: float) -> None:
        self.stick = intent
        self.cycle_s = self.dt_s(intent)

    def release(self, now_s: float) -> None:
        if self.stick is not None:
            self.realtime(JOG_CANCEL)  # "stop the jog loop and simply send a jog cancel"
        self.stick = None

    def tick(self, now_s: float) -> None:
        if self.stick is None or self.in_flight:
            return
        intent = self.stick
        dt = self.dt_s(intent)
        speeds = self.axis_speeds_mm_min(intent)
        feed = math.sqrt(sum(s * s for s in speeds.values()))
        moves = {a: s / 60 * dt for a, s in speeds.items()}
        line = build_jog_line(moves=moves, feed_mm_min=round(feed, 3), axes=self.limits.axes)
        if self.send(line):
            self.in_flight = True

    def on_line_reply(self, line: str, resp: Ok | ErrorReply, now_s: float) -> None:
        self.in_flight = False


class LongJog(_Host):
    """One jog to the edge of travel, cancelled with 0x85 on release or change."""

    name = "one long jog + 0x85"
    cycle_s = 0.010

    def __init__(self, model: MachineModel, ledger: Ledger) -> None:
        super().__init__(model, ledger)
        self.active = False
        self.want: ContinuousIntent | None = None

    def press(self, intent: ContinuousIntent, now_s: float) -> None:
        if self.active:
            self.realtime(JOG_CANCEL)
        self.stick = intent
        self.want = intent

    def release(self, now_s: float) -> None:
        if self.active:
            self.realtime(JOG_CANCEL)
            self.active = False
        self.stick = None
        self.want = None

    def tick(self, now_s: float) -> None:
        intent = self.want
        if intent is None or self.model.mpos_mm is None:
            return
        self.want = None
        speeds = self.axis_speeds_mm_min(intent)
        feed = math.sqrt(sum(s * s for s in speeds.values()))
        pos = self.model.mpos_mm
        # Distance to the edge of travel along the direction: the soft-limit box, or without
        # soft limits the homed machine space -$13x..0 (firmware-facts §2), as senders compute it.
        travel = self.model.settings.for_axes(len(self.limits.axes)).max_travel_mm
        env = self.limits.envelope
        lo = env.min_mm if env is not None else tuple(-t for t in travel)
        hi = env.max_mm if env is not None else (0.0,) * len(travel)
        reach = math.inf
        for a, s in speeds.items():
            i = self.limits.axes.index(a)
            room = (hi[i] - pos[i]) if s > 0 else (pos[i] - lo[i])
            reach = min(reach, max(room - 0.01, 0.0) * feed / abs(s))
        moves = {a: s / feed * reach for a, s in speeds.items()}
        if reach > 0.01 and self.send(
            build_jog_line(moves=moves, feed_mm_min=round(feed, 3), axes=self.limits.axes)
        ):
            self.active = True


@dataclass(frozen=True)
class Shipped:
    """smoothjog's own engine, built by the host itself as the product builds it.

    Not a factory: the host fills in what it learns from the link (its byte time, a relay's idle
    poll) before it makes the engine, which a factory would bypass. At 9600 baud an engine built
    by a factory took 115200 baud's byte time and sized its polls and blocks for that wire.
    """

    tuning: JogTuning | None = None


#: What a scenario runs: a reference host's engine factory, or smoothjog as shipped.
Method = EngineFactory | Shipped


REFERENCE_FACTORIES: dict[str, EngineFactory] = {
    "fixed 150 ms, no cancel": PendantPost150,
    "wiki, dt as printed": lambda m, ledger: WikiJog(m, ledger, corrected=False),
    "wiki, dt corrected": lambda m, ledger: WikiJog(m, ledger, corrected=True),
    "one long jog + 0x85": LongJog,
}
