"""The virtual-time rig: wire timing, determinism, RX overflow, ground truth."""

from __future__ import annotations

import itertools

import pytest

from smoothjog.core.errors import SimError
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.rig import LINK_MODELS, LinkModel, SimRig
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


# ----------------------------------------------------------------- modelled links


def _oks(rig: SimRig, sends_s: list[float]) -> list[tuple[float, float]]:
    """Send an empty line at each time: when each reached the controller, when its ok came."""
    out = []
    for t in sends_s:
        rig.run_until(t)
        arrived = rig.host_send(b"\n", t)
        got = rig.run_until(t + 0.2)
        oks = [at for at, line in got if line == b"ok"]
        assert len(oks) == 1
        out.append((arrived, oks[0]))
    return out


def test_ftdi_holds_the_controllers_bytes_until_its_latency_timer_expires() -> None:
    ftdi = LinkModel(batch_timer_s=0.016, seed=3)
    rig = SimRig(GrblFirmware(), ftdi)
    plain = SimRig(GrblFirmware(), LinkModel())
    sends = [1.0 + 0.2173 * i for i in range(12)]  # at every phase of the 16 ms timer
    held = _oks(rig, sends)
    direct = _oks(plain, sends)
    # Host to controller is untouched; every ok waits in the adapter for up to one timer period,
    # and they all leave on the one timer grid (nothing filled a 62-byte packet).
    assert [a for a, _ in held] == pytest.approx([a for a, _ in direct], abs=1e-12)
    waits = [h - d for (_, h), (_, d) in zip(held, direct, strict=True)]
    assert all(0.0 <= w <= 0.016 + 1e-9 for w in waits)
    assert max(waits) > 0.008
    phase = held[0][1]
    assert all(abs(((t - phase) / 0.016) - round((t - phase) / 0.016)) < 1e-6 for _, t in held)


def test_ftdi_sends_a_packet_as_soon_as_62_bytes_are_in_then_restarts_its_timer() -> None:
    ftdi = LinkModel(batch_timer_s=0.016, seed=3)
    rig = SimRig(GrblFirmware(), ftdi)
    rig.run_until(1.0)
    rig.send_line("$$", 1.0)  # some 350 bytes back to back: five full packets, then the rest
    got = rig.run_until(1.5)
    total = sum(len(line) + 2 for _, line in got)
    times = sorted({t for t, _ in got})
    gaps = [(b - a) / ftdi.byte_time_s for a, b in itertools.pairwise(times)]
    assert len(times) == total // 62 + 1
    assert gaps[:-1] == pytest.approx([62.0] * (len(gaps) - 1))
    # The rest waits one full period from the last full packet: the timer restarted there.
    assert times[-1] - times[-2] == pytest.approx(0.016)


def test_a_stall_stops_both_directions_then_the_backlog_arrives() -> None:
    link = LinkModel(latency_s=0.002, stall_s=0.2, stall_gap_s=(2.5, 3.5), seed=5)
    rig = SimRig(GrblFirmware(), link)
    rig.run_until(0.5)
    sent: list[tuple[float, float]] = []  # (sent, reached the controller)
    replies: list[float] = []
    t = 0.5
    while t < 9.0:
        sent.append((t, rig.host_send(b"?", t)))
        t += 0.01
        replies += [at for at, _ in rig.run_until(t)]
    normal = link.byte_time_s + link.latency_s
    late = [(s, a) for s, a in sent if a - s > normal + 1e-9]
    # Stalls: runs of queries held back (200 ms each), 2.5-3.5 s apart, two or three in 8.5 s.
    runs: list[list[tuple[float, float]]] = []
    for s, a in late:
        if runs and s - runs[-1][-1][0] < 0.05:
            runs[-1].append((s, a))
        else:
            runs.append([(s, a)])
    assert 2 <= len(runs) <= 4
    for run in runs:
        assert 0.17 < run[-1][0] - run[0][0] < 0.21 + 0.01
        end = run[-1][0]
        # Nothing sent in the stall reaches the controller before it ends; then all at once.
        assert all(a > end for _, a in run)
        assert run[-1][1] - run[0][1] < 0.01
    starts = [run[0][0] for run in runs]
    assert all(2.2 < b - a < 3.6 for a, b in itertools.pairwise(starts))
    # Nothing reaches the host during a stall either: the replies have a gap there.
    assert replies == sorted(replies)
    gaps = [b - a for a, b in itertools.pairwise(replies)]
    assert sum(g > 0.18 for g in gaps) == len(runs)


