"""Replay files: every intent kind parsed, and every malformed line named by file and line."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import pytest

from smoothjog.core.errors import SmoothjogError
from smoothjog.core.intents import ContinuousIntent, GotoIntent, StepIntent, StopIntent
from smoothjog.inputs.replay import ReplayError, TimedIntent, load_replay, parse_replay

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "square.jsonl"


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        (
            '{"t": 0.0, "axes": {"x": 1.0, "y": -0.5}, "speed": 0.8}',
            [TimedIntent(0.0, ContinuousIntent({"X": 1.0, "Y": -0.5}, 0.8))],
        ),
        ('{"t": 1.5, "axes": {"x": 0}}', [TimedIntent(1.5, ContinuousIntent({"X": 0.0}, 1.0))]),
        (
            '{"t": 2, "axes": {"Z": -1, "a": 1}, "speed": 1}',
            [TimedIntent(2.0, ContinuousIntent({"Z": -1.0, "A": 1.0}, 1.0))],
        ),
        (
            '{"t": 2.0, "step": {"z": -0.1}, "speed": 0.2}',
            [TimedIntent(2.0, StepIntent("Z", -0.1, 0.2))],
        ),
        (
            '{"t": 2.5, "step": {"x": 0.001, "Y": -100}, "speed": 0.5}',
            [
                TimedIntent(2.5, StepIntent("X", 0.001, 0.5)),
                TimedIntent(2.5, StepIntent("Y", -100.0, 0.5)),
            ],
        ),
        (
            '{"t": 3.0, "goto": {"x": -100, "y": -50.5}, "speed": 0.5}',
            [TimedIntent(3.0, GotoIntent({"X": -100.0, "Y": -50.5}, 0.5))],
        ),
        ('{"t": 4.0, "stop": true}', [TimedIntent(4.0, StopIntent())]),
        (
            '  {"t": 0, "speed": 0.001, "axes": {"w": -1}}  ',
            [TimedIntent(0.0, ContinuousIntent({"W": -1.0}, 0.001))],
        ),
    ],
)
def test_each_intent_kind(line: str, expected: list[TimedIntent]) -> None:
    """One line of each kind becomes the intents it names, axis letters upper-cased."""
    parsed = parse_replay([line])
    assert parsed == expected
    for item in parsed:
        assert type(item.t_s) is float
        intent = item.intent
        if isinstance(intent, ContinuousIntent):
            assert all(type(v) is float for v in intent.axes.values())
        elif isinstance(intent, GotoIntent):
            assert all(type(v) is float for v in intent.target_mpos_mm.values())
        elif isinstance(intent, StepIntent):
            assert type(intent.dist_mm) is float


def test_comments_blank_lines_and_order_are_kept() -> None:
    """Comments and blank lines are skipped; equal times are allowed; order is the file's."""
    lines = [
        "# a comment",
        "",
        "   ",
        '{"t": 0, "axes": {"x": -1}}',
        "  # an indented comment",
        '{"t": 0.5, "step": {"z": 1}, "speed": 0.3}',
        '{"t": 0.5, "step": {"z": 2}, "speed": 0.3}',
        '{"t": 1, "stop": true}',
    ]
    assert parse_replay(lines) == [
        TimedIntent(0.0, ContinuousIntent({"X": -1.0}, 1.0)),
        TimedIntent(0.5, StepIntent("Z", 1.0, 0.3)),
        TimedIntent(0.5, StepIntent("Z", 2.0, 0.3)),
        TimedIntent(1.0, StopIntent()),
    ]


def test_empty_script() -> None:
    """Nothing but comments is an empty script, not an error."""
    assert parse_replay(["# nothing", ""]) == []


def test_the_example_file_loads() -> None:
    """examples/square.jsonl: every kind it uses, times non-decreasing."""
    script = load_replay(EXAMPLE)
    kinds = {type(item.intent) for item in script}
    assert kinds == {ContinuousIntent, StepIntent, GotoIntent}
    times = [item.t_s for item in script]
    assert times == sorted(times)
    assert script[-1] == TimedIntent(5.5, GotoIntent({"X": -100.0, "Y": -100.0}, 0.6))


