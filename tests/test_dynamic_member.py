"""The bank member's lean arithmetic (estimation/dynamic/member.py) against the generic EKF it
replaced: equal states, covariances, NIS and counts within 1e-9 where the math is the same;
the inertial prediction over a batch of IMU ticks against one Euler step per tick."""

from __future__ import annotations

import math

import numpy as np
import pytest
from filter_states import random_start

from tether_companion.estimation.dynamic import generated, state
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.imu_batch import ImuBatch
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


@pytest.mark.parametrize(
    ("cable", "weight"), [("straight", 0.0), ("catenary", 0.3), ("force_balance", 0.3)]
)
def test_lean_members_equal_the_generic_ekf(cable: str, weight: float) -> None:
    """Three members in a bank (the force balance in stacked arrays) against three generic
    EKFs, from different starts: same states, covariances, NIS and counts."""
    rng = np.random.default_rng(11)
    constants = ModelConstants(1.5, 0.2, weight)
    models = CATENARY if weight > 0.0 else STRAIGHT
    process = models.force_balance if cable == "force_balance" else generated.inertial
    x0, p0, q = random_start(rng)
    starts = [x0 + offset for offset in (0.0, 0.05, -0.05)]
    lean = [
        MemberFilter(
            x, p0, q, constants, process, gate_probability=0.999, max_consecutive_rejections=3
        )
        for x in starts
    ]
    bank = FilterBank(list(lean), 0.0, 30.0, consider=None)  # the optimal updates
    references = [
        ExtendedKalmanFilter(
            x,
            p0,
            np.diag(q),
            ReferenceProcess(process, constants),
            gate_probability=0.999,
            max_consecutive_rejections=3,
        )
        for x in starts
    ]
    r = 0.8
    outcomes = []
    for k in range(400):
        rotation = rotation_ned_to_body(*rng.normal(scale=0.1, size=2), 0.01 * k)
        thrust = 14.7 + rng.normal(scale=0.5)
        accel_inputs = [*rotation.ravel().tolist(), thrust]
        z = np.array(models.accel(references[0].x.tolist(), accel_inputs, constants.values())[0])
        z += rng.normal(scale=0.9, size=3)
        if k % 50 == 7:
            z += 40.0  # an outlier for the gate (and, three in a row, the forced fusion)
        u = accel_inputs if cable == "force_balance" else [*accel_inputs[:9], *z.tolist()]
        for member, reference in zip(lean, references, strict=True):
            assert member.predict(0.005, u)
            assert reference.predict(0.005, np.array(u))

        def rows(x: list[float], inputs: list[float] = accel_inputs) -> tuple:
            return models.accel(x, inputs, constants.values())

        def measure(x: np.ndarray, inputs: list[float] = accel_inputs) -> tuple:
            h, jac = models.accel(x.tolist(), inputs, constants.values())
            return np.array(h), np.array(jac).reshape(3, N)

        got, _, _ = bank.update_force_balance("accel", z.tolist(), rows, r)
        for reference, result in zip(references, got, strict=True):
            want = reference.update("accel", z, measure, np.eye(3) * r)
            assert result.status == want.status
            assert result.nis == pytest.approx(want.nis, rel=1e-9, abs=1e-9)
        if k % 10 == 3:  # a scalar measurement (the rangefinder's height), outliers too
            height = 2.5 + rng.normal(scale=0.05) + (3.0 if k % 70 == 3 else 0.0)
            got, _, _ = bank.update_scalar("range", height, _height, 0.0025)
            for reference, result in zip(references, got, strict=True):
                want = reference.update("range", np.array([height]), _height, np.eye(1) * 0.0025)
                assert result.status == want.status
                assert result.nis == pytest.approx(want.nis, rel=1e-9, abs=1e-9)
        for member, reference in zip(lean, references, strict=True):
            np.testing.assert_allclose(member.x, reference.x, rtol=0.0, atol=1e-9)
            np.testing.assert_allclose(member.P, reference.P, rtol=0.0, atol=1e-9)
        outcomes.append(got[0].status)
    assert {"fused", "gated"} <= set(outcomes)
    for member, reference in zip(lean, references, strict=True):
        assert member.sensors["range"].gated > 0 and member.sensors["range"].fused > 0
        ours, theirs = member.sensors["accel"], reference.sensors["accel"]
        assert (ours.fused, ours.gated, ours.forced) == (theirs.fused, theirs.gated, theirs.forced)


