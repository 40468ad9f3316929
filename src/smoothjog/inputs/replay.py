"""Timed jog intents from a JSON Lines file: how tests, benchmarks and users script jogs.

One object per line, times in seconds from the start, in non-decreasing order:

    {"t": 0.0, "axes": {"x": 1.0, "y": -0.5}, "speed": 0.8}   hold a stick deflection
    {"t": 1.5, "axes": {"x": 0}}                               neutral: stop
    {"t": 2.0, "step": {"z": -0.1}, "speed": 0.2}              exact step(s), queued in order
    {"t": 3.0, "goto": {"x": -100, "y": -50}, "speed": 0.5}    straight G53 move to machine coords
    {"t": 4.0, "stop": true}                                   stop now, drop queued steps

Blank lines and lines starting with `#` are skipped. Axis letters may be lower or upper case.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from smoothjog.core.errors import JogBuildError, SmoothjogError
from smoothjog.core.intents import (
    ContinuousIntent,
    GotoIntent,
    Intent,
    StepIntent,
    StopIntent,
    validate_intent,
)
from smoothjog.core.units import ALL_AXES

_KEYS = frozenset({"t", "axes", "speed", "step", "goto", "stop"})


class ReplayError(SmoothjogError):
    """A replay file is malformed; the message names the file and the line."""


@dataclass(frozen=True)
class TimedIntent:
    """An intent and the time (s from the start) at which it takes effect."""

    t_s: float
    intent: Intent


def load_replay(path: str | Path) -> list[TimedIntent]:
    """Read and check a replay file; raises ReplayError naming the line at fault."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ReplayError(f"replay file {p} does not exist: check the path") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ReplayError(f"cannot read replay file {p}: {exc}") from None
    # split("\n"), not splitlines(): a form feed or U+2028 must not shift the line numbers.
    return parse_replay(text.split("\n"), source=str(p))


def parse_replay(lines: Iterable[str], *, source: str = "<replay>") -> list[TimedIntent]:
    """Parse replay lines (see the module docstring) into timed intents."""
    out: list[TimedIntent] = []
    last_t = 0.0
    for number, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        where = f"{source}:{number}"
        try:
            obj = json.loads(line)
        except json.JSONDecodeError as exc:
            raise ReplayError(f"{where}: not valid JSON ({exc.msg})") from None
        if not isinstance(obj, dict):
            raise ReplayError(f"{where}: each line must be a JSON object")
        unknown = sorted(set(obj) - _KEYS)
        if unknown:
            raise ReplayError(
                f"{where}: unknown key {unknown[0]!r}; allowed: {', '.join(sorted(_KEYS))}"
            )
        t = _number(obj.get("t"), where, "t")
        if t < last_t:
            raise ReplayError(f"{where}: time {t} goes back before {last_t}; sort the lines")
        last_t = t
        # Without "speed": full stick speed, and half for steps and go-tos as elsewhere.
        default_speed = 0.5 if ("step" in obj or "goto" in obj) else 1.0
        speed = _number(obj.get("speed", default_speed), where, "speed")
        kinds = [k for k in ("axes", "step", "goto", "stop") if k in obj]
        if len(kinds) != 1:
            raise ReplayError(f"{where}: give exactly one of axes, step, goto or stop")
        kind = kinds[0]
        intents: list[Intent]
        if kind == "stop":
            if obj["stop"] is not True:
                raise ReplayError(f'{where}: "stop" must be true (leave the line out otherwise)')
            intents = [StopIntent()]
        elif kind == "axes":
            intents = [ContinuousIntent(_axes(obj["axes"], where, "axes"), speed)]
        elif kind == "step":
            steps = _axes(obj["step"], where, "step")
            intents = [StepIntent(axis, dist, speed) for axis, dist in steps.items()]
        else:
            intents = [GotoIntent(_axes(obj["goto"], where, "goto"), speed)]
        for intent in intents:
            # The one check of an intent (core/intents.py), here without a machine: any axis
            # letter, any top feed. The engine checks it again against the real machine.
            try:
                validate_intent(intent, ALL_AXES, math.inf)
            except JogBuildError as exc:
                raise ReplayError(f"{where}: {exc}") from None
            out.append(TimedIntent(t, intent))
    return out


def _number(value: object, where: str, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ReplayError(f"{where}: {key!r} must be a finite number, got {value!r}")
    return float(value)


def _axes(value: object, where: str, key: str) -> dict[str, float]:
    if not isinstance(value, dict) or not value:
        raise ReplayError(f'{where}: {key!r} must be an object such as {{"x": 1.0}}')
    axes: dict[str, float] = {}
    for name, v in value.items():
        letter = str(name).upper()
        if len(letter) != 1 or letter not in ALL_AXES:
            raise ReplayError(f"{where}: {name!r} is not an axis letter")
        axes[letter] = _number(v, where, f"{key}.{name}")
    return axes
