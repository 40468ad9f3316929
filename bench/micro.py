"""Per-intent cost of the engine: set_intent plus the poll that acts on it, timed while jogging."""

from __future__ import annotations

import math
import statistics
import time

from smoothjog.core.jogger import ContinuousIntent
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.rig import LinkModel, SimRig
from smoothjog.vsession import VirtualSession


def measure_us(samples: int = 2000) -> list[float]:
    """Microseconds per intent for `samples` stick updates of a 1 Hz sweep, in virtual time."""
    vs = VirtualSession(SimRig(GrblFirmware(machine="hobby-router"), LinkModel()))
    vs.handshake()
    engine = vs.engine
    assert engine is not None
    timings: list[float] = []
    t0 = vs.now_s
    for k in range(samples):
        vs.run_until(t0 + k * 0.02)
        x = -math.sin(2 * math.pi * k * 0.02)
        intent = ContinuousIntent({"X": round(x, 4) or 0.001, "Y": 0.3}, 0.5)
        start = time.perf_counter()
        engine.set_intent(intent, vs.now_s)
        outputs = engine.poll(vs.now_s)
        timings.append((time.perf_counter() - start) * 1e6)
        for output in outputs:
            vs._send(output)
    return timings


def main(argv: list[str] | None = None) -> int:
    """Print the median and 90th percentile; the target is a 50 µs median."""
    timings = measure_us()
    median = statistics.median(timings)
    p90 = statistics.quantiles(timings, n=10)[-1]
    print("| measure | µs |\n|---|---|")
    print(f"| per-intent median | {median:.1f} |\n| per-intent p90 | {p90:.1f} |")
    print(f"- {'met' if median <= 50 else 'NOT met'}: median <= 50 µs")
    return 0
