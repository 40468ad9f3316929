"""`smoothjog jog --replay` run as a real subprocess: virtual time, real time, and over TCP."""

from __future__ import annotations

import math
import os
import queue
import re
import signal
import subprocess
import sys
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import pytest

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "square.jsonl"
#: Generous: a virtual-time replay of a few seconds takes about one second of wall clock.
RUN_TIMEOUT_S = 60.0


def child_env() -> dict[str, str]:
    """The environment for a child smoothjog: no config file, UTF-8 output."""
    env = {k: v for k, v in os.environ.items() if k != "SMOOTHJOG_CONFIG"}
    env["PYTHONIOENCODING"] = "utf-8"
    return env


def run_jog(*args: str, timeout_s: float = RUN_TIMEOUT_S) -> subprocess.CompletedProcess[str]:
    """Run `python -m smoothjog jog ARGS` to completion and capture its output."""
    return run_smoothjog("jog", *args, timeout_s=timeout_s)


def run_smoothjog(*args: str, timeout_s: float) -> subprocess.CompletedProcess[str]:
    """Run `python -m smoothjog ARGS` to completion (or fail the test) and capture its output."""
    argv = [sys.executable, "-m", "smoothjog", *args]
    with subprocess.Popen(
        argv,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        encoding="utf-8",
        env=child_env(),
    ) as proc:
        try:
            out, err = proc.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
            pytest.fail(
                f"`smoothjog {' '.join(args)}` did not exit within {timeout_s} s;"
                f" stdout {out!r}, stderr {err!r}"
            )
    return subprocess.CompletedProcess(argv, proc.returncode, out, err)


def write_replay(path: Path, *lines: str) -> Path:
    """A replay file with these lines."""
    path.write_text("".join(f"{line}\n" for line in lines), encoding="utf-8")
    return path


@dataclass(frozen=True)
class Summary:
    """The summary `smoothjog jog` prints, read back."""

    where: str
    duration_s: float
    distance_mm: float | None
    stops: int
    tracked_um: float
    tracked_steps: float
    final_state: str
    final_mpos: tuple[float, ...]
    faults: list[str]


_SUMMARY = re.compile(
    r"replay finished on (?P<where>.+)\n"
    r"  duration        (?P<duration>[-\d.]+) s\n"
    r"(?:  distance        (?P<distance>[-\d.]+) mm \(simulator ground truth\)\n)?"
    r"  lines sent      (?P<lines>\d+)\n"
    r"  stops           (?P<stops>\d+)\n"
    r"  tracked - real  (?P<um>[-\d.]+) µm, (?P<steps>[-\d.]+) steps \(worst axis, worst stop\)\n"
    r"  final state     (?P<state>\S+) at MPos (?P<mpos>[-\d., ]+)\n"
    r"(?:  told:\n(?P<notes>(?:    - .*\n)+))?"
    r"(?:  faults          none\n|  faults:\n(?P<faults>(?:    - .*\n)+))\Z"
)


def parse_summary(stdout: str) -> Summary:
    """The fields of the summary; fails the test if stdout is not exactly one summary."""
    match = _SUMMARY.fullmatch(stdout)
    assert match is not None, f"not a replay summary:\n{stdout}"
    faults = match["faults"] or ""
    return Summary(
        where=match["where"],
        duration_s=float(match["duration"]),
        distance_mm=None if match["distance"] is None else float(match["distance"]),
        stops=int(match["stops"]),
        tracked_um=float(match["um"]),
        tracked_steps=float(match["steps"]),
        final_state=match["state"],
        final_mpos=tuple(float(v) for v in match["mpos"].split(", ")),
        faults=[line.removeprefix("    - ") for line in faults.splitlines()],
    )


def assert_clean_success(result: subprocess.CompletedProcess[str]) -> Summary:
    """Exit 0, nothing on stderr, a summary that ends Idle with no fault."""
    assert result.returncode == 0, (result.stdout, result.stderr)
    assert result.stderr == ""
    summary = parse_summary(result.stdout)
    assert summary.final_state == "Idle"
    assert summary.faults == []
    # The engine's promise: after a stop the host's idea of the position is the machine's.
    assert summary.tracked_steps <= 1.0
    return summary


# ------------------------------------------------------------------------ virtual time


