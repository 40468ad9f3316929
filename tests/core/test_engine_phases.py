"""The jog engine's phase machine, fed scripted replies and reports: one table row per branch.

Each row is a script of what the controller says and what the user asks, with checks of what the
engine sends in between, and what the phase, the faults and the counters must be at the end. The
engine runs on its own (tests/core/engine_harness.py routes lines as the host does); no simulator.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import pytest

from smoothjog.core import increments as inc
from smoothjog.core.engine import EngineLimits, JogTuning, Phase, SendLine
from smoothjog.core.engine.stopper import MAX_RECANCELS
from smoothjog.core.errors import JogBuildError
from smoothjog.core.gcode import TravelBox
from smoothjog.core.intents import ContinuousIntent, GotoIntent, Intent, StepIntent, StopIntent
from smoothjog.core.ledger import ENGINE, Entry
from smoothjog.core.machine import KeepOut, MachineModel
from smoothjog.core.realtime import STATUS_QUERY
from smoothjog.core.responses import Ok, parse_response
from tests.core.engine_harness import (
    ACCEL_MM_S2,
    BANNER,
    MAX_RATE_MM_MIN,
    START_MPOS,
    STEPS_PER_MM,
    EngineHarness,
    Step,
    handshake_lines,
    intent,
    jog_target,
    kinds,
    ok,
    ok_all,
    poll,
    sends,
    wait,
)

Where = Sequence[float] | Callable[[EngineHarness], Sequence[float]]


# ------------------------------------------------------------------------------ script steps


def jog(axes: dict[str, float] | None = None, speed: float = 1.0) -> Step:
    return intent(ContinuousIntent(axes if axes is not None else {"X": -1.0}, speed))


NEUTRAL = jog({"X": 0.0})
STOP = intent(StopIntent())


def sends_jogs(h: EngineHarness) -> None:
    """Poll once: the engine sends several jog lines (how many depends on its tuning) and `?`."""
    got = kinds(h.poll())
    assert got.count("$J") >= 2, got
    assert set(got) <= {"$J", "?"}, got


def stream(dt_s: float) -> Step:
    """Jog on for dt_s: every line answered one 2 ms tick after it was sent."""
    return lambda h: h.run(h.t + dt_s)


def ok_but_one(h: EngineHarness) -> None:
    """Answer every engine line but the newest."""
    for _ in range(len(h.unanswered()) - 1):
        h.ok()


def error(code: int) -> Step:
    def step(h: EngineHarness) -> None:
        h.error(code)

    return step


def line(text: str) -> Step:
    """The controller prints this line (replies go to whoever's line is oldest)."""

    def step(h: EngineHarness) -> None:
        h.feed(text)

    return step


def foreign(text: str) -> Step:
    """Another sender's line takes RX room until its reply."""

    def step(h: EngineHarness) -> None:
        h.foreign_line(text)

    return step


def report(
    state: str, where: Where = START_MPOS, pn: str = "", fs: tuple[float, float] = (0, 0)
) -> Step:
    def step(h: EngineHarness) -> None:
        h.status(state, where(h) if callable(where) else where, pn=pn, fs=fs)

    return step


def path_end(h: EngineHarness) -> Sequence[float]:
    """Where every jog line sent so far ends."""
    return h.path_end()


def rest_at(mpos: Sequence[float]) -> Step:
    """An Idle report at mpos, from where the jogs that follow start."""

    def step(h: EngineHarness) -> None:
        h.rest_at(mpos)

    return step


def acked_end(h: EngineHarness) -> Sequence[float]:
    """Where the jog lines answered so far end."""
    waiting = len([t for t in h.unanswered() if t.startswith("$J=")])
    lines = h.jog_lines()
    return jog_target(h.origin, lines[: len(lines) - waiting])


def check(predicate: Callable[[EngineHarness], object], what: str) -> Step:
    def step(h: EngineHarness) -> None:
        assert predicate(h), what

    return step


def phase_is(phase: Phase) -> Step:
    return check(lambda h: h.engine.phase is phase, f"phase is {phase}")


# ------------------------------------------------------------------------------ the rows
@dataclass(frozen=True)
class Expect:
    """What must hold once the script has run."""

    phase: Phase
    #: Substrings of the fault events, in order; () means no fault at all.
    faults: tuple[str, ...] = ()
    #: EngineStats counters that must have these values.
    stats: dict[str, int] = field(default_factory=dict)
    #: (cancelled, recancels) of each StopRecord, in order.
    stops: tuple[tuple[bool, int], ...] = ()
    #: Event kinds that must not appear.
    never: tuple[str, ...] = ("info",)


def row(
    name: str,
    script: Sequence[Step],
    expect: Expect,
    **harness: Any,
) -> Any:
    """One table row: EngineHarness arguments, the script, and what must hold after it."""
    return pytest.param(harness, script, expect, id=name)


def run_row(harness: dict[str, Any], script: Sequence[Step], expect: Expect) -> EngineHarness:
    """Run the script on a fresh engine and check the expectations."""
    h = EngineHarness(**harness)
    for step in script:
        step(h)
    assert h.engine.phase is expect.phase
    faults = h.fault_texts()
    assert len(faults) == len(expect.faults), faults
    for text, want in zip(faults, expect.faults, strict=True):
        assert want in text
    for name, value in expect.stats.items():
        assert getattr(h.engine.stats, name) == value, name
    assert [(s.cancelled, s.recancels) for s in h.engine.stats.stops] == list(expect.stops)
    for kind in expect.never:
        assert kind not in h.event_kinds()
    return h


# A jog under way: several lines sent at t=0 and none answered yet.
JOGGING = [jog(), sends_jogs]
# A stop asked while those wait: nothing may go out until the last ok (firmware-facts §3.1).
STOPPING = [*JOGGING, NEUTRAL, sends(), ok_but_one, sends(), ok, sends("0x85", "G4P0")]
# The sync line answered: a report is asked for at once to read where the machine rests.
SYNCED = [*STOPPING, ok, sends("?")]

STOP_ROWS = [
    row(
        "neutral-waits-for-every-ok-then-cancels-syncs-and-reads",
        [*SYNCED, report("Idle"), sends()],
        Expect(Phase.IDLE, stats={"cancels": 1, "recancels": 0}, stops=((True, 0),)),
    ),
    row(
        "stop-intent-is-the-same-handshake",
        [*JOGGING, STOP, sends(), ok_all, sends("0x85", "G4P0"), ok, sends("?"), report("Idle")],
        Expect(Phase.IDLE, stats={"cancels": 1}, stops=((True, 0),)),
    ),
    row(
        "stop-waits-for-the-idle-report-not-a-jog-one",
        [*SYNCED, report("Jog"), phase_is(Phase.STOPPING), report("Idle")],
        Expect(Phase.IDLE, stops=((True, 0),)),
    ),
    row(
        "sync-error-9-cancels-again",
        [*STOPPING, error(9), sends("0x85", "G4P0"), ok, sends("?"), report("Idle")],
        Expect(Phase.IDLE, stats={"cancels": 2, "recancels": 1}, stops=((True, 1),)),
    ),
    row(
        "sync-error-9-past-the-limit-fails",
        [
            *STOPPING,
            *[s for _ in range(MAX_RECANCELS) for s in (error(9), sends("0x85", "G4P0"))],
            error(9),
            sends("?"),  # the position is read afresh at once, as after a good sync
            report("Idle"),
        ],
        Expect(
            Phase.IDLE,
            faults=("stop sync failed: error:9",),
            stats={"recancels": MAX_RECANCELS, "cancels": MAX_RECANCELS + 1},
            stops=((True, MAX_RECANCELS),),
        ),
    ),
    row(
        "sync-other-error-fails-at-once",
        [*STOPPING, error(20), sends("?"), report("Idle")],
        Expect(
            Phase.IDLE,
            faults=("stop sync failed: error:20",),
            stats={"recancels": 0, "error_replies": 1},
            stops=((True, 0),),
        ),
    ),
    row(
        "stop-in-idle-sends-nothing",
        [sends("?"), STOP, sends(), phase_is(Phase.IDLE)],
        Expect(Phase.IDLE),
    ),
    row(
        "stop-in-idle-while-the-controller-jogs-cancels",
        # Another sender's jog runs (Jog reported) with nothing of ours queued: cancel it anyway.
        [report("Jog"), STOP, sends("0x85", "G4P0", "?"), ok, report("Idle")],
        Expect(Phase.IDLE, stats={"cancels": 1}, stops=((True, 0),)),
    ),
    row(
        "stop-while-stepping-waits-for-the-oks",
        [
            intent(StepIntent("X", -1.0)),
            intent(StepIntent("X", -1.0)),
            sends("$J", "$J", "?"),
            STOP,
            sends(),
            ok_all,
            sends("0x85", "G4P0"),
            ok,
            report("Idle"),
        ],
        Expect(Phase.IDLE, stops=((True, 0),)),
    ),
    row(
        "stop-while-settling-cancels-the-queue",
        [
            intent(StepIntent("X", -1.0)),
            sends("$J", "?"),
            ok,
            poll,
            phase_is(Phase.SETTLING),
            STOP,
            sends("0x85", "G4P0"),
            ok,
            report("Idle"),
        ],
        Expect(Phase.IDLE, stops=((True, 0),)),
    ),
]


@pytest.mark.parametrize(("harness", "script", "expect"), STOP_ROWS)
def test_stop_handshake(harness: dict[str, Any], script: list[Step], expect: Expect) -> None:
    """The full stop of firmware-facts §3.1 and §3.6, and its re-cancel on error:9."""
    run_row(harness, script, expect)


REPLY_ROWS = [
    row(
        "jog-error-15-faults-and-stops",
        [*JOGGING, error(15), phase_is(Phase.STOPPING), sends(), ok_all, sends("0x85", "G4P0")],
        Expect(
            Phase.STOPPING,
            faults=("jog rejected: error:15 the jog target lies outside",),
            stats={"soft_limit_errors": 1, "error_replies": 1},
        ),
        soft_limits=True,
    ),
    row(
        "jog-error-while-stepping-faults-and-stops",
        [
            intent(StepIntent("X", -1.0)),
            intent(StepIntent("Y", -1.0)),
            sends("$J", "$J", "?"),
            error(20),
            ok,
            sends("0x85", "G4P0"),
        ],
        Expect(
            Phase.STOPPING,
            faults=("jog rejected: error:20",),
            stats={"soft_limit_errors": 0, "error_replies": 1},
        ),
    ),
    row(
        "jog-error-while-settling-faults-and-stops",
        [intent(StepIntent("X", -1.0)), sends("$J", "?"), error(15), sends("G4P0")],
        Expect(Phase.STOPPING, faults=("jog rejected: error:15",)),
    ),
    row(
        "jog-error-while-stopping-keeps-the-handshake",
        [*JOGGING, NEUTRAL, poll, error(15), ok_all, sends("0x85", "G4P0"), ok, report("Idle")],
        Expect(Phase.IDLE, faults=("jog rejected: error:15",), stops=((True, 0),)),
    ),
]


@pytest.mark.parametrize(("harness", "script", "expect"), REPLY_ROWS)
def test_replies_to_jog_lines(harness: dict[str, Any], script: list[Step], expect: Expect) -> None:
    """A rejected G91 jog leaves every later increment off: fault, stop, re-sync."""
    run_row(harness, script, expect)


RACE = "the controller ran a jog block in Run state (a Grbl race)"
HOLD_INPUT = "input was pressed: the controller is stopping"
OUTSIDE = "the jog was stopped outside smoothjog"
LEFT_PATH = "it left the path smoothjog sent"
STEPPING = [intent(StepIntent("X", -1.0)), intent(StepIntent("X", -1.0)), sends("$J", "$J", "?")]

STATUS_ROWS = [
    row(
        "run-while-jogging-settles",
        [
            *JOGGING,
            ok,
            report("Run"),
            phase_is(Phase.SETTLING),
            sends(),
            ok_all,
            sends(),
            report("Idle", path_end),
        ],
        Expect(Phase.IDLE, faults=(RACE,), stats={"run_state_seen": 1}, stops=((False, 0),)),
    ),
    row(
        "run-while-stepping-settles",
        [*STEPPING, ok, report("Run"), phase_is(Phase.SETTLING), ok, report("Idle", path_end)],
        Expect(Phase.IDLE, faults=(RACE,), stats={"run_state_seen": 1}, stops=((False, 0),)),
    ),
    row(
        "run-while-stopping-drops-the-handshake",
        [*STOPPING, report("Run"), phase_is(Phase.SETTLING), ok, sends(), report("Idle")],
        Expect(Phase.IDLE, faults=(RACE,), stats={"run_state_seen": 1}, stops=((False, 0),)),
    ),
    row(
        "settling-waits-for-every-reply",
        [*STEPPING, ok, report("Run"), report("Idle", path_end), phase_is(Phase.SETTLING)],
        Expect(Phase.SETTLING, faults=(RACE,)),
    ),
    row(
        "run-while-idle-is-no-race",
        [report("Run"), sends("?")],
        Expect(Phase.IDLE, stats={"run_state_seen": 0}),
    ),
    row(
        "feed-hold-input-while-jogging-abandons",
        # The state still reads Jog, so the lines left unanswered are cancelled at once.
        [*JOGGING, ok, report("Jog", pn="H"), phase_is(Phase.IDLE), ok_all, sends("0x85", "G4P0")],
        Expect(Phase.STOPPING, faults=(HOLD_INPUT,)),
    ),
    row(
        "door-input-while-stepping-abandons",
        [*STEPPING, report("Jog", pn="D"), phase_is(Phase.IDLE), ok_all, sends("0x85", "G4P0")],
        Expect(Phase.STOPPING, faults=(HOLD_INPUT,)),
    ),
    row(
        "door-input-while-settling-abandons",
        [intent(StepIntent("X", -1.0)), sends("$J", "?"), ok, report("Jog", pn="D")],
        Expect(Phase.IDLE, faults=(HOLD_INPUT,)),
    ),
    row(
        "other-pins-are-ignored",
        [*JOGGING, ok, report("Jog", pn="XPRS"), phase_is(Phase.JOGGING)],
        Expect(Phase.JOGGING),
    ),
    row(
        "hold-input-while-idle-is-no-fault",
        [report("Idle", pn="H"), sends("?")],
        Expect(Phase.IDLE, never=("fault",)),
    ),
    row(
        "hold-input-active-since-rest-still-jogs",
        # Grbl acts on a change of the input, not its level (a floating or inverted pin):
        # the pin that read active at rest is no press, so the jog runs on.
        [report("Idle", pn="PH"), *JOGGING, ok, report("Jog", pn="PH"), phase_is(Phase.JOGGING)],
        Expect(Phase.JOGGING, never=("fault",)),
    ),
    row(
        "door-input-pressed-beside-a-stuck-hold-input-abandons",
        [report("Idle", pn="H"), *JOGGING, ok, report("Jog", pn="HD"), phase_is(Phase.IDLE)],
        Expect(Phase.IDLE, faults=("door input was pressed",), never=()),
    ),
    row(
        "idle-short-of-the-path-while-jogging",
        [*JOGGING, ok_all, report("Idle"), sends("0x85", "G4P0")],
        Expect(Phase.STOPPING, faults=(OUTSIDE,)),
    ),
    row(
        "idle-at-the-acked-end-is-a-dry-queue",
        [*JOGGING, ok, ok, report("Idle", acked_end)],
        Expect(Phase.JOGGING),
    ),
    row(
        "idle-at-the-end-of-a-clipped-queue",
        # Soft limits clip the jog toward + at the edge: the queue runs out there, no fault, and
        # the estimate rests at the end at once (it would still be braking toward it).
        [
            jog({"X": 1.0}),
            stream(0.03),
            ok_all,
            check(lambda h: not h.engine.track.at_rest_at_end(), "still on its way"),
            report("Idle", path_end),
            check(lambda h: h.engine.track.at_rest_at_end(), "known to rest at the end"),
            sends(),
        ],
        Expect(Phase.JOGGING, never=("fault",)),
        soft_limits=True,
    ),
    row(
        "off-every-segment-while-jogging",
        # The report showed a jog running off the path: once every line is answered, cancel
        # what runs and sync.
        [
            *JOGGING,
            ok,
            report("Jog", (-1.0, 5.0, -1.0), fs=(5000, 0)),
            sends(),
            ok_all,
            sends("0x85", "G4P0"),
        ],
        Expect(Phase.STOPPING, faults=(LEFT_PATH,)),
    ),
    row(
        "off-the-path-while-stepping-is-no-desync",
        [*STEPPING, ok, report("Jog", (-1.0, 5.0, -1.0))],
        Expect(Phase.STEPPING),
    ),
    *[
        row(
            f"{state.lower()}-while-jogging-abandons",
            [*JOGGING, ok, report(state), ok_all, sends()],
            Expect(Phase.IDLE, faults=(f"jogging stopped: {reason}",)),
        )
        for state, reason in [
            ("Alarm", "the controller is in Alarm"),
            ("Hold:0", "the controller is in feed hold"),
            ("Door:1", "the safety door is open"),
            ("Check", "the controller is in check mode"),
            ("Home", "the controller is homing"),
            ("Sleep", "the controller is asleep"),
            ("Tool", "the controller is in state Tool"),
        ]
    ],
    row(
        "alarm-while-stopping-abandons",
        [*SYNCED, report("Alarm")],
        Expect(Phase.IDLE, faults=("jogging stopped: the controller is in Alarm",)),
    ),
    row(
        "alarm-while-idle-is-no-fault",
        [report("Alarm"), sends("?")],
        Expect(Phase.IDLE),
    ),
]


@pytest.mark.parametrize(("harness", "script", "expect"), STATUS_ROWS)
def test_status_reports(harness: dict[str, Any], script: list[Step], expect: Expect) -> None:
    """What each report does to a jog under way (firmware-facts §1.4, §3.2, §3.3, §9)."""
    run_row(harness, script, expect)


DOOR = "the safety door opened"
CANCEL_OWED_ROWS = [
    row(
        "door-message-with-jogs-unanswered-cancels-after-resume",
        [
            *JOGGING,
            ok,
            line("[MSG:Check Door]"),
            # The model still holds the last report's state (Idle), so the owed cancel begins a
            # stop at once; it waits for the oks, and the Door report abandons it (a 2nd fault).
            sends(),
            report("Door:0"),
            sends(),
            report("Idle"),
            # The stale lines run after the resume (firmware-facts §3.1): wait for their oks.
            sends(),
            ok_all,
            report("Jog"),
            sends("0x85", "G4P0"),
            ok,
            report("Idle"),
        ],
        Expect(
            Phase.IDLE,
            faults=(DOOR, "jogging stopped: the safety door is open"),
            stats={"cancels": 1},
            stops=((True, 0),),
        ),
    ),
    row(
        "owed-cancel-waits-for-every-stale-line-then-cancels-them-together",
        # After the resume the stale lines run on their own, parsed together into Grbl's empty
        # planner: one 0x85 after the last ok throws them all away (firmware-facts §3.7). A
        # cancel at the first report of one running would keep the rest in the RX buffer, to
        # start one after another.
        [
            *JOGGING,
            report("Door:1"),
            report("Idle"),
            sends(),
            report("Jog", fs=(300, 0)),
            sends(),
            ok_all,
            report("Jog", fs=(600, 0)),
            sends("0x85", "G4P0"),
        ],
        Expect(
            Phase.STOPPING,
            faults=("jogging stopped: the safety door is open",),
            stats={"cancels": 1},
        ),
    ),
    row(
        "door-report-with-jogs-unanswered-cancels-once-jog-again",
        [*JOGGING, report("Door:1"), ok_all, report("Jog"), sends("0x85", "G4P0")],
        Expect(Phase.STOPPING, faults=("jogging stopped: the safety door is open",)),
    ),
    row(
        "hold-report-with-jogs-unanswered-cancels-once-idle",
        [*JOGGING, report("Hold:0"), sends(), ok_all, report("Idle"), sends("0x85", "G4P0")],
        Expect(Phase.STOPPING, faults=("jogging stopped: the controller is in feed hold",)),
    ),
    row(
        "alarm-with-jogs-unanswered-cancels-once-unlocked",
        [
            *JOGGING,
            line("ALARM:1"),
            ok_all,
            report("Alarm"),
            sends(),
            report("Idle"),
            sends("0x85", "G4P0"),
        ],
        Expect(Phase.STOPPING, faults=("ALARM:1",)),
    ),
    row(
        "door-with-every-jog-answered-owes-no-cancel",
        [*JOGGING, ok_all, line("[MSG:Check Door]"), report("Door:0"), report("Idle"), sends()],
        Expect(Phase.IDLE, faults=(DOOR,), stats={"cancels": 0}),
    ),
    row(
        "other-messages-change-nothing",
        [*JOGGING, line("[MSG:Pgm End]"), phase_is(Phase.JOGGING)],
        Expect(Phase.JOGGING),
    ),
]


@pytest.mark.parametrize(("harness", "script", "expect"), CANCEL_OWED_ROWS)
def test_cancel_owed_after_door_or_hold(
    harness: dict[str, Any], script: list[Step], expect: Expect
) -> None:
    """Jogs left unanswered by a door or hold run after the resume: cancel them then (§3.3)."""
    run_row(harness, script, expect)


NOT_SENT = "jog not sent: "
BUILD_ROWS = [
    row(
        "jog-line-too-long-for-the-controller",
        [
            jog(),
            sends("G4P0", "?"),  # nothing moved: the sync line alone, no cancel
            ok,
            report("Idle"),
            phase_is(Phase.IDLE),
            jog(),
            sends("G4P0"),  # the engine keeps working: the same refusal, not a crash
        ],
        Expect(
            Phase.STOPPING,
            faults=(NOT_SENT + "the jog line", NOT_SENT + "the jog line"),
            stops=((False, 0),),
        ),
        limits={"max_line_chars": 10},
    ),
    row(
        "step-line-too-long-for-the-controller",
        [intent(StepIntent("X", -1.0)), sends("G4P0", "?")],
        Expect(Phase.STOPPING, faults=(NOT_SENT,)),
        limits={"max_line_chars": 10},
    ),
    row(
        "go-to-beyond-what-grbl-can-write",
        [
            intent(GotoIntent({"X": -1e9})),
            sends("G4P0", "?"),
            ok,
            report("Idle"),
            intent(StepIntent("X", -1.0)),
            sends("$J"),
            ok,
            poll,
            report("Idle", path_end),
        ],
        Expect(
            Phase.IDLE,
            faults=(NOT_SENT + "cannot write -1000000000.0",),
            stops=((False, 0), (False, 0)),
        ),
    ),
]


@pytest.mark.parametrize(("harness", "script", "expect"), BUILD_ROWS)
def test_lines_that_cannot_be_built(
    harness: dict[str, Any], script: list[Step], expect: Expect
) -> None:
    """A JogBuildError inside poll is a fault and a stop, never an exception out of poll."""
    run_row(harness, script, expect)


RESET = "the controller was reset"
RESET_ROWS = [
    row(
        "banner-mid-session-forgets-every-line-and-owes-a-cancel",
        [
            *JOGGING,
            ok,
            line(""),
            line(BANNER),
            phase_is(Phase.IDLE),
            check(lambda h: "jog lines had no reply yet" in h.fault_texts()[0], "says so"),
            check(lambda h: h.engine.can_jog()[0] is False, "no jog before a report"),
            # The reset dropped the `?` still pending: one goes out at once.
            sends("?"),
            report("Idle"),
            intent(StepIntent("X", -1.0)),
            # Jog lines still on the wire at the reset may start the restarted controller:
            # the owed cancel and its sync come first (the sync waits behind any such line).
            sends("0x85", "G4P0"),
            ok,  # goes to the sync: the lines lost to the reset are forgotten
            report("Idle"),
            sends("$J"),
            ok,
            poll,
            phase_is(Phase.SETTLING),
            report("Idle", (-2.0, -1.0, -1.0)),
        ],
        Expect(Phase.IDLE, faults=(RESET,), stops=((True, 0), (False, 0))),
    ),
    row(
        "banner-with-every-jog-answered-owes-nothing",
        [
            *JOGGING,
            ok_all,
            line(BANNER),
            report("Idle"),
            intent(StepIntent("X", -1.0)),
            sends("$J"),
        ],
        Expect(Phase.STEPPING, faults=(RESET,)),
    ),
    row(
        "alarm-abandons-motion",
        [*JOGGING, ok, line("ALARM:2"), ok_all, sends(), phase_is(Phase.IDLE)],
        Expect(Phase.IDLE, faults=("ALARM:2 a G-code move would have left the machine's travel",)),
    ),
]


@pytest.mark.parametrize(("harness", "script", "expect"), RESET_ROWS)
def test_resets_and_alarms(harness: dict[str, Any], script: list[Step], expect: Expect) -> None:
    """A banner or ALARM:N ends the jog where it is (firmware-facts §3.4, §5.6)."""
    run_row(harness, script, expect)


ZONE = KeepOut("vise", (-30.0, -30.0, -100.0), (-20.0, -20.0, 0.0))
STEP_ROWS = [
    row(
        "steps-and-go-to-in-order-then-settle",
        [
            intent(StepIntent("X", -1.0)),
            intent(StepIntent("Y", -2.5, speed=0.25)),
            intent(GotoIntent({"X": -10.0, "Z": -3.0})),
            check(lambda h: h.engine.busy(), "steps queued are busy"),
            sends("$J", "$J", "$J", "?"),
            check(
                lambda h: (
                    h.jog_lines()
                    == ["$J=G21G91X-1F2500", "$J=G21G91Y-2.5F1250", "$J=G21G53X-10Z-3F2576.941"]
                ),
                "the lines in order",
            ),
            ok_all,
            sends(),
            phase_is(Phase.SETTLING),
            report("Idle", (-10.0, -3.5, -3.0)),
            check(lambda h: not h.engine.busy(), "idle after the settle"),
        ],
        Expect(Phase.IDLE, stops=((False, 0),)),
    ),
    row(
        "step-past-the-soft-limit-is-shortened-and-says-so",
        # Homed at -1 with the + soft limit at 0: a 5 mm step goes to one step inside it.
        [
            intent(StepIntent("X", 5.0)),
            sends("$J", "?"),
            check(lambda h: h.jog_lines() == ["$J=G21G91X0.9875F2500"], "shortened"),
            check(
                lambda h: any(
                    "step X+ shortened to 0.9875 mm (asked 5 mm): the soft limit" in e.text
                    for e in h.engine.events
                ),
                "says so",
            ),
        ],
        Expect(Phase.STEPPING, never=("fault",)),
        soft_limits=True,
    ),
    row(
        "step-with-no-room-is-refused-in-words",
        [
            rest_at((-0.0125, -1.0, -1.0)),
            intent(StepIntent("X", 5.0)),
            sends("?"),
            report("Idle", (-0.0125, -1.0, -1.0)),
        ],
        Expect(
            Phase.IDLE,
            faults=("step refused: no room to jog X+, the soft limit is there (at X -0.01",),
            stops=((False, 0),),
        ),
        soft_limits=True,
    ),
    row(
        "go-to-through-a-keep-out-refused",
        [intent(GotoIntent({"X": -50.0, "Y": -50.0})), sends("?")],
        Expect(Phase.SETTLING, faults=("jog refused: the path crosses the keep-out zone 'vise'",)),
        keepouts=(ZONE,),
    ),
    row(
        "go-to-where-the-machine-is-sends-nothing",
        [intent(GotoIntent({"X": -1.0})), sends("?")],
        Expect(Phase.SETTLING),
    ),
    row(
        "steps-never-fill-the-planner-past-the-reserve",
        [
            *[intent(StepIntent("X", -1.0)) for _ in range(14)],
            sends(*["$J"] * 12, "?"),  # 15 usable blocks less the reserve of 3
            ok,
            ok,
            wait(0.5),
            sends("$J", "$J", "?"),
        ],
        Expect(Phase.STEPPING),
        rx_bytes=1024,
    ),
    row(
        "steps-wait-for-rx-room",
        [
            foreign("$" * 100),
            intent(StepIntent("X", -1.0)),
            intent(StepIntent("X", -1.0)),
            sends("$J", "?"),  # 101 + 18 bytes of the 128: the second waits
            line("ok"),  # the foreign line's reply
            sends("$J"),
        ],
        Expect(Phase.STEPPING),
    ),
    row(
        "a-held-stick-waits-for-the-machine-position",
        [jog(), sends("?"), phase_is(Phase.IDLE), check(lambda h: h.engine.busy(), "held")],
        Expect(Phase.IDLE),
        handshake=["[OPT:V,15,128]", "<Idle|WPos:0.000,0.000,0.000|FS:0,0>"],
    ),
    row(
        "a-step-waits-for-the-machine-position",
        [intent(StepIntent("X", 1.0)), sends("?"), sends()],
        Expect(Phase.STEPPING),
        handshake=["[OPT:V,15,128]", "<Idle|WPos:0.000,0.000,0.000|FS:0,0>"],
    ),
]


@pytest.mark.parametrize(("harness", "script", "expect"), STEP_ROWS)
def test_steps_and_go_to(harness: dict[str, Any], script: list[Step], expect: Expect) -> None:
    """Steps and go-tos are sent in order, within the planner and RX room, and checked first."""
    run_row(harness, script, expect)


# ------------------------------------------------------------------------------ single checks
@pytest.mark.parametrize(
    ("state", "soft_limits", "mpos", "reason"),
    [
        pytest.param("Idle", False, START_MPOS, None, id="idle"),
        pytest.param("Jog", False, START_MPOS, None, id="jog"),
        pytest.param("Alarm", False, START_MPOS, "the controller is in Alarm", id="alarm"),
        pytest.param("Hold:0", False, START_MPOS, "the controller is in feed hold", id="hold"),
        pytest.param("Door:0", False, START_MPOS, "the safety door is open", id="door"),
        pytest.param("Check", False, START_MPOS, "check mode ($C)", id="check"),
        pytest.param("Run", False, START_MPOS, "running a program", id="run"),
        pytest.param("Home", False, START_MPOS, "the controller is homing", id="home"),
        pytest.param("Sleep", False, START_MPOS, "asleep", id="sleep"),
        pytest.param("Tool", False, START_MPOS, "the controller is in state Tool", id="unknown"),
        # Unhomed (MPos 0 after $X) jogs, so a machine on a limit switch can be jogged off it.
        pytest.param("Idle", True, (0.0, 0.0, 0.0), None, id="unhomed-soft-limits"),
        pytest.param("Idle", False, (0.0, 0.0, 0.0), None, id="at-zero-without-soft-limits"),
        pytest.param("Idle", True, START_MPOS, None, id="homed-soft-limits"),
    ],
)
def test_can_jog_says_why_not(
    state: str, soft_limits: bool, mpos: tuple[float, ...], reason: str | None
) -> None:
    h = EngineHarness(soft_limits=soft_limits)
    h.status(state, mpos)
    allowed, why = h.engine.can_jog()
    view = h.engine.view(h.t)
    assert (allowed, view.can_jog) == (reason is None, reason is None)
    if reason is None:
        assert why is None
    else:
        assert why is not None
        assert reason in why
        assert view.reason == why


def test_can_jog_waits_for_the_first_report() -> None:
    h = EngineHarness(handshake=["[OPT:V,15,128]"])
    assert h.engine.can_jog() == (False, "waiting for the controller's first status report")
    h.intent(ContinuousIntent({"X": 1.0}))
    assert kinds(h.poll()) == ["?"]
    assert h.engine.phase is Phase.IDLE
    assert h.engine.view(h.t).stop_point_mm is None  # no position yet


V_MM_S = MAX_RATE_MM_MIN / 60.0


def streaming(h: EngineHarness, until_s: float) -> list[tuple[float, float, int]]:
    """Jog -X at full speed until until_s; (t, queued mm, queued blocks) after every poll."""
    h.intent(ContinuousIntent({"X": -1.0}))
    seen = []
    while h.t < until_s:
        h.run(h.t + 0.002)
        view = h.engine.view(h.t)
        seen.append((h.t, view.queued_mm, view.queued_blocks))
    return seen


def test_streaming_keeps_the_stopping_distance_and_the_round_trip_queued() -> None:
    """Once the first lines are answered the queue never drops below v²/2a + v·(committed + rtt)."""
    h = EngineHarness(rx_bytes=1024)
    seen = streaming(h, 0.3)
    # Every line is answered after one 2 ms tick; 10.5 ms blocks commit at most 31 ms (§4.1).
    target_mm = inc.queue_target_mm(V_MM_S, ACCEL_MM_S2, inc.committed_s(0.0105) + 0.002)
    steady = [q for t, q, _ in seen if t >= 0.01]
    assert min(steady) >= target_mm
    usable = h.engine.limits.planner_blocks - h.engine.tuning.planner_reserve_blocks
    assert max(blocks for _, _, blocks in seen) <= usable
    assert h.engine.view(h.t).commanded_speed_mm_s == pytest.approx(V_MM_S)


@pytest.mark.parametrize(
    ("planner_blocks", "reserve"), [(6, 3), (8, 3), (15, 3), (15, 10)], ids=str
)
def test_streaming_never_fills_the_planner_past_the_reserve(
    planner_blocks: int, reserve: int
) -> None:
    """No more blocks are queued than the planner holds less the reserve (an ok never waits)."""
    h = EngineHarness(
        rx_bytes=4096,
        limits={"planner_blocks": planner_blocks},
        tuning=JogTuning(planner_reserve_blocks=reserve, link_margin_s=0.5),
    )
    h.intent(ContinuousIntent({"X": -1.0}))
    first = [o for o in h.poll() if isinstance(o, SendLine)]
    assert len(first) == planner_blocks - reserve  # the long queue wanted is cut by the planner
    seen = streaming(h, 0.2)
    assert max(blocks for _, _, blocks in seen) <= planner_blocks - reserve


def test_streaming_shares_the_rx_buffer_with_other_senders() -> None:
    """A foreign line in the RX buffer leaves the engine less room, never an overrun (§5.1)."""
    alone = EngineHarness()
    alone.intent(ContinuousIntent({"X": -1.0}))
    n_alone = len([o for o in alone.poll() if isinstance(o, SendLine)])

    shared = EngineHarness()
    shared.foreign_line("$G" + "X" * 98)  # 101 bytes of the 128
    shared.intent(ContinuousIntent({"X": -1.0}))
    sent = [o.text for o in shared.poll() if isinstance(o, SendLine)]
    assert 1 <= len(sent) < n_alone
    assert sum(len(text) + 1 for text in sent) <= 128 - 101
    assert shared.ledger.in_flight_bytes <= 128
    # The foreign line's reply goes to its owner; the room it frees goes to the engine.
    shared.feed("ok")
    assert [entry.owner for entry, _ in shared.other_replies] == ["foreign:cncjs"]
    while shared.unanswered():
        shared.ok()
    assert len([o for o in shared.poll() if isinstance(o, SendLine)]) >= 1


@pytest.mark.parametrize(
    ("new_axes", "speed", "tuning", "choice"),
    [
        pytest.param({"X": 1.0}, 1.0, JogTuning(), "let-run", id="reverse-short-queue"),
        pytest.param({"Y": 1.0}, 1.0, JogTuning(), "let-run", id="right-angle"),
        pytest.param({"X": -1.0}, 0.3, JogTuning(), "let-run", id="slow-down"),
        pytest.param(
            {"X": 1.0}, 1.0, JogTuning(link_margin_s=0.2), "cancel", id="reverse-long-queue"
        ),
        pytest.param({"X": -1.0, "Y": -0.2}, 1.0, JogTuning(), None, id="small-change"),
        pytest.param({"X": -1.0}, 1.0, JogTuning(), None, id="same-intent-again"),
        pytest.param({"X": -0.001}, 0.001, JogTuning(), None, id="to-below-the-slowest-feed"),
    ],
)
def test_turns_pick_the_faster_of_let_run_and_cancel(
    new_axes: dict[str, float], speed: float, tuning: JogTuning, choice: str | None
) -> None:
    h = EngineHarness(rx_bytes=1024, tuning=tuning)
    streaming(h, 0.1)
    h.intent(ContinuousIntent(new_axes, speed))
    h.poll()
    choices = [c for _, c, _, _ in h.engine.stats.turn_choices]
    assert choices == ([] if choice is None else [choice])
    assert h.engine.phase is (Phase.STOPPING if choice == "cancel" else Phase.JOGGING)


def test_a_stick_below_grbls_slowest_feed_sends_nothing() -> None:
    """Below 1 mm/min (firmware-facts §4.2) the stick counts as neutral."""
    h = EngineHarness()
    h.intent(ContinuousIntent({"X": 0.001}, speed=0.001))
    assert kinds(h.poll()) == ["?"]
    assert h.engine.phase is Phase.JOGGING
    assert h.engine.view(h.t).queued_mm == 0.0


def test_a_reply_out_of_order_is_reported_not_acted_on() -> None:
    """Grbl answers in order; a reply the engine cannot place is an info event, no crash."""
    h = EngineHarness()
    h.intent(ContinuousIntent({"X": -1.0}))
    h.poll()
    first, second, *_ = h.ledger.outstanding()
    h.engine.on_reply(second, Ok(), h.t)  # the second line's reply while the first waits
    assert [e.kind for e in h.engine.events] == ["info"]
    assert "came out of order" in h.engine.events[-1].text
    stranger = Entry(ENGINE, "$J=G21G91X-1F100", 19, 0.0)
    h.engine.on_reply(stranger, Ok(), h.t)  # never sent by this engine at all
    assert h.event_kinds() == ["info", "info"]
    h.engine.on_reply(first, Ok(), h.t)  # the oldest is still placed normally
    assert h.event_kinds() == ["info", "info"]
    assert h.engine.phase is Phase.JOGGING


@pytest.mark.parametrize(
    ("ratios", "message"),
    [
        pytest.param({"A": 0.5}, "speed ratio for unknown axis 'A'", id="unknown-axis"),
        pytest.param({"X": 0.0}, "speed ratio 0.0 for X must be in (0, 1]", id="zero"),
        pytest.param({"Y": 1.5}, "speed ratio 1.5 for Y must be in (0, 1]", id="above-one"),
        pytest.param({"Z": -0.25}, "must be in (0, 1]", id="negative"),
    ],
)
def test_set_speed_ratios_refuses(ratios: dict[str, float], message: str) -> None:
    h = EngineHarness()
    with pytest.raises(JogBuildError, match=re.escape(message)):
        h.engine.set_speed_ratios(ratios)


def test_speed_ratios_scale_the_feed() -> None:
    h = EngineHarness()
    h.engine.set_speed_ratios({"X": 0.5, "Z": 1.0})
    h.intent(ContinuousIntent({"X": -1.0}))
    h.poll()
    assert all(text.endswith("F2500") for text in h.jog_lines())


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        pytest.param(ContinuousIntent({"A": 1.0}), "cannot jog axis 'A'", id="continuous"),
        pytest.param(StepIntent("X", 500.0), "outside 0.001 to 100.0 mm", id="step"),
        pytest.param(GotoIntent({}), "needs at least one axis", id="go-to"),
    ],
)
def test_invalid_intents_are_refused_at_once(bad: Intent, message: str) -> None:
    h = EngineHarness()
    with pytest.raises(JogBuildError, match=re.escape(message)):
        h.intent(bad)
    assert not h.engine.busy()
    assert kinds(h.poll()) == ["?"]


