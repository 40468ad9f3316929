"""The jog engine running HandwheelIntent, fed scripted replies: one table row per branch.

The harness machine has 80 steps/mm, 5000 mm/min and 500 mm/s² on every axis and rests at
(-1, -1, -1). Position mode moves every detent, to the step nearest the running total
(firmware-facts §1.5); velocity mode keeps no more than v²/2a + v·committed ahead of the
machine (11.11 mm at full feed, less half a step for the rounding to the grid: 111 detents of
0.1 mm) and drops the rest.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import pytest

from smoothjog.core.engine import Phase
from smoothjog.core.gcode import TravelBox
from smoothjog.core.intents import (
    ContinuousIntent,
    HandwheelIntent,
    StepIntent,
    StopIntent,
)
from smoothjog.core.machine import KeepOut
from tests.core.engine_harness import (
    START_MPOS,
    STEPS_PER_MM,
    EngineHarness,
    Step,
    intent,
    ok,
    ok_all,
    poll,
    sends,
    wait,
)

STEP_MM = 1.0 / STEPS_PER_MM


# ------------------------------------------------------------------------------ script steps


def wheel(
    counts: int,
    step_mm: float = 0.01,
    mode: Literal["position", "velocity"] = "position",
    axis: str = "X",
) -> Step:
    return intent(HandwheelIntent(axis, counts, step_mm, mode))


def vel(counts: int, step_mm: float = 0.1) -> Step:
    """A velocity-mode report on X."""
    return wheel(counts, step_mm, "velocity")


def stream(dt_s: float) -> Step:
    """Run on for dt_s: every line answered one 2 ms tick after it was sent."""
    return lambda h: h.run(h.t + dt_s)


def line(text: str) -> Step:
    """The controller prints this line (a reply goes to whoever's line is oldest)."""

    def step(h: EngineHarness) -> None:
        h.feed(text)

    return step


def foreign(nbytes: int) -> Step:
    """Another sender's line of nbytes (newline included) takes RX room until its reply."""

    def step(h: EngineHarness) -> None:
        h.foreign_line("$" * (nbytes - 1))

    return step


def report(state: str, where: Sequence[float] | None = None) -> Step:
    """A status report; where=None puts the machine at the end of every jog line sent."""

    def step(h: EngineHarness) -> None:
        h.status(state, where if where is not None else h.path_end())

    return step


def phase_is(phase: Phase) -> Step:
    def step(h: EngineHarness) -> None:
        assert h.engine.phase is phase, h.engine.phase

    return step


def each(n: int, *steps: Step) -> list[Step]:
    """The steps repeated n times."""
    return [s for _ in range(n) for s in steps]


def x_line(dist_mm: str) -> str:
    """The jog line the wheel writes for dist_mm on X at full feed."""
    return f"$J=G21G91X{dist_mm}F5000"


# ------------------------------------------------------------------------------ the rows
@dataclass(frozen=True)
class Expect:
    """What must hold once the script has run."""

    phase: Phase
    #: Every jog line sent, in order (None: not checked).
    lines: tuple[str, ...] | None = None
    #: Where the jog lines sent end on X (exactly, on the step grid), or None.
    end_x_mm: float | None = None
    #: EngineStats counters that must have these values.
    stats: dict[str, int] = field(default_factory=dict)
    #: (cancelled, recancels) of each StopRecord, in order.
    stops: tuple[tuple[bool, int], ...] = ()
    #: How many info events (a wheel stopped at a limit) and how many faults.
    infos: int = 0
    faults: int = 0


def row(name: str, script: Sequence[Step], expect: Expect, **harness: Any) -> Any:
    """One table row: EngineHarness arguments, the script, and what must hold after it."""
    return pytest.param(harness, script, expect, id=name)


def run_row(harness: dict[str, Any], script: Sequence[Step], expect: Expect) -> EngineHarness:
    h = EngineHarness(**harness)
    for step in script:
        step(h)
    assert h.engine.phase is expect.phase
    if expect.lines is not None:
        assert h.jog_lines() == list(expect.lines)
    if expect.end_x_mm is not None:
        assert h.path_end()[0] == pytest.approx(expect.end_x_mm, abs=1e-9)
    for name, value in expect.stats.items():
        assert getattr(h.engine.stats, name) == value, name
    assert [(s.cancelled, s.recancels) for s in h.engine.stats.stops] == list(expect.stops)
    assert h.event_kinds().count("info") == expect.infos, h.engine.events
    assert len(h.fault_texts()) == expect.faults, h.fault_texts()
    return h


X0 = START_MPOS[0]


def on_grid(x_mm: float) -> float:
    """The step nearest x_mm on X (no ties in these rows)."""
    return round(x_mm * STEPS_PER_MM) / STEPS_PER_MM


POSITION_ROWS = [
    row(
        "37-detents-of-0.01-mm-are-the-nearest-step-in-one-line",
        # 0.37 mm is 29.6 steps: Grbl would run 30 (firmware-facts §1.5), so the line says so.
        [wheel(37), sends("$J", "?")],
        Expect(Phase.STEPPING, lines=(x_line("0.375"),), end_x_mm=on_grid(X0 + 0.37)),
    ),
    row(
        "single-detents-follow-the-running-target-not-a-rounding-each",
        # 0.8 step a detent: targets 1, 2, 2, 3, 4, 5, 6, 6, 7, 8 steps; two reports move no
        # step and send nothing, and ten detents are exactly 0.1 mm (not ten steps, 0.125).
        [sends("?"), *each(10, wheel(1), poll, ok_all)],
        Expect(
            Phase.STEPPING,
            lines=tuple(x_line("0.0125") for _ in range(8)),
            end_x_mm=X0 + 0.1,
        ),
    ),
    row(
        "half-step-targets-round-away-from-machine-zero-as-lround",
        # 0.00625 mm is half a step. Grbl rounds the absolute target with lround (firmware-
        # facts §1.5), ties away from zero; from -80 steps: -79.5 -> -80 (no line), -79,
        # -78.5 -> -79 (no line), then four back: -80.5 -> -81.
        [sends("?"), *each(3, wheel(1, 0.00625), poll, ok_all), wheel(-4, 0.00625), poll],
        Expect(
            Phase.STEPPING,
            lines=(x_line("0.0125"), x_line("-0.025")),
            end_x_mm=X0 - STEP_MM,
        ),
    ),
    row(
        "reports-while-earlier-moves-run-queue-behind-them",
        # Every line answered, the machine still running: the next report goes at once, with
        # no stop, Idle report and fresh start in between.
        [
            wheel(100, 0.1),
            sends("$J", "?"),
            ok,
            poll,
            phase_is(Phase.SETTLING),
            wheel(50, 0.1),
            sends("$J"),
            phase_is(Phase.STEPPING),
            ok,
            poll,
            report("Idle"),
        ],
        Expect(Phase.IDLE, lines=(x_line("10"), x_line("5")), stops=((False, 0),)),
    ),
    row(
        "a-wheel-faster-than-the-machine-merges-into-one-line",
        # 30 mm queued is more than holding full speed needs (11.8 mm): later reports wait and
        # merge, then go as one line when the queue has drained to that.
        [
            wheel(300, 0.1),
            sends("$J", "?"),
            ok,
            *each(3, wheel(10, 0.1), sends()),
            stream(0.6),
        ],
        Expect(Phase.SETTLING, lines=(x_line("30"), x_line("3")), end_x_mm=X0 + 33.0),
    ),
    row(
        "a-reversal-is-a-move-back-after-the-queued-ones",
        # Two reports before one poll: the other way never merges, and nothing is cancelled.
        [wheel(10), wheel(-4), sends("$J", "$J", "?")],
        Expect(
            Phase.STEPPING,
            lines=(x_line("0.1"), x_line("-0.0375")),
            end_x_mm=on_grid(X0 + 0.06),
            stats={"cancels": 0},
        ),
    ),
    row(
        "merging-waits-at-the-planner-reserve",
        # 15 blocks less the reserve of 3: the 13th to 20th reports merge into one line,
        # sent once the machine has run far enough to free a block.
        [
            wheel(1, 0.1),
            sends("$J", "?"),
            *each(11, wheel(1, 0.1), sends("$J")),
            *each(8, wheel(1, 0.1), sends()),
            ok,
            wait(0.05),
            sends("$J"),
        ],
        Expect(
            Phase.STEPPING,
            lines=(*(x_line("0.1") for _ in range(12)), x_line("0.8")),
            end_x_mm=X0 + 2.0,
        ),
        rx_bytes=1024,
    ),
    row(
        "merging-waits-for-rx-room",
        # 101 bytes of another sender's + 19 of ours fill the 128: three reports merge.
        [
            foreign(101),
            wheel(1, 0.1),
            sends("$J", "?"),
            *each(3, wheel(1, 0.1), sends()),
            line("ok"),  # the other sender's reply frees its 101 bytes
            sends("$J"),
        ],
        Expect(Phase.STEPPING, lines=(x_line("0.1"), x_line("0.3")), end_x_mm=X0 + 0.4),
    ),
    row(
        "a-wheel-spun-into-the-soft-limit-stops-one-step-inside",
        # Clipped, not refused: 2 mm toward + stops at -0.0125, the detents past it are dropped
        # (also those of the next report), and turning back moves off the edge at once.
        [
            wheel(200),
            sends("$J", "?"),
            wheel(5),
            sends(),
            wheel(-10),
            sends("$J"),
        ],
        Expect(
            Phase.STEPPING,
            lines=(x_line("0.9875"), x_line("-0.1")),
            end_x_mm=-STEP_MM - 0.1,
            stats={"wheel_clips": 2, "soft_limit_errors": 0},
            infos=1,
        ),
        soft_limits=True,
    ),
    row(
        "a-wheel-stops-one-step-short-of-a-keep-out-zone",
        [wheel(-250, 0.1), sends("$J", "?")],
        Expect(
            Phase.STEPPING,
            lines=(x_line("-18.9875"),),
            end_x_mm=-20.0 + STEP_MM,
            stats={"wheel_clips": 1},
            infos=1,
        ),
        keepouts=(KeepOut("vise", (-30.0, -5.0, -100.0), (-20.0, 5.0, 0.0)),),
    ),
    row(
        "a-line-rounded-past-the-envelope-is-not-sent",
        # 1e5 steps/mm: the edge is 1.00007 mm away, written 1.0001, which lies outside.
        [wheel(300), sends("?")],
        Expect(Phase.SETTLING, lines=(), stats={"wheel_clips": 1}),
        limits={
            "steps_per_mm": (1e5, 1e5, 1e5),
            "envelope": TravelBox((-800.0, -800.0, -800.0), (0.00008, 0.0, 0.0)),
        },
    ),
    row(
        "a-wheel-report-while-a-stick-is-held-stops-the-stick-first",
        [
            intent(ContinuousIntent({"X": -1.0})),
            poll,
            wheel(5, 0.1),
            sends(),  # the stick's lines are unanswered: no cancel yet (firmware-facts §3.1)
            ok_all,
            sends("0x85", "G4P0"),
            ok,
            report("Idle", START_MPOS),
            sends("$J"),
        ],
        Expect(Phase.STEPPING, stops=((True, 0),)),
    ),
    row(
        "a-report-of-no-detents-changes-nothing",
        [intent(ContinuousIntent({"X": -1.0})), poll, wheel(0), poll, phase_is(Phase.JOGGING)],
        Expect(Phase.JOGGING, stats={"cancels": 0}),
    ),
    row(
        "after-a-run-race-the-wheel-waits-for-rest",
        # firmware-facts §9: once a settle has resumed for the wheel and the race comes, the
        # queue runs out by itself and nothing more is sent until Idle.
        [
            wheel(100, 0.1),
            sends("$J", "?"),
            ok,
            poll,
            phase_is(Phase.SETTLING),
            wheel(10, 0.1),
            sends("$J"),
            report("Run", START_MPOS),
            phase_is(Phase.SETTLING),
            wheel(5, 0.1),
            sends(),
            phase_is(Phase.SETTLING),
            ok,
            report("Idle"),
            sends("$J"),
        ],
        Expect(
            Phase.STEPPING,
            lines=(x_line("10"), x_line("1"), x_line("0.5")),
            end_x_mm=X0 + 11.5,
            stops=((False, 0),),
            faults=1,
        ),
    ),
    row(
        "a-target-behind-an-off-grid-start-sends-nothing",
        # After a 0.005 mm step the parser is at -79.6 steps (the machine at -80): the step
        # nearest one more 0.001 mm is -80, behind it; no line goes the wrong way, and the
        # next detent, reaching -79, moves.
        [
            intent(StepIntent("X", 0.005)),
            sends("$J", "?"),
            ok,
            wheel(1, 0.001),
            sends(),
            wheel(1, 0.001),
            sends("$J"),
        ],
        Expect(
            Phase.STEPPING,
            lines=("$J=G21G91X0.005F2500", x_line("0.0075")),
            end_x_mm=X0 + STEP_MM,
        ),
    ),
]


@pytest.mark.parametrize(("harness", "script", "expect"), POSITION_ROWS)
def test_position_mode(harness: dict[str, Any], script: list[Step], expect: Expect) -> None:
    """Every detent moves, in order, exactly on the step grid; merged where it waits anyway."""
    run_row(harness, script, expect)


VELOCITY_ROWS = [
    row(
        "counts-beyond-the-stopping-distance-are-dropped",
        [vel(-1000), sends("$J", "?"), vel(-5), sends()],
        Expect(Phase.STEPPING, lines=(x_line("-11.1"),), stats={"wheel_counts_dropped": 894}),
    ),
    row(
        "the-rounding-to-the-grid-counts-against-the-lead",
        # 30 detents of 0.37037 mm are 11.1111 mm, within 11.1111, but their target is the
        # nearest step, 888.9 -> 889 steps, 11.1125 mm: one detent fewer fits.
        [vel(-1000, 0.37037), sends("$J", "?")],
        Expect(Phase.STEPPING, lines=(x_line("-10.7375"),), stats={"wheel_counts_dropped": 971}),
    ),
    row(
        "the-lead-is-measured-from-where-the-machine-is-now",
        # 0.1 s after the first ok the machine has run ~2.5 mm of the full lead: a report
        # then (with no poll between) finds that much room, not none.
        [vel(-111), sends("$J", "?"), ok, wait(0.1), vel(-50), sends("$J")],
        Expect(
            Phase.STEPPING,
            lines=(x_line("-11.1"), x_line("-2.5")),
            stats={"wheel_counts_dropped": 25},
        ),
    ),
    row(
        "counts-waiting-for-room-are-part-of-the-lead",
        # 111 + 18 bytes do not fit in 128: 5 mm waits, so only 61 of the next 100 detents fit.
        [foreign(111), vel(-50), sends("?"), vel(-100), sends(), line("ok"), sends("$J")],
        Expect(Phase.STEPPING, lines=(x_line("-11.1"),), stats={"wheel_counts_dropped": 39}),
    ),
    row(
        "nothing-is-sent-once-the-wheel-has-been-still-past-the-timeout",
        [foreign(111), vel(-20), sends("?"), wait(0.15), line("ok"), sends()],
        Expect(Phase.SETTLING, lines=(), stats={"wheel_counts_dropped": 20}),
    ),
    row(
        "counts-that-find-room-within-the-timeout-are-sent",
        [foreign(111), vel(-20), sends("?"), wait(0.05), line("ok"), sends("$J")],
        Expect(Phase.STEPPING, lines=(x_line("-2"),), stats={"wheel_counts_dropped": 0}),
    ),
    row(
        "a-reversal-cancels-what-is-queued-then-goes-the-other-way",
        # The lead is full; the reversal's detents are not measured against the path that is
        # being cancelled, so all 50 are kept and run after the stop.
        [
            vel(-111),
            sends("$J", "?"),
            ok,
            vel(50),
            sends("0x85", "G4P0"),
            ok,
            report("Idle", (-3.0, -1.0, -1.0)),
            sends("$J"),
        ],
        Expect(
            Phase.STEPPING,
            lines=(x_line("-11.1"), x_line("5")),
            stats={"cancels": 1, "wheel_counts_dropped": 0},
            stops=((True, 0),),
        ),
    ),
    row(
        "a-reversal-drops-the-counts-still-waiting-the-other-way",
        [foreign(111), vel(-20), sends("?"), vel(5), sends(), line("ok"), sends("$J")],
        Expect(Phase.STEPPING, lines=(x_line("0.5"),), stats={"cancels": 0}),
    ),
    row(
        "a-reversal-outlasting-the-timeout-in-its-stop-still-runs",
        # The stop took 0.3 s: the detents waited for the engine, not for a still wheel.
        [
            vel(-20),
            sends("$J", "?"),
            ok,
            vel(5),
            sends("0x85", "G4P0"),
            ok,
            wait(0.3),
            report("Idle", (-2.0, -1.0, -1.0)),
            sends("$J", "?"),
        ],
        Expect(Phase.STEPPING, lines=(x_line("-2"), x_line("0.5")), stops=((True, 0),)),
    ),
    row(
        "the-other-way-after-the-motion-ended-is-no-reversal",
        # Once the velocity move has run out, a report back is a plain move behind the
        # position-mode one that runs now: nothing is cancelled.
        [
            vel(-5),
            sends("$J", "?"),
            ok,
            poll,
            report("Idle"),
            wheel(100, 0.1),
            sends("$J"),
            ok,
            vel(5),
            sends("$J"),
        ],
        Expect(
            Phase.STEPPING,
            lines=(x_line("-0.5"), x_line("10"), x_line("0.5")),
            stats={"cancels": 0},
            stops=((False, 0),),
        ),
    ),
    row(
        "the-other-way-after-an-alarm-ended-the-motion-is-no-reversal",
        [
            vel(-5),
            sends("$J", "?"),
            ok,
            report("Alarm", START_MPOS),
            report("Idle", START_MPOS),  # unlocked
            wheel(100, 0.1),
            sends("$J"),
            ok,
            vel(5),
            sends("$J"),
        ],
        Expect(
            Phase.STEPPING,
            lines=(x_line("-0.5"), x_line("10"), x_line("0.5")),
            stats={"cancels": 0},
            faults=1,
        ),
    ),
]


@pytest.mark.parametrize(("harness", "script", "expect"), VELOCITY_ROWS)
def test_velocity_mode(harness: dict[str, Any], script: list[Step], expect: Expect) -> None:
    """The machine follows the wheel and stops when it stops (LinuxCNC's MPG velocity mode)."""
    run_row(harness, script, expect)


QUEUED = [  # 12 lines in the planner, 3 detents waiting behind them
    wheel(1, 0.1),
    sends("$J", "?"),
    *each(11, wheel(1, 0.1), sends("$J")),
    *each(3, wheel(1, 0.1), sends()),
]
STOP_ROWS = [
    row(
        f"{name}-drops-the-queued-wheel-moves",
        [
            *QUEUED,
            intent(stop),
            sends(),
            ok_all,
            sends("0x85", "G4P0"),
            ok,
            report("Idle", START_MPOS),
            sends(),
            wait(0.5),
            sends("?"),
        ],
        Expect(Phase.IDLE, lines=tuple(x_line("0.1") for _ in range(12)), stops=((True, 0),)),
        rx_bytes=1024,
    )
    for name, stop in [("stop", StopIntent()), ("neutral", ContinuousIntent({"X": 0.0}))]
]


@pytest.mark.parametrize(("harness", "script", "expect"), STOP_ROWS)
def test_stop_drops_the_wheel(harness: dict[str, Any], script: list[Step], expect: Expect) -> None:
    """A stop or a neutral stick cancels with the full handshake and forgets every detent."""
    h = run_row(harness, script, expect)
    assert not h.engine.busy()


def test_a_report_does_not_push_the_estimate_ahead() -> None:
    """The lead a velocity wheel may keep is measured from the estimate: a status report puts
    it where the machine is at that moment, and a poll at the same moment leaves it there (it
    used to count the time since the previous poll twice: ~4 ms ahead at every report)."""
    h = EngineHarness()
    h.intent(HandwheelIntent("X", -111, 0.1, "velocity"))
    h.poll(0.0)
    h.ok()
    h.poll(0.1)
    h.status("Jog", (X0 - 2.0, -1.0, -1.0), fs=(3000, 0), now_s=0.104)
    queued_mm = h.engine.view(h.t).queued_mm
    h.poll(0.104)
    assert h.engine.view(h.t).queued_mm == pytest.approx(queued_mm, abs=1e-9)