@pytest.mark.parametrize(
    ("args", "where", "start_mm"),
    [
        ([], "grbl, hobby-router", (-1.0, -1.0, -1.0)),
        (["--machine", "slow-machine"], "grbl, slow-machine", (0.0, 0.0, 0.0)),
        (["--firmware", "grblhal"], "grblhal, hobby-router", (-1.0, -1.0, -1.0)),
        (["--firmware", "fluidnc"], "fluidnc, hobby-router", (-1.0, -1.0, -1.0)),
        (
            ["--firmware", "grblhal", "--machine", "slow-machine"],
            "grblhal, slow-machine",
            (0.0, 0.0, 0.0),
        ),
    ],
)
def test_example_square_on_the_simulator(
    args: list[str], where: str, start_mm: tuple[float, ...]
) -> None:
    """The shipped example on every simulated firmware: ends at the go-to target, Idle."""
    summary = assert_clean_success(run_jog("--replay", str(EXAMPLE), *args))
    assert summary.where == f"the built-in simulator ({where}, virtual time)"
    # The script ends with two 0.1 mm Z steps down and a go-to X-100 Y-100 (machine coords).
    assert summary.final_mpos == pytest.approx((-100.0, -100.0, start_mm[2] - 0.2), abs=1e-3)
    # A stick stop, the steps and the go-to: at least the stick stop is recorded.
    assert summary.stops >= 1
    # The last intent is at 5.5 s; the go-to of well over 100 mm takes a while after it.
    assert 5.5 < summary.duration_s < 60.0
    assert summary.distance_mm is not None
    straight_mm = math.dist(start_mm, summary.final_mpos)
    assert straight_mm < summary.distance_mm < 1000.0


@pytest.mark.parametrize(
    ("axis", "sign", "speed"),
    [("x", -1.0, 0.6), ("z", 1.0, 1.0)],
)
def test_a_stick_jog_moves_and_stops(tmp_path: Path, axis: str, sign: float, speed: float) -> None:
    """Hold one axis for 1 s, release: one stop, and the distance travelled is the displacement."""
    script = write_replay(
        tmp_path / "stick.jsonl",
        f'{{"t": 0, "axes": {{"{axis}": {sign}}}, "speed": {speed}}}',
        f'{{"t": 1.0, "axes": {{"{axis}": 0}}}}',
    )
    summary = assert_clean_success(run_jog("--replay", str(script), "--machine", "slow-machine"))
    assert summary.stops == 1
    index = "xyz".index(axis)
    moved_mm = summary.final_mpos[index]  # slow-machine powers up at MPos 0
    assert math.copysign(1.0, moved_mm) == sign
    assert summary.distance_mm == pytest.approx(abs(moved_mm), abs=0.01)
    other = [v for i, v in enumerate(summary.final_mpos) if i != index]
    assert other == [0.0, 0.0]
    # Well under what one second at the requested speed could cover, and clearly a move.
    max_mm_s = {"x": 5000 / 60, "y": 5000 / 60, "z": 1000 / 60}[axis]
    assert 0.1 < abs(moved_mm) < 2 * max_mm_s * speed
    assert summary.duration_s >= 1.0


def test_an_empty_replay_does_nothing(tmp_path: Path) -> None:
    """A script of comments only: no motion, no stop, still Idle where it started."""
    script = write_replay(tmp_path / "empty.jsonl", "# nothing to do")
    summary = assert_clean_success(run_jog("--replay", str(script)))
    assert summary.stops == 0
    assert summary.distance_mm == 0.0
    assert summary.final_mpos == (-1.0, -1.0, -1.0)


@pytest.mark.parametrize(
    ("lines", "at_limit"),
    [
        # Into the + corner of hobby-router's soft limits (the machine space is -travel..0).
        (
            ['{"t": 0, "axes": {"x": 1, "y": 1, "z": 1}}', '{"t": 1.5, "axes": {"x": 0}}'],
            {0: 0.0, 1: 0.0, 2: 0.0},
        ),
        # Down Z to the bottom (100 mm at 25 mm/s) and keep pushing, then stop.
        (['{"t": 0, "axes": {"z": -1}}', '{"t": 5.5, "stop": true}'], {2: -100.0}),
        # Against the + X limit, change direction along it, release.
        (
            [
                '{"t": 0, "axes": {"x": 1}}',
                '{"t": 0.5, "axes": {"x": 1, "y": -1}, "speed": 0.5}',
                '{"t": 1.5, "axes": {"x": 0, "y": 0}}',
            ],
            {0: 0.0},
        ),
    ],
    ids=["plus-corner", "z-bottom", "slide-along-x"],
)
def test_jogging_into_the_soft_limits_ends_idle_without_error_15(
    tmp_path: Path, lines: list[str], at_limit: dict[int, float]
) -> None:
    """The engine clips the stick at the envelope: the controller never answers error:15."""
    script = write_replay(tmp_path / "limit.jsonl", *lines)
    result = run_jog("--replay", str(script))
    assert "error:15" not in result.stdout + result.stderr
    summary = assert_clean_success(result)
    envelope = [(-800.0, 0.0), (-800.0, 0.0), (-100.0, 0.0)]
    for value, (low, high) in zip(summary.final_mpos, envelope, strict=True):
        assert low <= value <= high
    for index, limit_mm in at_limit.items():
        # Stopped at the limit, within a few steps (X/Y 80 steps/mm, Z 400 steps/mm).
        assert summary.final_mpos[index] == pytest.approx(limit_mm, abs=0.05)