def test_view_while_jogging_and_after_a_fault() -> None:
    h = EngineHarness()
    idle = h.engine.view(0.0)
    assert (idle.phase, idle.state, idle.can_jog, idle.reason) == ("idle", "Idle", True, None)
    assert idle.mpos_mm == START_MPOS
    assert idle.stop_point_mm == START_MPOS  # at rest: where it is
    assert (idle.queued_mm, idle.queued_blocks, idle.commanded_speed_mm_s) == (0.0, 0, 0.0)
    assert idle.fault is None

    streaming(h, 0.1)
    before, after = (jog_target(START_MPOS, h.jog_lines()[:n]) for n in (2, 3))
    h.status("Jog", before, fs=(5000, 0))
    h.advance(0.01)
    h.status("Jog", after, fs=(5000, 0))
    view = h.engine.view(h.t)
    assert view.phase == "jogging"
    assert view.state == "Jog"
    assert view.feed_mm_min == 5000.0
    assert view.commanded_speed_mm_s == pytest.approx(V_MM_S)
    assert view.actual_speed_mm_s == pytest.approx(math.dist(before, after) / 0.01, rel=1e-3)
    assert view.queued_mm > 0.0
    assert view.queued_blocks > 0
    assert view.stop_point_mm is not None
    assert view.stop_point_mm[0] < START_MPOS[0]  # ahead on the -X path
    assert view.t_s == h.t

    h.status("Alarm")
    view = h.engine.view(h.t)
    assert view.fault is not None
    assert view.fault[0].startswith("jogging stopped: the controller is in Alarm")
    assert view.actual_speed_mm_s >= 0.0
    assert (view.can_jog, view.phase) == (False, "idle")
    h.engine.clear_fault()
    assert h.engine.view(h.t).fault is None


