"""`python -m bench reset`: a reset by another sender, then a press, per firmware and link."""

from __future__ import annotations

import pytest
from bench import reset


def test_the_table_has_a_row_per_firmware_and_link_and_a_cell_per_delay(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert reset.main(["--firmware", "grbl", "--links", "ideal", "--delays-ms", "0,20"]) == 0
    rows = [r for r in capsys.readouterr().out.splitlines() if r.startswith("| grbl")]
    assert len(rows) == 1
    cells = [c.strip() for c in rows[0].strip("|").split("|")]
    assert cells[:2] == ["grbl", "ideal"]
    assert all(0.0 < float(c) <= 3.0 for c in cells[2:])  # tests/test_reset_ghosts.py's bound


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--firmware", "marlin"], "unknown firmware marlin"),
        (["--links", "bluetooth"], "unknown link bluetooth"),
    ],
)
def test_unknown_names_are_refused_in_words(argv: list[str], words: str) -> None:
    with pytest.raises(SystemExit, match=words):
        reset.main(argv)


def test_bad_delays_are_refused_in_words(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        reset.main(["--delays-ms", "soon"])
    assert "--delays-ms takes one or more delays" in capsys.readouterr().err
