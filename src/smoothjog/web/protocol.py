"""The pendant's WebSocket messages: parse and validate what the page sends, shape what it gets.

Every client message is checked here before anything reaches the backend, so a malformed or
hostile message becomes a PendantMessageError (answered with an error message) and never a call.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Final

from smoothjog.authority.commands import COMMAND_NAMES
from smoothjog.core.errors import SmoothjogError

#: Bounds of a step jog in mm; outside them a click is surely a mistake (a typo or a bad unit).
STEP_MIN_MM: Final = 0.001
STEP_MAX_MM: Final = 100.0
#: The largest message the page ever needs; anything bigger is refused unread.
MAX_MESSAGE_BYTES: Final = 4096


class PendantError(SmoothjogError):
    """The pendant could not start or was misused (bad address, bad setting)."""


class PendantMessageError(PendantError):
    """A message from the page is malformed or out of range; the text is sent back to it."""


@dataclass(frozen=True)
class JogMessage:
    """Hold a continuous jog: deflection per axis in [-1, 1] at a speed fraction in (0, 1]."""

    axes: Mapping[str, float]
    speed: float

    @property
    def neutral(self) -> bool:
        """True when every deflection is zero (the same as a stop)."""
        return all(v == 0.0 for v in self.axes.values())


@dataclass(frozen=True)
class StopMessage:
    """Return to neutral now."""


@dataclass(frozen=True)
class StepMessage:
    """Move one axis by an exact distance."""

    axis: str
    dist_mm: float


@dataclass(frozen=True)
class RatiosMessage:
    """Set the per-axis speed ratios, each in (0, 1]."""

    ratios: Mapping[str, float]


@dataclass(frozen=True)
class TakeControlMessage:
    """A watcher asks to become the controlling client."""


@dataclass(frozen=True)
class PingMessage:
    """The page measures the link: the server answers {"type": "pong", "id": id} at once."""

    id: int


#: The longest console line accepted from the page (grblHAL reads 256 characters).
CONSOLE_MAX_CHARS: Final = 256


@dataclass(frozen=True)
class CommandMessage:
    """A machine command (unlock, home, a console line...); `id` matches its result."""

    name: str
    id: int
    axes: tuple[str, ...] = ()
    wcs: str = ""
    kind: str = ""
    step: str = ""
    line: str = ""


ClientMessage = (
    JogMessage
    | StopMessage
    | StepMessage
    | RatiosMessage
    | TakeControlMessage
    | CommandMessage
    | PingMessage
)


def _reject_constant(name: str) -> float:
    """json.loads hook: NaN and Infinity are not JSON and never a valid jog value."""
    raise PendantMessageError(f"{name} is not a number the pendant accepts; send a finite number")


def _number(value: object, what: str) -> float:
    """A finite JSON number (bool is refused although Python counts it as an int)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise PendantMessageError(f"{what} must be a number, got {json.dumps(value)}")
    number = float(value)
    if not math.isfinite(number):
        raise PendantMessageError(f"{what} must be finite, got {number}")
    return number


def _axis(value: object, known_axes: Sequence[str], what: str) -> str:
    """An axis letter this machine has."""
    if not isinstance(value, str) or value not in known_axes:
        raise PendantMessageError(
            f"{what} must be one of {', '.join(known_axes)}, got {json.dumps(value)}"
        )
    return value


def _axis_map(
    value: object, known_axes: Sequence[str], what: str, lo: float, hi: float, *, open_lo: bool
) -> dict[str, float]:
    """An object of axis letter -> number within [lo, hi] (or (lo, hi] with open_lo)."""
    if not isinstance(value, dict) or not value:
        raise PendantMessageError(f'{what} must be a non-empty object like {{"X": 0.5}}')
    out: dict[str, float] = {}
    for key, raw in value.items():
        axis = _axis(key, known_axes, f"{what} key")
        number = _number(raw, f"{what}.{axis}")
        if number > hi or number < lo or (open_lo and number == lo):
            bracket = "(" if open_lo else "["
            raise PendantMessageError(
                f"{what}.{axis} must be in {bracket}{lo:g}, {hi:g}], got {number:g}"
            )
        out[axis] = number
    return out


