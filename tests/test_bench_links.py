"""The per-link benchmark: link names, tunings, phases and the table's verdicts."""

from __future__ import annotations

import pytest
from bench import links
from bench import scenarios as sc
from bench.hosts import Shipped

from smoothjog.config import Config
from smoothjog.core.engine import JogTuning
from smoothjog.sim.rig import LINK_MODELS


def test_link_names_parse_to_the_registry() -> None:
    assert links.parse_names("all") == list(LINK_MODELS)
    assert links.parse_names("none") == []
    assert links.parse_names("") == []
    assert links.parse_names("ftdi,9600") == ["ftdi", "9600"]
    with pytest.raises(SystemExit, match="unknown link bluetooth"):
        links.parse_names("ideal,bluetooth")


def test_rows_name_the_tuning_they_ran_with() -> None:
    rows = links.hosts()
    assert [h.name for h in rows] == ["smoothjog", "smoothjog", links.LONG_JOG]
    assert "link margin 0 ms" in rows[0].tuning
    assert rows[1].tuning.startswith("CLI defaults")
    assert links.cli_tuning().link_margin_s == Config().jog.link_margin_s


def test_every_phase_runs_on_its_own_seed_of_the_same_link() -> None:
    base = LINK_MODELS["wifi"]
    phased = [links.phase_link(base, k) for k in range(5)]
    assert len({p.seed for p in phased}) == 5
    assert all(p.latency_s == base.latency_s and p.jitter_s == base.jitter_s for p in phased)


def test_a_scenario_session_runs_on_the_link_it_is_given() -> None:
    factory = links.hosts()[0].factory
    vs, _t0 = sc._session(factory, "hobby-router", "grbl", LINK_MODELS["9600"])
    assert vs.rig.link == LINK_MODELS["9600"]
    assert vs.rig.firmware.tx_byte_s == pytest.approx(10 / 9600)
    vs.close()


@pytest.mark.parametrize("row", [0, 1])
def test_the_smoothjog_rows_run_the_engine_the_host_builds_for_the_link(row: int) -> None:
    # The engine as shipped: the host hands it the wire's byte time (and with it sizes blocks
    # and polls). A factory building the engine itself kept 115200 baud's at 9600 baud.
    method = links.hosts()[row].factory
    assert isinstance(method, Shipped)
    vs, _t0 = sc._session(method, "hobby-router", "grbl", LINK_MODELS["9600"])
    engine = vs.host.engine
    assert engine is not None
    assert engine.tuning.byte_s == pytest.approx(10 / 9600)
    assert engine.tuning.link_margin_s == (method.tuning or JogTuning()).link_margin_s
    vs.close()


def _results(sj_mm: float, long_mm: float) -> links.Results:
    def row(s1_mm: float) -> dict[str, dict[str, float]]:
        return {
            "S1": {"dist_mm": s1_mm, "time_s": 0.2, "restarts": 0.0},
            "S2": {"within_2pct": 1.0, "dips": 0.0, "mean_of_v": 1.0},
            "S4": {"dist_mm": 10.0, "time_s": 0.3},
            "S5": {"dist_mm": 0.3, "time_s": 0.045, "restarts": 0.0},
        }

    return {"ideal": {0: row(sj_mm), 1: row(sj_mm), 2: row(long_mm)}}


def test_the_table_says_whether_the_s1_ratio_meets_its_target() -> None:
    ph = sc.physics("hobby-router")
    met = links.table(_results(10.4, 10.0), links.hosts(), ph)
    missed = links.table(_results(10.6, 10.0), links.hosts(), ph)
    assert met[-1] == "| ideal | 1.040 (met) | 1.040 (met) |"
    assert missed[-1] == "| ideal | 1.060 (NOT met) | 1.060 (NOT met) |"
    assert sum(line.startswith("| ideal | ") for line in met) == 4  # three hosts, one ratio


def test_the_releases_are_spread_over_the_send_cycle_of_each_link() -> None:
    # At 9600 baud a jog line takes 25 ms to cross, so smoothjog's blocks are about 78 ms:
    # phases spread over the ideal wire's 10.5 ms would sample a small part of that cycle.
    shipped = links.hosts()[1].factory
    ideal_s = links.cycle_on_link_s(shipped, LINK_MODELS["ideal"])
    slow_s = links.cycle_on_link_s(shipped, LINK_MODELS["9600"])
    assert ideal_s == pytest.approx(0.0105, rel=0.05)
    assert slow_s > 3 * ideal_s
