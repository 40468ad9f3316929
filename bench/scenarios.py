"""The benchmark scenarios S1-S7, run in the simulator's virtual time, measured on ground truth.

Every scenario starts the simulated machine, lets the host handshake, then moves the stick along
X toward the far end of travel (the hobby router starts homed at the + corner) and measures what
the machine really did from the simulator's segment trace.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from bench import measure
from bench.hosts import Method, Shipped
from smoothjog.core.intents import ContinuousIntent
from smoothjog.core.units import mm_min_to_mm_s
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import get_firmware_profile
from smoothjog.sim.rig import LinkModel, SimRig
from smoothjog.virtual import VirtualHost

Factory = Method

#: The stick's X direction: toward the far end of travel from the homed + corner.
DIRECTION = -1.0


@dataclass
class Run:
    """One scenario run: its figures and, for plots, the velocity along X over time."""

    metrics: dict[str, float]
    series: list[tuple[float, float]] = field(default_factory=list)
    commanded: list[tuple[float, float]] = field(default_factory=list)
    host_name: str = ""


@dataclass(frozen=True)
class Physics:
    """The physical quantities of a profile along X at full speed."""

    speed_mm_s: float
    accel_mm_s2: float

    @property
    def stop_mm(self) -> float:
        """v²/(2a)."""
        return self.speed_mm_s**2 / (2 * self.accel_mm_s2)

    @property
    def stop_s(self) -> float:
        """v/a."""
        return self.speed_mm_s / self.accel_mm_s2


def physics(machine: str) -> Physics:
    """v and a along X for a machine profile."""
    fw = GrblFirmware(machine=machine)
    return Physics(mm_min_to_mm_s(fw.settings[110]), fw.settings[120])


#: The wire of every scenario (115200 baud 8N1, no added latency).
LINK = LinkModel()
#: How fast the controller's clock runs against the host's (1.0: exact; see SimRig).
CLOCK_RATIO = 1.0


def _session(
    factory: Factory, machine: str, firmware: str, link: LinkModel | None = None
) -> tuple[VirtualHost, float]:
    fw = GrblFirmware(get_firmware_profile(firmware), machine)
    rig = SimRig(fw, LINK if link is None else link, clock_ratio=CLOCK_RATIO)
    # Soft limits off, as in the real-firmware runs of the reference methods: the printed wiki
    # method queues 16 x 41 mm, which runs past the 800 mm travel and would meet error:15.
    rig.host_send(b"$20=0\n", 0.0)
    if isinstance(factory, Shipped):
        vs = VirtualHost(rig, tuning=factory.tuning)
    else:
        vs = VirtualHost(rig, engine_factory=factory)
    vs.handshake()
    t0 = vs.now_s + 0.05
    vs.run_until(t0)
    return vs, t0


def _stick(speed: float, x: float = DIRECTION) -> ContinuousIntent:
    return ContinuousIntent({"X": x}, speed)


def _series(
    vs: VirtualHost, t0: float, t1: float, origin: float | None = None
) -> list[tuple[float, float]]:
    """X velocity over [t0, t1], times relative to origin (the scenario's event; default t0)."""
    zero = t0 if origin is None else origin
    samples = measure.sample_velocity(vs.rig.trace, t0, t1, dt_s=0.002)
    return [(t - zero, v[0]) for t, v in samples]


def _hold_s(ph: Physics) -> float:
    return max(2.0, 3.0 * ph.stop_s)


def _held(
    factory: Factory,
    machine: str,
    firmware: str,
    phase_s: float,
    speed: float = 1.0,
    link: LinkModel | None = None,
) -> tuple[Physics, VirtualHost, float]:
    """Press the stick toward -X at speed and hold it up to the scenario's event (hold + phase).

    Returns the profile's physics, the session and the event time.
    """
    ph = physics(machine)
    vs, t0 = _session(factory, machine, firmware, link)
    vs.set_intent(_stick(speed))
    t_event = t0 + _hold_s(ph) + phase_s
    vs.run_until(t_event)
    return ph, vs, t_event


def release(
    factory: Factory,
    machine: str,
    firmware: str,
    phase_s: float,
    speed: float,
    *,
    link: LinkModel | None = None,
) -> Run:
    """S1/S5: hold, then release; distance and time to standstill after the release."""
    _ph, vs, t_rel = _held(factory, machine, firmware, phase_s, speed, link)
    vs.set_intent(_stick(speed, 0.0))
    vs.run_until_idle(30.0)
    vs.run_until(vs.now_s + 0.5)
    trace = vs.rig.trace
    end = measure.last_motion_end(trace)
    run = Run(
        {
            "dist_mm": measure.distance_after(trace, t_rel),
            "time_s": max(end - t_rel, 0.0),
            "restarts": float(measure.restarts_after(trace, t_rel)),
        },
        _series(vs, t_rel - 0.5, t_rel + 1.5, t_rel),
    )
    vs.close()
    return run


def hold(
    factory: Factory, machine: str, firmware: str, phase_s: float, *, link: LinkModel | None = None
) -> Run:
    """S2: a 6 s hold at full speed: share of time within 2 % of v, and the dips."""
    ph = physics(machine)
    vs, t0 = _session(factory, machine, firmware, link)
    vs.set_intent(_stick(1.0))
    t_end = t0 + max(6.0, 2 * ph.stop_s + 3.0) + phase_s
    vs.run_until(t_end)
    window0 = t0 + 1.5 * ph.stop_s + 0.2
    vs.set_intent(_stick(1.0, 0.0))
    vs.run_until_idle(30.0)
    # Measured once the trace holds every segment up to t_end (it records finished segments).
    share, dips = measure.hold_quality(vs.rig.trace, window0, t_end, ph.speed_mm_s)
    mean = measure.mean_speed(vs.rig.trace, window0, t_end) / ph.speed_mm_s
    run = Run(
        {"within_2pct": share, "dips": float(dips), "mean_of_v": mean},
        _series(vs, t0, t_end + 1.0),
    )
    vs.close()
    return run


def reversal(
    factory: Factory, machine: str, firmware: str, phase_s: float, *, link: LinkModel | None = None
) -> Run:
    """S3: full speed one way, then the other: time to full speed the other way."""
    ph, vs, t_rev = _held(factory, machine, firmware, phase_s, link=link)
    # The stick flips through neutral in one instant: each method reacts to both events as it
    # is written (the reference methods cancel at neutral); smoothjog acts on the newest intent.
    vs.set_intent(_stick(1.0, 0.0))
    vs.set_intent(_stick(1.0, -DIRECTION))
    t_end = t_rev + 4 * ph.stop_s + 2.0
    vs.run_until(t_end + 0.1)
    took = measure.time_to_velocity(vs.rig.trace, t_rev, t_end, 0, -DIRECTION * ph.speed_mm_s)
    vs.set_intent(_stick(1.0, 0.0))
    vs.run_until_idle(30.0)
    run = Run(
        {"time_s": took if took is not None else math.inf},
        _series(vs, t_rev - 0.5, t_rev + 2 * ph.stop_s + 1.0, t_rev),
    )
    vs.close()
    return run


def client_dies(
    factory: Factory, machine: str, firmware: str, phase_s: float, *, link: LinkModel | None = None
) -> Run:
    """S4: the host dies mid-jog: how far the machine coasts on what was queued."""
    _ph, vs, t_kill = _held(factory, machine, firmware, phase_s, link=link)
    vs.kill()
    vs.run_until(t_kill + 20.0)
    trace = vs.rig.trace
    run = Run(
        {
            "dist_mm": measure.distance_after(trace, t_kill),
            "time_s": measure.last_motion_end(trace) - t_kill,
        },
        _series(vs, t_kill - 0.5, t_kill + 2.0, t_kill),
    )
    vs.close()
    return run


def speed_change(
    factory: Factory, machine: str, firmware: str, phase_s: float, *, link: LinkModel | None = None
) -> Run:
    """S6: 100 % to 30 %: time to settle within 2 % of the new speed."""
    ph, vs, t_change = _held(factory, machine, firmware, phase_s, link=link)
    vs.set_intent(_stick(0.3))
    t_end = t_change + 3 * ph.stop_s + 1.5
    vs.run_until(t_end + 0.1)
    took = measure.settle_time(vs.rig.trace, t_change, t_end, 0.3 * ph.speed_mm_s)
    vs.set_intent(_stick(0.3, 0.0))
    vs.run_until_idle(30.0)
    run = Run(
        {"time_s": took if took is not None else math.inf},
        _series(vs, t_change - 0.5, t_change + 2 * ph.stop_s + 1.0, t_change),
    )
    vs.close()
    return run


def sine_sweep(
    factory: Factory, machine: str, firmware: str, phase_s: float, *, link: LinkModel | None = None
) -> Run:
    """S7: the stick swept as a 1 Hz sine at half speed: lag of actual behind commanded velocity."""
    ph = physics(machine)
    vs, t0 = _session(factory, machine, firmware, link)
    freq_hz, speed, sample_s = 1.0, 0.5, 0.020
    duration_s = 4.0
    t = 0.0
    commanded: list[tuple[float, float]] = []
    while t < duration_s:
        x = DIRECTION * math.sin(2 * math.pi * freq_hz * (t + phase_s))
        vs.run_until(t0 + t)
        vs.set_intent(_stick(speed, round(x, 4)))
        t += sample_s
    vs.run_until(t0 + duration_s)
    vs.set_intent(_stick(speed, 0.0))
    vs.run_until_idle(30.0)
    a0, a1 = t0 + 1.0, t0 + duration_s
    for k in range(int((a1 - a0) / 0.001)):
        tk = a0 + k * 0.001
        x = DIRECTION * math.sin(2 * math.pi * freq_hz * (tk - t0 + phase_s))
        commanded.append((tk, x * speed * ph.speed_mm_s))
    actual = [(tt, v[0]) for tt, v in measure.sample_velocity(vs.rig.trace, a0, a1)]
    lag, match = measure.lag_and_match(commanded, actual)
    run = Run(
        {"lag_s": lag, "match": match},
        _series(vs, t0, t0 + duration_s),
        [(tt - t0, c) for tt, c in commanded[::2]],
    )
    vs.close()
    return run