def test_load_replay_reads_a_file(tmp_path: Path) -> None:
    """A file with Windows line ends and a comment parses like the same lines given directly."""
    path = tmp_path / "crlf.jsonl"
    path.write_bytes(b'# header\r\n{"t": 0, "axes": {"y": 0.5}}\r\n{"t": 1, "stop": true}\r\n')
    assert load_replay(str(path)) == [
        TimedIntent(0.0, ContinuousIntent({"Y": 0.5}, 1.0)),
        TimedIntent(1.0, StopIntent()),
    ]


GOOD = '{"t": 0, "stop": true}'


@pytest.mark.parametrize(
    ("lines", "line_no", "needle"),
    [
        # not JSON, not an object
        (['{"t": 0,'], 1, "not valid JSON"),
        (["t=0 stop"], 1, "not valid JSON"),
        ([GOOD, "[1, 2]"], 2, "must be a JSON object"),
        (["3"], 1, "must be a JSON object"),
        (['"stop"'], 1, "must be a JSON object"),
        (["null"], 1, "must be a JSON object"),
        # keys
        (['{"t": 0, "stop": true, "when": 1}'], 1, "unknown key 'when'"),
        (['{"t": 0, "Axes": {"x": 1}}'], 1, "unknown key 'Axes'"),
        # t
        (['{"stop": true}'], 1, "'t' must be a finite number, got None"),
        (['{"t": NaN, "stop": true}'], 1, "'t' must be a finite number"),
        (['{"t": Infinity, "stop": true}'], 1, "'t' must be a finite number"),
        (['{"t": "0", "stop": true}'], 1, "'t' must be a finite number"),
        (['{"t": true, "stop": true}'], 1, "'t' must be a finite number"),
        (['{"t": 1, "stop": true}', '{"t": 0.5, "stop": true}'], 2, "goes back"),
        (['{"t": -0.1, "stop": true}'], 1, "goes back"),
        # speed
        (['{"t": 0, "axes": {"x": 1}, "speed": 0}'], 1, "must be in (0, 1]"),
        (['{"t": 0, "axes": {"x": 1}, "speed": 1.01}'], 1, "must be in (0, 1]"),
        (['{"t": 0, "axes": {"x": 1}, "speed": -0.5}'], 1, "must be in (0, 1]"),
        (['{"t": 0, "step": {"x": 1}, "speed": 2}'], 1, "must be in (0, 1]"),
        (['{"t": 0, "axes": {"x": 1}, "speed": NaN}'], 1, "'speed' must be a finite number"),
        (['{"t": 0, "axes": {"x": 1}, "speed": "fast"}'], 1, "'speed' must be a finite number"),
        # kinds
        (['{"t": 0, "axes": {"x": 1}, "stop": true}'], 1, "exactly one of"),
        (['{"t": 0, "step": {"x": 1}, "goto": {"x": 0}}'], 1, "exactly one of"),
        (['{"t": 0}'], 1, "exactly one of"),
        (['{"t": 0, "speed": 0.5}'], 1, "exactly one of"),
        # deflections
        (['{"t": 0, "axes": {"x": 1.5}}'], 1, "deflection X=1.5 must be in [-1, 1]"),
        (['{"t": 0, "axes": {"y": -1.01}}'], 1, "deflection Y=-1.01 must be in [-1, 1]"),
        (['{"t": 0, "axes": {"x": "1"}}'], 1, "'axes.x' must be a finite number"),
        (['{"t": 0, "axes": {"x": null}}'], 1, "'axes.x' must be a finite number"),
        (['{"t": 0, "axes": {}}'], 1, "'axes' must be an object"),
        (['{"t": 0, "axes": [1, 0]}'], 1, "'axes' must be an object"),
        # steps
        (['{"t": 0, "step": {"x": 0.0005}}'], 1, "is outside 0.001 to 100.0 mm"),
        (['{"t": 0, "step": {"x": -0.0009}}'], 1, "is outside 0.001 to 100.0 mm"),
        (['{"t": 0, "step": {"x": 0}}'], 1, "is outside 0.001 to 100.0 mm"),
        (['{"t": 0, "step": {"z": 100.5}}'], 1, "step of 100.5 mm is outside 0.001 to 100.0 mm"),
        (['{"t": 0, "step": {"z": -101}}'], 1, "is outside 0.001 to 100.0 mm"),
        (['{"t": 0, "step": {"x": Infinity}}'], 1, "'step.x' must be a finite number"),
        (['{"t": 0, "step": 1}'], 1, "'step' must be an object"),
        # goto
        (['{"t": 0, "goto": {"x": NaN}}'], 1, "'goto.x' must be a finite number"),
        (['{"t": 0, "goto": {}}'], 1, "'goto' must be an object"),
        # axis letters
        (['{"t": 0, "axes": {"q": 1}}'], 1, "'q' is not an axis letter"),
        (['{"t": 0, "step": {"xy": 1}}'], 1, "'xy' is not an axis letter"),
        (['{"t": 0, "goto": {"": 1}}'], 1, "'' is not an axis letter"),
        (['{"t": 0, "axes": {"1": 1}}'], 1, "'1' is not an axis letter"),
        # the line number counts comments and blank lines
        (["# c", "", GOOD, "", '{"t": 1, "stop": 1, "x": 2}'], 5, "unknown key 'x'"),
    ],
)
def test_malformed_lines_name_the_source_and_line(
    lines: list[str], line_no: int, needle: str
) -> None:
    """Each malformed line: a ReplayError starting `source:line:` and saying what is wrong."""
    with pytest.raises(ReplayError) as caught:
        parse_replay(lines, source="case.jsonl")
    message = str(caught.value)
    assert message.startswith(f"case.jsonl:{line_no}: "), message
    assert needle in message, message
    assert "\n" not in message
    assert isinstance(caught.value, SmoothjogError)


