"""Randomised press/release/reverse/speed-change/step sequences with safety checks on ground truth.

For every sequence: no ghost jog (no motion after a completed stop until the next intent), no
error:15, the soft-limit envelope and the keep-out zones never crossed by the real machine, `$G`
unchanged from start to end, and tracked-minus-real within one step at every stop. Sequences run
back to back on one simulated machine per firmware profile and link model (`--links`: the named
models of smoothjog.sim.rig.LINK_MODELS, all by default), from a seeded generator.

With faults (`--drop`, `--corrupt`, `--outside`), the link also loses or flips bytes at seeded
rates and outside events strike at random times: a feed hold `!` or a jog cancel 0x85 from
another sender, a soft reset 0x18, a stall of the link. Further checks then: the machine never
moves again after an outside stop until a new press; a fresh press at the start of every
sequence moves the machine or the engine reports a fault (else the engine is wedged). The fuzz
plays the operator between sequences ($X after an alarm, a reset when stuck) and, should the
host or the engine raise, counts the exception, starts a fresh session and carries on.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import dataclasses
import logging
import math
import random
import time
from dataclasses import dataclass, field

from bench import measure
from smoothjog.core.engine import EngineEvent, Jogger, Output, Phase
from smoothjog.core.engine.stopper import StopPhase
from smoothjog.core.engine.tracker import PathSeg
from smoothjog.core.errors import SmoothjogError
from smoothjog.core.intents import ContinuousIntent, Intent, StepIntent, StopIntent
from smoothjog.core.ledger import ENGINE
from smoothjog.core.machine import KeepOut
from smoothjog.core.realtime import JOG_CANCEL
from smoothjog.core.responses import GcodeModes
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.motion import TraceSegment
from smoothjog.sim.profiles import get_firmware_profile
from smoothjog.sim.rig import LINK_MODELS, LinkModel, SimRig
from smoothjog.virtual import VirtualHost

#: A vise near the middle of the hobby router's table, in machine coordinates.
VISE = KeepOut("vise", (-420.0, -420.0, -100.0), (-380.0, -380.0, 0.0))
#: Real positions may sit this far beyond a boundary (float printing of MPos): well under a step.
TOLERANCE_MM = 1e-6


#: The outside events, with the byte another sender puts on the wire (None: a link stall).
OUTSIDE_EVENTS: dict[str, bytes | None] = {
    "feed hold": b"!",
    "jog cancel": b"\x85",
    "soft reset": b"\x18",
    "stall": None,
}
#: The simulator stamps each cancel with the machine's rest (not the end of the firmware's $1
#: delay after it); a record this much later than the rest seen in the trace still counts.
CANCEL_END_SLACK_S = 0.005
#: How long an injected stall lasts: a uniform draw from this range (s).
STALL_RANGE_S = (0.1, 0.6)
#: The wedge probe: a press held this long at this speed must move the machine this far.
PROBE_HOLD_S = 0.8
PROBE_SPEED = 0.2
PROBE_MIN_MM = 0.5


@dataclass(frozen=True)
class Faults:
    """What the fuzz injects: line noise on the link and outside events between the intents."""

    #: Share of bytes lost / with one bit flipped, in the directions named by `directions`.
    drop_rate: float = 0.0
    corrupt_rate: float = 0.0
    directions: str = "both"  # "both", "to-controller" or "to-host"
    #: Chance, at each random intent, that one outside event strikes during its hold.
    outside_rate: float = 0.0

    @property
    def active(self) -> bool:
        """True when anything is injected (the fault checks run then)."""
        return bool(self.drop_rate or self.corrupt_rate or self.outside_rate)

    def on(self, link: LinkModel) -> LinkModel:
        """The link with this noise."""
        up = self.directions in ("both", "to-controller")
        down = self.directions in ("both", "to-host")
        return dataclasses.replace(
            link,
            drop_to_controller=self.drop_rate if up else 0.0,
            corrupt_to_controller=self.corrupt_rate if up else 0.0,
            drop_to_host=self.drop_rate if down else 0.0,
            corrupt_to_host=self.corrupt_rate if down else 0.0,
        )


@dataclass
class FuzzReport:
    """Counts over all sequences of one firmware profile on one link."""

    firmware: str
    link: str = "ideal"
    sequences: int = 0
    stops: int = 0
    ghost_jogs: int = 0
    soft_limit_errors: int = 0
    envelope_crossings: int = 0
    keepout_entries: int = 0
    gcode_state_changed: bool = False
    worst_tracking_steps: float = 0.0
    #: Stops whose tracked position was more than one step off the real one.
    stops_over_one_step: int = 0
    #: With noise toward the host: stops the engine checked against a reported position more
    #: than a step off the real one; their tracked error is not counted above.
    stops_on_a_wrong_report: int = 0
    #: Stops that ended a jog someone else had stopped first: the lines left in the controller
    #: ran off the tracked path, so their tracked error is not counted above.
    stops_after_outside: int = 0
    #: Faults claiming something outside smoothjog stopped or moved the machine: nothing does in
    #: runs without outside events or noise, so each one is a false alarm of the engine.
    false_outside_alarms: int = 0
    # With faults ---------------------------------------------------------------------------
    #: Outside events injected, by kind; outside stops are those that stopped a moving machine
    #: (a hold or cancel while it moved) or reset it.
    outside: dict[str, int] = field(default_factory=dict)
    outside_stops: int = 0
    #: Outside holds and cancels sent while smoothjog's own cancel was already on the wire,
    #: or was decided and followed before the machine came to rest (the controller saw one
    #: cancel either way), so they are not outside stops.
    outside_during_own_cancel: int = 0
    #: Outside holds and cancels that struck a machine braking into the end of everything
    #: smoothjog had sent, where it then rested anyway (not outside stops either).
    outside_stopped_nothing: int = 0
    #: The longest motion of one such restart (lines left in the controller's buffer that ran
    #: before smoothjog's cancel caught them), mm.
    worst_restart_mm: float = 0.0
    #: The machine moved again after an outside stop, before any new press.
    restarts_after_outside_stop: int = 0
    #: A fresh press moved the machine less than PROBE_MIN_MM and the engine reported no fault.
    wedged: int = 0
    #: Sequences after which the host never came to rest (60 s), or stayed out of Idle.
    never_idle: int = 0
    #: Exceptions out of the host, the engine or the session (each one: a fresh session).
    crashes: int = 0
    #: Faults the engine reported.
    faults_reported: int = 0
    #: Bytes lost and flipped by the noise: (to controller, to host) each.
    noise: tuple[int, int, int, int] = (0, 0, 0, 0)
    faults: list[str] = field(default_factory=list)

    @property
    def clean(self) -> bool:
        """True when every safety check held."""
        return (
            self.ghost_jogs == 0
            and self.soft_limit_errors == 0
            and self.envelope_crossings == 0
            and self.keepout_entries == 0
            and not self.gcode_state_changed
            and self.worst_tracking_steps <= 1.0 + 1e-9
            and self.false_outside_alarms == 0
            and self.restarts_after_outside_stop == 0
            and self.wedged == 0
            and self.never_idle == 0
            and self.crashes == 0
        )


def _random_intent(rng: random.Random) -> Intent:
    kind = rng.random()
    if kind < 0.12:
        axis = rng.choice("XYZ")
        return StepIntent(axis, rng.choice([-1, 1]) * rng.choice([0.01, 0.1, 1.0, 10.0]), 0.5)
    if kind < 0.2:
        return StopIntent()
    axes = {}
    for axis in rng.sample("XYZ", rng.choice([1, 1, 2, 3])):
        axes[axis] = rng.choice([-1.0, -0.5, -0.1, 0.3, 0.7, 1.0])
    return ContinuousIntent(axes, rng.choice([0.1, 0.3, 0.6, 1.0]))


def _gcode_words(vs: VirtualHost) -> tuple[str, ...]:
    for resp in vs.query_line("$G"):
        if isinstance(resp, GcodeModes):
            return resp.words
    return ()


class _Session:
    """One simulated machine and the host driving it, as the fuzz sees them."""

    def __init__(self, firmware: str, link: LinkModel, events: list[EngineEvent]) -> None:
        fw = GrblFirmware(get_firmware_profile(firmware), "hobby-router")
        self.vs = VirtualHost(SimRig(fw, link), keepouts=(VISE,), on_event=events.append)
        self.model = self.vs.handshake()
        engine = self.vs.engine
        assert engine is not None
        self.engine: Jogger = engine
        self.env = engine.limits.envelope
        self.checked_upto = 0
        self.gcode_before = _gcode_words(self.vs)
        #: When each intent other than a stop was given (a press, for the restart check).
        self.presses_s: list[float] = []
        #: Every outside event injected: when, which.
        self.outside_log: list[tuple[float, str]] = []
        #: When the engine wrote each of its own jog cancels.
        self.own_cancels_s: list[float] = []
        #: When the engine wrote each of its own jog lines.
        self.own_jogs_s: list[float] = []
        engine_send = engine.lines.send

        def send(
            line: str, kind: str, now_s: float, out: list[Output], seg: PathSeg | None = None
        ) -> None:
            if kind == "jog":
                self.own_jogs_s.append(now_s)
            engine_send(line, kind, now_s, out, seg)

        engine.lines.send = send  # type: ignore[method-assign]
        host = self.vs.host
        host_send_realtime = host.send_realtime

        def send_realtime(owner: str, byte: bytes) -> None:
            if owner == ENGINE and byte == JOG_CANCEL:
                self.own_cancels_s.append(self.vs.now_s)
            host_send_realtime(owner, byte)

        host.send_realtime = send_realtime  # type: ignore[method-assign]

    def send_outside(self, byte: bytes) -> None:
        """Another sender puts byte on the wire now (the host knows nothing of it)."""

        async def send() -> None:
            self.vs.link.send_realtime(byte)

        self.vs.loop.run_until_complete(send())

    def harvest(self, report: FuzzReport) -> None:
        """Add the engine's own counts to the report (once, at the session's end)."""
        stats = self.engine.stats
        report.stops += len(stats.stops)
        report.soft_limit_errors += stats.soft_limit_errors
        trace = self.vs.rig.trace
        starts = [seg.t0_s for seg in trace]
        steps_per_mm = self.engine.limits.steps_per_mm
        link = self.vs.rig.link
        noisy_reports = bool(link.drop_to_host or link.corrupt_to_host)
        for stop in stats.stops:
            before = [e for e in self.outside_log if e[0] <= stop.t_s]
            last = f"{before[-1][1]} at {before[-1][0]:.3f} s" if before else "none"
            # The engine measures its error against the position the controller reported; with
            # noise toward the host that report can itself be wrong, which ground truth shows.
            real = measure.position_at(trace, stop.t_s, starts) if noisy_reports else ()
            off = max(
                (abs(m - r) * k for m, r, k in zip(stop.mpos_mm, real, steps_per_mm, strict=False)),
                default=0.0,
            )
            if off > 1.0 + 1e-9:
                report.stops_on_a_wrong_report += 1
                report.faults.append(
                    f"stop at {stop.t_s:.3f} s checked against a report {off:.1f} steps off the "
                    f"real position (last outside event before it: {last})"
                )
                continue
            if stop.after_outside_stop:
                # The path it tracked was broken by someone else's stop; the engine re-reads
                # the position (the next stop is judged again).
                report.stops_after_outside += 1
                continue
            report.worst_tracking_steps = max(report.worst_tracking_steps, stop.tracked_error_steps)
            if stop.tracked_error_steps > 1.0 + 1e-9:
                report.stops_over_one_step += 1
                report.faults.append(
                    f"tracked-real {stop.tracked_error_steps:.2f} steps at the stop at "
                    f"{stop.t_s:.3f} s (last outside event before it: {last})"
                )
        a, b, c, d = (x + y for x, y in zip(report.noise, self.vs.rig.noise_counts, strict=True))
        report.noise = (a, b, c, d)

    def close(self, report: FuzzReport, *, check_gcode: bool) -> None:
        """Harvest, compare `$G` with the start (if asked and possible), close quietly."""
        self.harvest(report)
        if check_gcode and self.vs.host.error is None:
            with contextlib.suppress(SmoothjogError, TimeoutError, asyncio.CancelledError):
                report.gcode_state_changed |= _gcode_words(self.vs) != self.gcode_before
        with contextlib.suppress(Exception):
            self.vs.close()


def run_fuzz(
    firmware: str,
    sequences: int,
    seed: int = 1,
    link: str | LinkModel = "ideal",
    faults: Faults | None = None,
) -> FuzzReport:
    """Run `sequences` random sequences on one firmware profile and link, counting violations."""
    faults = faults or Faults()
    rng = random.Random(seed)
    # Fault decisions draw from their own RNG: the intents are the same with and without faults.
    frng = random.Random(f"faults:{seed}")
    base = LINK_MODELS[link] if isinstance(link, str) else link
    wire = faults.on(base)
    report = FuzzReport(firmware, link if isinstance(link, str) else "custom")
    events: list[EngineEvent] = []
    session = _Session(firmware, wire, events)
    for _ in range(sequences):
        if not faults.active:
            ok = _sequence(session, rng, report)
            report.sequences += 1
            if not ok:
                break
            continue
        try:
            ok = _fault_sequence(session, rng, frng, faults, report, events)
            if session.vs.host.error is not None:
                raise session.vs.host.error
        except Exception as exc:  # a misbehaving engine is a finding: count it and go on
            report.crashes += 1
            report.faults.append(f"crash: {exc!r}")
            ok = False
        report.sequences += 1
        if not ok:
            session.close(report, check_gcode=False)
            fresh = _fresh_session(firmware, wire, events, report)
            if fresh is None:
                return _finish(report, events, faults)
            session, wire = fresh
    session.close(report, check_gcode=True)
    return _finish(report, events, faults)


def _fresh_session(
    firmware: str, wire: LinkModel, events: list[EngineEvent], report: FuzzReport
) -> tuple[_Session, LinkModel] | None:
    """A new machine on a new seed of the wire; a handshake that fails is a crash too."""
    for _attempt in range(3):
        wire = dataclasses.replace(wire, seed=wire.seed + 1)
        try:
            return _Session(firmware, wire, events), wire
        except Exception as exc:  # the fuzz goes on while it can start a session at all
            report.crashes += 1
            report.faults.append(f"crash: a fresh session failed: {exc!r}")
    return None


def _finish(report: FuzzReport, events: list[EngineEvent], faults: Faults) -> FuzzReport:
    """Count the engine's faults into the report."""
    fault_texts = [e.text for e in events if e.kind == "fault"]
    report.faults_reported = len(fault_texts)
    if not faults.active:
        report.false_outside_alarms = sum(
            "stopped outside smoothjog" in f or "left the path" in f or "off the path" in f
            for f in fault_texts
        )
    report.faults += fault_texts[:5]
    return report


