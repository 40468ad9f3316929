"""Validation of the page's WebSocket messages and of the dead-man setting, no server."""

from __future__ import annotations

import json

import pytest

from smoothjog.web.protocol import (
    JogMessage,
    PendantError,
    PendantMessageError,
    PingMessage,
    RatiosMessage,
    StepMessage,
    StopMessage,
    TakeControlMessage,
    dumps,
    parse_client_message,
    view_message,
)
from smoothjog.web.server import create_app
from tests.web.recording import RecordingBackend

AXES = ("X", "Y", "Z")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            '{"type":"jog","axes":{"X":0.5,"Y":-1},"speed":1}',
            JogMessage({"X": 0.5, "Y": -1.0}, 1.0),
        ),
        ('{"type":"jog","axes":{"Z":1},"speed":0.01}', JogMessage({"Z": 1.0}, 0.01)),
        ('{"type":"stop"}', StopMessage()),
        ('{"type":"step","axis":"X","dist_mm":0.1}', StepMessage("X", 0.1)),
        ('{"type":"step","axis":"Z","dist_mm":-100}', StepMessage("Z", -100.0)),
        ('{"type":"step","axis":"Y","dist_mm":0.001}', StepMessage("Y", 0.001)),
        ('{"type":"ratios","ratios":{"Z":0.25}}', RatiosMessage({"Z": 0.25})),
        ('{"type":"take_control"}', TakeControlMessage()),
        ('{"type":"ping","id":7}', PingMessage(7)),
    ],
)
def test_valid_messages_parse(text: str, expected: object) -> None:
    assert parse_client_message(text, AXES) == expected


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("not json", "not valid JSON"),
        ("[1,2]", "JSON object"),
        ('{"axes":{"X":1}}', "unknown message type"),
        ('{"type":"fly"}', "unknown message type"),
        ('{"type":"jog","axes":{"X":1.5},"speed":0.5}', "axes.X must be in [-1, 1]"),
        ('{"type":"jog","axes":{"X":-1.01},"speed":0.5}', "axes.X must be in"),
        ('{"type":"jog","axes":{"A":0.5},"speed":0.5}', "must be one of X, Y, Z"),
        ('{"type":"jog","axes":{},"speed":0.5}', "non-empty object"),
        ('{"type":"jog","axes":[0.5],"speed":0.5}', "non-empty object"),
        ('{"type":"jog","axes":{"X":"1"},"speed":0.5}', "must be a number"),
        ('{"type":"jog","axes":{"X":true},"speed":0.5}', "must be a number"),
        ('{"type":"jog","axes":{"X":NaN},"speed":0.5}', "finite number"),
        ('{"type":"jog","axes":{"X":0.5},"speed":Infinity}', "finite number"),
        ('{"type":"jog","axes":{"X":0.5},"speed":0}', "speed must be in (0, 1]"),
        ('{"type":"jog","axes":{"X":0.5},"speed":1.2}', "speed must be in (0, 1]"),
        ('{"type":"jog","axes":{"X":0.5}}', "speed must be a number"),
        ('{"type":"step","axis":"X","dist_mm":0.0005}', "between 0.001 and 100 mm"),
        ('{"type":"step","axis":"X","dist_mm":100.5}', "between 0.001 and 100 mm"),
        ('{"type":"step","axis":"W","dist_mm":1}', "must be one of"),
        ('{"type":"step","axis":"X"}', "dist_mm must be a number"),
        ('{"type":"ratios","ratios":{"X":0}}', "ratios.X must be in (0, 1]"),
        ('{"type":"ratios","ratios":{"X":2}}', "ratios.X must be in (0, 1]"),
        ('{"type":"stop","pad":"' + "x" * 5000 + '"}', "longer than 4096"),
        ("[" * 100_000, "longer than"),
        ('{"type":"ping"}', "ping id must be a whole number"),
        ('{"type":"ping","id":-1}', "ping id must be a whole number"),
        ('{"type":"ping","id":1.5}', "ping id must be a whole number"),
    ],
)
def test_invalid_messages_are_refused_in_words(text: str, fragment: str) -> None:
    with pytest.raises(PendantMessageError) as info:
        parse_client_message(text, AXES)
    assert fragment in str(info.value)


def test_deeply_nested_json_is_refused_not_crashing() -> None:
    with pytest.raises(PendantMessageError):
        parse_client_message("[" * 2000 + "]" * 2000, AXES)


def test_known_axes_come_from_the_machine() -> None:
    text = '{"type":"jog","axes":{"A":0.5},"speed":0.5}'
    assert parse_client_message(text, ("X", "Y", "Z", "A")) == JogMessage({"A": 0.5}, 0.5)


def test_neutral_jog_is_recognised() -> None:
    assert JogMessage({"X": 0.0, "Y": 0.0}, 0.5).neutral
    assert not JogMessage({"X": 0.0, "Y": 0.1}, 0.5).neutral


def test_view_message_replaces_non_finite_numbers_with_null() -> None:
    view = {"t_s": 1.0, "mpos": [1.0, float("nan")], "queue": {"queued_mm": float("inf")}}
    text = dumps(view_message(view))
    assert json.loads(text) == {
        "type": "view",
        "t_s": 1.0,
        "mpos": [1.0, None],
        "queue": {"queued_mm": None},
    }


@pytest.mark.parametrize("window_s", [0.0, -1.0, float("nan")])
def test_the_deadman_window_must_be_positive(window_s: float) -> None:
    with pytest.raises(PendantError, match="dead-man window must be positive"):
        create_app(RecordingBackend(), token=None, deadman_s=window_s)
