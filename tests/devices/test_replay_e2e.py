"""Recorded devices drive the simulated machine end to end through `smoothjog jog --input-replay`.

The same command users run: the recording is read, its kind's decoder turns it into intents,
the arbiter lets them through, the one host drives the built-in Grbl 1.1h simulator (hobby
router, homed at the pull-off corner, 80 steps/mm, 500 mm/s² on X) in virtual time over its
ideal in-process wire. Positions are the controller's own MPos at the end.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from smoothjog.cli import main
from smoothjog.devices import load_device_replay
from smoothjog.inputs.device import HidReport
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import get_firmware_profile
from smoothjog.sim.rig import SimRig
from smoothjog.virtual import VirtualHost

FIXTURES = Path(__file__).parent / "fixtures"
_MPOS = re.compile(r"final state\s+(\w+) at MPos (-?[\d.]+), (-?[\d.]+), (-?[\d.]+)")


def _replay(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, tuple[float, ...]]:
    code = main(["jog", *args])
    out = capsys.readouterr().out
    m = _MPOS.search(out)
    assert m is not None, out
    return code, out, tuple(float(v) for v in m.groups()[1:])


def _start(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> tuple[float, ...]:
    # Where the machine stands before any jog: a replay of nothing but a stop.
    script = tmp_path / "nothing.jsonl"
    script.write_text('{"t": 0, "stop": true}\n')
    _, _, mpos = _replay(capsys, "--replay", str(script))
    return mpos


def test_37_whb04b_detents_in_step_mode_move_037_mm_on_the_step_grid(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    start = _start(capsys, tmp_path)
    code, out, mpos = _replay(
        capsys, "--input-replay", str(FIXTURES / "whb04b" / "step_37.hid"), "--input-kind", "whb04b"
    )
    assert code == 0, out
    # 37 x 0.01 mm = 0.37 mm; the nearest step at 80 steps/mm is 30 steps = 0.375 mm.
    assert mpos[0] - start[0] == pytest.approx(0.375, abs=1e-9)
    assert mpos[1:] == start[1:]
    assert "device          whb04b" in out
    assert "refused" in out


def test_a_whb04b_velocity_spin_stops_within_the_stopping_distance_of_the_wheel(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    start = _start(capsys, tmp_path)
    code, out, mpos = _replay(
        capsys,
        "--input-replay",
        str(FIXTURES / "whb04b" / "velocity_spin.hid"),
        "--input-kind",
        "whb04b",
    )
    assert code == 0, out
    moved = start[0] - mpos[0]
    # 40 detents of 0.05 mm: never more than was turned (velocity mode may drop counts).
    assert 0.0 < moved <= 40 * 0.05 + 1e-9


def test_a_gamepad_released_at_speed_stops_as_a_pendant_release_does(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    pad = FIXTURES / "gamepad" / "xpad-full-left-release.evtest"
    code, out, pad_end = _replay(capsys, "--input-replay", str(pad), "--input-kind", "gamepad")
    assert code == 0, out
    # The same hold as a script (the pendant's intents): full left at the pad's default 50 %
    # speed from 0.2 s, released at 2.2 s.
    script = tmp_path / "hold.jsonl"
    script.write_text('{"t": 0.2, "axes": {"x": -1}, "speed": 0.5}\n{"t": 2.2, "axes": {"x": 0}}\n')
    _, _, script_end = _replay(capsys, "--replay", str(script))
    start = _start(capsys, tmp_path)
    assert start[0] - pad_end[0] > 70.0  # about 2 s at 41.7 mm/s
    assert pad_end[1:] == start[1:]  # the other axes at rest add nothing
    # The pad stops no further than the pendant's release; it may stop short by its 16 ms
    # ramp in (0.67 mm at 41.7 mm/s) and by the pendant's stopping run (v^2/2a = 1.74 mm at
    # 500 mm/s^2, measured up to 1.35x that on this link), because its stick slows first.
    ramp_mm = 0.016 * 41.67
    stop_mm = 1.5 * 41.67**2 / (2 * 500)
    assert 0.0 <= pad_end[0] - script_end[0] <= ramp_mm + stop_mm


def test_a_gamepad_unplugged_mid_jog_stops_the_machine(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    pad = FIXTURES / "gamepad" / "xpad-unplug-mid-jog.evtest"
    code, out, end = _replay(capsys, "--input-replay", str(pad), "--input-kind", "gamepad")
    assert code == 0, out
    assert "final state     Idle" in out
    start = _start(capsys, tmp_path)
    moved = start[0] - end[0]
    # Held from 0.2 s to the end of the recording at 1.5 s at 41.7 mm/s, then a stop:
    # about 54 mm plus the stopping distance, never the rest of the travel.
    assert 45.0 < moved < 60.0
    assert "stream ended" in out


def test_a_keypad_hold_moves_and_stops(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    keys = FIXTURES / "keyboard" / "diagonal-kp8-kp6.txt"
    start = _start(capsys, tmp_path)
    code, out, end = _replay(capsys, "--input-replay", str(keys), "--input-kind", "keyboard")
    assert code == 0, out
    assert end != start


def test_input_replay_errors_are_sentences(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    missing = str(tmp_path / "none.hid")
    assert main(["jog", "--input-replay", missing, "--input-kind", "whb04b"]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["jog", "--input-replay", str(FIXTURES / "whb04b" / "step_37.hid")]) == 2
    assert "needs --input-kind" in capsys.readouterr().err


def _config(tmp_path: Path, text: str) -> str:
    path = tmp_path / "devices.toml"
    path.write_text(text)
    return str(path)


def test_a_shuttle_ring_held_then_centred_jogs_and_stops(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    start = _start(capsys, tmp_path)
    # The homed router has 1 mm of room in +X: the ring is read the other way round.
    config = _config(tmp_path, '[[device]]\nkind = "shuttle"\ninvert = true\n')
    ring = str(FIXTURES / "shuttle" / "ring_hold.hid")
    code, out, end = _replay(
        capsys, "--config", config, "--input-replay", ring, "--input-kind", "shuttle"
    )
    assert code == 0, out
    moved = start[0] - end[0]
    # About 1.5 s at full speed (83.3 mm/s) plus the ramps, then a stop at the centre.
    assert 100.0 < moved < 150.0
    assert end[1:] == start[1:]


def test_a_spacemouse_push_jogs_and_its_release_stops(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    start = _start(capsys, tmp_path)
    config = _config(tmp_path, '[[device]]\nkind = "spacemouse"\naxes = { X = "-x" }\n')
    push = str(FIXTURES / "spacemouse" / "push_x.hid")
    code, out, end = _replay(
        capsys, "--config", config, "--input-replay", push, "--input-kind", "spacemouse"
    )
    assert code == 0, out
    moved = start[0] - end[0]
    # About 1 s near full speed (83.3 mm/s) plus the ramps, then the release stops it.
    assert 60.0 < moved < 110.0
    assert end[1:] == start[1:]


def test_an_encoder_knob_turns_the_handwheel(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    start = _start(capsys, tmp_path)
    knob = str(FIXTURES / "knob" / "rel-dial.txt")
    code, out, end = _replay(capsys, "--input-replay", knob, "--input-kind", "knob")
    assert code == 0, out
    assert end != start


def test_a_whb04b_switched_off_mid_move_stops_short_of_what_was_turned(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    start = _start(capsys, tmp_path)
    wheel = str(FIXTURES / "whb04b" / "sleep_mid_move.hid")
    code, out, end = _replay(capsys, "--input-replay", wheel, "--input-kind", "whb04b")
    assert code == 0, out
    moved = start[0] - end[0]
    # 50 detents of 1 mm were turned; the sleep report 0.3 s after the last stops the rest
    # (and its 0x81 byte is not read as 127 more detents).
    assert 5.0 < moved < 40.0
    assert "switched off or asleep" in out


def test_whb04b_velocity_mode_stops_within_the_stopping_distance_of_the_last_detent() -> None:
    # The replay's own harness on the host the command uses, to read the simulator's trace.
    replay = load_device_replay(str(FIXTURES / "whb04b" / "velocity_spin.hid"), "whb04b")
    last_detent_s = max(r.t_s for r in replay.items if isinstance(r, HidReport) and r.data[6])
    rig = SimRig(GrblFirmware(get_firmware_profile("grbl"), "hobby-router"))
    vh = VirtualHost(rig)
    try:
        vh.handshake()
        t_play_s = vh.now_s  # the recording's 0 on the loop's (and the simulator's) clock
        said = vh._run(replay.play(vh.host))
        assert vh.run_until_idle(10.0)
    finally:
        vh.close()
    wheel_stopped_s = t_play_s + last_detent_s
    after_mm = 0.0
    for seg in rig.trace:
        if seg.t1_s <= wheel_stopped_s:
            continue
        share = (seg.t1_s - max(seg.t0_s, wheel_stopped_s)) / (seg.t1_s - seg.t0_s)
        after_mm += share * math.dist(seg.start_mm, seg.end_mm)
    # 100 % on the selector is X's full rate, 5000 mm/min, at 500 mm/s^2.
    v_mm_s = 5000 / 60
    assert after_mm <= v_mm_s**2 / (2 * 500)
    moved_mm = sum(math.dist(seg.start_mm, seg.end_mm) for seg in rig.trace)
    assert 0.0 < moved_mm <= 40 * 0.05 + 1e-9
    assert any("intents" in line and "0 refused" in line for line in said), said
