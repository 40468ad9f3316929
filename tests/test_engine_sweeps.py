"""A stick swept back and forth the way a thumb moves a gamepad's, on the built-in simulator.

The stick runs a 1 Hz sine on X, 50 updates a second, passing slowly through zero at every
reversal, while Y is pushed into its soft limit (the machine starts homed at the + corner), so X
slides along that edge. Every stop here is smoothjog's own: none may be called an outside stop,
and the machine must keep following the stick.
"""

from __future__ import annotations

import math

import pytest

from smoothjog.core.engine import EngineEvent
from smoothjog.core.intents import ContinuousIntent
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.rig import LinkModel, SimRig
from smoothjog.virtual import VirtualHost


@pytest.mark.parametrize("speed", [0.25, 0.5])
def test_a_stick_swept_along_an_edge_is_never_taken_for_an_outside_stop(speed: float) -> None:
    events: list[EngineEvent] = []
    rig = SimRig(GrblFirmware(machine="hobby-router"), LinkModel())
    with VirtualHost(rig, on_event=events.append) as vs:
        vs.handshake()
        t0 = vs.now_s
        lowest_x_mm = 0.0
        for k in range(750):  # 15 s
            vs.run_until(t0 + k * 0.02)
            x = -math.sin(2 * math.pi * k * 0.02)
            # Never exactly 0 (which would be a release): the stick's own wobble near centre.
            vs.set_intent(ContinuousIntent({"X": round(x, 4) or 0.001, "Y": 0.3}, speed))
            lowest_x_mm = min(lowest_x_mm, rig.firmware.mpos_mm()[0])
    assert [e.text for e in events if e.kind == "fault"] == []
    # It followed the stick: each half cycle carries X v/π mm away from the edge and back.
    v_mm_s = speed * 5000 / 60
    assert lowest_x_mm < -0.5 * v_mm_s / math.pi
