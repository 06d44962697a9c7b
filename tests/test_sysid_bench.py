"""Pieces of ``bench sysid`` (the full benchmark flies for a minute; run it by hand)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from sysid_synthetic import id_data

from tether_companion.bench.sysid import naive_linear_curve, run_four_state
from tether_companion.cli import main
from tether_companion.estimation.thrust_input import StaticThrustInput
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.scenario import load_scenario
from tether_companion.sysid.thrust_model import StaticModelFile


def test_naive_linear_curve_is_least_squares_through_zero():
    rng = np.random.default_rng(1)
    pwm = 1400.0 + 300.0 * rng.random((500, 4))
    cmd = (pwm - 1000.0) / 1000.0
    data = id_data(pwm, 6.0 * cmd.sum(axis=1), 0.01)
    curve = naive_linear_curve([data], (1000.0, 2000.0))
    assert curve.coefficients_n == pytest.approx((0.0, 6.0, 0.0))


def test_four_state_run_reports_finite_errors_and_exact_thrust_for_the_true_curve():
    scenario = dataclasses.replace(load_scenario("paper-circle"), duration_s=4.0)
    vehicle = load_vehicle(scenario.vehicle)
    true_curve = run_four_state(scenario, StaticThrustInput(vehicle), seed=1)
    assert all(np.isfinite(v) for v in true_curve.values())
    # the static curve misses only the motor lag on this smooth orbit
    assert true_curve["thrust_n"] < 0.1
    halved = dataclasses.replace(
        vehicle.thrust_curve,
        coefficients_n=tuple(0.5 * c for c in vehicle.thrust_curve.coefficients_n),
    )
    wrong = run_four_state(
        scenario, StaticThrustInput(StaticModelFile(n_motors=4, thrust_curve=halved)), seed=1
    )
    assert wrong["thrust_n"] > 5.0


def test_bench_sysid_bad_arguments_exit_2(capsys):
    assert main(["bench", "sysid", "--seeds", "0"]) == 2
    assert "--seeds" in capsys.readouterr().err