def _sequence(session: _Session, rng: random.Random, report: FuzzReport) -> bool:
    """One random sequence on a clean wire; False when the machine is left out of Idle."""
    vs = session.vs
    for _ in range(rng.randint(1, 5)):
        try:
            vs.set_intent(_random_intent(rng))
        except SmoothjogError as exc:  # an invalid random intent is a finding, not a crash
            report.faults.append(repr(exc))
        vs.run_until(vs.now_s + rng.choice([0.005, 0.03, 0.1, 0.3, 0.8]))
    _stop_and_check(session, report)
    if session.model.state not in ("Idle", None):
        report.faults.append(f"state {session.model.state} after a sequence")
        return False
    return True


def _stop_and_check(session: _Session, report: FuzzReport, idle_timeout_s: float = 60.0) -> bool:
    """Stop, wait for rest, then the ghost-jog, envelope and keep-out checks; False: never idle."""
    vs = session.vs
    vs.set_intent(StopIntent())
    idle = vs.run_until_idle(idle_timeout_s)
    if not idle:
        report.never_idle += 1
        report.faults.append(
            f"never idle: {idle_timeout_s:.0f} s after a stop at {vs.now_s - idle_timeout_s:.3f} s"
            f" (controller {vs.rig.firmware.status_state()}, host model {session.model.state})"
        )
    t_idle = vs.now_s
    vs.run_until(vs.now_s + 0.3)  # anything moving now is a ghost jog
    trace = vs.rig.trace
    new = trace[session.checked_upto :]
    for seg in new:
        if seg.t0_s >= t_idle - 1e-9 and seg.speed_mm_s > 0:
            report.ghost_jogs += 1
            report.faults.append(
                f"ghost jog: at rest and idle at {t_idle:.3f} s, moving at {seg.t0_s:.3f} s "
                f"({measure.distance_after(new, seg.t0_s):.2f} mm)"
            )
            break
    env = session.env
    for seg in new:
        for p in (seg.start_mm, seg.end_mm):
            if env is not None and not all(
                lo - TOLERANCE_MM <= x <= hi + TOLERANCE_MM
                for x, lo, hi in zip(p, env.min_mm, env.max_mm, strict=True)
            ):
                report.envelope_crossings += 1
        if _enters(VISE, seg.start_mm, seg.end_mm):
            if not report.keepout_entries:
                report.faults.append(
                    f"keep-out: the machine moved inside the vise at {seg.t0_s:.3f} s"
                    f" ({_fmt(seg.start_mm)} to {_fmt(seg.end_mm)})"
                )
            report.keepout_entries += 1
    session.checked_upto = len(trace)
    return idle