@pytest.mark.parametrize(
    ("content", "needle"),
    [
        (b'{"t": 0, "axes": {"x": 1}}\n{"t": 1,\n', ":2: not valid JSON"),
        (b'{"t": 0, "axes": {"x": 2}}\n', ":1: deflection X=2.0 must be in [-1, 1]"),
        (b'# caf\xe9\n{"t": 0, "stop": true}\n', "cannot read replay file"),
        (None, "does not exist: check the path"),
    ],
    ids=["json", "deflection", "not-utf8", "missing"],
)
def test_a_bad_replay_file_is_one_sentence(
    tmp_path: Path, content: bytes | None, needle: str
) -> None:
    """A malformed or missing file: one `smoothjog:` line naming it, no traceback, no summary."""
    path = tmp_path / "bad.jsonl"
    if content is not None:
        path.write_bytes(content)
    result = run_jog("--replay", str(path))
    assert result.returncode != 0
    assert result.stdout == ""
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("smoothjog: "), lines[0]
    assert str(path) in lines[0], lines[0]
    assert needle in lines[0], lines[0]


HOBBY_ROUTER = (
    Path(__file__).resolve().parent.parent
    / "src"
    / "smoothjog"
    / "data"
    / "machines"
    / "hobby-router.toml"
)


def powered_up_router(path: Path, *, homing: bool = True) -> Path:
    """The hobby router just switched on: MPos 0, in Alarm when homing is on ($22=1)."""
    text = HOBBY_ROUTER.read_text(encoding="utf-8").replace('start = "homed"', 'start = "power-up"')
    if not homing:
        text = text.replace("22 = 1 ", "22 = 0 ")
    path.write_text(text, encoding="utf-8")
    return path


def test_a_machine_in_alarm_at_power_up_is_refused_in_words(tmp_path: Path) -> None:
    """$22=1 at power-up: Alarm. Nothing runs; one sentence says why and what to do next."""
    machine = powered_up_router(tmp_path / "alarm.toml")
    result = run_jog("--replay", str(EXAMPLE), "--machine", str(machine))
    assert result.returncode != 0
    assert result.stdout == ""
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("smoothjog: jogging refused"), lines[0]
    assert "the controller is in Alarm: unlock with $X or home with $H first" in lines[0]


def test_an_unhomed_machine_is_warned_and_a_clipped_jog_told(tmp_path: Path) -> None:
    """Soft limits on, homing off, MPos 0 at power-up: a + jog goes nowhere, and says so."""
    machine = powered_up_router(tmp_path / "unhomed.toml", homing=False)
    script = write_replay(
        tmp_path / "plus.jsonl", '{"t": 0, "axes": {"x": 1}}', '{"t": 1, "axes": {"x": 0}}'
    )
    result = run_jog("--replay", str(script), "--machine", str(machine))
    assert "the machine looks unhomed" in result.stderr
    assert "the jog stops at the soft limit" in result.stdout


def test_an_unknown_machine_is_one_sentence(tmp_path: Path) -> None:
    """--machine with a name that is not a profile: one sentence, no traceback."""
    script = write_replay(tmp_path / "ok.jsonl", '{"t": 0, "stop": true}')
    result = run_jog("--replay", str(script), "--machine", "no-such-machine")
    assert result.returncode != 0
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("smoothjog: ")
    assert "no-such-machine" in lines[0]


# A keep-out written as docs/config.md shows it, but with X and Y only: it blocks every Z height
# above that area of hobby-router (which powers up homed at MPos -1,-1,-1).
XY_KEEPOUT = """\
[[keepout]]
name = "vise"
min_mm = [-50, -60]
max_mm = [20, -30]
"""


def inside_xy_keepout(mpos: tuple[float, ...]) -> bool:
    """True when a position lies in the open interior of XY_KEEPOUT (any Z)."""
    return -50.0 < mpos[0] < 20.0 and -60.0 < mpos[1] < -30.0