def test_default_source_name() -> None:
    """Without a source the message still says where: `<replay>:N`."""
    with pytest.raises(ReplayError, match=re.escape("<replay>:2: ")):
        parse_replay([GOOD, "{"])


def test_a_bad_line_in_a_file_names_the_path(tmp_path: Path) -> None:
    """load_replay names the file it read and the line number within it."""
    path = tmp_path / "bad.jsonl"
    path.write_text(f'{GOOD}\n# fine\n{{"t": 2, "axes": {{"x": 2}}}}\n', encoding="utf-8")
    with pytest.raises(ReplayError) as caught:
        load_replay(path)
    assert str(caught.value).startswith(f"{path}:3: deflection X=2.0")


def test_line_numbers_count_only_line_feeds(tmp_path: Path) -> None:
    """A form feed (an editor's page break) is not a line end: the bad line is still line 3."""
    path = tmp_path / "paged.jsonl"
    path.write_text(f"{GOOD}\n\f\n{{bad}}\n", encoding="utf-8")
    with pytest.raises(ReplayError) as caught:
        load_replay(path)
    assert str(caught.value).startswith(f"{path}:3: not valid JSON"), str(caught.value)


def test_a_comment_may_hold_any_character(tmp_path: Path) -> None:
    """A comment is skipped whole, even with a Unicode line separator inside it."""
    path = tmp_path / "notes.jsonl"
    path.write_text(f"# X first\u2028then Y\n{GOOD}\n", encoding="utf-8")
    assert load_replay(path) == [TimedIntent(0.0, StopIntent())]


@pytest.mark.parametrize(
    ("make", "needle"),
    [
        (lambda d: d / "missing.jsonl", "does not exist: check the path"),
        (lambda d: d, "cannot read replay file"),
        (
            lambda d: _write(d / "latin1.jsonl", b'# caf\xe9\n{"t": 0, "stop": true}\n'),
            "cannot read replay file",
        ),
        (lambda d: _write(d / "utf16.jsonl", GOOD.encode("utf-16")), "cannot read replay file"),
    ],
    ids=["missing", "directory", "latin-1", "utf-16"],
)
def test_unreadable_files(tmp_path: Path, make: Callable[[Path], Path], needle: str) -> None:
    """A file that is absent, a directory or not UTF-8: a ReplayError naming the path."""
    path = make(tmp_path)
    with pytest.raises(ReplayError) as caught:
        load_replay(path)
    message = str(caught.value)
    assert str(path) in message
    assert needle in message
    assert "\n" not in message


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path
