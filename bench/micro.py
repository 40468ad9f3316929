"""Per-intent cost of the engine: set_intent plus the poll that acts on it, timed while jogging."""

from __future__ import annotations

import math
import statistics
import time

from smoothjog.core.engine import EngineLimits, Jogger, Output
from smoothjog.core.intents import ContinuousIntent, Intent
from smoothjog.core.ledger import Ledger
from smoothjog.core.machine import MachineModel
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.rig import LinkModel, SimRig
from smoothjog.virtual import VirtualHost


class _TimedJogger(Jogger):
    """The engine, timing each set_intent together with the poll that acts on it."""

    def __init__(self, model: MachineModel, ledger: Ledger) -> None:
        super().__init__(model, EngineLimits.from_model(model), None, ledger)
        self.timings_us: list[float] = []
        self._intent_us: float | None = None

    def set_intent(self, intent: Intent, now_s: float) -> None:
        start = time.perf_counter()
        super().set_intent(intent, now_s)
        self._intent_us = (time.perf_counter() - start) * 1e6

    def poll(self, now_s: float) -> list[Output]:
        start = time.perf_counter()
        out = super().poll(now_s)
        if self._intent_us is not None:
            self.timings_us.append(self._intent_us + (time.perf_counter() - start) * 1e6)
            self._intent_us = None
        return out


def measure_us(samples: int = 2000) -> list[float]:
    """Microseconds per intent for `samples` stick updates of a 1 Hz sweep, in virtual time."""
    rig = SimRig(GrblFirmware(machine="hobby-router"), LinkModel())
    with VirtualHost(rig, engine_factory=_TimedJogger) as vs:
        vs.handshake()
        engine = vs.driver
        assert isinstance(engine, _TimedJogger)
        t0 = vs.now_s
        for k in range(samples):
            vs.run_until(t0 + k * 0.02)
            x = -math.sin(2 * math.pi * k * 0.02)
            vs.set_intent(ContinuousIntent({"X": round(x, 4) or 0.001, "Y": 0.3}, 0.5))
        vs.run_until(vs.now_s + 0.001)
        return engine.timings_us


def main(argv: list[str] | None = None) -> int:
    """Print the median and 90th percentile; the target is a 50 µs median."""
    timings = measure_us()
    median = statistics.median(timings)
    p90 = statistics.quantiles(timings, n=10)[-1]
    print("| measure | µs |\n|---|---|")
    print(f"| per-intent median | {median:.1f} |\n| per-intent p90 | {p90:.1f} |")
    print(f"- {'met' if median <= 50 else 'NOT met'}: median <= 50 µs")
    return 0
