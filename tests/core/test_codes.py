"""Tests for core/codes.py: complete tables, hints for jog-relevant codes, unknown codes cope."""

from __future__ import annotations

import pytest

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


# The facts' corrections to the firmware's own tables (facts §5.7, §8).
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
