"""Random byte streams never crash or hang the simulated controller, nor break its physics."""

from __future__ import annotations

import math
import random

import pytest

from smoothjog.sim.motion import TraceSegment
from tests.sim.rigtools import Host

OVERRIDES = [bytes((b,)) for b in range(0x90, 0x98)]


def _random_action(rng: random.Random) -> bytes:
    """One thing a sender might do: a G0/G1 line, overrides, a hold, a jog, a cancel..."""
    r = rng.random()
    if r < 0.30:
        x, y = rng.uniform(-200, 0), rng.uniform(-200, 0)
        word = rng.choice(["G0", "G1"])
        return f"{word}X{x:.3f}Y{y:.3f}F{rng.choice([500, 3000, 9000, 20000])}\n".encode()
    if r < 0.55:
        return b"".join(rng.choice(OVERRIDES) for _ in range(rng.randint(1, 3)))
    if r < 0.62:
        return b"!"
    if r < 0.70:
        return b"~"
    if r < 0.78:
        return f"$J=G91X{rng.uniform(-20, 20):.3f}F{rng.choice([1000, 5000])}\n".encode()
    if r < 0.83:
        return b"\x85"
    if r < 0.86:
        return b"\x84"
    if r < 0.88:
        return b"G4P0.2\n"
    return b"?"


def _physics_violation(host: Host) -> str | None:
    """The first segment faster than an axis allows, or a speed change beyond the acceleration."""
    settings = host.fw.settings
    n = host.fw.n_axes
    max_rate = [settings[110 + i] / 60.0 for i in range(n)]
    accel = [settings[120 + i] for i in range(n)]
    prev: tuple[TraceSegment, float, list[float]] | None = None
    for seg in host.fw.trace:
        dt = seg.t1_s - seg.t0_s
        length = math.dist(seg.start_mm, seg.end_mm)
        if dt <= 0.0 or length < 1e-9:
            prev = None
            continue
        unit = [(e - s) / length for s, e in zip(seg.start_mm, seg.end_mm, strict=True)]
        speed = length / dt
        for i in range(n):
            if abs(speed * unit[i]) > max_rate[i] * 1.001 + 0.5:
                return f"axis {i} at {speed * unit[i]:.2f} mm/s at t={seg.t0_s:.4f}"
        if prev is not None:
            last, last_speed, last_unit = prev
            straight = sum(a * b for a, b in zip(unit, last_unit, strict=True)) > 0.99999
            if straight and abs(seg.t0_s - last.t1_s) < 1e-9:
                # Speeds are segment averages: allow the change over the two half segments,
                # plus the rounding of a whole step at either end.
                a = min(accel[i] / abs(u) for i, u in enumerate(unit) if abs(u) > 1e-9)
                span = (dt + last.t1_s - last.t0_s) / 2
                limit = a * span * 1.02 + 0.02 / min(dt, last.t1_s - last.t0_s)
                if abs(speed - last_speed) > limit:
                    return f"{last_speed:.2f} -> {speed:.2f} mm/s at t={seg.t0_s:.4f}"
        prev = (seg, speed, unit)
    return None


# Seeds 60 and 1015 once made the main loop spin on a freeze that ended a rounding error late.
@pytest.mark.parametrize("seed", [*range(120), 1015])
def test_random_streams_keep_the_controller_sane(seed: int) -> None:
    rng = random.Random(seed)
    host = Host(machine="fast")
    for _ in range(25):
        host.send(_random_action(rng))
        host.run(rng.choice([0.0, 0.001, 0.01, 0.05, 0.2]))
    host.send(b"~")
    host.run(0.2)
    host.send(b"~")
    host.run(20.0)
    assert _physics_violation(host) is None
    # Still answering: whatever happened, a reset brings back the banner and a report.
    host.send(b"\x18")
    assert any(line.startswith("Grbl 1.1h") for line in host.until(lambda x: x.startswith("Grbl")))
    assert host.status().startswith("<")
