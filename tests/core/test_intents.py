"""The one validation of every intent: each refusal is a sentence naming what is wrong."""

from __future__ import annotations

import math
import re

import pytest

from smoothjog.core.errors import JogBuildError
from smoothjog.core.intents import (
    AnyIntent,
    ContinuousIntent,
    GotoIntent,
    HandwheelIntent,
    StepIntent,
    StopIntent,
    validate_intent,
)

AXES = ("X", "Y", "Z")
MAX_FEED_MM_MIN = 5000.0


@pytest.mark.parametrize(
    ("intent", "message"),
    [
        (StepIntent("Q", 1.0), "cannot step axis 'Q': the machine has ('X', 'Y', 'Z')"),
        (StepIntent("X", 500.0), "step of 500.0 mm is outside 0.001 to 100.0 mm"),
        (StepIntent("X", -0.0001), "step of -0.0001 mm is outside 0.001 to 100.0 mm"),
        (StepIntent("X", 1.0, 0.0), "step speed 0.0 must be in (0, 1]"),
        (
            StepIntent("X", 1.0, 1e-6),
            "speed 1e-06 gives 0.005 mm/min, below Grbl's 1 mm/min minimum",
        ),
        (GotoIntent({"Q": 1.0}), "cannot go to Q: the machine has ('X', 'Y', 'Z')"),
        (GotoIntent({"X": math.nan}), "go-to target X=nan is not a number"),
        (GotoIntent({}), "a go-to needs at least one axis target"),
        (GotoIntent({"X": -1.0}, 2.0), "go-to speed 2.0 must be in (0, 1]"),
        (ContinuousIntent({"Q": 1.0}), "cannot jog axis 'Q': the machine has ('X', 'Y', 'Z')"),
        (ContinuousIntent({"X": 1.5}), "deflection X=1.5 must be in [-1, 1]"),
        (ContinuousIntent({"X": math.inf}), "deflection X=inf must be in [-1, 1]"),
        (ContinuousIntent({"X": 1.0}, 0.0), "speed 0.0 must be in (0, 1]"),
        (
            HandwheelIntent("Q", 1, 0.01, "position"),
            "cannot turn the handwheel on axis 'Q': the machine has ('X', 'Y', 'Z')",
        ),
        (
            HandwheelIntent("X", 1, 0.0, "position"),
            "handwheel step of 0.0 mm per count is outside 0.001 to 100.0 mm",
        ),
        (
            HandwheelIntent("X", 1, -0.1, "velocity"),
            "handwheel step of -0.1 mm per count is outside 0.001 to 100.0 mm",
        ),
        (
            HandwheelIntent("X", 1.5, 0.01, "position"),  # type: ignore[arg-type]
            "handwheel counts 1.5 must be a whole number",
        ),
        (
            HandwheelIntent("X", True, 0.01, "position"),
            "handwheel counts True must be a whole number",
        ),
        (
            HandwheelIntent("X", 1, 0.01, "jog"),  # type: ignore[arg-type]
            "handwheel mode 'jog' must be one of position, velocity",
        ),
        (
            HandwheelIntent("X", 1, 0.01, "velocity", 0.0),
            "handwheel speed 0.0 must be in (0, 1]",
        ),
        (
            HandwheelIntent("X", 1, 0.01, "velocity", 1e-6),
            "speed 1e-06 gives 0.005 mm/min, below Grbl's 1 mm/min minimum",
        ),
    ],
)
def test_invalid_intents_are_refused_with_a_sentence(intent: AnyIntent, message: str) -> None:
    with pytest.raises(JogBuildError, match=f"^{re.escape(message)}$"):
        validate_intent(intent, AXES, MAX_FEED_MM_MIN)


@pytest.mark.parametrize(
    "intent",
    [
        StepIntent("X", 0.001),
        StepIntent("Z", -100.0, 1.0),
        GotoIntent({"X": -10.0, "Y": 0.0}),
        ContinuousIntent({"X": -1.0, "Y": 0.3}, 0.1),
        ContinuousIntent({}),
        StopIntent(),
        HandwheelIntent("Y", -7, 0.01, "position"),
        HandwheelIntent("Z", 0, 1.0, "velocity", 0.5),
    ],
)
def test_valid_intents_pass(intent: AnyIntent) -> None:
    validate_intent(intent, AXES, MAX_FEED_MM_MIN)


def test_the_axes_may_be_any_sequence() -> None:
    with pytest.raises(JogBuildError, match=re.escape("the machine has ('X', 'Y')")):
        validate_intent(StepIntent("Z", 1.0), ["X", "Y"], MAX_FEED_MM_MIN)


def test_the_feed_floor_follows_the_max_feed() -> None:
    validate_intent(StepIntent("X", 1.0, 0.01), AXES, 100.0)  # 1 mm/min: just allowed
    with pytest.raises(JogBuildError, match="below Grbl's 1 mm/min minimum"):
        validate_intent(StepIntent("X", 1.0, 0.01), AXES, 99.0)
