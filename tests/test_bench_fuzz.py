"""The fuzz: its fault injection, its outside-stop detectors, and that it survives a crash."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest
from bench import fuzz

from smoothjog.sim.motion import TraceSegment
from smoothjog.sim.rig import LINK_MODELS


def _seg(t0: float, t1: float, x0: float, x1: float) -> TraceSegment:
    return TraceSegment(t0, t1, (x0, 0.0, 0.0), (x1, 0.0, 0.0))


#: Moving 1.0-1.2 s, at rest until 1.5 s, moving again 1.5-1.6 s.
TRACE = [
    _seg(1.0, 1.1, 0.0, 1.0),
    _seg(1.1, 1.2, 1.0, 1.5),
    _seg(1.2, 1.5, 1.5, 1.5),
    _seg(1.5, 1.6, 1.5, 2.0),
]


def test_the_rest_after_an_outside_stop_is_the_end_of_the_motion_going_on() -> None:
    assert fuzz._moving_at(TRACE, 1.05, 0)
    assert not fuzz._moving_at(TRACE, 1.3, 0)
    assert fuzz._rest_after(TRACE, 1.05, 0) == pytest.approx(1.2)
    assert fuzz._rest_after(TRACE, 1.3, 0) == pytest.approx(1.3)


def test_faults_put_the_noise_on_the_directions_asked_for() -> None:
    up = fuzz.Faults(drop_rate=0.01, corrupt_rate=0.02, directions="to-controller").on(
        LINK_MODELS["ideal"]
    )
    assert (up.drop_to_controller, up.corrupt_to_controller) == (0.01, 0.02)
    assert (up.drop_to_host, up.corrupt_to_host) == (0.0, 0.0)
    both = fuzz.Faults(drop_rate=0.01, directions="both").on(LINK_MODELS["ftdi"])
    assert both.drop_to_host == both.drop_to_controller == 0.01
    assert both.batch_timer_s == LINK_MODELS["ftdi"].batch_timer_s
    assert not fuzz.Faults().active


def test_outside_events_are_injected_and_counted() -> None:
    r = fuzz.run_fuzz("grbl", 3, seed=3, link="ideal", faults=fuzz.Faults(outside_rate=1.0))
    assert r.sequences == 3
    assert sum(r.outside.values()) >= 3  # one per random intent, at least one intent each
    assert r.crashes == 0


def test_the_fuzz_counts_an_exception_and_carries_on_with_a_fresh_session(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    calls: list[int] = []
    real_probe = fuzz._probe

    def failing_probe(*args: object) -> None:
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("the engine fell over")
        real_probe(*args)

    monkeypatch.setattr(fuzz, "_probe", failing_probe)
    r = fuzz.run_fuzz("grbl", 3, seed=3, link="ideal", faults=fuzz.Faults(outside_rate=0.01))
    assert r.sequences == 3
    assert r.crashes == 1
    assert len(calls) == 3
    assert any("the engine fell over" in f for f in r.faults)


def test_a_feed_hold_that_grblhal_ignores_in_jog_is_no_outside_stop(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # grblHAL's state machine leaves a jog alone on `!` (the simulator does as its facts say):
    # the machine runs on, and a rest the engine makes later is not a restart. On Grbl the
    # same holds are outside stops.
    monkeypatch.setattr(fuzz, "OUTSIDE_EVENTS", {"feed hold": b"!"})
    faults = fuzz.Faults(outside_rate=1.0)
    hal = fuzz.run_fuzz("grblhal", 12, seed=5, link="ideal", faults=faults)
    assert hal.outside.get("feed hold", 0) >= 12
    assert hal.outside_stops == 0
    assert hal.restarts_after_outside_stop == 0
    assert hal.outside_stopped_nothing > 0
    grbl = fuzz.run_fuzz("grbl", 12, seed=5, link="ideal", faults=faults)
    assert grbl.outside_stops > 0


def test_an_outside_cancel_counts_as_stopping_nothing_only_if_it_threw_nothing_away() -> None:
    # The simulator's record of each cancel (steps left unrun, lines dropped) decides: a cancel
    # that struck a machine braking into the end of what it held changed nothing anyone could
    # see, so a held stick jogging on afterwards is no restart; one that threw motion away is.
    def session(log: list[tuple[float, int, int]]) -> Any:
        rig = SimpleNamespace(clock_ratio=1.0, firmware=SimpleNamespace(cancel_log=log))
        return SimpleNamespace(vs=SimpleNamespace(rig=rig))

    assert fuzz._threw_nothing_away(session([(10.2, 0, 0)]), 10.0, 10.2)
    assert fuzz._threw_nothing_away(session([(10.2, 1, 0)]), 10.0, 10.2)
    assert not fuzz._threw_nothing_away(session([(10.2, 40, 0)]), 10.0, 10.2)
    assert not fuzz._threw_nothing_away(session([(10.2, 0, 1)]), 10.0, 10.2)
    assert not fuzz._threw_nothing_away(session([]), 10.0, 10.2)
    # A cancel that ended before the event, or long after the rest, is not this one.
    assert not fuzz._threw_nothing_away(session([(9.9, 0, 0)]), 10.0, 10.2)
    assert not fuzz._threw_nothing_away(session([(10.5, 0, 0)]), 10.0, 10.2)
    # Two cancels ended the motion and one of them threw steps away: it stopped something.
    both = session([(10.1, 0, 0), (10.2, 30, 0)])
    assert not fuzz._threw_nothing_away(both, 10.0, 10.2)