def _height(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    row = np.zeros((1, N))
    row[0, 2] = -1.0
    return np.array([-x[2]]), row


def test_not_finite_or_not_definite_innovation_covariance_is_counted() -> None:
    x0, p0, q = random_start(np.random.default_rng(1))
    member = MemberFilter(x0, p0, q, ModelConstants(1.5, 0.2, 0.0), generated.inertial)
    bank = FilterBank([member], 0.0, 30.0)
    before = member.x.copy()

    def nan_rows(x: list[float]) -> tuple:
        return x[:3], [math.nan] * (3 * N)

    def zero_rows(x: list[float]) -> tuple:
        return x[:3], [0.0] * (3 * N)

    (result,), _, _ = bank.update_force_balance("accel", before[:3] + 0.1, nan_rows, 0.5)
    assert result.status == "nonfinite"
    (result,), _, _ = bank.update_force_balance("accel", before[:3] + 0.1, zero_rows, -1.0)
    assert result.status == "singular"
    nan_row = np.full((1, N), math.nan)
    (result,), _, _ = bank.update_scalar("range", 2.0, lambda x: (x[:1], nan_row), 0.5)
    assert result.status == "nonfinite"
    zero_row = np.zeros((1, N))
    (result,), _, _ = bank.update_scalar("range", 2.0, lambda x: (x[:1], zero_row), -1.0)
    assert result.status == "singular"
    (result,), _, _ = bank.update_scalar("range", math.nan, _height, 0.5)
    assert result.status == "nonfinite"
    np.testing.assert_array_equal(member.x, before)
    assert member.sensors["accel"].nonfinite == 1 and member.sensors["accel"].singular == 1
    assert member.sensors["range"].nonfinite == 2 and member.sensors["range"].singular == 1


def _random_ticks(rng: np.random.Generator, count: int) -> list[tuple[float, list[float]]]:
    """IMU ticks: irregular intervals [s], inputs ``(R_v^b row-major, specific force)``."""
    ticks = []
    for _ in range(count):
        roll, pitch, yaw = rng.normal(scale=(0.2, 0.2, 1.0))
        force = rng.normal(scale=0.5, size=3) + (0.0, 0.0, -9.8)
        u = [*rotation_ned_to_body(roll, pitch, yaw).ravel().tolist(), *force.tolist()]
        ticks.append((float(rng.uniform(0.003, 0.007)), u))
    return ticks


def _inertial_transition(dt: float, u: list[float], constants: ModelConstants) -> np.ndarray:
    """``I + dt F`` of one tick of the inertial formulation (dense)."""
    f = np.zeros((N, N))
    f[state.POSITION, state.VELOCITY] = np.eye(3)
    f[V_ROWS] = np.array(generated.inertial([0.0] * N, u, constants.values())[1]).reshape(3, N)
    return np.eye(N) + dt * f


def test_the_inertial_model_is_affine_in_the_state() -> None:
    """The batch's premise: ``x' = (v, c(u) + J(u) b, 0...)`` with ``J`` on the bias only."""
    rng = np.random.default_rng(5)
    constants = ModelConstants(1.5, 0.2, 0.0)
    for _, u in _random_ticks(rng, 20):
        x = rng.normal(size=N).tolist()
        xdot, jac = generated.inertial(x, u, constants.values())
        xdot0, jac0 = generated.inertial([0.0] * N, u, constants.values())
        jac = np.array(jac).reshape(3, N)
        np.testing.assert_array_equal(jac, np.array(jac0).reshape(3, N))
        assert not jac[:, : state.BIAS.start].any() and not jac[:, state.BIAS.stop :].any()
        np.testing.assert_allclose(xdot[:3], x[3:6], rtol=0.0, atol=1e-15)
        np.testing.assert_allclose(
            xdot[3:6], np.array(xdot0[3:6]) + jac @ np.array(x), rtol=0.0, atol=1e-12
        )
        assert not any(xdot[6:])


@pytest.mark.parametrize("ticks", [1, 2, 4, 7])
def test_a_batch_steps_the_state_as_tick_by_tick_euler(ticks: int) -> None:
    """One step over the summed ticks gives the state of one Euler step per tick (1e-9), and
    the covariance of the ticks' transitions composed, ``Phi P Phi^T + T Q``."""
    rng = np.random.default_rng(ticks)
    x0, p0, q = random_start(rng)
    constants = ModelConstants(1.5, 0.2, 0.0)
    per_tick = MemberFilter(x0, p0, q, constants, generated.inertial)
    batched = MemberFilter(x0, p0, q, constants, generated.inertial)
    other = MemberFilter(x0 + 0.1, p0 * 2.0, q, constants, generated.inertial)
    bank = FilterBank([batched, other], 0.0, 30.0)
    batch = ImuBatch()
    phi = np.eye(N)
    for dt, u in _random_ticks(rng, ticks):
        per_tick.predict(dt, u)
        assert batch.add(dt, u, constants.values())
        phi = _inertial_transition(dt, u, constants) @ phi
    bank.predict_batch(batch, np.diag(q))
    np.testing.assert_allclose(batched.x, per_tick.x, rtol=0.0, atol=1e-9)
    expected = phi @ p0 @ phi.T + batch.duration_s * np.diag(q)
    np.testing.assert_allclose(batched.P, expected, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(other.P, 2.0 * phi @ p0 @ phi.T + batch.duration_s * np.diag(q))
    # the published mean: the same step on one state
    np.testing.assert_allclose(batch.step_state(x0, np.diag(q)), per_tick.x, rtol=0.0, atol=1e-9)
    # the tick-by-tick Euler covariance differs only by second-order terms
    np.testing.assert_allclose(batched.P, per_tick.P, rtol=0.0, atol=1e-3 * ticks**2)


def test_a_batch_refuses_what_is_not_finite() -> None:
    """A negative interval or a non-finite input leaves the batch as it was."""
    batch = ImuBatch()
    u = [*np.eye(3).ravel().tolist(), 0.0, 0.0, -9.8]
    c = (1.5, 0.2, 0.0)
    assert not batch.add(-0.001, u, c)
    assert not batch.add(0.005, [*u[:9], math.nan, 0.0, -9.8], c)
    assert not batch.add(math.inf, u, c)
    assert batch.ticks == 0 and batch.duration_s == 0.0
