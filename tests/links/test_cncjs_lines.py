"""What the CNCjs link makes of CNCjs's text: decorated replies, echoed writes, addresses."""

from __future__ import annotations

import pytest

from smoothjog.core.errors import LinkError
from smoothjog.links.cncjs import CncjsLink, parse_cncjs_url, undecorate, wire_lines


@pytest.mark.parametrize(
    ("line", "own"),
    [
        ("error:9 (G-code lock)", "error:9"),
        ("error:15 (Travel exceeded)", "error:15"),
        ("ALARM:1 (Hard limit)", "ALARM:1"),
        ("$110=500.000 (X-axis maximum rate, mm/min)", "$110=500.000"),
        ("ok", "ok"),
        ("<Idle|MPos:0.000,0.000,0.000|FS:0,0>", "<Idle|MPos:0.000,0.000,0.000|FS:0,0>"),
        ("[MSG:Pgm End]", "[MSG:Pgm End]"),
        ("error:9", "error:9"),
    ],
)
def test_cncjs_decorations_are_taken_off(line: str, own: str) -> None:
    assert undecorate(line) == own


@pytest.mark.parametrize(
    ("data", "partial", "lines", "rest"),
    [
        ("$J=G91X1F100\n", "", ["$J=G91X1F100"], ""),
        ("$G\n$J=G91X1\n", "", ["$G", "$J=G91X1"], ""),
        ("G0 X1\r\n", "", ["G0 X1", ""], ""),  # Grbl answers the empty line too
        ("?", "", [], ""),
        ("\x85", "", [], ""),
        ("\x18", "", [], ""),
        ("G1 X1 ?F100\n", "", ["G1 X1 F100"], ""),  # realtime picked out of the line
        ("G1 X", "", [], "G1 X"),
        ("1\n", "G1 X", ["G1 X1"], ""),
        ("\n", "", [""], ""),
    ],
)
def test_echoed_writes_become_the_lines_the_controller_buffers(
    data: str, partial: str, lines: list[str], rest: str
) -> None:
    assert wire_lines(data, partial) == (lines, rest)


@pytest.mark.parametrize(
    ("url", "clean"),
    [
        ("http://127.0.0.1:8000", "http://127.0.0.1:8000"),
        ("http://raspberrypi.local/", "http://raspberrypi.local:8000"),
        ("https://cnc:8443", "https://cnc:8443"),
        ("http://[::1]:9000", "http://[::1]:9000"),
    ],
)
def test_cncjs_addresses(url: str, clean: str) -> None:
    assert parse_cncjs_url(url) == clean


@pytest.mark.parametrize("url", ["127.0.0.1:8000", "tcp://cnc:23", "http://", "http://h:99999"])
def test_bad_cncjs_addresses_are_refused_in_words(url: str) -> None:
    with pytest.raises(LinkError, match=r"CNCjs address|port"):
        parse_cncjs_url(url)


def test_a_cncjs_link_needs_the_port() -> None:
    with pytest.raises(LinkError, match="--cncjs-port"):
        CncjsLink("http://127.0.0.1:8000", "", "t.o.k")
