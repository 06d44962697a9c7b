"""The bank member's lean arithmetic (estimation/dynamic/member.py) against the generic EKF it
replaced: equal states, covariances, NIS and counts within 1e-9 where the math is the same,
and the covariance brought to the state's time before any update when the prediction is
decimated."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.estimation.dynamic import generated, state
from tether_companion.estimation.dynamic.member import MemberFilter
from tether_companion.estimation.dynamic.models import CATENARY, STRAIGHT, ModelConstants
from tether_companion.estimation.ekf import ExtendedKalmanFilter
from tether_companion.frames import rotation_ned_to_body

N = state.N_STATES
V_ROWS = slice(3, 6)


class ReferenceProcess:
    """The generic EKF's process model over a generated function, as the filter had it before
    the lean member (``F`` assembled as a 13x13 array, the numpy prediction)."""

    is_random_walk = False

    def __init__(self, function, constants: ModelConstants) -> None:  # noqa: ANN001
        self.function = function
        self.constants = constants

    def jacobian(self, x: np.ndarray, u: np.ndarray | None) -> np.ndarray:
        xdot, dv = self.function(x.tolist(), list(u), self.constants.values())
        self._xdot = np.array(xdot, dtype=float)
        jac = np.zeros((N, N))
        jac[state.POSITION, state.VELOCITY] = np.eye(3)
        jac[V_ROWS] = np.array(dv, dtype=float).reshape(3, N)
        return jac

    def derivative(self, x: np.ndarray, u: np.ndarray | None) -> np.ndarray:
        return self._xdot  # jacobian() ran first at this x (the EKF calls it first)


def _start(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x = np.zeros(N)
    x[state.POSITION] = (3.0, 1.5, -2.5)
    x[state.VELOCITY] = rng.normal(scale=0.3, size=3)
    x[state.TENSION] = 4.0
    x[state.SCALE] = 1.02
    x[state.BIAS] = rng.normal(scale=0.05, size=3)
    x[state.WIND] = (1.0, -0.5)
    a = rng.normal(size=(N, N)) * 0.05
    p0 = a @ a.T + np.diag([0.3, 0.3, 0.05, 0.2, 0.2, 0.2, 1.0, 0.01, 0.01, 0.01, 0.01, 1.0, 1.0])
    q = np.array([1e-6] * 3 + [1e-4] * 3 + [2.0, 1e-5] + [1e-4] * 3 + [0.05] * 2)
    return x, p0, q


@pytest.mark.parametrize(
    ("cable", "weight"), [("straight", 0.0), ("catenary", 0.3), ("force_balance", 0.3)]
)
def test_lean_member_equals_the_generic_ekf(cable: str, weight: float) -> None:
    rng = np.random.default_rng(11)
    constants = ModelConstants(1.5, 0.2, weight)
    models = CATENARY if weight > 0.0 else STRAIGHT
    process = models.force_balance if cable == "force_balance" else generated.inertial
    x0, p0, q = _start(rng)
    lean = MemberFilter(
        x0, p0, q, constants, process, gate_probability=0.999, max_consecutive_rejections=3
    )
    reference = ExtendedKalmanFilter(
        x0,
        p0,
        np.diag(q),
        ReferenceProcess(process, constants),
        gate_probability=0.999,
        max_consecutive_rejections=3,
    )
    r = 0.8
    outcomes = []
    for k in range(400):
        rotation = rotation_ned_to_body(*rng.normal(scale=0.1, size=2), 0.01 * k)
        thrust = 14.7 + rng.normal(scale=0.5)
        accel_inputs = [*rotation.ravel().tolist(), thrust]
        z = np.array(models.accel(reference.x.tolist(), accel_inputs, constants.values())[0])
        z += rng.normal(scale=0.9, size=3)
        if k % 50 == 7:
            z += 40.0  # an outlier for the gate (and, three in a row, the forced fusion)
        u = accel_inputs if cable == "force_balance" else [*accel_inputs[:9], *z.tolist()]
        assert lean.predict(0.005, u)
        assert reference.predict(0.005, np.array(u))
        value, jacobian = models.accel(lean.x_values(), accel_inputs, constants.values())
        got = lean.update_force_balance("accel", (z - value).tolist(), jacobian, r)

        def measure(x: np.ndarray, inputs: list[float] = accel_inputs) -> tuple:
            h, jac = models.accel(x.tolist(), inputs, constants.values())
            return np.array(h), np.array(jac).reshape(3, N)

        want = reference.update("accel", z, measure, np.eye(3) * r)
        assert got.status == want.status
        assert got.nis == pytest.approx(want.nis, rel=1e-9, abs=1e-9)
        if k % 10 == 3:  # a scalar measurement (the rangefinder's height), outliers too
            height = np.array([2.5 + rng.normal(scale=0.05) + (3.0 if k % 70 == 3 else 0.0)])
            got = lean.update("range", height, _height, np.eye(1) * 0.0025)
            want = reference.update("range", height, _height, np.eye(1) * 0.0025)
            assert got.status == want.status
            assert got.nis == pytest.approx(want.nis, rel=1e-9, abs=1e-9)
        np.testing.assert_allclose(lean.x, reference.x, rtol=0.0, atol=1e-9)
        np.testing.assert_allclose(lean.P, reference.P, rtol=0.0, atol=1e-9)
        outcomes.append(got.status)
    assert {"fused", "gated"} <= set(outcomes)
    assert lean.sensors["range"].gated > 0 and lean.sensors["range"].fused > 0
    ours, theirs = lean.sensors["accel"], reference.sensors["accel"]
    assert (ours.fused, ours.gated, ours.forced) == (theirs.fused, theirs.gated, theirs.forced)


def _height(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    row = np.zeros((1, N))
    row[0, 2] = -1.0
    return np.array([-x[2]]), row


def test_not_finite_or_not_definite_innovation_covariance_is_counted() -> None:
    x0, p0, q = _start(np.random.default_rng(1))
    member = MemberFilter(x0, p0, q, ModelConstants(1.5, 0.2, 0.0), generated.inertial)
    before = member.x.copy()
    result = member.update_force_balance("accel", [0.1, 0.1, 0.1], [math.nan] * (3 * N), 0.5)
    assert result.status == "nonfinite"
    singular = [0.0] * (3 * N)
    assert member.update_force_balance("accel", [0.1, 0.1, 0.1], singular, -1.0).status == (
        "singular"
    )
    np.testing.assert_array_equal(member.x, before)
    assert member.sensors["accel"].nonfinite == 1 and member.sensors["accel"].singular == 1


def test_decimated_covariance_catches_up_before_an_update() -> None:
    """Four state steps without the covariance: the covariance waits, then one Euler step over
    the whole 0.02 s with the latest Jacobian is taken before the next update."""
    x0, p0, q = _start(np.random.default_rng(2))
    constants = ModelConstants(1.5, 0.2, 0.0)
    u = [*rotation_ned_to_body(0.1, -0.05, 0.3).ravel().tolist(), 0.1, -0.2, -9.7]
    member = MemberFilter(x0, p0, q, constants, generated.inertial)
    for _ in range(4):
        member.predict(0.005, u, covariance=False)
    np.testing.assert_array_equal(member.P, p0)  # nothing propagated yet
    f = np.zeros((N, N))
    f[state.POSITION, state.VELOCITY] = np.eye(3)
    f[V_ROWS] = np.array(generated.inertial(member.x.tolist(), u, constants.values())[1]).reshape(
        3, N
    )
    expected = p0 + 0.02 * (f @ p0 + (f @ p0).T + np.diag(q))
    row = np.zeros((1, N))
    row[0, 2] = -1.0
    member.update("range", np.array([2.5]), lambda x: (np.array([-x[2]]), row), np.eye(1))
    gain = expected @ row.T / (row @ expected @ row.T + 1.0)
    np.testing.assert_allclose(member.P, expected - gain @ row @ expected, rtol=0.0, atol=1e-12)