def _wifi() -> LinkModel:
    return LinkModel(
        baud=1_000_000, bits_per_byte=8, latency_s=0.0025, jitter_s=0.0225, jitter_shape="skewed"
    )


def test_jittered_chunks_never_overtake_each_other() -> None:
    link = _wifi()
    rig = SimRig(GrblFirmware(), link)
    rig.run_until(0.5)
    t = 0.5
    arrivals = []
    replies: list[float] = []
    for i in range(2000):
        arrivals.append(rig.host_send(b"?", t))
        t += 0.002 if i % 2 else 0.0005  # far closer than the jitter: draws would overtake
        replies += [at for at, _ in rig.run_until(t)]
    assert arrivals == sorted(arrivals)
    assert replies == sorted(replies)
    # Some chunks were held behind a slower one before them, then went out right after it.
    gaps = [b - a for a, b in itertools.pairwise(arrivals)]
    assert sum(g == pytest.approx(link.byte_time_s, abs=1e-12) for g in gaps) > 100


def test_skewed_jitter_stays_in_its_range_with_a_long_tail() -> None:
    link = _wifi()
    rig = SimRig(GrblFirmware(), link)
    rig.run_until(0.5)
    t = 0.5
    transit = []
    for _ in range(2000):
        # Further apart than the longest transit: each one is its own draw, never held back.
        transit.append(rig.host_send(b"?", t) - t - link.byte_time_s)
        t += 0.03
        rig.run_until(t)
    assert min(transit) >= link.latency_s - 1e-12
    assert max(transit) <= link.latency_s + link.jitter_s + 1e-12
    extra = sorted((x - link.latency_s) / link.jitter_s for x in transit)
    # Most chunks near the low end, a tail toward the top (Beta(1.3, 4): median 0.21).
    assert 0.15 < extra[len(extra) // 2] < 0.3
    assert extra[-1] > 0.6


def test_a_bridge_paces_bytes_into_the_controller_at_the_baud_rate() -> None:
    link = LinkModel(latency_s=0.020, jitter_s=0.040, jitter_shape="skewed", seed=2)
    rig = SimRig(GrblFirmware(), link)
    rig.run_until(0.5)
    times: list[float] = []
    t = 0.5
    for _ in range(200):
        sent = rig.send_line("G4P0", t)  # 5 bytes; the transport may bunch chunks up
        times.append(sent)
        t += 0.0004
    assert times == sorted(times)
    gaps = [b - a for a, b in itertools.pairwise(times)]
    # Whatever the Wi-Fi did, the bridge's UART sends at most one byte per byte time.
    assert min(gaps) >= 5 * link.byte_time_s - 1e-12


@pytest.mark.parametrize("baud", [9600, 38400])
def test_slow_baud_serialises_both_directions(baud: int) -> None:
    link = LinkModel(baud=baud)
    rig = SimRig(GrblFirmware(), link)
    rig.run_until(1.0)
    first = rig.host_send(b"$$\n", 1.0)
    again = rig.host_send(b"\n", 1.0)  # waits for the wire
    assert first == pytest.approx(1.0 + 3 * link.byte_time_s)
    assert again == pytest.approx(first + link.byte_time_s)
    got = rig.run_until(4.0)
    # Lines back to back: each one's last byte at least its length after the previous one's.
    for (a, _), (b, line) in itertools.pairwise(got):
        assert b - a >= (len(line) + 2) * link.byte_time_s - 1e-12


@pytest.mark.parametrize("name", list(LINK_MODELS))
def test_every_named_link_is_deterministic_and_described(name: str) -> None:
    link = LINK_MODELS[name]
    assert link.description
    assert _scenario(link) == _scenario(link)


def test_the_ideal_link_is_the_default_wire() -> None:
    assert LINK_MODELS["ideal"] == LinkModel()
    assert LINK_MODELS["9600"].byte_time_s == pytest.approx(10 / 9600)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"jitter_shape": "normal"},
        {"batch_timer_s": -0.016},
        {"batch_bytes": 0},
        {"stall_s": -0.1},
        {"stall_s": 3.0, "stall_gap_s": (2.5, 3.5)},
        {"stall_s": 0.2, "stall_gap_s": (3.5, 2.5)},
    ],
)
def test_link_model_refuses_impossible_link_features(kwargs: dict[str, object]) -> None:
    with pytest.raises(SimError):
        LinkModel(**kwargs)  # type: ignore[arg-type]


