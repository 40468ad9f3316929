"""The outside-event sign table, one row per sign: evidence in, verdict out.

Each row builds the evidence its sign reads (a path, a report, the memory of earlier reports)
and expects that sign's verdict. With the sign's entry taken out of signs.SIGNS, the row gets
another sign's verdict or none, so each row fails without its entry.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import pytest

from smoothjog.core import increments as inc
from smoothjog.core.engine import signs as signs_mod
from smoothjog.core.engine.clearance import Clearance
from smoothjog.core.engine.limits import EngineLimits, JogTuning
from smoothjog.core.engine.lines import LineTag
from smoothjog.core.engine.records import Notices, Phase
from smoothjog.core.engine.signs import SIGNS, Evidence, Reaction, Signs, Stage, stop_off_path
from smoothjog.core.engine.tracker import PathSeg, PathTracker
from smoothjog.core.ledger import ENGINE, Entry, Ledger
from smoothjog.core.responses import StatusReport, parse_response

STEPS = (80.0, 80.0, 80.0)
ACCEL = (500.0, 500.0, 500.0)
V = 10.0  # mm/s: 600 mm/min
X = (1.0, 0.0, 0.0)
MOVE = inc.VectorMove((V, 0.0, 0.0), V, 500.0)
DOCS = Path(__file__).parents[2] / "docs" / "jogging.md"


def _signs(*lengths_mm: float) -> Signs:
    """Signs over a straight X path of acknowledged jogs of these lengths at V."""
    track = PathTracker(STEPS, ACCEL, 0.01, 0.05)
    track.begin((0.0, 0.0, 0.0), 0.0)
    x0 = 0.0
    for length in lengths_mm:
        seg = PathSeg((x0, 0.0, 0.0), (x0 + length, 0.0, 0.0), length, V, 500.0, x0, unit_vec=X)
        track.append(seg)
        seg.acked = True
        x0 += length
    track.moving_since_ack = True
    limits = EngineLimits(
        axes=("X", "Y", "Z"),
        steps_per_mm=STEPS,
        max_rate_mm_min=(6000.0, 6000.0, 6000.0),
        accel_mm_s2=ACCEL,
        planner_blocks=15,
        rx_buffer_bytes=128,
        max_line_chars=80,
        idle_delay_s=0.025,
        envelope=None,
        keepouts=(),
        firmware="grbl",
    )
    return Signs(track, JogTuning(), Clearance(limits, track, Notices()))


def _report(state: str, fs_mm_min: float | None, pins: str = "") -> StatusReport:
    fs = "" if fs_mm_min is None else f"|FS:{fs_mm_min:.0f},0"
    pn = f"|Pn:{pins}" if pins else ""
    report = parse_response(f"<{state}|MPos:5.000,0.000,0.000{fs}{pn}>")
    assert isinstance(report, StatusReport)
    return report


def _evidence(report: StatusReport, **changes: object) -> Evidence:
    ev = Evidence(
        report=report,
        asked_s=1.0,
        now_s=1.02,
        mpos=(5.0, 0.0, 0.0),
        phase=Phase.JOGGING,
        runs_as_sent=True,
        off_path=False,
        predicted_mm=10.0,
        estimate_before_mm=10.0,
        commanded=MOVE,
        jog_unbraked=False,
        others_poll=False,
        relayed=False,
        oldest=None,
        rtt_s=0.005,
        report_wire_s=0.004,
        pressed="",
        jogs_unanswered=True,
    )
    return dataclasses.replace(ev, **changes)  # type: ignore[arg-type]


def _rest_inside_block() -> tuple[Signs, Evidence]:
    s = _signs(2.0, 2.0, 2.0)
    s.track.x_reported_mm = s.track.x_est_mm = 3.2
    s.rest_inside = (0.0, 3.2, s.track.path[1])  # a report at rest there, built at 0 s
    return s, _evidence(_report("Jog", 0))


def _rest_short_of_acked_path() -> tuple[Signs, Evidence]:
    s = _signs(2.0, 2.0, 2.0)
    s.track.x_est_mm = 1.0
    s.cruised = True
    return s, _evidence(_report("Jog", 0))


def _slowed_inside_block() -> tuple[Signs, Evidence]:
    s = _signs(20.0)
    s.track.x_reported_mm = s.track.x_est_mm = 10.0
    return s, _evidence(_report("Jog", 60))


def _slowed_since_last_report() -> tuple[Signs, Evidence]:
    s = _signs(6.5, 13.5)
    s.track.x_reported_mm = s.track.x_est_mm = 6.0
    s.prev_jog_report = (5.0, V, 20.0, s.track.path[0])  # at V 1 mm back, 20 mm acknowledged
    return s, _evidence(_report("Jog", 120))


def _lag_behind_estimate() -> tuple[Signs, Evidence]:
    s = _signs(20.0)
    s.track.x_est_mm = 10.0
    s.seen_at_speed = MOVE
    return s, _evidence(_report("Jog", 300), asked_s=1.019, predicted_mm=12.0)


def _line_unread() -> tuple[Signs, Evidence]:
    s = _signs()
    ledger = Ledger(128)
    entry: Entry = ledger.record_line(ENGINE, "$J=G21G91X1F600", 0.9, LineTag("jog"))
    s._unread_entry = entry  # one report already asked after the line was in
    s._unread_reports = 1
    s._unread_seen_s = 0.95
    return s, _evidence(_report("Jog", 0), oldest=entry)


def _off_path() -> tuple[Signs, Evidence]:
    return _signs(20.0), _evidence(_report("Jog", 600), off_path=True)


def _hold_or_door_input() -> tuple[Signs, Evidence]:
    return _signs(20.0), _evidence(_report("Jog", 600, "H"), pressed="feed-hold")


def _idle_short_of_path_end() -> tuple[Signs, Evidence]:
    return _signs(20.0), _evidence(_report("Idle", 0))


def _left_jog_states() -> tuple[Signs, Evidence]:
    return _signs(20.0), _evidence(_report("Hold", 0))


#: (sign, stage, the evidence it reads, the words of its verdict)
ROWS: list[tuple[str, Stage, Callable[[], tuple[Signs, Evidence]], str]] = [
    ("rest-inside-block", Stage.MOTION, _rest_inside_block, "before the end of a jog"),
    ("rest-short-of-acked-path", Stage.MOTION, _rest_short_of_acked_path, "stood still"),
    ("slowed-inside-block", Stage.MOTION, _slowed_inside_block, "into a jog that runs"),
    ("slowed-since-last-report", Stage.MOTION, _slowed_since_last_report, "slowed to"),
    ("lag-behind-estimate", Stage.MOTION, _lag_behind_estimate, "behind the path"),
    ("line-unread", Stage.MOTION, _line_unread, "left a jog line unread"),
    ("off-path", Stage.MOTION, _off_path, "left the path"),
    ("hold-or-door-input", Stage.STATE, _hold_or_door_input, "feed-hold input was pressed"),
    ("idle-short-of-path-end", Stage.STATE, _idle_short_of_path_end, "short of the path's end"),
    ("left-jog-states", Stage.STATE, _left_jog_states, "feed hold"),
]


@pytest.mark.parametrize(("name", "stage", "given", "words"), ROWS, ids=[r[0] for r in ROWS])
def test_each_sign_gives_its_verdict(
    name: str, stage: Stage, given: Callable[[], tuple[Signs, Evidence]], words: str
) -> None:
    signs, evidence = given()
    verdict = signs.read(stage, evidence)
    assert verdict is not None, f"{name}: no verdict"
    assert verdict.sign == name
    assert words in verdict.how
    entry = next(sign for sign in SIGNS if sign.name == name)
    assert verdict.reaction is entry.reaction


@pytest.mark.parametrize(("name", "stage", "given", "words"), ROWS, ids=[r[0] for r in ROWS])
def test_without_its_entry_a_row_gets_no_such_verdict(
    monkeypatch: pytest.MonkeyPatch,
    name: str,
    stage: Stage,
    given: Callable[[], tuple[Signs, Evidence]],
    words: str,
) -> None:
    monkeypatch.setattr(signs_mod, "SIGNS", tuple(s for s in SIGNS if s.name != name))
    signs, evidence = given()
    verdict = signs.read(stage, evidence)
    assert verdict is None or verdict.sign != name


def test_the_table_has_one_row_per_sign_in_precedence_order() -> None:
    assert [r[0] for r in ROWS] == [s.name for s in SIGNS]
    assert len({s.name for s in SIGNS}) == len(SIGNS)


def test_every_sign_has_a_row_in_the_docs() -> None:
    text = DOCS.read_text(encoding="utf-8")
    section = text[text.index("## Outside events: the sign table") :]
    for name in [*(s.name for s in SIGNS), "stop-off-path"]:
        assert f"| `{name}` |" in section, name


def test_a_stop_off_the_path_by_more_than_five_steps_is_someone_elses() -> None:
    verdict = stop_off_path(6.0, owed=False, path_faulted=False)
    assert verdict is not None
    assert verdict.reaction is Reaction.RECORD
    assert stop_off_path(4.0, owed=False, path_faulted=False) is None
    assert stop_off_path(60.0, owed=True, path_faulted=False) is None  # already seen as outside
    assert stop_off_path(60.0, owed=False, path_faulted=True) is None  # a fault said why


def test_a_line_unread_counts_every_report_after_an_earlier_verdict() -> None:
    """line-unread keeps count even when an earlier sign gave the verdict."""
    s, ev = _line_unread()
    s.track.x_est_mm = 1.0
    s.cruised = True
    s.track = _signs(2.0, 2.0, 2.0).track
    s.clearance.track = s.track
    verdict = s.read(Stage.MOTION, ev)
    assert verdict is not None
    assert verdict.sign == "rest-short-of-acked-path"
    assert s._unread_reports == 2
