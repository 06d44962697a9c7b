"""An upper bound fused as the prior truncated to it (estimation/dynamic/truncation.py): the
pseudo Kalman update moves a Gaussian to the truncated normal's mean and variance, and a state
correlated with the bounded quantity as the joint Gaussian's conditional moments; the bound's
likelihood is ``Phi(beta)``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from tether_companion.estimation.dynamic.truncation import (
    inverse_mills,
    log_probability_within,
    pseudo_measurement,
)


@pytest.mark.parametrize("beta", [-60.0, -36.0, -8.0, -2.0, -0.5, 0.0, 0.7, 3.0, 9.0])
def test_the_pseudo_update_gives_the_truncated_moments(beta: float) -> None:
    """g ~ N(m, s), bound z = m + beta sqrt(s): one scalar Kalman update of g itself with the
    pseudo pair lands on scipy's truncated normal's mean and variance."""
    m, s = 4.0, 0.49
    z = m + beta * math.sqrt(s)
    y_star, s_star = pseudo_measurement(z - m, s)
    mean = m + s * y_star / s_star
    variance = s - s * s / s_star
    truncated = stats.truncnorm(-np.inf, beta, loc=m, scale=math.sqrt(s))
    if beta > -37.0:  # scipy's own moments lose precision in the far tail
        assert mean == pytest.approx(truncated.mean(), abs=1e-9 * max(1.0, abs(beta)))
        assert variance == pytest.approx(truncated.var(), rel=1e-6, abs=1e-12)
    assert mean < z  # always within the bound
    assert 0.0 < variance <= s


def test_far_beyond_the_bound_the_state_sits_on_it_with_the_tail_spread() -> None:
    """beta -> -inf: the truncated g at the bound, sd sqrt(s) / |beta| (the exponential tail)."""
    y_star, s_star = pseudo_measurement(-100.0, 1.0)
    mean = 100.0 + y_star / s_star
    variance = 1.0 - 1.0 / s_star
    assert mean == pytest.approx(-0.01, abs=2e-4)
    assert math.sqrt(variance) == pytest.approx(0.01, rel=0.02)


def test_far_inside_the_bound_nothing_moves() -> None:
    y_star, s_star = pseudo_measurement(50.0, 1.0)
    assert y_star == 0.0 and s_star == math.inf


def test_a_correlated_state_moves_as_the_joint_gaussian_conditioned_on_the_bound() -> None:
    """x = (a, g) jointly Gaussian, bound g <= z: the Kalman update with H = (0, 1) and the
    pseudo pair gives E[a | g <= z] and Var[a | g <= z] (Monte Carlo, 4e6 samples)."""
    rng = np.random.default_rng(7)
    mean = np.array([1.0, 2.0])
    cov = np.array([[0.8, 0.5], [0.5, 0.6]])
    z = 1.7
    h = np.array([0.0, 1.0])
    s = float(h @ cov @ h)
    y_star, s_star = pseudo_measurement(z - float(h @ mean), s)
    gain = cov @ h / s_star
    post_mean = mean + gain * y_star
    post_cov = cov - np.outer(cov @ h, cov @ h) / s_star
    samples = rng.multivariate_normal(mean, cov, size=4_000_000)
    kept = samples[samples[:, 1] <= z]
    assert post_mean == pytest.approx(kept.mean(axis=0), abs=3e-3)
    assert post_cov == pytest.approx(np.cov(kept.T), abs=3e-3)


@pytest.mark.parametrize("beta", [-45.0, -20.0, -1.0, 0.0, 2.0, 30.0])
def test_the_bounds_likelihood_is_the_probability_within_it(beta: float) -> None:
    assert log_probability_within(beta * 2.0, 4.0) == pytest.approx(
        stats.norm.logcdf(beta), rel=1e-6
    )
    if beta > -37.0:
        assert inverse_mills(beta) == pytest.approx(
            math.exp(stats.norm.logpdf(beta) - stats.norm.logcdf(beta)), rel=1e-9
        )