@pytest.mark.parametrize("z_mm", [None, -60.0], ids=["at-the-top", "lower-down"])
def test_a_keepout_with_only_x_and_y_stops_the_stick_at_its_face(
    tmp_path: Path, z_mm: float | None
) -> None:
    """The stick pushed along -Y into an X/Y-only zone stops at its face, at any Z, and ends
    Idle: no traceback, no fault, and the machine never entered the zone."""
    config = tmp_path / "xy.toml"
    config.write_text(XY_KEEPOUT, encoding="utf-8")
    lines = []
    if z_mm is not None:  # first go down, clear of the zone, then push into it there
        lines.append(f'{{"t": 0, "goto": {{"z": {z_mm}}}, "speed": 1}}')
    t0_s = 0.0 if z_mm is None else 4.0
    lines += [
        f'{{"t": {t0_s}, "axes": {{"y": -1}}, "speed": 0.5}}',  # 41.7 mm/s for 1.5 s: ~62 mm
        f'{{"t": {t0_s + 1.5}, "axes": {{"y": 0}}}}',
    ]
    script = write_replay(tmp_path / "into-the-vise.jsonl", *lines)
    result = run_jog("--replay", str(script), "--config", str(config))
    assert "Traceback" not in result.stderr
    summary = assert_clean_success(result)
    x_mm, y_mm, z_end_mm = summary.final_mpos
    assert x_mm == pytest.approx(-1.0, abs=1e-3)
    assert z_end_mm == pytest.approx(-1.0 if z_mm is None else z_mm, abs=1e-3)
    # Stopped just outside the face y = -30 (the engine keeps one 1/80 mm step clear of it):
    # blocked there at this Z although the zone names no Z at all.
    assert -30.0 < y_mm < -29.95
    assert not inside_xy_keepout(summary.final_mpos)
    # Ground truth: the simulator's path is exactly as long as the straight legs (down Z, if
    # asked, then -Y to the face), so the machine took no detour: it was never inside the zone.
    assert summary.distance_mm is not None
    corner = (-1.0, -1.0, z_end_mm)
    legs_mm = math.dist((-1.0, -1.0, -1.0), corner) + math.dist(corner, summary.final_mpos)
    assert summary.distance_mm == pytest.approx(legs_mm, abs=0.01)


def test_the_example_square_with_an_xy_keepout_from_the_docs(tmp_path: Path) -> None:
    """The reported crash: docs/config.md's vise with only X and Y, the shipped example replay.
    The run ends with a summary (no traceback); the machine is never left inside the zone."""
    config = tmp_path / "docs-vise.toml"
    config.write_text(
        '[[keepout]]\nname = "vise"\nmin_mm = [-120, -80]\nmax_mm = [-40, -20]\n',
        encoding="utf-8",
    )
    result = run_jog("--replay", str(EXAMPLE), "--config", str(config))
    assert "Traceback" not in result.stdout + result.stderr
    summary = parse_summary(result.stdout)
    assert summary.final_state == "Idle"
    x_mm, y_mm, _ = summary.final_mpos
    assert not (-120.0 < x_mm < -40.0 and -80.0 < y_mm < -20.0)
    # The only thing allowed to go wrong is the go-to being refused because it crosses the zone
    # (reported in the summary and logged on stderr).
    assert all("keep-out zone 'vise'" in fault for fault in summary.faults), summary.faults
    assert all("keep-out zone 'vise'" in line for line in result.stderr.splitlines())


def test_a_keepout_naming_an_axis_the_machine_lacks_is_one_sentence(tmp_path: Path) -> None:
    """Four numbers on a 3-axis machine: refused at start-up naming the file and the key."""
    config = tmp_path / "four.toml"
    config.write_text(
        '[[keepout]]\nname = "rotary"\nmin_mm = [0, 0, 0, 0]\nmax_mm = [1, 1, 1, 90]\n',
        encoding="utf-8",
    )
    script = write_replay(tmp_path / "ok.jsonl", '{"t": 0, "stop": true}')
    result = run_jog("--replay", str(script), "--config", str(config))
    assert result.returncode != 0
    assert result.stdout == ""
    assert "Traceback" not in result.stderr
    (sentence,) = result.stderr.splitlines()
    assert sentence.startswith(f"smoothjog: {config}: [keepout 'rotary'] min_mm"), sentence
    assert "3 axes (X Y Z)" in sentence
    assert "no axis A" in sentence


# ------------------------------------------------------------------------ real time

SHORT_SCRIPT = (
    '{"t": 0, "axes": {"x": -1}, "speed": 0.5}',
    '{"t": 0.4, "axes": {"x": 0}}',
    '{"t": 0.6, "step": {"z": -0.5}, "speed": 0.5}',
)


