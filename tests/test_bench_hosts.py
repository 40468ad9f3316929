"""The benchmark's reference methods behave as written, on the simulator in virtual time."""

from __future__ import annotations

import pytest
from bench import hosts, jog
from bench import scenarios as sc

from smoothjog.virtual import VirtualHost


def _jog_lines(vs: VirtualHost, t0: float, hold_s: float) -> list[tuple[float, str]]:
    """The jog lines the host wrote while the stick was held, with their times from t0."""
    sent: list[tuple[float, str]] = []
    forward = vs.rig.host_send

    def spy(data: bytes, now_s: float) -> float:
        if data.startswith(b"$J="):
            sent.append((now_s - t0, data.decode().strip()))
        return forward(data, now_s)

    vs.rig.host_send = spy  # type: ignore[method-assign]
    vs.set_intent(sc._stick(1.0))
    vs.run_until(t0 + hold_s)
    return sent


def test_pendant_timer_fires_late_and_drifts_from_its_own_firing() -> None:
    vs, t0 = sc._session(hosts.PendantPost150, "hobby-router", "grbl")
    late = hosts.PendantPost150.timer_late_s
    sent = [t for t, _line in _jog_lines(vs, t0, 1.0)]
    # The first line goes with the press, the second 100 ms later, then one every 150 ms; each
    # timer firing is `late` after it was due and the next is armed from that firing.
    expected = [0.0, 0.100 + late]
    while expected[-1] + 0.150 + late < 1.0:
        expected.append(expected[-1] + 0.150 + late)
    assert sent == pytest.approx(expected, abs=1e-9)
    assert late > 0


def test_pendant_lines_are_150_ms_of_travel_at_the_full_feed() -> None:
    vs, t0 = sc._session(hosts.PendantPost150, "hobby-router", "grbl")
    lines = [line for _t, line in _jog_lines(vs, t0, 0.5)]
    # 5000 mm/min for 150 ms is 12.5 mm, toward -X; no cancel byte is ever part of the method.
    assert lines
    assert all("X-12.5" in line and "F5000" in line for line in lines)


def test_pendant_release_stops_sending_and_the_queue_runs_out() -> None:
    vs, t0 = sc._session(hosts.PendantPost150, "hobby-router", "grbl")
    vs.set_intent(sc._stick(1.0))
    vs.run_until(t0 + 1.0)
    vs.set_intent(sc._stick(1.0, 0.0))
    t_rel = vs.now_s
    assert vs.run_until_idle(5.0)
    from bench import measure

    coast = measure.distance_after(vs.rig.trace, t_rel)
    # No cancel: the machine runs out what was queued, at least the stopping distance v²/2a
    # and at most that plus two 12.5 mm lines.
    ph = sc.physics("hobby-router")
    assert ph.stop_mm < coast < ph.stop_mm + 25.0


def test_calibration_flags_a_row_more_than_10_percent_off() -> None:
    results = {
        name: {
            key: dict(zip(jog.REAL_METRICS[key], values, strict=True))
            for key, values in real.items()
        }
        for name, real in jog.REAL_FIRMWARE.items()
    }
    rows = jog.calibration(results)
    assert sum(row.endswith("| yes |") for row in rows) == 20  # the real figures match themselves
    results["fixed 150 ms, no cancel"]["S4"]["dist_mm"] = 15.5 * 1.11
    rows = jog.calibration(results)
    bad = [row for row in rows if row.endswith("| NO |")]
    assert len(bad) == 1
    assert "| S4 |" in bad[0]


def test_lag_is_the_delay_of_a_follower_and_infinite_for_one_that_does_not_follow() -> None:
    import math

    from bench import measure

    ts = [k * 0.001 for k in range(3000)]
    commanded = [(t, math.sin(2 * math.pi * t)) for t in ts]
    delayed = [(t, math.sin(2 * math.pi * (t - 0.120))) for t in ts]
    assert measure.lag_and_match(commanded, delayed)[0] == pytest.approx(0.120, abs=0.002)
    assert measure.lag_and_match(commanded, delayed)[1] > 0.99
    # Moving, but at a rhythm of its own (a 3 Hz square wave): no shift makes it the command.
    own = [(t, 1.0 if math.sin(2 * math.pi * 3 * t) >= 0 else -1.0) for t in ts]
    assert math.isinf(measure.lag_and_match(commanded, own)[0])
    # Standing still.
    assert math.isinf(measure.lag_and_match(commanded, [(t, 0.0) for t in ts])[0])
