"""Tests for core/codes.py: complete tables, hints, unknown codes cope, names match their rows."""

from __future__ import annotations

from collections.abc import Mapping

import pytest

from smoothjog.core import codes
from smoothjog.core.codes import (
    ALARM_CODES,
    ERROR_CODES,
    CodeInfo,
    alarm_info,
    describe_alarm,
    describe_error,
    error_info,
)


def test_error_table_covers_1_to_38() -> None:
    assert sorted(ERROR_CODES) == list(range(1, 39))


def test_alarm_table_covers_1_to_10() -> None:
    assert sorted(ALARM_CODES) == list(range(1, 11))


@pytest.mark.parametrize("info", [*ERROR_CODES.values(), *ALARM_CODES.values()])
def test_records_are_filled_and_keyed_by_their_code(info: CodeInfo) -> None:
    table = ERROR_CODES if info in ERROR_CODES.values() else ALARM_CODES
    assert table[info.code] is info
    assert info.name
    assert info.meaning
    assert info.hint
    assert not info.meaning.endswith(".")
    assert not info.hint.endswith(".")


# Codes a jogging user can meet, with a word the hint must contain to be useful.
JOG_HINTS = [
    (error_info, 3, "$J="),
    (error_info, 8, "wait"),
    (error_info, 9, "$X"),
    (error_info, 11, "shorter"),
    (error_info, 15, "home"),
    (error_info, 16, "G53"),
    (error_info, 20, "exponent"),
    (error_info, 22, "F"),
    (error_info, 25, "once"),
    (error_info, 36, "S and T"),
    (alarm_info, 1, "$H"),
    (alarm_info, 2, "$X"),
    (alarm_info, 3, "$H"),
]


@pytest.mark.parametrize(("lookup", "code", "word"), JOG_HINTS)
def test_jog_relevant_hints(lookup: object, code: int, word: str) -> None:
    assert callable(lookup)
    info = lookup(code)
    assert isinstance(info, CodeInfo)
    assert word in info.hint


# The facts' corrections to the firmware's own tables (firmware-facts §5.7, §8).
CORRECTIONS = [
    (3, "'$J' without '='"),
    (8, "Alarm"),
    (11, "79"),
    (16, "even G0, G1 and G94"),
    (26, "machine zero"),
    (36, "S, T"),
]


@pytest.mark.parametrize(("code", "phrase"), CORRECTIONS)
def test_meanings_carry_the_facts_corrections(code: int, phrase: str) -> None:
    assert phrase in ERROR_CODES[code].meaning


@pytest.mark.parametrize("code", [0, 18, 19, 39, 79, 255, -1])
def test_unknown_or_unassigned_errors_get_a_record(code: int) -> None:
    info = error_info(code)
    assert info.code == code
    assert "1.1h" in info.meaning or "1.1h" in info.hint


@pytest.mark.parametrize("code", [0, 11, 14, 99])
def test_unknown_alarms_get_a_generic_record(code: int) -> None:
    info = alarm_info(code)
    assert info.code == code
    assert info.name == "Unknown alarm"


@pytest.mark.parametrize(
    ("describe", "code", "start"),
    [
        (describe_error, 15, "error:15 (Travel exceeded): "),
        (describe_error, 99, "error:99 (Unknown error): "),
        (describe_alarm, 2, "ALARM:2 (Soft limit): "),
        (describe_alarm, 42, "ALARM:42 (Unknown alarm): "),
    ],
)
def test_describe_is_one_sentence_with_the_hint(describe: object, code: int, start: str) -> None:
    assert callable(describe)
    text = describe(code)
    assert isinstance(text, str)
    assert text.startswith(start)
    assert text.endswith(".")
    assert ". " not in text  # one sentence
    assert "\n" not in text
    lookup = error_info if text.startswith("error") else alarm_info
    assert lookup(code).hint in text


def _named(prefix: str) -> dict[str, int]:
    """The module's int constants whose names start with prefix (ALARM_CODES is not one)."""
    found = {name: getattr(codes, name) for name in dir(codes) if name.startswith(prefix)}
    return {name: value for name, value in found.items() if isinstance(value, int)}


@pytest.mark.parametrize(
    ("prefix", "table", "firmware_prefix"),
    [("ERR_", ERROR_CODES, "STATUS_"), ("ALARM_", ALARM_CODES, "EXEC_ALARM_")],
    ids=["errors", "alarms"],
)
def test_each_named_code_is_its_rows_firmware_name(
    prefix: str, table: Mapping[int, CodeInfo], firmware_prefix: str
) -> None:
    named = _named(prefix)
    for name, code in named.items():
        assert table[code].symbol == firmware_prefix + name.removeprefix(prefix), name
    # Every assigned row has its constant, and no two constants share a code.
    assigned = {code for code, info in table.items() if info.symbol is not None}
    assert sorted(named.values()) == sorted(assigned)


def test_unassigned_rows_have_no_symbol() -> None:
    assert ERROR_CODES[18].symbol is None
    assert ERROR_CODES[19].symbol is None


# The codes the engine and the simulator test against, written out again (firmware-facts §5.6,
# §5.7).
@pytest.mark.parametrize(
    ("name", "code"),
    [
        ("STATUS_OK", 0),
        ("ERR_INVALID_STATEMENT", 3),
        ("ERR_IDLE_ERROR", 8),
        ("ERR_SYSTEM_GC_LOCK", 9),
        ("ERR_SOFT_LIMIT_ERROR", 10),
        ("ERR_OVERFLOW", 11),
        ("ERR_TRAVEL_EXCEEDED", 15),
        ("ERR_INVALID_JOG_COMMAND", 16),
        ("ERR_GCODE_UNDEFINED_FEED_RATE", 22),
        ("ERR_GCODE_UNUSED_WORDS", 36),
        ("ALARM_SOFT_LIMIT", 2),
        ("ALARM_ABORT_CYCLE", 3),
    ],
)
def test_codes_a_host_meets(name: str, code: int) -> None:
    assert getattr(codes, name) == code
