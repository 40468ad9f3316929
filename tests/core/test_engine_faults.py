"""The fault shown to the user clears when the user acts anew, not while a stick is held."""

from __future__ import annotations

from smoothjog.core.intents import StepIntent, StopIntent
from tests.core.engine_harness import EngineHarness
from tests.core.test_engine_outside import HELD, _cruising, _estimate_mm


def _refused_step(h: EngineHarness) -> None:
    h.rest_at((-1 / 80, -1.0, -1.0))  # one step inside the + soft limit: no room that way
    h.intent(StepIntent("X", 5.0))
    h.poll()
    assert h.engine.view(h.t).fault is not None


def test_a_new_step_clears_the_fault() -> None:
    h = EngineHarness(soft_limits=True)
    _refused_step(h)
    h.intent(StepIntent("X", -1.0))
    assert h.engine.view(h.t).fault is None


def test_a_held_stick_keeps_the_fault_and_a_new_press_clears_it() -> None:
    h = _cruising()  # a held jog at full speed
    h.status("Jog", _estimate_mm(h, behind_mm=2.0), fs=(0, 0))  # stopped from outside
    fault = h.engine.view(h.t).fault
    assert fault is not None
    h.intent(HELD)  # the same stick, re-sent by its input
    assert h.engine.view(h.t).fault == fault
    h.intent(StopIntent())
    assert h.engine.view(h.t).fault == fault  # a release alone clears nothing
    h.intent(HELD)
    assert h.engine.view(h.t).fault is None