def _fault_sequence(
    session: _Session,
    rng: random.Random,
    frng: random.Random,
    faults: Faults,
    report: FuzzReport,
    events: list[EngineEvent],
) -> bool:
    """One random sequence with outside events; False when the session must be replaced."""
    vs = session.vs
    if not _recover(session):
        report.never_idle += 1
        report.faults.append(f"could not bring the machine back to Idle ({session.model.state})")
        return False
    _probe(session, report, events)
    # Outside holds, cancels and resets: when, which, whether smoothjog had already decided
    # on a cancel of its own that was still waiting for a line's ok, and where everything it
    # had sent ends when no more will follow (it was stopping or letting the queue run out).
    stops: list[tuple[float, str, bool, tuple[float, ...] | None]] = []
    for _ in range(rng.randint(1, 5)):
        intent = _random_intent(rng)
        try:
            vs.set_intent(intent)
        except SmoothjogError as exc:  # an invalid random intent is a finding, not a crash
            report.faults.append(repr(exc))
        if not isinstance(intent, StopIntent):
            session.presses_s.append(vs.now_s)
        hold_s = rng.choice([0.005, 0.03, 0.1, 0.3, 0.8])
        end_s = vs.now_s + hold_s
        if frng.random() < faults.outside_rate:
            vs.run_until(vs.now_s + frng.random() * hold_s)
            kind = frng.choice(list(OUTSIDE_EVENTS))
            report.outside[kind] = report.outside.get(kind, 0) + 1
            session.outside_log.append((vs.now_s, kind))
            byte = OUTSIDE_EVENTS[kind]
            if byte is None:
                vs.rig.inject_stall(frng.uniform(*STALL_RANGE_S), max(vs.now_s, vs.rig.now_s))
            elif _own_cancel_sent(session.engine):
                # smoothjog's own 0x85 is already on its way: a hold or cancel behind it on
                # the same wire finds the jog cancel under way and changes nothing
                # (firmware-facts §3.1), and a press made before it may rightly go on.
                report.outside_during_own_cancel += kind != "soft reset"
                if kind == "soft reset":
                    stops.append((vs.now_s, kind, False, None))
                session.send_outside(byte)
            else:
                engine = session.engine
                stops.append((vs.now_s, kind, _own_cancel_due(engine), _path_end(engine)))
                session.send_outside(byte)
        vs.run_until(max(end_s, vs.now_s))
    start_checked = session.checked_upto
    # A host that never comes to rest is replaced (the operator restarts it), once checked.
    idle = _stop_and_check(session, report, idle_timeout_s=20.0)
    trace = vs.rig.trace
    steps_per_mm = session.engine.limits.steps_per_mm
    hold_cancels = session.vs.rig.firmware.profile.facts.jog_cancel.feed_hold_cancels
    for t, kind, own_due, final_end in stops:
        # A hold or cancel of a machine at rest stops nothing; a reset stops it in any case.
        if kind != "soft reset" and not _moving_at(trace, t, start_checked):
            continue
        if kind == "feed hold" and not hold_cancels:
            # grblHAL leaves a jog alone on a feed hold (firmware-facts §7; the fuzz only jogs):
            # it stopped nothing, and a rest that follows is the engine's own doing (a queue
            # let run out at a keep-out's corner, say), not a restart.
            report.outside_stopped_nothing += 1
            continue
        rest = _rest_after(trace, t, start_checked)
        if kind != "soft reset" and _threw_nothing_away(session, t, rest):
            # Every jog cancel that ended the motion threw away no planned motion and no
            # unread line: the machine rested where it would have without it (braking into
            # the end of what it held), and what runs later is what ran anyway. No report can
            # show such a cancel, so a held stick rightly jogs on.
            report.outside_stopped_nothing += 1
            continue
        if final_end is not None and not any(t < j <= rest for j in session.own_jogs_s):
            at_rest = measure.position_at(trace, rest)
            if all(
                abs(r - e) * k <= 1.0 + 1e-9
                for r, e, k in zip(at_rest, final_end, steps_per_mm, strict=False)
            ):
                # It struck a machine braking into the end of all smoothjog had sent (a stop,
                # a queue let run out, a jog run up to an edge or a keep-out), which sent no
                # jog more before the machine rested, and rested there anyway: it stopped
                # nothing that anyone could see, and a press made before it may rightly go on.
                report.outside_stopped_nothing += 1
                continue
        if own_due and any(t < c <= rest for c in session.own_cancels_s):
            # smoothjog's own 0x85 was decided and went out before that stop ended: the
            # controller saw one cancel of one motion (a second 0x85 during a cancel changes
            # nothing, firmware-facts §3.1), which no report can tell from smoothjog's own.
            report.outside_during_own_cancel += 1
            continue
        report.outside_stops += 1
        later = [p for p in session.presses_s if p > t]
        until = later[0] if later else math.inf
        again = [
            seg
            for seg in trace[start_checked:]
            if seg.speed_mm_s > measure.REST_MM_S and rest + 1e-6 < seg.t0_s < until
        ]
        if again:
            report.restarts_after_outside_stop += 1
            moved = measure.distance_after(again, again[0].t0_s)
            report.worst_restart_mm = max(report.worst_restart_mm, moved)
            speed = _speed_at(trace, t, start_checked)
            was = f"moving at {speed:.1f} mm/s" if rest > t else "at rest"
            report.faults.append(
                f"restart: {kind} at {t:.3f} s (machine {was}), at rest at {rest:.3f} s, moving "
                f"again at {again[0].t0_s:.3f} s ({moved:.2f} mm) with no new press"
            )
    return idle


