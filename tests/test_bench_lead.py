"""The lead sweep (`python -m bench lead`): what it measures and how it refuses bad options."""

from __future__ import annotations

import pytest
from bench import lead


def test_a_lead_cut_below_what_the_link_needs_shows_as_dips_and_a_shorter_coast() -> None:
    points = lead.sweep(["ftdi"], [0.0, 30.0], phases=1)
    assert [(p.link, p.cut_ms) for p in points] == [("ftdi", 0.0), ("ftdi", 30.0)]
    full, cut = points
    assert full.long_s1_mm == cut.long_s1_mm > 0.0  # one reference per link
    assert full.s2_dips == 0
    assert full.s2_within == pytest.approx(1.0)
    # 30 ms less queue than the engine sizes for FTDI: the planner runs dry between lines.
    assert cut.s2_dips > 0
    assert cut.s4_mm < full.s4_mm
    rows = lead.table(points, stop_mm=6.94)
    assert rows[2].startswith("| ftdi | 0 ms | ")
    assert "(1." in rows[2]  # S4 as a multiple of v²/2a


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--cut-ms", "five"], "--cut-ms takes numbers"),
        (["--cut-ms", "-5"], "0 ms or more"),
        (["--phases", "0"], "--phases takes a whole number"),
        (["--links", "bluetooth"], "unknown link bluetooth"),
    ],
)
def test_bad_options_are_refused_in_words(
    argv: list[str], words: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        lead.main(argv)
    assert exc.value.code not in (0, None)
    # argparse prints its refusal; an unknown link's refusal is the exit's own message.
    assert words in capsys.readouterr().err + str(exc.value.code)


def test_no_link_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert lead.main(["--links", "none"]) == 2
    assert "no link to run" in capsys.readouterr().err
