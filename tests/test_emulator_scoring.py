"""The emulator's scorer: position and velocity against the truth at the stamp, and the honesty
of the covariance an estimate carries (3-sigma count, NEES)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.emulator.scoring import Scorer, TruthHistory


def _circle_truth(dt_s: float = 1.0 / 600.0, seconds: float = 5.0) -> TruthHistory:
    truth = TruthHistory(dt_s)
    for k in range(int(seconds / dt_s) + 1):
        t = k * dt_s
        truth.record(t, (2.5 * math.cos(0.4 * t), 2.5 * math.sin(0.4 * t), -2.0 + 0.1 * t))
    return truth


def test_true_velocity_is_the_derivative_of_the_recorded_position() -> None:
    truth = _circle_truth()
    for t in (0.0, 1.234, 4.9):
        expected = [-math.sin(0.4 * t), math.cos(0.4 * t), 0.1]
        np.testing.assert_allclose(truth.velocity_at(t), expected, atol=2e-3)
    assert truth.velocity_at(7.0) is None and TruthHistory(0.01).velocity_at(0.0) is None


def test_velocity_rmse_and_covariance_honesty() -> None:
    truth = _circle_truth()
    rng = np.random.default_rng(4)
    scorer = Scorer()
    sigma = np.array([0.1, 0.2, 0.05])
    n = 4000
    for k in range(n):
        t = 0.5 + 4.0 * k / n
        error = rng.normal(0.0, sigma)
        scorer.add("ODOMETRY", truth.at(t) + error, t, t + 0.01, truth, np.diag(sigma**2))
        scorer.add_velocity(truth.velocity_at(t) + np.array([0.1, 0.0, 0.0]), t, t + 0.01, truth)
    report = scorer.report()
    assert report.with_covariance == n
    assert report.nees_mean == pytest.approx(3.0, rel=0.1)
    # an honest Gaussian leaves 1 - 0.9973^3 = 0.8 % with some axis beyond 3 sigma
    assert 0.002 * n < report.beyond_3_sigma < 0.015 * n
    assert report.velocity_scored == n
    assert report.velocity_rmse_m_s["north"] == pytest.approx(0.1, abs=2e-3)
    assert report.velocity_rmse_m_s["east"] < 2e-3
    assert "beyond 3 sigma" in report.format_text() and "velocity RMSE" in report.format_text()


def test_overconfident_covariance_is_counted_and_bad_covariances_are_skipped() -> None:
    truth = _circle_truth()
    scorer = Scorer()
    scorer.add("X", truth.at(1.0) + [0.5, 0, 0], 1.0, 1.0, truth, np.eye(3) * 0.01)
    scorer.add("X", truth.at(1.1), 1.1, 1.1, truth, np.full((3, 3), math.nan))
    scorer.add("X", truth.at(1.2), 1.2, 1.2, truth)
    scorer.add_velocity(np.array([math.nan, 0.0, 0.0]), 1.2, 1.2, truth)
    report = scorer.report()
    assert report.scored == 3 and report.with_covariance == 1 and report.beyond_3_sigma == 1
    assert report.nees_mean == pytest.approx(25.0) and report.velocity_scored == 0
