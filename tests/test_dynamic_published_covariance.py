"""The dynamic filter's published covariance covers what its own leaves out: the turn of the
cable's direction by an unmodelled horizontal force (growing with the range, falling with the
pull) and the winch length's correlated error along the cable."""

from __future__ import annotations

import dataclasses

import numpy as np

from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.observability import (
    MIN_TENSION_N,
    unmodelled_position_covariance,
)
from tether_companion.estimation.dynamic.offline import run_dynamic
from tether_companion.sim.scenario import load_scenario


def test_a_force_error_turns_the_cable_across_it_by_range_over_tension() -> None:
    # level cable 4 m north: a 0.2 N east force turns it by 0.05 rad, 0.2 m east
    q = unmodelled_position_covariance(np.array([4.0, 0.0, 0.0]), 4.0, 0.2, 0.0)
    np.testing.assert_allclose(q, np.diag([0.0, 0.2**2, 0.0]), atol=1e-15)
    # twice the range, same direction and pull: twice the standard deviation
    far = unmodelled_position_covariance(np.array([8.0, 0.0, 0.0]), 4.0, 0.2, 0.0)
    np.testing.assert_allclose(far, 4.0 * q, atol=1e-15)
    # a vertical cable: both horizontal directions are across it
    up = unmodelled_position_covariance(np.array([0.0, 0.0, -2.0]), 4.0, 0.2, 0.0)
    np.testing.assert_allclose(up, np.diag([0.1**2, 0.1**2, 0.0]), atol=1e-15)


def test_nothing_along_the_cable_but_the_length_error() -> None:
    p = np.array([3.0, -2.0, -2.5])
    u = p / np.linalg.norm(p)
    without = unmodelled_position_covariance(p, 3.0, 0.2, 0.0)
    np.testing.assert_allclose(without @ u, 0.0, atol=1e-12)
    with_length = unmodelled_position_covariance(p, 3.0, 0.2, 0.05)
    assert np.isclose(u @ with_length @ u, 0.05**2)
    np.testing.assert_allclose(with_length, with_length.T)
    assert np.all(np.linalg.eigvalsh(with_length) >= -1e-15)
    # the tilted cable's horizontal across-direction carries the full (|p| sigma / T)^2
    across_h = np.array([-u[1], u[0], 0.0]) / np.hypot(u[0], u[1])
    gain = np.linalg.norm(p) * 0.2 / 3.0
    assert np.isclose(across_h @ without @ across_h, gain**2)


def test_no_pull_is_a_huge_but_finite_variance() -> None:
    q = unmodelled_position_covariance(np.array([1.0, 1.0, -1.0]), 0.0, 0.2, 0.0)
    assert np.all(np.isfinite(q))
    # the across-cable direction's variance is (|p| sigma / MIN_TENSION_N)^2: hundreds of m^2
    assert np.trace(q) > (0.2 / MIN_TENSION_N) ** 2
    assert np.all(np.isfinite(unmodelled_position_covariance(np.zeros(3), 2.0, 0.2, 0.05)))


def test_the_estimator_publishes_its_own_covariance_plus_the_unmodelled_part() -> None:
    scenario = dataclasses.replace(load_scenario("paper-circle"), duration_s=2.0, seed=1)
    runs = [
        run_dynamic(
            scenario,
            EstimatorConfig(),
            dataclasses.replace(DynamicFilterConfig(), unmodelled_force_std_n=sigma),
        )
        for sigma in (0.0, 0.3)
    ]
    bare, considered = runs
    tick = -1
    np.testing.assert_array_equal(bare.position_ned_m, considered.position_ned_m)
    expected = unmodelled_position_covariance(
        bare.position_ned_m[tick], float(bare.tension_n[tick]), 0.3, 0.0
    )
    difference = considered.covariance[tick, :3, :3] - bare.covariance[tick, :3, :3]
    np.testing.assert_allclose(difference, expected, rtol=1e-9, atol=1e-12)
    assert np.trace(expected) > 0.0
