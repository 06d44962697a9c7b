"""The wind's process model (estimation/dynamic/noise.py): a first-order Gauss-Markov process
about calm, ``w' = -w / tau + n`` with ``n``'s density ``2 sigma^2 / tau``, in both
formulations' predictions (the inertial batch's transition, the force-balance member's Euler
step)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.imu_batch import BatchStep
from tether_companion.estimation.dynamic.member import MemberFilter
from tether_companion.estimation.dynamic.models import STRAIGHT, ModelConstants
from tether_companion.estimation.dynamic.noise import process_noise_density, wind_decay_per_s

N = state.N_STATES
W = state.WIND
STEP_S = 0.02
FLIGHT_S = 40.0


def _start() -> tuple[np.ndarray, np.ndarray]:
    """A state 4 m out with a 6 m/s north, -3 m/s east wind and a 0.5 m/s wind spread."""
    x = np.zeros(N)
    x[state.POSITION] = (4.0, 0.0, -2.5)
    x[state.TENSION], x[state.SCALE] = 4.0, 1.0
    x[W] = (6.0, -3.0)
    p = np.eye(N) * 1e-2
    p[W, W] = np.eye(2) * 0.25
    return x, p


def _expected(x0: np.ndarray, p0: np.ndarray, t: float, sigma: float, tau: float):
    """The Gauss-Markov process's mean and variance after ``t`` [s]."""
    decay = math.exp(-t / tau)
    mean = x0[W] * decay
    variance = np.diag(p0[W, W]) * decay**2 + sigma**2 * (1.0 - decay**2)
    return mean, variance


def test_the_default_wind_reverts_toward_calm_and_spreads_to_its_stationary_sd() -> None:
    """The configured process (3 m/s, 15 s): the inertial batch's step decays the wind by
    ``exp(-T / tau)`` exactly, its variance follows the process's to the first-order noise
    (1 %); the force-balance member's Euler steps follow both (1 %); nothing else is
    touched by the wind's decay (its columns of the covariance decay with it)."""
    dynamic = DynamicFilterConfig()
    sigma, tau = dynamic.noise.wind_std_mps, dynamic.noise.wind_correlation_s
    rate = wind_decay_per_s(dynamic)
    assert rate == pytest.approx(1.0 / tau)
    q = process_noise_density(dynamic)
    assert q[W] == pytest.approx([2.0 * sigma**2 / tau] * 2)
    x0, p0 = _start()
    mean, variance = _expected(x0, p0, FLIGHT_S, sigma, tau)

    zeros3, zeros9 = [0.0] * 3, [0.0] * 9
    step = BatchStep(1, STEP_S, zeros3, zeros3, zeros9, zeros9, rate)
    x, p = x0.copy(), p0.copy()
    for _ in range(int(FLIGHT_S / STEP_S)):
        x = step.step_state(x)
        p = step.step_covariance(p, np.diag(q))
    np.testing.assert_allclose(x[W], mean, rtol=1e-9)
    np.testing.assert_allclose(np.diag(p)[W], variance, rtol=1e-2)
    assert np.diag(p)[W] == pytest.approx([sigma**2] * 2, rel=0.01)  # 40 s > 2.5 tau
    np.testing.assert_array_equal(x[: W.start], x0[: W.start])
    one_step = step.step_covariance(p0, np.zeros((N, N)))
    np.testing.assert_allclose(one_step[W, : W.start], 0.0)  # p0 has no wind cross terms
    decay = math.exp(-STEP_S / tau)
    p0_cross = p0.copy()
    p0_cross[W.start, state.TENSION] = p0_cross[state.TENSION, W.start] = 0.03
    crossed = step.step_covariance(p0_cross, np.zeros((N, N)))
    assert crossed[W.start, state.TENSION] == pytest.approx(0.03 * decay, rel=1e-12)

    hover = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.5 * 9.80665]
    member = MemberFilter(
        x0, p0, q, ModelConstants(1.5, 0.2, 0.0), STRAIGHT.force_balance, wind_decay_per_s=rate
    )
    for _ in range(int(FLIGHT_S / STEP_S)):
        assert member.predict(STEP_S, hover)
    np.testing.assert_allclose(member.x[W], mean, rtol=1e-2)
    np.testing.assert_allclose(np.diag(member.P)[W], variance, rtol=1e-2)


def test_without_a_decay_the_wind_is_the_random_walk_it_was() -> None:
    """``wind_decay_per_s`` 0 (the default of the classes): the wind's mean stays and its
    variance grows by ``T q``, in the batch and in the force-balance member."""
    x0, p0 = _start()
    q = np.zeros(N)
    q[W] = 0.05
    zeros3, zeros9 = [0.0] * 3, [0.0] * 9
    step = BatchStep(1, STEP_S, zeros3, zeros3, zeros9, zeros9)
    x, p = step.step_state(x0), step.step_covariance(p0, np.diag(q))
    np.testing.assert_array_equal(x[W], x0[W])
    np.testing.assert_allclose(np.diag(p)[W], np.diag(p0)[W] + STEP_S * 0.05, rtol=1e-12)
    hover = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.5 * 9.80665]
    member = MemberFilter(x0, p0, q, ModelConstants(1.5, 0.2, 0.0), STRAIGHT.force_balance)
    assert member.predict(STEP_S, hover)
    np.testing.assert_array_equal(member.x[W], x0[W])
    np.testing.assert_allclose(np.diag(member.P)[W], np.diag(p0)[W] + STEP_S * 0.05, rtol=1e-12)
