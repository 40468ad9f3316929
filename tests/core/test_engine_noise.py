"""Lines damaged on the wire: what the firmware's format cannot show must not wedge the engine."""

from __future__ import annotations

from smoothjog.core.intents import ContinuousIntent
from tests.core.engine_harness import EngineHarness

AT_REST = (-284.013, -282.425, -1.0)
#: The same report with its X sign lost on the wire: still a well-formed report.
SIGN_LOST = (284.013, -282.425, -1.0)
PRESS = ContinuousIntent({"Y": -1.0}, 0.1)


def test_a_press_after_a_report_outside_the_travel_jogs_once_a_right_report_comes() -> None:
    # Noise fuzz, Grbl over the Wi-Fi bridge: `MPos:284.013,...` for -284.013 came just before
    # a press. No line fits from there; the run stood for good, saying nothing.
    h = EngineHarness(soft_limits=True)
    h.rest_at(AT_REST)
    h.status("Idle", SIGN_LOST)
    h.intent(PRESS)
    h.run(h.t + 0.1)
    assert h.jog_lines() == []
    infos = [e.text for e in h.engine.events if e.kind == "info"]
    assert any("outside the soft limits" in t and "X 284.01" in t for t in infos), infos
    h.status("Idle", AT_REST)
    h.run(h.t + 0.2)
    assert h.jog_lines(), "the held stick jogs once a report puts the machine right"
    assert h.fault_texts() == []
    # The path starts where the machine is: every line is a Y- jog from there.
    assert all("X" not in line for line in h.jog_lines())
    assert abs(h.engine.track.path[0].start_mm[0] - AT_REST[0]) <= 1 / 80  # one step


def test_a_state_no_firmware_has_stops_the_jog_and_says_the_report_may_be_damaged() -> None:
    # `Joc` for `Jog`: one flipped bit (noise fuzz). Stopping stays right; the words say why.
    h = EngineHarness()
    h.rest_at(AT_REST)
    h.intent(PRESS)
    h.run(h.t + 0.2)
    assert h.jog_lines()
    h.status("Joc", AT_REST, fs=(500, 0))
    faults = h.fault_texts()
    assert any("'Joc'" in t and "damaged on the wire" in t for t in faults), faults