def test_busy_follows_intents_steps_and_phases() -> None:
    h = EngineHarness()
    assert not h.engine.busy()
    h.intent(ContinuousIntent({"X": -1.0}))
    assert h.engine.busy()  # an intent held, nothing sent yet
    h.intent(StopIntent())
    assert not h.engine.busy()
    h.intent(StepIntent("X", -1.0))
    assert h.engine.busy()
    h.poll()
    h.ok()
    h.poll()
    assert h.engine.phase is Phase.SETTLING
    assert h.engine.busy()
    h.status("Idle", (-2.0, -1.0, -1.0))
    assert not h.engine.busy()


def test_status_is_polled_and_re_asked_when_unanswered() -> None:
    """One `?` at a time (§5.2), again after the timeout; faster while busy than at rest."""
    h = EngineHarness()
    tuning = h.engine.tuning
    assert kinds(h.poll(0.0)) == ["?"]
    assert kinds(h.poll(tuning.status_timeout_s / 2)) == []  # asked, no report yet
    assert kinds(h.poll(tuning.status_timeout_s)) == ["?"]  # asked again
    h.status("Idle")
    t0 = h.t
    assert kinds(h.poll(t0 + tuning.poll_idle_s / 2)) == []
    assert kinds(h.poll(t0 + tuning.poll_idle_s)) == ["?"]
    h.status("Jog")  # someone else's jog: polled at the moving rate
    t1 = h.t
    assert kinds(h.poll(t1 + tuning.poll_moving_s)) == ["?"]