def _threw_nothing_away(session: _Session, t_s: float, rest_s: float) -> bool:
    """True when the jog cancels that ended between t_s and the rest (host time) left no
    planned step unrun and dropped no unread line (the simulator's ground truth); False when
    any did, or none ended there."""
    rig = session.vs.rig
    ratio = rig.clock_ratio
    ended = [
        (unrun, dropped)
        for at_s, unrun, dropped in rig.firmware.cancel_log
        if t_s < at_s / ratio <= rest_s + CANCEL_END_SLACK_S
    ]
    return bool(ended) and all(unrun <= 1 and dropped == 0 for unrun, dropped in ended)


def _fmt(p: tuple[float, ...]) -> str:
    return ",".join(f"{v:.3f}" for v in p)


def _path_end(engine: Jogger) -> tuple[float, ...] | None:
    """Where everything the engine has sent ends (None without a path)."""
    track = engine.track
    return track.end_mm if track.path else None


def _own_cancel_due(engine: Jogger) -> bool:
    """True while the engine's own stop waits for a line's ok before the 0x85 it will send."""
    stop = engine.stopping.handshake
    return (
        engine.phase is Phase.STOPPING
        and stop.phase is StopPhase.WAIT_ACKS
        and bool(engine.track.path)
    )


def _own_cancel_sent(engine: Jogger) -> bool:
    """True while the engine's own stop has sent its 0x85 and waits for the sync line."""
    stop = engine.stopping.handshake
    return engine.phase is Phase.STOPPING and stop.phase is StopPhase.WAIT_SYNC and stop.cancelled


