"""The jog intents an input may hand the engine, and the one check of each against a machine.

An intent says what the user wants (hold a velocity, step, go to a point, turn a handwheel,
stop); it knows nothing of Grbl. `validate_intent` refuses one that no machine with these axes
and this top feed could carry out, with a sentence saying what is wrong.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal

from smoothjog.core.errors import JogBuildError

STEP_MIN_MM = 0.001
STEP_MAX_MM = 100.0

HANDWHEEL_MODES = ("position", "velocity")


@dataclass(frozen=True)
class ContinuousIntent:
    """Hold a velocity: stick deflection per axis in [-1, 1] and a global speed in (0, 1]."""

    axes: Mapping[str, float]
    speed: float = 1.0

    def is_neutral(self) -> bool:
        """True when no axis is deflected."""
        return all(v == 0.0 for v in self.axes.values())


@dataclass(frozen=True)
class StepIntent:
    """Move exactly dist_mm along one axis (0.001 to 100 mm), after any steps already queued."""

    axis: str
    dist_mm: float
    speed: float = 0.5


@dataclass(frozen=True)
class GotoIntent:
    """Jog in a straight line to a machine position (G53), at speed (fraction of the max feed)."""

    target_mpos_mm: Mapping[str, float]
    speed: float = 0.5


@dataclass(frozen=True)
class StopIntent:
    """Stop now (full cancel handshake) and drop any steps not yet sent.

    by names who stopped, in words, for every page to see; button says a STOP button or key
    gave it (always news, even from the input holding the jog); release says it is the holder
    of a held jog letting go of it (nothing to announce). None plays a part in equality.
    """

    by: str = field(default="", compare=False)
    button: bool = field(default=False, compare=False)
    release: bool = field(default=False, compare=False)


@dataclass(frozen=True)
class HandwheelIntent:
    """Detents turned on one axis since the last report, each worth step_mm (> 0).

    Position mode executes exactly counts x step_mm, every count. Velocity mode stops when the
    wheel stops and drops counts that would run further ahead than the stopping distance.
    """

    axis: str
    counts: int  # signed detents since the last report
    step_mm: float
    mode: Literal["position", "velocity"]
    speed: float = 1.0


Intent = ContinuousIntent | StepIntent | GotoIntent | StopIntent | HandwheelIntent
#: The same union under its earlier name: every intent an input can produce, all run by the engine.
AnyIntent = Intent


def validate_intent(intent: Intent, axes: Sequence[str], max_feed_mm_min: float) -> None:
    """Raise JogBuildError, in words, if the intent cannot be run on these axes at this feed.

    max_feed_mm_min is the feed at speed 1.0. A stop is always valid.
    """
    axes = tuple(axes)
    if isinstance(intent, StepIntent):
        _check_step(intent, axes, max_feed_mm_min)
    elif isinstance(intent, GotoIntent):
        _check_goto(intent, axes, max_feed_mm_min)
    elif isinstance(intent, ContinuousIntent):
        _check_continuous(intent, axes)
    elif isinstance(intent, HandwheelIntent):
        _check_handwheel(intent, axes, max_feed_mm_min)


def _check_step(intent: StepIntent, axes: tuple[str, ...], max_feed_mm_min: float) -> None:
    if intent.axis not in axes:
        raise JogBuildError(f"cannot step axis {intent.axis!r}: the machine has {axes}")
    if not (STEP_MIN_MM <= abs(intent.dist_mm) <= STEP_MAX_MM):
        raise JogBuildError(
            f"step of {intent.dist_mm!r} mm is outside {STEP_MIN_MM} to {STEP_MAX_MM} mm"
        )
    if not (0.0 < intent.speed <= 1.0):
        raise JogBuildError(f"step speed {intent.speed!r} must be in (0, 1]")
    _check_feed(intent.speed, max_feed_mm_min)


def _check_goto(intent: GotoIntent, axes: tuple[str, ...], max_feed_mm_min: float) -> None:
    for axis, value in intent.target_mpos_mm.items():
        if axis not in axes:
            raise JogBuildError(f"cannot go to {axis}: the machine has {axes}")
        if not math.isfinite(value):
            raise JogBuildError(f"go-to target {axis}={value!r} is not a number")
    if not intent.target_mpos_mm:
        raise JogBuildError("a go-to needs at least one axis target")
    if not (0.0 < intent.speed <= 1.0):
        raise JogBuildError(f"go-to speed {intent.speed!r} must be in (0, 1]")
    _check_feed(intent.speed, max_feed_mm_min)


def _check_continuous(intent: ContinuousIntent, axes: tuple[str, ...]) -> None:
    for axis, value in intent.axes.items():
        if axis not in axes:
            raise JogBuildError(f"cannot jog axis {axis!r}: the machine has {axes}")
        if not (math.isfinite(value) and -1.0 <= value <= 1.0):
            raise JogBuildError(f"deflection {axis}={value!r} must be in [-1, 1]")
    if not (math.isfinite(intent.speed) and 0.0 < intent.speed <= 1.0):
        raise JogBuildError(f"speed {intent.speed!r} must be in (0, 1]")


def _check_handwheel(
    intent: HandwheelIntent, axes: tuple[str, ...], max_feed_mm_min: float
) -> None:
    if intent.axis not in axes:
        raise JogBuildError(
            f"cannot turn the handwheel on axis {intent.axis!r}: the machine has {axes}"
        )
    if not (STEP_MIN_MM <= intent.step_mm <= STEP_MAX_MM):
        raise JogBuildError(
            f"handwheel step of {intent.step_mm!r} mm per count is outside "
            f"{STEP_MIN_MM} to {STEP_MAX_MM} mm"
        )
    # bool is an int subclass, but True detents is a caller's bug, not a count.
    if not isinstance(intent.counts, int) or isinstance(intent.counts, bool):
        raise JogBuildError(f"handwheel counts {intent.counts!r} must be a whole number")
    if intent.mode not in HANDWHEEL_MODES:
        raise JogBuildError(
            f"handwheel mode {intent.mode!r} must be one of {', '.join(HANDWHEEL_MODES)}"
        )
    if not (math.isfinite(intent.speed) and 0.0 < intent.speed <= 1.0):
        raise JogBuildError(f"handwheel speed {intent.speed!r} must be in (0, 1]")
    _check_feed(intent.speed, max_feed_mm_min)


def _check_feed(speed: float, max_feed_mm_min: float) -> None:
    feed_mm_min = max_feed_mm_min * speed
    if feed_mm_min < 1.0:
        raise JogBuildError(
            f"speed {speed!r} gives {feed_mm_min:.3g} mm/min, below Grbl's 1 mm/min minimum"
        )
