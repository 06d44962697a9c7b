"""A heavy cable's elevation at the anchor is a hinge (aid/elevation_hinge.py): flat where the
cable rests on the ground, the free catenary's where it hangs. A flat reading says only that
the drone is at or beyond the touchdown distance; fused as the free curve's elevation it put
the state on the kink with the reading's noise (the heavy 5 N winch figure-8, angle alone,
docs/estimation.md angle21). The censored reading's moments against numerical integration,
its pseudo reading as a Kalman update, and the estimator's update on a heavy cable."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.aid.cable_angle import hinged_reading
from tether_companion.estimation.dynamic.aid.elevation_hinge import (
    hinge_moments,
    pseudo_reading,
)
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.models import rests_on_ground
from tether_companion.estimation.dynamic.offline import run_dynamic
from tether_companion.sim.scenario import load_scenario

HEAVY_N_PER_M = 0.1 * GRAVITY_MPS2
"""The heavy winch cable's weight per length [N/m]."""


def _integrated(
    z: float, m: float, s: float, r: float, hinge: float, r_flat: float
) -> tuple[float, float, float]:
    """The posterior mean and variance of ``t ~ N(m, s)`` and the reading's log-likelihood
    (without ``-log sqrt(2 pi)``) by quadrature over ``t`` (the module docstring's model)."""
    sd = math.sqrt(s)
    t = np.linspace(m - 12.0 * sd, m + 12.0 * sd, 400_001)
    prior = np.exp(-0.5 * (t - m) ** 2 / s) / math.sqrt(2.0 * math.pi * s)
    flat = math.exp(-0.5 * (z - hinge) ** 2 / r_flat) / math.sqrt(r_flat)
    free = np.exp(-0.5 * (z - t) ** 2 / r) / math.sqrt(r)
    joint = prior * np.where(t < hinge, flat, free)
    total = np.trapezoid(joint, t)
    mean = np.trapezoid(joint * t, t) / total
    variance = np.trapezoid(joint * (t - mean) ** 2, t) / total
    return mean, variance, math.log(total)


@pytest.mark.parametrize(
    ("z", "m", "s"),
    [
        (0.0, 0.05, 0.04**2),  # a flat reading, the state's cable free just inside the kink
        (0.0, 0.20, 0.05**2),  # flat, the state far on the free side
        (0.0, -0.10, 0.04**2),  # flat, the state resting
        (0.15, 0.12, 0.03**2),  # a lifted reading, the state free: the plain update
        (0.10, -0.05, 0.04**2),  # lifted, the state resting
        (0.01, 0.0, 0.02**2),  # at the kink
    ],
)
def test_the_censored_moments_are_the_posteriors(z: float, m: float, s: float) -> None:
    r, hinge = 0.01**2, 0.002
    r_flat = r + 0.007**2
    mean, variance, log_likelihood = hinge_moments(z, m, s, r, hinge, r_flat)
    want = _integrated(z, m, s, r, hinge, r_flat)
    assert mean == pytest.approx(want[0], abs=1e-6)
    assert variance == pytest.approx(want[1], rel=1e-4)
    assert log_likelihood == pytest.approx(want[2], abs=1e-5)


def test_the_pseudo_reading_is_a_kalman_update_to_those_moments() -> None:
    z, m, s, r, hinge, r_flat = 0.0, 0.05, 0.04**2, 0.01**2, 0.0, 0.0122**2
    z_star, r_star, _ = pseudo_reading(z, m, s, r, hinge, r_flat)
    gain = s / (s + r_star)
    mean, variance, _ = hinge_moments(z, m, s, r, hinge, r_flat)
    assert m + gain * (z_star - m) == pytest.approx(mean, rel=1e-12)
    assert s * (1.0 - gain) == pytest.approx(variance, rel=1e-12)


def test_far_from_the_hinge_it_is_the_reading_itself() -> None:
    """A lifted reading (0.3 rad) of a state whose cable hangs well clear of the ground."""
    z_star, r_star, _ = pseudo_reading(0.3, 0.31, 0.02**2, 0.01**2, 0.0, 0.0122**2)
    assert z_star == pytest.approx(0.3, abs=1e-12)
    assert r_star == pytest.approx(0.01**2, rel=1e-9)