def _speed_at(trace: list[TraceSegment], t_s: float, start: int) -> float:
    """The machine's speed at t_s (mm/s)."""
    return max((s.speed_mm_s for s in trace[start:] if s.t0_s <= t_s < s.t1_s), default=0.0)


def _moving_at(trace: list[TraceSegment], t_s: float, start: int) -> bool:
    """True when the machine was moving at t_s."""
    return any(s.t0_s <= t_s < s.t1_s and s.speed_mm_s > measure.REST_MM_S for s in trace[start:])


def _rest_after(trace: list[TraceSegment], t_s: float, start: int) -> float:
    """When the motion going on at t_s ended (t_s itself when at rest then)."""
    rest = t_s
    for seg in trace[start:]:
        if seg.t1_s <= rest or seg.speed_mm_s <= measure.REST_MM_S:
            continue
        if seg.t0_s > rest + 1e-6:
            break
        rest = seg.t1_s
    return rest


def _recover(session: _Session) -> bool:
    """The operator between sequences: `$X` after an alarm, a reset (then `$X`) when stuck.

    The host's model knows no state (None) while it shakes hands again after a reset, and it
    reads the settings again after that: wait for both. (Its reports say Idle while it
    watches a restarted controller before reading it; a probe pressed then was released
    before the settings were read, and counted as a wedge.)
    """
    vs = session.vs
    deadline_s = vs.now_s + 10.0
    while vs.now_s < deadline_s:
        vs.run_until(vs.now_s + 0.3)
        state = session.model.state
        if state is None or (vs.host.rehandshaking and state in ("Idle", "Jog")):
            continue  # a held controller (Hold, Door) waits for the operator, below
        if state == "Idle":
            return True
        if state == "Alarm":
            with contextlib.suppress(SmoothjogError, TimeoutError):
                vs.query_line("$X")
        else:
            session.send_outside(b"\x18")
            vs.run_until(vs.now_s + 1.0)
    return session.model.state == "Idle"