def test_realtime_on_the_simulator(tmp_path: Path) -> None:
    """--realtime: the same replay on the wall clock; ends Idle and exits."""
    script = write_replay(tmp_path / "short.jsonl", *SHORT_SCRIPT)
    summary = assert_clean_success(run_jog("--replay", str(script), "--realtime", timeout_s=20))
    assert summary.where == "simulated grbl (hobby-router) at 115200 baud"
    assert summary.distance_mm is not None  # the built-in simulator's ground truth
    assert summary.distance_mm > 0.0
    assert summary.stops >= 1
    x_mm, y_mm, z_mm = summary.final_mpos
    assert -60.0 < x_mm < -2.0  # 0.4 s at up to 41.7 mm/s from -1
    assert y_mm == -1.0
    assert z_mm == pytest.approx(-1.5, abs=1e-3)
    assert 0.6 <= summary.duration_s < 20.0


class Child:
    """A long-running smoothjog child; its output is read on threads so waits can time out."""

    def __init__(self, *args: str) -> None:
        """Start `python -m smoothjog ARGS`."""
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "smoothjog", *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            encoding="utf-8",
            env=child_env(),
        )
        self._lines: queue.Queue[str | None] = queue.Queue()
        self.stdout: list[str] = []
        self.stderr: list[str] = []
        assert self.proc.stdout is not None
        assert self.proc.stderr is not None
        self._pumps = [
            threading.Thread(target=self._pump_out, args=(self.proc.stdout,), daemon=True),
            threading.Thread(
                target=lambda: self.stderr.extend(self.proc.stderr or ()), daemon=True
            ),
        ]
        for pump in self._pumps:
            pump.start()

    def _pump_out(self, stream: TextIO) -> None:
        for line in stream:
            self._lines.put(line)
        self._lines.put(None)

    def wait_for(self, pattern: str, timeout_s: float) -> re.Match[str]:
        """The first stdout line matching pattern; fails the test on timeout or end of output."""
        regex = re.compile(pattern)
        while True:
            try:
                line = self._lines.get(timeout=timeout_s)
            except queue.Empty:
                pytest.fail(f"no line matching {pattern!r} within {timeout_s} s: {self.stdout}")
            if line is None:
                self._lines.put(None)
                pytest.fail(f"output ended without {pattern!r}: {self.stdout} {self.stderr}")
            self.stdout.append(line)
            if match := regex.search(line):
                return match

    def stop(self, timeout_s: float = 15.0) -> int:
        """SIGINT, then wait for the exit and all output; kills it (and fails) if it hangs."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        try:
            code = self.proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            self._drain()
            pytest.fail(
                f"still running {timeout_s} s after SIGINT; stdout {''.join(self.stdout)!r},"
                f" stderr {''.join(self.stderr)!r}"
            )
        self._drain()
        return code

    def _drain(self) -> None:
        for pump in self._pumps:
            pump.join(timeout=10)
        while (line := self._lines.get(timeout=1)) is not None:
            self.stdout.append(line)
        for stream in (self.proc.stdout, self.proc.stderr):
            if stream is not None:
                stream.close()


def test_replay_over_tcp_against_the_served_simulator(tmp_path: Path) -> None:
    """`smoothjog sim --tcp 0` in one process, `jog --connect` in another: end to end."""
    sim = Child("sim", "--tcp", "0")
    try:
        ready = sim.wait_for(r"tcp 127\.0\.0\.1:(\d+)", timeout_s=30)
        port = int(ready[1])
        assert "machine grbl-defaults" in ready.string
        script = write_replay(tmp_path / "tcp.jsonl", *SHORT_SCRIPT)
        result = run_jog(
            "--replay", str(script), "--connect", f"tcp://127.0.0.1:{port}", timeout_s=20
        )
    finally:
        code = sim.stop()
    summary = assert_clean_success(result)
    assert summary.where == f"tcp://127.0.0.1:{port}"
    assert summary.distance_mm is None
    x_mm, y_mm, z_mm = summary.final_mpos
    # grbl-defaults: Idle at 0, 500 mm/min at 10 mm/s^2, no soft limits.
    assert -5.0 < x_mm < -0.01
    assert y_mm == 0.0
    assert z_mm == pytest.approx(-0.5, abs=1e-3)
    assert code == 0
    assert sim.stderr == [
        "smoothjog sim: stopped on SIGINT (RX bytes dropped 0; errors sent: none;"
        " G-code motion blocks 0)\n"
    ]
