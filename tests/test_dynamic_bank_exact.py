"""One bank member's arithmetic on its own 2-D arrays (``np.dot``, perf14) against the
arithmetic it replaced, ``matmul`` on the member's arrays with a stacking axis added: **bit for
bit** the same numbers for every product the bank and the batch step make
(:func:`~tether_companion.estimation.dynamic.imu_batch.product`, ``bank_arrays.apply_each``), so one
member steps and fuses exactly as before. Several members' stacked products (``matmul`` with
m > 1 uses BLAS's matrix-matrix kernels where one member's uses its matrix-vector ones) agree
with one member's to rounding only (1e-12), as they did before."""

from __future__ import annotations

import numpy as np
import pytest
from filter_states import random_start

from tether_companion.estimation.dynamic import generated, state
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.bank_arrays import apply_each
from tether_companion.estimation.dynamic.imu_batch import ImuBatch, product
from tether_companion.estimation.dynamic.member import MemberFilter
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.frames import rotation_ned_to_body

N = state.N_STATES


def _height(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    row = np.zeros((1, N))
    row[0, 2] = -1.0
    return np.array([-x[2]]), row


@pytest.mark.parametrize("consider", [state.CALIBRATION, None])
def test_one_member_steps_and_fuses_as_a_stacked_member(consider: slice | None) -> None:
    """A bank of one member and a bank of three copies of it, fed the same batches, force
    balances (outliers gated) and heights: the same outcomes, every member's state and
    covariance the single member's to rounding after every step."""
    rng = np.random.default_rng(3)
    x0, p0, q = random_start(rng)
    constants = ModelConstants(1.5, 0.2, 0.0)

    def member() -> MemberFilter:
        return MemberFilter(x0, p0, q, constants, generated.inertial, gate_probability=0.999)

    single = FilterBank([member()], 0.0, 30.0, consider=consider)
    stacked = FilterBank([member() for _ in range(3)], 0.0, 30.0, consider=consider)
    accel = constants.models.accel
    statuses = set()
    for k in range(60):
        batch = ImuBatch()
        for _ in range(4):
            roll, pitch, yaw = rng.normal(scale=(0.2, 0.2, 1.0))
            force = rng.normal(scale=0.5, size=3) + (0.0, 0.0, -9.8)
            u = [*rotation_ned_to_body(roll, pitch, yaw).ravel().tolist(), *force.tolist()]
            assert batch.add(float(rng.uniform(0.003, 0.007)), u, constants.values())
        for bank in (single, stacked):
            bank.predict_batch(batch, np.diag(q))
        _assert_same(single, stacked)
        rotation = rotation_ned_to_body(*rng.normal(scale=0.1, size=2), 0.05 * k)
        inputs = [*rotation.ravel().tolist(), 14.7 + rng.normal(scale=0.5)]
        z = np.array(accel(single.filters[0].x.tolist(), inputs, constants.values())[0])
        z += rng.normal(scale=0.9, size=3) + (30.0 if k % 17 == 5 else 0.0)

        def rows(x: list[float], inputs: list[float] = inputs) -> tuple:
            return accel(x, inputs, constants.values())

        (want,), _, _ = single.update_force_balance("accel", z.tolist(), rows, 0.8)
        for got in stacked.update_force_balance("accel", z.tolist(), rows, 0.8)[0]:
            assert got.status == want.status
            assert got.nis == pytest.approx(want.nis, rel=1e-12, abs=1e-12)
        statuses.add(want.status)
        _assert_same(single, stacked)
        if k % 3 == 1:
            height = 2.5 + rng.normal(scale=0.05) + (3.0 if k % 21 == 1 else 0.0)
            (want,), _, _ = single.update_scalar("range", height, _height, 0.0025)
            for got in stacked.update_scalar("range", height, _height, 0.0025)[0]:
                assert got.status == want.status
            assert got.nis == pytest.approx(want.nis, rel=1e-12, abs=1e-12)
            statuses.add(want.status)
            _assert_same(single, stacked)
    assert {"fused", "gated"} <= statuses


def _assert_same(single: FilterBank, stacked: FilterBank) -> None:
    (one,) = single.filters
    for kf in stacked.filters:
        np.testing.assert_allclose(kf.x, one.x, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(kf.P, one.P, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize(
    ("a_shape", "b_shape"),
    [((17, 17), (17, 17)), ((17,), (17, 17)), ((17, 17), (3, 17)), ((3, 17), (17, 3))],
)
def test_product_of_one_members_arrays_is_the_stacked_matmul_bit_for_bit(
    a_shape: tuple[int, ...], b_shape: tuple[int, ...]
) -> None:
    """``product(a, b)`` (``np.dot``) equals ``matmul`` of the arrays with a stacking axis
    added (what the bank computed for one member before) exactly: a state times ``Phi^T``,
    ``Phi P``, ``(Phi P) Phi^T``, ``P H^T``, ``H (P H^T)``, ``K (P H^T)^T``."""
    rng = np.random.default_rng(len(a_shape) * 10 + b_shape[0])
    for _ in range(200):
        a = rng.normal(size=a_shape)
        b = rng.normal(size=b_shape)
        b = b.T if b_shape == (3, 17) else b
        for right in (b, np.ascontiguousarray(b.T).T):  # a transposed view too (Phi^T)
            # before: a state as a (1, n) stack by the matrix, a matrix as a (1, ., .) stack
            before = (a[None] @ right)[0] if a.ndim == 1 else (a[None] @ right[None])[0]
            np.testing.assert_array_equal(product(a, right), before)


@pytest.mark.parametrize("columns", [17, 3])
def test_apply_to_one_members_vector_is_the_stacked_matmul_bit_for_bit(columns: int) -> None:
    """``P v`` of one member (``np.dot``, matrix by vector) equals ``matmul`` of the stacked
    matrix by the stacked column (``P h`` of the range update, ``P H^T S^-1 y``) exactly."""
    rng = np.random.default_rng(columns)
    for _ in range(200):
        p, v = rng.normal(size=(17, columns)), rng.normal(size=columns)
        np.testing.assert_array_equal(apply_each(p, v), (p[None] @ v[None, :, None])[0, :, 0])
        np.testing.assert_array_equal(apply_each(p[None], v[None])[0], apply_each(p, v))