@pytest.mark.parametrize(
    "script",
    [
        pytest.param([], id="idle"),
        pytest.param(JOGGING, id="jogging"),
        pytest.param(STEPPING, id="stepping"),
        pytest.param(STOPPING, id="stopping"),
        pytest.param(SYNCED, id="waiting-for-status"),
        pytest.param([*STEPPING, ok_all, poll], id="settling"),
        pytest.param([*STOPPING, ok], id="sync-answered"),
        pytest.param([jog(), stream(0.05)], id="streaming"),
        pytest.param([jog(), stream(0.05), ok_all], id="streaming-all-answered"),
    ],
)
def test_the_next_deadline_is_never_in_the_past(script: list[Step]) -> None:
    """The driver's wake-up: its value is the engine's choice, but never before now."""
    h = EngineHarness()
    for step in script:
        step(h)
    for now_s in (h.t, h.t + 0.001, h.t + 1.0):
        assert h.engine.next_deadline_s(now_s) >= now_s


def test_reset_machine_takes_new_limits_and_forgets_the_jog() -> None:
    h = EngineHarness()
    h.intent(ContinuousIntent({"X": -1.0}))
    h.poll()
    new = dataclasses.replace(h.engine.limits, planner_blocks=6)
    h.engine.reset_machine(new)
    assert h.engine.limits is new
    assert h.engine.phase is Phase.IDLE
    h.ledger.reset()
    h.intent(ContinuousIntent({"X": -1.0}))
    assert len([o for o in h.poll() if isinstance(o, SendLine)]) <= 6 - 3
    h.ok()  # the lines dropped by the reset are forgotten: this reply is placed
    assert "info" not in h.event_kinds()