def parse_client_message(text: str | bytes, known_axes: Sequence[str]) -> ClientMessage:
    """Parse one WebSocket text frame from the page, or raise PendantMessageError saying why."""
    if len(text) > MAX_MESSAGE_BYTES:
        raise PendantMessageError(f"message longer than {MAX_MESSAGE_BYTES} bytes refused")
    try:
        data = json.loads(text, parse_constant=_reject_constant)
    except (ValueError, RecursionError) as exc:
        raise PendantMessageError(f"message is not valid JSON ({exc})") from None
    if not isinstance(data, dict):
        raise PendantMessageError('message must be a JSON object with a "type" field')
    kind = data.get("type")
    if kind == "jog":
        axes = _axis_map(data.get("axes"), known_axes, "axes", -1.0, 1.0, open_lo=False)
        speed = _number(data.get("speed"), "speed")
        if not 0.0 < speed <= 1.0:
            raise PendantMessageError(f"speed must be in (0, 1], got {speed:g}")
        return JogMessage(axes=axes, speed=speed)
    if kind == "stop":
        return StopMessage()
    if kind == "step":
        axis = _axis(data.get("axis"), known_axes, "axis")
        dist_mm = _number(data.get("dist_mm"), "dist_mm")
        if not STEP_MIN_MM <= abs(dist_mm) <= STEP_MAX_MM:
            raise PendantMessageError(
                f"dist_mm must be between {STEP_MIN_MM:g} and {STEP_MAX_MM:g} mm "
                f"(either sign), got {dist_mm:g}"
            )
        return StepMessage(axis=axis, dist_mm=dist_mm)
    if kind == "ratios":
        ratios = _axis_map(data.get("ratios"), known_axes, "ratios", 0.0, 1.0, open_lo=True)
        return RatiosMessage(ratios=ratios)
    if kind == "take_control":
        return TakeControlMessage()
    if kind == "command":
        return _command(data, known_axes)
    if kind == "ping":
        raw_id = data.get("id")
        if isinstance(raw_id, bool) or not isinstance(raw_id, int) or not 0 <= raw_id < 2**31:
            raise PendantMessageError(f"ping id must be a whole number from 0, got {raw_id!r}")
        return PingMessage(raw_id)
    raise PendantMessageError(
        f"unknown message type {json.dumps(kind)}; expected jog, stop, step, ratios, "
        "take_control, command or ping"
    )


def _text(value: object, what: str, max_chars: int) -> str:
    if not isinstance(value, str):
        raise PendantMessageError(f"{what} must be a string, got {json.dumps(value)}")
    if len(value) > max_chars:
        raise PendantMessageError(f"{what} is longer than {max_chars} characters")
    return value


def _command(data: Mapping[str, object], known_axes: Sequence[str]) -> CommandMessage:
    """Check the shape of a command; whether it may run now is the machine side's decision."""
    name = data.get("name")
    if name not in COMMAND_NAMES:
        raise PendantMessageError(
            f"unknown command {json.dumps(name)}; expected one of {', '.join(COMMAND_NAMES)}"
        )
    raw_id = data.get("id", 0)
    if isinstance(raw_id, bool) or not isinstance(raw_id, int) or not 0 <= raw_id < 2**31:
        raise PendantMessageError(f"id must be a whole number from 0, got {json.dumps(raw_id)}")
    assert isinstance(name, str)
    if name == "zero":
        axes = data.get("axes")
        if not isinstance(axes, list) or not axes:
            raise PendantMessageError('zero needs "axes", a list such as ["X", "Y"]')
        picked = tuple(dict.fromkeys(_axis(a, known_axes, "axes item") for a in axes))
        return CommandMessage(name, raw_id, axes=picked)
    if name == "wcs":
        return CommandMessage(name, raw_id, wcs=_text(data.get("wcs"), "wcs", 8))
    if name == "override":
        return CommandMessage(
            name,
            raw_id,
            kind=_text(data.get("kind"), "kind", 16),
            step=_text(data.get("step"), "step", 8),
        )
    if name == "console":
        return CommandMessage(name, raw_id, line=_text(data.get("line"), "line", CONSOLE_MAX_CHARS))
    return CommandMessage(name, raw_id)


def _finite_or_none(value: object) -> object:
    """Replace NaN and infinities (which JSON cannot carry) by null, recursively."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite_or_none(v) for v in value]
    return value


def view_message(view: Mapping[str, object]) -> dict[str, object]:
    """The server->client view message: the backend's snapshot plus "type": "view"."""
    body = {str(k): _finite_or_none(v) for k, v in view.items()}
    return {"type": "view", **body}


def role_message(role: str, *, controlled: bool, deadman_s: float) -> dict[str, object]:
    """Tell a client its role; `controlled` says whether some client holds control."""
    return {"type": "role", "role": role, "controlled": controlled, "deadman_s": deadman_s}


def result_message(
    command_id: int, command: str, *, ok: bool, lines: Sequence[str], error: str | None
) -> dict[str, object]:
    """The outcome of one machine command: what was sent, what came back, and any error."""
    return {
        "type": "result",
        "id": command_id,
        "command": command,
        "ok": ok,
        "lines": list(lines),
        "error": error,
    }


def error_message(text: str, *, code: str | None = None) -> dict[str, object]:
    """An error in words for the page to show; `code` names the ones the page acts on."""
    message: dict[str, object] = {"type": "error", "text": text}
    if code is not None:
        message["code"] = code
    return message


def pong_message(ping_id: int) -> dict[str, object]:
    """The answer to a ping, sent at once."""
    return {"type": "pong", "id": ping_id}


def dumps(message: Mapping[str, object]) -> str:
    """Serialise a server message; unknown objects become their str() rather than a crash."""
    return json.dumps(message, default=str, allow_nan=False, separators=(",", ":"))
