"""The ``bench paper`` and ``bench speed`` building blocks (no full Monte Carlo here)."""

from __future__ import annotations

import dataclasses
import importlib.util

import numpy as np
import pytest

from tether_companion.bench import paper, speed
from tether_companion.cli import main
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.tether_models import FourStateModel
from tether_companion.sim.scenario import load_scenario


def test_variants_change_what_the_sweep_names() -> None:
    base = load_scenario("paper-circle")
    config = paper._config_for(EstimatorConfig(), "g_squared")
    task = paper._Task("altitude_m", "g_squared", "altitude_m", 7.0, 4)
    scenario = paper._variant(base, task, config, 5.0)
    assert scenario.trajectory.mean_altitude_m == 7.0 and scenario.seed == 4
    assert scenario.duration_s == 5.0
    # the simulated accelerometer gets the noise the filter assumes: 0.1 g
    assert scenario.sensors.accel_noise_std_mps2 == pytest.approx(0.980665)
    task = paper._Task("table2", "mps2_squared", "tension_n", 0.5, 1)
    scenario = paper._variant(
        base, task, paper._config_for(EstimatorConfig(), "mps2_squared"), None
    )
    assert (
        scenario.cable.tension_n == 0.5
        and scenario.sensors.accel_noise_std_mps2 == pytest.approx(0.1)
    )
    task = paper._Task("speed_mps", "mps2_squared", "speed_mps", 3.0, 1)
    assert paper._variant(base, task, EstimatorConfig(), None).trajectory.speed_mps == 3.0


def test_aggregate_and_targets() -> None:
    def table(value: float) -> dict:
        axes = {"north_m": value, "east_m": value, "down_m": value / 4}
        return {"3S": dict(axes), "4S": {**axes, "tension_n": value / 2}}

    outcomes = [
        (
            paper._Task("table2", "mps2_squared", "tension_n", fc, seed),
            table(v * k),
            table(v * k / 2),
        )
        for fc, k in ((0.5, 1.0), (2.0, 1.0), (4.0, 1.0), (10.0, 2.0))
        for seed, v in ((1, 0.1), (2, 0.3))
    ]
    results = paper._aggregate(outcomes)
    cell = results["table2"]["mps2_squared"]["4"]["whole_run"]["4S"]["north_m"]
    assert cell["mean"] == pytest.approx(0.2) and cell["n"] == 2
    assert cell["std"] == pytest.approx(np.std([0.1, 0.3], ddof=1))
    targets = paper._targets(results)
    assert len(targets) == 12  # 4 quantities at 2, 4 and 10 N
    # at 2 and 4 N: north/east 0.2, down 0.05, tension 0.1 -> all met; at 10 N all doubled
    for quantity, tension, mean, bound, met in targets:
        assert met == (tension != 10.0), (quantity, tension, mean, bound)


def test_bench_arguments_are_validated(capsys) -> None:
    for argv in (
        ["bench", "paper", "--seeds", "0"],
        ["bench", "paper", "--jobs", "x"],
        ["bench", "nope"],
    ):
        with pytest.raises(SystemExit) as info:
            main(argv)
        assert info.value.code == 2


@pytest.mark.skipif(importlib.util.find_spec("filterpy") is None, reason="filterpy not installed")
def test_speed_comparison_runs_the_same_filter_as_filterpy() -> None:
    scenario = dataclasses.replace(load_scenario("paper-circle"), duration_s=2.0)
    rows = speed._record(scenario, 300)
    config = dataclasses.replace(EstimatorConfig(), initial_tension_n=2.0)
    config = dataclasses.replace(config, gate=dataclasses.replace(config.gate, probability=1.0))
    model = FourStateModel(1.5)
    _, ours = speed._ours(rows, config, model)
    _, theirs = speed._filterpy(rows, config, model)
    np.testing.assert_allclose(ours, theirs, atol=1e-9)
    assert np.abs(ours[-1, :3]).max() < 10.0


def test_filter_step_costs_time_both_estimators_on_the_same_samples() -> None:
    """``bench speed``'s filter rows (``bench dynamic``'s measurement): both estimators ran
    every IMU tick of the same recorded flight and the ratio is theirs."""
    from tether_companion.bench.dynamic import step_costs

    result = step_costs("realistic-circle", 2.0, 1)
    us = result["us_per_tick"]
    assert result["ticks"]["paper_4s"] == result["ticks"]["dynamic"] == 400
    assert result["ticks"]["dynamic_former"] == 400
    assert 0.0 < us["paper_4s"] < 1e5 and 0.0 < us["dynamic"] < 1e5
    assert result["ratio_dynamic_to_paper"] == pytest.approx(us["dynamic"] / us["paper_4s"])