@pytest.mark.parametrize(
    ("idle_setting", "idle_delay_s"),
    [("25", 0.025), ("0", 0.0), ("255", 0.0), ("fast", 0.025)],
    ids=["25ms", "0ms", "always-on", "not-a-number"],
)
def test_limits_read_the_step_idle_delay(idle_setting: str, idle_delay_s: float) -> None:
    """$1 in ms; 255 keeps the motors on (no delay); an unreadable value takes the default."""
    model = MachineModel()
    for text in [*handshake_lines(soft_limits=False), f"$1={idle_setting}"]:
        model.apply(parse_response(text))
    limits = EngineLimits.from_model(model)
    assert limits.idle_delay_s == pytest.approx(idle_delay_s)
    assert (limits.planner_blocks, limits.rx_buffer_bytes, limits.max_line_chars) == (15, 128, 79)
    assert limits.envelope is None
    assert limits.steps_per_mm == (80.0, 80.0, 80.0)


EDGE_MM = -1.0 / STEPS_PER_MM  # one step inside the envelope's 0 end (firmware-facts §2)
CLIP_ROWS = [
    row(
        "soft-limits-stop-the-queue-one-step-inside",
        [
            jog({"X": 1.0}),
            stream(0.2),
            check(lambda h: path_end(h)[0] == pytest.approx(EDGE_MM, abs=1e-9), "at the edge"),
            check(
                lambda h: (
                    [e.text[:39] for e in h.engine.events if e.kind == "info"]
                    == ["the jog stops at the soft limit (at X -"]
                ),
                "says once why it stands while the stick is held",
            ),
        ],
        Expect(Phase.JOGGING, never=("fault",)),
        soft_limits=True,
    ),
    row(
        "blocked-axis-dropped-to-slide-along-the-edge",
        [
            rest_at((-1.0, -5.0, -1.0)),
            jog({"X": 1.0, "Y": 1.0}),
            stream(0.3),
            check(
                lambda h: path_end(h) == pytest.approx((EDGE_MM, EDGE_MM, -1.0), abs=1e-9),
                "slid along X's edge to Y's",
            ),
        ],
        Expect(Phase.JOGGING, never=("fault",)),
        soft_limits=True,
    ),
    row(
        "keep-out-stops-a-held-jog-short",
        [
            jog(),
            stream(0.5),
            check(lambda h: -20.0 < path_end(h)[0] <= -19.98, "just short of the vise"),
            check(
                lambda h: any(
                    "stops at the keep-out zone 'vise'" in e.text for e in h.engine.events
                ),
                "says why it stands",
            ),
        ],
        Expect(Phase.JOGGING, never=("fault",)),
        keepouts=(KeepOut("vise", (-30.0, -5.0, -100.0), (-20.0, 5.0, 0.0)),),
    ),
    row(
        "increment-that-rounds-to-nothing-is-not-sent",
        # 1e5 steps/mm: the zone is 0.03 mm past a step of inset, below the 4 decimals written.
        [jog({"X": 1.0}), sends("?"), phase_is(Phase.JOGGING)],
        Expect(Phase.JOGGING),
        keepouts=(KeepOut("clamp", (-0.99996, -50.0, -50.0), (0.0, 50.0, 50.0)),),
        limits={"steps_per_mm": (1e5, 1e5, 1e5)},
    ),
    row(
        "increment-rounded-past-the-envelope-is-not-sent",
        # 1.00007 mm to the edge is written as 1.0001: that end lies outside, so nothing goes.
        [jog({"X": 1.0}), sends("?"), phase_is(Phase.JOGGING)],
        Expect(Phase.JOGGING),
        limits={
            "steps_per_mm": (1e5, 1e5, 1e5),
            "envelope": TravelBox((-800.0, -800.0, -800.0), (0.00008, 0.0, 0.0)),
        },
    ),
]