def _on_the_heavy_cable(
    position: tuple[float, float, float], tension_n: float
) -> tuple[DynamicTetherEstimator, float]:
    """An estimator after 3 s of the paper circle, told of the heavy winch cable, every
    member at ``position`` [m] with chord tension ``tension_n`` +- 0.1 N and 0.5 m of
    horizontal standard deviation (uncorrelated), the ground station's latencies 0; and the
    time [s]."""
    scenario = dataclasses.replace(load_scenario("paper-circle"), duration_s=3.0, seed=2)
    dynamic = dataclasses.replace(
        DynamicFilterConfig(), winch_latency_s=0.0, cable_angle_latency_s=0.0
    )
    run = run_dynamic(scenario, EstimatorConfig(), dynamic)
    est = run.estimator
    assert est.initialised
    est.constants.weight_n_per_m = HEAVY_N_PER_M
    for member in est.bank.filters:
        x, p = member.x.copy(), member.P.copy()
        x[state.POSITION] = position
        x[state.TENSION] = tension_n
        for i in (*range(3), state.TENSION):
            p[i, :] = 0.0
            p[:, i] = 0.0
        p[0, 0] = p[1, 1] = 0.25
        p[2, 2] = 0.01
        p[state.TENSION, state.TENSION] = 0.1**2
        member.x, member.P = x, p
    return est, float(run.time_s[-1])


def test_a_flat_reading_keeps_a_free_states_drone_beyond_the_kink_uncertain() -> None:
    """Drone 4.5 m out and 3 m up at 5 N of chord tension on the 0.1 kg/m cable: it hangs free
    with its touchdown kink at 4.84 m, the elevation there 0.069 rad and falling 0.21 rad/m
    out. A flat reading says the drone is at or beyond the kink: the radial mean moves out
    past it (5.08 m) and keeps the truncated prior's spread (0.27 m). Fused as the free
    curve's elevation (main before angle21) it put the drone ON the kink, 4.82 m, at 0.09 m."""
    position = (4.5, 0.0, -3.0)
    est, t = _on_the_heavy_cable(position, 5.0)
    assert not rests_on_ground(est.bank.best.x.tolist(), est.constants.values())
    est.on_cable_angle(0.0, 0.0, t + 0.001, 0.01)
    assert est.ground_station.cable_angle.status.fused == 1
    best = est.bank.best
    assert best.x[0] > 4.95
    assert math.sqrt(best.P[0, 0]) > 0.2


def test_a_lifted_reading_of_a_free_state_is_the_plain_reading() -> None:
    """The drone 3.5 m out (its elevation 0.24 rad, 0.2 rad clear of the hinge) read at its own
    free elevation plus 0.01: the member's reading is the reading itself, its
    log-likelihood the plain Gaussian's (the hinge's resting piece has no weight left)."""
    est, _ = _on_the_heavy_cable((3.5, 0.0, -3.0), 5.0)
    angle = est.ground_station.cable_angle
    best = est.bank.best
    h, jac = angle.evaluate(est.constants, best.x)
    z = np.array((float(h[0]) + 0.01, float(h[1])))
    r = np.diag((0.01**2, 0.01**2))
    z_member, r_member, log_likelihood = hinged_reading(
        best.x, best.P, z, r, lambda x: angle.evaluate(est.constants, x)
    )
    np.testing.assert_allclose(z_member, z, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(r_member, r, rtol=1e-9)
    s = jac @ best.P @ jac.T + r
    y = z - h
    gaussian = -0.5 * (float(y @ np.linalg.solve(s, y)) + math.log(np.linalg.det(s)))
    assert log_likelihood == pytest.approx(gaussian, abs=1e-9)


@pytest.mark.parametrize("distance", [-60.0, -9.0, 0.0, 9.0, 60.0])
def test_far_tails_stay_finite(distance: float) -> None:
    """The hinge 60 standard deviations from the state either way (a cable 0.4 m from the
    anchor reads 1.44 rad): finite moments and likelihood."""
    m, s = 0.5, 0.01**2
    z_star, r_star, log_likelihood = pseudo_reading(0.5, m, s, 0.01**2, m + distance * 0.01, 2e-4)
    assert all(math.isfinite(v) for v in (z_star, r_star, log_likelihood))
    assert r_star > 0.0
