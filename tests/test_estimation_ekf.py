"""The generic EKF: closed-form agreement, gating, NaN rejection, covariance repair and reset."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm

from tether_companion.estimation.ekf import (
    FUSED,
    GATED,
    NONFINITE,
    SINGULAR,
    ExtendedKalmanFilter,
    chi2_threshold,
)


def _linear(h: np.ndarray):
    def measure(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return h @ x, h

    return measure


def test_random_walk_matches_closed_form_kalman_filter(rng: np.random.Generator) -> None:
    n = 3
    q = np.diag([0.5, 0.2, 1.0])
    r = np.diag([0.3, 0.1])
    h = rng.normal(size=(2, n))
    x_ref = rng.normal(size=n)
    p_ref = np.eye(n) * 2.0
    ekf = ExtendedKalmanFilter(x_ref, p_ref, q)  # gate disabled by default
    for _ in range(50):
        dt = float(rng.uniform(0.001, 0.05))
        z = rng.normal(size=2)
        # textbook KF, paper eqs. 30-34 with Phi = I and Q_k = Q_c dt
        p_ref = p_ref + q * dt
        k = p_ref @ h.T @ np.linalg.inv(h @ p_ref @ h.T + r)
        x_ref = x_ref + k @ (z - h @ x_ref)
        p_ref = (np.eye(n) - k @ h) @ p_ref
        ekf.predict(dt)
        assert ekf.update("lin", z, _linear(h), r).status == FUSED
        np.testing.assert_allclose(ekf.x, x_ref, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(ekf.P, p_ref, rtol=1e-9, atol=1e-12)


class _Linear:
    def __init__(self, a: np.ndarray) -> None:
        self.a = a

    def derivative(self, x: np.ndarray, u: np.ndarray | None) -> np.ndarray:
        return self.a @ x

    def jacobian(self, x: np.ndarray, u: np.ndarray | None) -> np.ndarray:
        return self.a


def test_continuous_prediction_converges_to_exact_lti_solution() -> None:
    a = np.array([[0.0, 1.0], [-2.0, -0.5]])
    q = np.diag([0.0, 0.4])
    x0 = np.array([1.0, -0.5])
    p0 = np.diag([0.3, 0.2])
    dt = 0.4
    ekf = ExtendedKalmanFilter(x0, p0, q, _Linear(a), substeps=4000)
    ekf.predict(dt)
    phi = expm(a * dt)
    # Van Loan: integral of e^{As} Q e^{A^T s} ds over [0, dt]
    block = expm(np.block([[-a, q], [np.zeros((2, 2)), a.T]]) * dt)
    q_d = block[2:, 2:].T @ block[:2, 2:]
    np.testing.assert_allclose(ekf.x, phi @ x0, rtol=1e-3)
    np.testing.assert_allclose(ekf.P, phi @ p0 @ phi.T + q_d, rtol=2e-3, atol=1e-5)


def test_gate_rejects_outlier_then_yields_after_consecutive_rejections() -> None:
    h = np.array([[1.0, 0.0]])
    r = np.array([[0.01]])
    ekf = ExtendedKalmanFilter(
        np.zeros(2),
        np.eye(2) * 0.01,
        np.zeros((2, 2)),
        gate_probability=0.999,
        max_consecutive_rejections=3,
    )
    threshold = chi2_threshold(0.999, 1)
    assert 10.0 < threshold < 11.0
    outlier = np.array([50.0])
    for expected_count in (1, 2, 3):
        result = ekf.update("pos", outlier, _linear(h), r)
        assert result.status == GATED and result.nis > threshold
        assert ekf.sensors["pos"].gated == expected_count
        np.testing.assert_array_equal(ekf.x, np.zeros(2))
    result = ekf.update("pos", outlier, _linear(h), r)
    assert result.status == FUSED and ekf.sensors["pos"].forced == 1
    assert ekf.x[0] > 1.0
    assert ekf.update("pos", np.array([ekf.x[0] + 0.01]), _linear(h), r).status == FUSED


@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_nonfinite_measurement_is_rejected_and_counted(bad: float) -> None:
    ekf = ExtendedKalmanFilter(np.ones(2), np.eye(2), np.eye(2))
    h = np.eye(2)
    result = ekf.update("s", np.array([1.0, bad]), _linear(h), np.eye(2))
    assert result.status == NONFINITE
    bad_jacobian = np.array([[1.0, 0.0], [0.0, bad]])
    assert ekf.update("s", np.ones(2), lambda x: (x, bad_jacobian), np.eye(2)).status == NONFINITE
    assert ekf.sensors["s"].nonfinite == 2
    np.testing.assert_array_equal(ekf.x, np.ones(2))
    np.testing.assert_array_equal(ekf.P, np.eye(2))
    assert not ekf.predict(math.nan) and not ekf.predict(-0.1)
    assert ekf.rejected_predictions == 2
    np.testing.assert_array_equal(ekf.P, np.eye(2))


def test_non_positive_definite_innovation_covariance_is_refused() -> None:
    ekf = ExtendedKalmanFilter(np.zeros(1), np.eye(1), np.zeros((1, 1)))
    result = ekf.update("s", np.array([1.0]), _linear(np.eye(1)), np.array([[-5.0]]))
    assert result.status == SINGULAR and ekf.sensors["s"].singular == 1
    np.testing.assert_array_equal(ekf.x, np.zeros(1))


@pytest.mark.parametrize("scalar", [False, True])
def test_covariance_that_lost_definiteness_is_repaired(scalar: bool) -> None:
    ekf = ExtendedKalmanFilter(np.zeros(2), np.eye(2), np.zeros((2, 2)))
    ekf.P = np.array([[1.0, 0.0], [0.0, -0.5]])  # as if rounding had broken it
    h = np.array([[1.0, 0.0]])
    if scalar:
        result = ekf.update_rows("s", [0.2], h.tolist(), 1.0)
    else:
        result = ekf.update("s", np.array([0.2]), _linear(h), np.array([[1.0]]))
    assert result.status == FUSED
    assert ekf.pd_repairs == 1
    np.linalg.cholesky(ekf.P)
    np.testing.assert_allclose(ekf.P, ekf.P.T)
    assert ekf.resets == 0


class _Exploding:
    def derivative(self, x: np.ndarray, u: np.ndarray | None) -> np.ndarray:
        return np.full_like(x, np.inf)

    def jacobian(self, x: np.ndarray, u: np.ndarray | None) -> np.ndarray:
        return np.zeros((x.size, x.size))


def test_non_finite_state_resets_filter_to_initial_condition() -> None:
    x0 = np.array([1.0, 2.0])
    ekf = ExtendedKalmanFilter(x0, np.eye(2), np.eye(2), _Exploding())
    ekf.predict(0.01)
    assert ekf.resets == 1
    np.testing.assert_array_equal(ekf.x, x0)
    np.testing.assert_array_equal(ekf.P, np.eye(2))


def test_nees_and_nis_are_the_textbook_quadratic_forms() -> None:
    p = np.array([[2.0, 0.5], [0.5, 1.0]])
    ekf = ExtendedKalmanFilter(np.array([1.0, 1.0]), p, np.zeros((2, 2)))
    error = np.array([1.0, 1.0])
    assert ekf.nees(np.zeros(2)) == pytest.approx(error @ np.linalg.inv(p) @ error)
    h = np.array([[1.0, 1.0]])
    r = np.array([[0.5]])
    result = ekf.update("s", np.array([4.0]), _linear(h), r)
    s = h @ p @ h.T + r
    assert result.nis == pytest.approx(2.0**2 / s[0, 0])


def test_invalid_construction_is_refused() -> None:
    with pytest.raises(ValueError, match="positive definite"):
        ExtendedKalmanFilter(np.zeros(2), np.diag([1.0, -1.0]), np.eye(2))
    with pytest.raises(ValueError, match="finite"):
        ExtendedKalmanFilter(np.array([0.0, math.nan]), np.eye(2), np.eye(2))
    with pytest.raises(ValueError, match=r"\(2, 2\)"):
        ExtendedKalmanFilter(np.zeros(2), np.eye(3), np.eye(2))
