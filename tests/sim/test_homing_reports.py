"""What `?` gets during a homing cycle (firmware-facts §5.6a).

Grbl 1.1h's homing loop runs no realtime checkpoint: a `?` sent during the cycle is answered once,
as the cycle ends, still in Home and with the homed position, before `$H`'s `ok`. grblHAL answers
inside its homing loop, with the live position, when `$10` bit 12 asks for it.
"""

from __future__ import annotations

from tests.sim.rigtools import Host, is_reply


def _home_asking(host: Host, every_s: float) -> list[str]:
    """Send `$H`, then `?` every every_s until its reply; the lines received meanwhile."""
    host.send("$H\n")
    lines: list[str] = []
    for _ in range(int(20.0 / every_s)):
        host.send(b"?")
        lines += host.run(every_s)
        if any(is_reply(line) for line in lines):
            return lines
    raise AssertionError(f"$H got no reply; got {lines}")


def _before_reply(lines: list[str]) -> list[str]:
    reply = next(i for i, line in enumerate(lines) if is_reply(line))
    assert lines[reply] == "ok"
    return lines[:reply]


def test_grbl_answers_a_question_asked_while_homing_once_as_the_cycle_ends() -> None:
    host = Host(machine="hobby-router")  # homed at the pull-off corner, -1 on every axis
    lines = _home_asking(host, 0.1)
    assert host.now_s > 1.0  # a cycle of more than ten questions
    reports = [line for line in _before_reply(lines) if line.startswith("<")]
    assert len(reports) == 1
    assert reports[0].startswith("<Home|MPos:-1.000,-1.000,-1.000|")
    assert host.state() == "Idle"


def test_grblhal_reports_while_homing_only_when_10_asks_for_it() -> None:
    host = Host(firmware="grblhal", machine="hobby-router")
    lines = _home_asking(host, 0.1)
    reports = [x for x in _before_reply(lines) if x.startswith("<")]
    assert len(reports) == 1  # by default as Grbl 1.1h: once, as the cycle ends
    assert reports[0].startswith("<Home|MPos:-1.000,-1.000,-1.000|")
    assert host.reply("$10=4097") == "ok"  # MPos, and bit 12: report while homing
    assert "$10=4097" in host.command("$$")  # kept in 16 bits, not wrapped to one byte
    lines = _home_asking(host, 0.1)
    reports = [x for x in _before_reply(lines) if x.startswith("<")]
    assert len(reports) >= 10
    assert all(x.startswith("<Home|MPos:") for x in reports)
    positions = {x.split("|")[1] for x in reports}
    assert len(positions) >= 8  # the machine is seen moving


def test_grbl_keeps_10_in_one_byte() -> None:
    host = Host(machine="hobby-router")
    assert host.reply("$10=4097") == "ok"
    assert "$10=1" in host.command("$$")
