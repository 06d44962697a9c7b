"""The own bound split by the dynamic filter's design choices (bench/estimators/bound_split.py)."""

from __future__ import annotations

import dataclasses

import pytest

from tether_companion.bench.estimators.bound_split import LABELS, bound_split, main
from tether_companion.bench.estimators.flight import fly
from tether_companion.bench.estimators.registry import FlightContext, kinds
from tether_companion.bench.estimators.scores import score_kind
from tether_companion.constants import GRAVITY_MPS2
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.scenario import load_scenario


def test_each_design_choice_widens_the_bound_and_the_first_row_is_the_scorecards():
    """A 7 s realistic circle with winch and angle, scored from 5 s: the RMSE and the own
    CRLB are the scorecard's (``score_kind``), and starting at the filter's first estimate,
    holding the azimuth zero, then the other calibration until released each widen it."""
    scenario = dataclasses.replace(load_scenario("realistic-circle"), duration_s=7.0, seed=3)
    kind = kinds()["dynamic-winch-angle"]
    rows = bound_split(scenario, kind, [3], settle_s=5.0)
    assert [r.label for r in rows] == ["RMSE", *LABELS]
    record = fly(scenario, [kind])
    context = FlightContext(scenario, load_vehicle(scenario.vehicle), GRAVITY_MPS2)
    score = score_kind(
        record,
        record.traces[kind.name],
        record.position_ned_m * 0.0,
        5.0,
        0.5,
        kind.own_bound(context, record),
    )
    n = score.estimated
    assert rows[0].horizontal_m ** 2 * n == pytest.approx(score.sq_horizontal_m2, rel=1e-6)
    assert rows[1].horizontal_m ** 2 * n == pytest.approx(score.own_bound_horizontal_m2, rel=1e-6)
    horizontal = [r.horizontal_m for r in rows[1:]]
    assert all(b >= a * (1 - 1e-9) for a, b in zip(horizontal, horizontal[1:], strict=False))
    assert horizontal[-1] > horizontal[0]


def test_bad_input_is_one_line_and_exit_2(capsys):
    assert main(["--scenario", "realistic-circle", "--estimator", "ekf-4s", "--seeds", "1"]) == 2
    assert main(["--scenario", "realistic-circle", "--estimator", "nope"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("error: ") for line in err)