@pytest.mark.parametrize(("harness", "script", "expect"), CLIP_ROWS)
def test_continuous_jogs_are_clipped(
    harness: dict[str, Any], script: list[Step], expect: Expect
) -> None:
    """A held jog stops short of the soft limits and keep-outs; nothing unsafe is written."""
    run_row(harness, script, expect)


def test_the_cancel_owed_at_a_reset_survives_the_re_handshake() -> None:
    """The host calls reset_machine after re-reading the controller: jog lines sent before the
    banner may still start it, so the cancel stays owed and goes out once it reports Jog."""
    h = EngineHarness()
    h.intent(ContinuousIntent({"X": -1.0}))
    h.poll()
    h.feed(BANNER)
    h.ledger.reset()
    h.engine.reset_machine(dataclasses.replace(h.engine.limits))
    h.status("Jog", (-1.5, -1.0, -1.0))
    assert kinds(h.poll()) == ["0x85", "G4P0", "?"]  # the reset dropped the pending `?`


def test_a_press_made_while_the_settings_are_re_read_after_a_reset_jogs() -> None:
    """The banner abandons the jog; a press after it (the re-handshake is still reading `$$`)
    is a new one, and must not be lost when the host hands the engine the new limits."""
    h = EngineHarness()
    h.rest_at(START_MPOS)
    h.intent(ContinuousIntent({"X": -1.0}))
    h.poll()
    h.feed(BANNER)
    h.ledger.reset()
    h.intent(ContinuousIntent({"X": -1.0}, 0.2))  # pressed during the re-handshake
    h.engine.reset_machine(dataclasses.replace(h.engine.limits))
    h.status("Idle", START_MPOS)
    # The jog lines sent before the reset may still start it: their cancel and sync come first
    # (and a `?` for the one the reset dropped).
    assert kinds(h.poll()) == ["0x85", "G4P0", "?"]
    h.ok()
    h.status("Idle", START_MPOS)
    h.poll()
    h.status("Idle", START_MPOS)
    assert "$J" in kinds(h.poll())