def _probe(session: _Session, report: FuzzReport, events: list[EngineEvent]) -> None:
    """A fresh, slow press where there is room: it moves the machine, or the engine says why."""
    vs = session.vs
    pos = vs.rig.firmware.mpos_mm()
    env = session.env
    reach = PROBE_SPEED * session.engine.limits.max_rate_mm_min[0] / 60 * PROBE_HOLD_S + 5.0
    best: tuple[float, str, float] | None = None
    for i, axis in enumerate(session.engine.limits.axes):
        for sign in (-1.0, 1.0):
            room = math.inf
            if env is not None:
                room = (env.max_mm[i] - pos[i]) if sign > 0 else (pos[i] - env.min_mm[i])
            end = list(pos)
            end[i] += sign * reach
            if room < reach or _enters(VISE, pos, tuple(end)):
                continue
            if best is None or room > best[0]:
                best = (room, axis, sign)
    if best is None:
        return  # nowhere to go: nothing to probe
    _room, axis, sign = best
    n_faults = sum(e.kind == "fault" for e in events)
    t0 = vs.now_s
    vs.set_intent(ContinuousIntent({axis: sign}, PROBE_SPEED))
    session.presses_s.append(t0)
    vs.run_until(t0 + PROBE_HOLD_S)
    vs.set_intent(StopIntent())
    vs.run_until_idle(10.0)
    moved = measure.distance_after(vs.rig.trace, t0)
    if moved < PROBE_MIN_MM and sum(e.kind == "fault" for e in events) == n_faults:
        report.wedged += 1
        last = [f"{e.kind}: {e.text}" for e in events[-3:]]
        report.faults.append(
            f"wedged: a press of {axis}{sign:+.0f} at {t0:.2f} s moved {moved:.3f} mm, no fault"
            f" (controller {vs.rig.firmware.status_state()}, host model {session.model.state};"
            f" last events: {'; '.join(last) or 'none'})"
        )


