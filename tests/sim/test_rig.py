"""The virtual-time rig: wire timing, determinism, RX overflow, ground truth."""

from __future__ import annotations

import itertools

import pytest

from smoothjog.core.errors import SimError
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.rig import LinkModel, SimRig
from tests.sim.rigtools import Host, mpos


def _scenario(link: LinkModel) -> tuple[list[tuple[float, bytes]], list[object]]:
    """A jog stream with a status poll and a cancel; returns everything observable."""
    rig = SimRig(GrblFirmware(machine="hobby-router"), link)
    got: list[tuple[float, bytes]] = []
    t = 0.0
    for i in range(40):
        rig.send_line(f"$J=G91X-{0.5 + i * 0.01:.3f}Y-0.2F3000", t)
        rig.host_send(b"?", t + 0.005)
        t += 0.03
        got += rig.run_until(t)
    rig.host_send(b"\x85", t)
    got += rig.run_until(t + 2.0)
    return got, list(rig.trace)


def test_two_runs_are_identical_to_the_byte() -> None:
    link = LinkModel(latency_s=0.002, jitter_s=0.003, seed=7)
    assert _scenario(link) == _scenario(link)


def test_a_different_seed_changes_the_timing() -> None:
    a = _scenario(LinkModel(latency_s=0.002, jitter_s=0.003, seed=1))
    b = _scenario(LinkModel(latency_s=0.002, jitter_s=0.003, seed=2))
    assert [t for t, _ in a[0]] != [t for t, _ in b[0]]


@pytest.mark.parametrize(("baud", "latency_s"), [(115200, 0.0), (115200, 0.004), (9600, 0.0)])
def test_reply_time_is_byte_times_plus_latency_plus_parse(baud: int, latency_s: float) -> None:
    link = LinkModel(baud=baud, latency_s=latency_s)
    fw = GrblFirmware()
    rig = SimRig(fw, link)
    rig.run_until(1.0)
    arrived = rig.send_line("$J=G91X1F100", 1.0)  # 13 bytes
    assert arrived == pytest.approx(1.0 + 13 * link.byte_time_s + latency_s)
    lines = rig.run_until(2.0)
    t_ok = next(t for t, line in lines if line == b"ok")
    expected = arrived + fw.profile.line_time_s + 4 * link.byte_time_s + latency_s
    assert t_ok == pytest.approx(expected)


def test_bytes_beyond_the_rx_ring_are_dropped_while_the_main_loop_is_blocked() -> None:
    host = Host()
    host.send("$J=G91X10F100\n" * 16)  # fills the 15 planner blocks; one line blocks in mc_line
    host.run(0.5)
    host.send("G4P0(" + "x" * 300 + ")\n")
    host.run(0.5)
    assert host.fw.rx.dropped > 0
    assert host.fw.rx.free() == 0


def test_ground_truth_trace_matches_the_reports() -> None:
    host = Host()
    assert host.reply("$J=G91X2Y1F300") == "ok"
    host.wait_state("Idle")
    last = host.rig.trace[-1]
    assert last.end_mm == pytest.approx((2.0, 1.0, 0.0))
    assert mpos(host.status()) == (2.0, 1.0, 0.0)
    times = [(seg.t0_s, seg.t1_s) for seg in host.rig.trace]
    assert all(t0 < t1 for t0, t1 in times)
    assert all(a[1] == pytest.approx(b[0]) for a, b in itertools.pairwise(times))


def test_host_cannot_send_in_the_past() -> None:
    rig = SimRig()
    rig.run_until(1.0)
    with pytest.raises(SimError, match="before the rig's time"):
        rig.host_send(b"?", 0.5)


@pytest.mark.parametrize(
    "kwargs", [{"baud": 0}, {"latency_s": -1.0}, {"jitter_s": -0.1}, {"bits_per_byte": 0}]
)
def test_link_model_refuses_impossible_values(kwargs: dict[str, float]) -> None:
    with pytest.raises(SimError):
        LinkModel(**kwargs)  # type: ignore[arg-type]