def _feeds(h: EngineHarness) -> set[str]:
    return {line.rsplit("F", 1)[1] for line in h.jog_lines()}


def test_speed_is_a_fraction_of_each_axis_own_maximum() -> None:
    """Z at 25 % jogs at a quarter of $112 (1500 mm/min here), not of the fastest axis."""
    z_slow = {"max_rate_mm_min": (5000.0, 5000.0, 1500.0)}
    h = EngineHarness(limits=z_slow)
    h.intent(ContinuousIntent({"Z": -1.0}, 0.25))
    h.run(0.2)
    assert _feeds(h) == {"375"}
    ratios = EngineHarness(limits=z_slow)
    ratios.engine.set_speed_ratios({"Z": 0.25})
    ratios.intent(ContinuousIntent({"Z": -1.0}, 1.0))
    ratios.run(0.2)
    assert _feeds(ratios) == {"375"}
    # A diagonal: each axis at the same fraction of its own maximum.
    diag = EngineHarness(limits=z_slow)
    diag.intent(ContinuousIntent({"X": -1.0, "Z": -1.0}, 0.5))
    diag.run(0.2)
    x_mm, z_mm = (float(v) for v in re.findall(r"[XZ](-?[\d.]+)", diag.jog_lines()[-2]))
    assert z_mm / x_mm == pytest.approx(1500 / 5000, rel=0.01)