# ----------------------------------------------------------------- fault injection


def _queries(link: LinkModel, n: int = 300) -> tuple[SimRig, list[bytes]]:
    """n status queries 20 ms apart; the rig and every line that came back."""
    rig = SimRig(GrblFirmware(), link)
    rig.run_until(0.5)
    got: list[bytes] = []
    t = 0.5
    for _ in range(n):
        rig.host_send(b"?", t)
        t += 0.02
        got += [line for _, line in rig.run_until(t)]
    got += [line for _, line in rig.run_until(t + 0.5)]
    return rig, got


def test_bytes_lost_on_the_way_to_the_controller_are_never_answered() -> None:
    rig, got = _queries(LinkModel(drop_to_controller=0.3, seed=4))
    dropped, _, corrupted, _ = rig.noise_counts
    assert 60 < dropped < 120  # 30 % of 300, seeded
    assert corrupted == 0
    assert sum(line.startswith(b"<") for line in got) + dropped == 300


def test_a_flipped_bit_on_the_way_to_the_controller_is_another_byte() -> None:
    rig, got = _queries(LinkModel(corrupt_to_controller=0.3, seed=4))
    _, _, corrupted, _ = rig.noise_counts
    assert 60 < corrupted < 120
    # No single bit flip of `?` is a realtime command: those queries go unanswered.
    assert sum(line.startswith(b"<") for line in got) + corrupted == 300


def test_bytes_lost_on_the_way_to_the_host_leave_what_remains_in_order() -> None:
    _, clean = _queries(LinkModel(seed=4), 100)
    rig, noisy = _queries(LinkModel(drop_to_host=0.01, seed=4), 100)
    _, dropped, _, _ = rig.noise_counts
    assert dropped > 10
    stream = iter(b"".join(clean))
    # Every byte that arrived is the next one of the clean stream that was not lost (a `\r`
    # whose `\n` was lost stays inside the joined line).
    assert all(byte in stream for byte in b"".join(noisy).replace(b"\r", b""))
    assert len(noisy) <= len(clean)


def test_a_corrupted_byte_on_the_way_to_the_host_has_one_bit_flipped() -> None:
    _, clean = _queries(LinkModel(seed=4), 100)
    rig, noisy = _queries(LinkModel(corrupt_to_host=0.005, seed=4), 100)
    _, _, _, corrupted = rig.noise_counts
    assert corrupted > 5
    flips = [
        a ^ b
        for c, n in zip(clean, noisy, strict=False)
        if len(c) == len(n)
        for a, b in zip(c, n, strict=True)
        if a != b
    ]
    assert flips
    assert all(bin(x).count("1") == 1 for x in flips)
    assert len(flips) <= corrupted


def _three_queries(stall: bool) -> list[float]:
    rig = SimRig(GrblFirmware(), LinkModel(latency_s=0.002))
    rig.run_until(1.0)
    rig.host_send(b"?", 1.0)
    if stall:
        rig.inject_stall(0.3, 1.0005)  # while the first query is on the wire
    rig.host_send(b"?", 1.1)
    got = rig.run_until(1.5)
    rig.host_send(b"?", 1.5)
    return [t for t, _ in got + rig.run_until(2.0)]


def test_an_injected_stall_holds_everything_in_flight_and_everything_sent_during_it() -> None:
    clean = _three_queries(stall=False)
    held = _three_queries(stall=True)
    assert len(clean) == len(held) == 3
    # The query on the wire when the stall began arrives 0.3 s late, so does its reply; the one
    # sent during the stall goes at its end (right behind the first); the last one is on time.
    assert held[0] == pytest.approx(clean[0] + 0.3, abs=1e-3)
    assert 1.3005 < held[1] < held[0] + 0.005
    assert held[2] == pytest.approx(clean[2], abs=1e-9)