def _enters(zone: KeepOut, a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    """True when the straight move a->b passes through the zone's open interior."""
    shrink = 1e-6
    lo = tuple(v + shrink for v in zone.min_mm)
    hi = tuple(v - shrink for v in zone.max_mm)
    t0, t1 = 0.0, 1.0
    for ai, bi, low, high in zip(a, b, lo, hi, strict=True):
        d = bi - ai
        if d == 0:
            if not low < ai < high:
                return False
            continue
        u0, u1 = (low - ai) / d, (high - ai) / d
        if u0 > u1:
            u0, u1 = u1, u0
        t0, t1 = max(t0, u0), min(t1, u1)
        if t0 >= t1:
            return False
    return True


def main(argv: list[str] | None = None) -> int:
    """Run the fuzz on every firmware profile x link and print one row each."""
    parser = argparse.ArgumentParser(prog="python -m bench fuzz")
    parser.add_argument(
        "--sequences", type=int, default=10_000, help="per firmware profile and link"
    )
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--firmware", default="grbl,grblhal,fluidnc")
    parser.add_argument(
        "--links",
        default="all",
        help=f"comma-separated link models ({', '.join(LINK_MODELS)}) or all (default)",
    )
    parser.add_argument("--drop", type=float, default=0.0, help="share of bytes lost")
    parser.add_argument("--corrupt", type=float, default=0.0, help="share of bytes bit-flipped")
    parser.add_argument(
        "--noise-dir",
        choices=("both", "to-controller", "to-host"),
        default="both",
        help="which way the noise of --drop and --corrupt goes",
    )
    parser.add_argument(
        "--outside",
        type=float,
        default=0.0,
        help="chance per random intent of an outside event (hold, cancel, reset, stall)",
    )
    args = parser.parse_args(argv)
    from bench.links import parse_names

    links = parse_names(args.links)
    faults = Faults(args.drop, args.corrupt, args.noise_dir, args.outside)
    # The host logs every engine fault; the fuzz counts them itself and prints a few.
    # With faults, an engine that raises is counted as a crash: its log line would only repeat it.
    logging.getLogger("smoothjog").setLevel(logging.CRITICAL if faults.active else logging.ERROR)
    worst = 0
    if faults.active:
        print(
            "| firmware | link | sequences | stops | ghost jogs | restarts after outside stop"
            " (longest, mm) | wedged | error:15 | envelope | keep-out | stops > 1 step (worst)"
            " | stops on a wrong report | stops after an outside stop (not judged) | never idle"
            " | crashes | outside events (stops; with smoothjog's own cancel; stopped nothing)"
            " | bytes lost / flipped | faults reported"
            " | wall s |"
        )
        print("|---" * 19 + "|")
    else:
        print(
            "| firmware | link | sequences | stops | ghost jogs | error:15 | envelope | keep-out"
            " | $G changed | worst tracked-real (steps) | false outside-stop alarms | wall s |"
        )
        print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.firmware.split(","):
        for link in links:
            t = time.perf_counter()
            r = run_fuzz(name, args.sequences, args.seed, link, faults)
            wall = f"{time.perf_counter() - t:.0f}"
            if faults.active:
                lost = r.noise[0] + r.noise[1]
                flipped = r.noise[2] + r.noise[3]
                print(
                    f"| {name} | {link} | {r.sequences} | {r.stops} | {r.ghost_jogs} | "
                    f"{r.restarts_after_outside_stop} ({r.worst_restart_mm:.2f}) | "
                    f"{r.wedged} | {r.soft_limit_errors} | "
                    f"{r.envelope_crossings} | {r.keepout_entries} | "
                    f"{r.stops_over_one_step} ({r.worst_tracking_steps:.2f}) | "
                    f"{r.stops_on_a_wrong_report} | {r.stops_after_outside} | {r.never_idle} | "
                    f"{r.crashes} | {sum(r.outside.values())} ({r.outside_stops}; "
                    f"{r.outside_during_own_cancel}; {r.outside_stopped_nothing}) | "
                    f"{lost} / {flipped} | {r.faults_reported} | {wall} |",
                    flush=True,
                )
            else:
                print(
                    f"| {name} | {link} | {r.sequences} | {r.stops} | {r.ghost_jogs} | "
                    f"{r.soft_limit_errors} | {r.envelope_crossings} | {r.keepout_entries} | "
                    f"{r.gcode_state_changed} | {r.worst_tracking_steps:.2f} | "
                    f"{r.false_outside_alarms} | {wall} |",
                    flush=True,
                )
            for fault in r.faults[:3]:
                print(f"  fault seen: {fault}")
            worst = worst or (0 if r.clean else 1)
    return worst