def test_an_owed_cancel_looks_for_the_stale_lines_often() -> None:
    """After a door with lines unanswered, someone else's resume starts them at any moment:
    the engine asks for reports as often as the wire allows (15 ms at 115200 baud for a
    50-byte report at 30 % of the wire), not every 50 ms, until it has cancelled them."""
    h = EngineHarness()
    h.intent(ContinuousIntent({"X": -1.0}))
    h.poll()
    h.status("Door:1")
    h.status("Idle")
    h.poll()
    asked = []
    for _ in range(10):
        h.advance(0.005)
        if STATUS_QUERY in [getattr(o, "byte", None) for o in h.poll()]:
            asked.append(h.t)
            h.status("Idle")
    assert len(asked) >= 3
    assert max(b - a for a, b in itertools.pairwise(asked)) <= 0.0155


@pytest.mark.parametrize(
    ("crawl_speed", "choice"),
    [
        # From 0.83 mm/s the queued blocks take longer to run out than a cancel and restart.
        pytest.param(0.01, "cancel", id="from-a-crawl"),
        # From half speed the queue runs out sooner than a stop and a start: let it run.
        pytest.param(0.5, "let-run", id="from-half-speed"),
    ],
)
def test_a_speed_up_cancels_only_when_the_slow_queue_would_take_longer(
    crawl_speed: float, choice: str
) -> None:
    h = EngineHarness(rx_bytes=1024)
    h.intent(ContinuousIntent({"X": -1.0}, crawl_speed))
    while h.t < 0.3:
        h.run(h.t + 0.002)
    h.intent(ContinuousIntent({"X": -1.0}, 1.0))
    h.poll()
    choices = [c for _, c, _, _ in h.engine.stats.turn_choices]
    assert choices == [choice]
    assert h.engine.phase is (Phase.STOPPING if choice == "cancel" else Phase.JOGGING)


def lock(reason: str | None) -> Step:
    """Another program takes the machine (a CNCjs job starts) or gives it back."""

    def step(h: EngineHarness) -> None:
        h.model.jog_lock = reason

    return step


JOB = "CNCjs is running a job: jogging waits until it ends"
LOCK_ROWS = [
    row(
        "a-lock-refuses-the-jog-in-words",
        [
            lock(JOB),
            jog(),
            poll,
            check(lambda h: not h.jog_lines(), "no jog"),
            phase_is(Phase.IDLE),
        ],
        Expect(Phase.IDLE),
    ),
    row(
        "a-lock-while-jogging-stops-with-the-full-handshake-and-says-why",
        [
            *JOGGING,
            lock(JOB),
            sends(),
            phase_is(Phase.STOPPING),
            ok_all,
            sends("0x85", "G4P0"),
        ],
        Expect(Phase.STOPPING, faults=("jogging stopped: " + JOB,)),
    ),
    row(
        "a-stick-held-through-the-lock-needs-a-new-press",
        [
            *JOGGING,
            lock(JOB),
            sends(),
            ok_all,
            sends("0x85", "G4P0"),
            ok,
            sends("?"),
            report("Idle"),
            lock(None),
            jog(),  # the same stick, still held: no new press
            check(lambda h: "$J" not in kinds(h.poll()), "no restart"),
            NEUTRAL,
            jog(),  # released and pressed again
            check(lambda h: "$J" in kinds(h.poll()), "jogs"),
        ],
        Expect(Phase.JOGGING, faults=("jogging stopped: " + JOB,), stops=((True, 0),)),
    ),
    row(
        "the-lock-lifted-jogs-again",
        [
            lock(JOB),
            jog(),
            poll,
            check(lambda h: not h.jog_lines(), "no jog"),
            lock(None),
            jog(),
            check(lambda h: "$J" in kinds(h.poll()), "jogs"),
        ],
        Expect(Phase.JOGGING),
    ),
]


@pytest.mark.parametrize(("harness", "script", "expect"), LOCK_ROWS)
def test_jog_lock_of_another_program(
    harness: dict[str, Any], script: list[Step], expect: Expect
) -> None:
    """A jog lock (models/machine.py jog_lock) refuses jogs and stops a running one."""
    h = run_row(harness, script, expect)
    if h.model.jog_lock is not None:
        assert h.engine.can_jog() == (False, JOB)


def test_a_relay_that_saw_a_change_gets_a_report_asked_for_at_once() -> None:
    h = EngineHarness(tuning=JogTuning(poll_idle_s=2.0))
    assert kinds(h.poll()) == ["?"]
    h.status("Idle", START_MPOS)
    h.advance(0.3)
    assert kinds(h.poll()) == []  # the next routine one is 2 s away
    h.engine.ask_status()
    assert kinds(h.poll()) == ["?"]
    h.status("Idle", START_MPOS)
    # While a jog runs the engine polls by itself: the hint changes nothing then.
    h.intent(ContinuousIntent({"X": -1.0}, 1.0))
    h.poll()
    asked = h.engine.reports.asked_s
    h.engine.ask_status()
    assert h.engine.reports.asked_s == asked
    assert h.engine.reports.last_sent_s > -math.inf
