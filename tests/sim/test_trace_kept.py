"""The simulator keeps its ground-truth trace only when asked: the embedded default runs all day."""

from __future__ import annotations

from pathlib import Path

from smoothjog.core.intents import ContinuousIntent
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import get_firmware_profile
from smoothjog.sim.rig import LinkModel, SimRig
from smoothjog.sim.serve import ServeOptions, build_firmware
from smoothjog.virtual import VirtualHost


def _jog(keep_trace: bool) -> tuple[int, float]:
    fw = GrblFirmware(get_firmware_profile("grbl"), "hobby-router", keep_trace=keep_trace)
    vh = VirtualHost(SimRig(fw, LinkModel()))
    vh.handshake()
    try:
        start = fw.mpos_mm()[0]
        vh.set_intent(ContinuousIntent({"X": -1.0}, 1.0))
        vh.run_until(vh.now_s + 1.0)
        vh.set_intent(ContinuousIntent({"X": 0.0}, 1.0))
        vh.run_until(vh.now_s + 1.0)
        return len(fw.motion.trace), start - fw.mpos_mm()[0]
    finally:
        vh.close()


def test_without_a_trace_the_machine_moves_and_keeps_no_segment() -> None:
    kept, moved_mm = _jog(keep_trace=False)
    assert kept == 0
    assert moved_mm > 50.0
    kept, moved_again_mm = _jog(keep_trace=True)
    assert kept > 50  # one per executed segment of about 10 ms
    assert moved_again_mm == moved_mm


def test_smoothjog_sim_keeps_a_trace_only_with_trace(tmp_path: Path) -> None:
    assert not build_firmware(ServeOptions()).motion.keep_trace
    assert build_firmware(ServeOptions(trace_path=tmp_path / "t.jsonl")).motion.keep_trace


def test_a_reset_mid_segment_leaves_the_part_already_run_in_the_trace() -> None:
    fw = GrblFirmware(get_firmware_profile("grbl"), "hobby-router")
    vh = VirtualHost(SimRig(fw, LinkModel()))
    vh.handshake()
    try:
        vh.set_intent(ContinuousIntent({"X": -1.0}, 1.0))
        vh.run_until(vh.now_s + 0.5053)  # mid-segment: segments are about 10 ms
        motion = fw.motion
        motion.advance(motion._now_s)
        at_reset = fw.mpos_mm()
        fw.motion.kill()
        last = fw.motion.trace[-1]
        # The trace ends where the machine is (to a step), not a segment short of it.
        assert abs(last.end_mm[0] - at_reset[0]) < 0.0125
    finally:
        vh.close()
