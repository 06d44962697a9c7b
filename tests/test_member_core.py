"""The members' matrix arithmetic in C (``_member_core``, ``member_core.c``) against the numpy
reference (``imu_batch.BatchStep``, ``FilterBank``'s updates with ``MEMBER_CORE`` off).

Not bit for bit, by decision (issue 12, 2026-11-27): numpy's 17x17 products are OpenBLAS's
dgemm / dgemv kernels, whose summation order and fused multiply-adds are the library's and the
CPU's; the C loops sum in index order, skip the transition's zeros and fuse nothing. Every
entry must agree to 1e-12 relative to its scale: a covariance entry to ``1e-12 sqrt(P_ii
P_jj)`` (the bound any entry of a covariance has), a state to ``1e-12 (|x_i| + sqrt(P_ii))``
(the update adds ``K y``, of the order of the state's standard deviation). One step from the
same arrays (random and from a recorded flight's ticks), and whole chains of steps.

Built where a C compiler is (``pip install -e .``); its absence fails this file there or with
``TETHER_REQUIRE_CORE=1``, and skips it only where it could not be built.
"""

from __future__ import annotations

import numpy as np
import pytest
from filter_states import random_start
from optional_extension import import_extension

from tether_companion.estimation.dynamic import bank as bank_module
from tether_companion.estimation.dynamic import bank_updates, generated, imu_batch, state
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.imu_batch import ImuBatch
from tether_companion.estimation.dynamic.member import MemberFilter
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.frames import rotation_ned_to_body

core, pytestmark = import_extension("tether_companion.estimation.dynamic._member_core")

N = state.N_STATES
TOLERANCE = 1e-12


def _numpy(monkeypatch: pytest.MonkeyPatch) -> None:
    """Run the numpy reference (as without the extension) from now on in this test."""
    monkeypatch.setattr(imu_batch, "MEMBER_CORE", None)
    monkeypatch.setattr(bank_module, "MEMBER_CORE", None)
    monkeypatch.setattr(bank_updates, "MEMBER_CORE", None)
    monkeypatch.setattr(bank_updates, "FUSE_FORCE_BALANCE", None)
    monkeypatch.setattr(bank_updates, "FUSE_SCALAR", None)


def _c(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(imu_batch, "MEMBER_CORE", core)
    monkeypatch.setattr(bank_module, "MEMBER_CORE", core)
    monkeypatch.setattr(bank_updates, "MEMBER_CORE", core)
    monkeypatch.setattr(bank_updates, "FUSE_FORCE_BALANCE", core.fuse_force_balance)
    monkeypatch.setattr(bank_updates, "FUSE_SCALAR", core.fuse_scalar)


def assert_close(x: np.ndarray, p: np.ndarray, x_ref: np.ndarray, p_ref: np.ndarray) -> None:
    """``x``, ``p`` equal the reference's to 1e-12 of each entry's scale (module docstring)."""
    sigma = np.sqrt(np.abs(np.diag(p_ref)))
    scale_p = np.outer(sigma, sigma)
    assert np.all(np.abs(p - p_ref) <= TOLERANCE * scale_p), np.max(np.abs(p - p_ref) / scale_p)
    scale_x = np.abs(x_ref) + sigma
    assert np.all(np.abs(x - x_ref) <= TOLERANCE * scale_x), np.max(np.abs(x - x_ref) / scale_x)


def _batch(rng: np.random.Generator, constants: ModelConstants, ticks: int = 4) -> ImuBatch:
    batch = ImuBatch()
    for _ in range(ticks):
        roll, pitch, yaw = rng.normal(scale=(0.2, 0.2, 1.0))
        force = rng.normal(scale=0.5, size=3) + (0.0, 0.0, -9.8)
        u = [*rotation_ned_to_body(roll, pitch, yaw).ravel().tolist(), *force.tolist()]
        assert batch.add(float(rng.uniform(0.003, 0.007)), u, constants.values())
    return batch


def test_batch_step_of_one_member_is_numpys_to_1e_12(monkeypatch: pytest.MonkeyPatch) -> None:
    """``Phi x + D`` and ``Phi P Phi^T + T Q`` of random batches, states and covariances (scaled
    1e-6..1e6): C's equal numpy's to 1e-12 of each entry's scale, and C really ran (it is not
    numpy's bits: the test can tell them apart)."""
    rng = np.random.default_rng(11)
    constants = ModelConstants(1.5, 0.2, 0.0)
    differs = 0
    for _ in range(300):
        x, p, q = random_start(rng)
        scale = 10.0 ** rng.uniform(-6, 6)
        p, q = p * scale, np.diag(q * scale)
        step = _batch(rng, constants, int(rng.integers(1, 9))).step()
        out_x, out_p = np.empty(N), np.empty((N, N))
        assert core.step(step.phi, x, step.d_p, step.d_v, out_x) is True
        assert core.step_covariance(step.phi, p, q, step.duration_s, out_p) is True
        _numpy(monkeypatch)
        want_x, want_p = step.step_state(x), step.step_covariance(p, q)
        _c(monkeypatch)
        got_x, (got_p, finite) = step.step_state(x), step.step_member_covariance(p, q)
        assert finite
        np.testing.assert_array_equal(got_x, out_x)
        np.testing.assert_array_equal(got_p, out_p)
        np.testing.assert_array_equal(got_p, got_p.T)
        assert_close(got_x, got_p, want_x, want_p)
        differs += not np.array_equal(got_p, want_p)
    assert differs > 0


def _bank(
    x0: np.ndarray,
    p0: np.ndarray,
    q: np.ndarray,
    constants: ModelConstants,
    members: int,
    consider: slice | None,
) -> FilterBank:
    """A bank of ``members`` filters from one start, member i's covariance scaled by 1 + 0.1 i."""
    filters = [
        MemberFilter(
            x0, p0 * (1 + 0.1 * i), q, constants, generated.inertial, gate_probability=0.999
        )
        for i in range(members)
    ]
    return FilterBank(filters, 0.0, 30.0, consider=consider)


@pytest.mark.parametrize("members", [1, 3])
@pytest.mark.parametrize("consider", [state.CALIBRATION, None])
def test_bank_steps_and_fuses_as_numpy_to_1e_12(
    monkeypatch: pytest.MonkeyPatch, members: int, consider: slice | None
) -> None:
    """Two banks from the same start, one in C and one in numpy, fed the same batches, force
    balances (outliers gated), heights (outliers gated) and a non-finite sample: the same
    outcomes and NIS, every member's state and covariance and the mixture's moments numpy's to
    1e-12 after one step from the same arrays and still after the whole chain."""
    rng = np.random.default_rng(5 + members)
    x0, p0, q = random_start(rng)
    constants = ModelConstants(1.5, 0.2, 0.0)

    banks = {name: _bank(x0, p0, q, constants, members, consider) for name in ("c", "numpy")}
    accel = constants.models.accel
    statuses = set()

    def each(run, *args):  # noqa: ANN001, ANN202 - the step on both banks
        outcomes = {}
        for name, b in banks.items():
            (_c if name == "c" else _numpy)(monkeypatch)
            outcomes[name] = run(b, *args)
        for got, want in zip(outcomes["c"], outcomes["numpy"], strict=True):
            assert got.status == want.status
            assert got.nis == pytest.approx(want.nis, rel=1e-10, abs=1e-12) or (
                np.isnan(got.nis) and np.isnan(want.nis)
            )
            statuses.add(got.status)
        for a, b in zip(banks["c"].filters, banks["numpy"].filters, strict=True):
            assert_close(a.x, a.P, b.x, b.P)
        _c(monkeypatch)
        got = banks["c"].mixture()
        np.testing.assert_array_equal(got[1], got[1].T)
        _numpy(monkeypatch)
        assert_close(*got, *banks["numpy"].mixture())

    def predict(b: FilterBank, batch: ImuBatch) -> list:
        b.predict_batch(batch, np.diag(q))
        return []

    def height(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        row = np.zeros((1, N))
        row[0, 2] = -1.0
        return np.array([-x[2]]), row

    for k in range(80):
        each(predict, _batch(rng, constants))
        rotation = rotation_ned_to_body(*rng.normal(scale=0.1, size=2), 0.05 * k)
        inputs = [*rotation.ravel().tolist(), 14.7 + rng.normal(scale=0.5)]
        z = np.array(accel(banks["numpy"].filters[0].x.tolist(), inputs, constants.values())[0])
        z += rng.normal(scale=0.9, size=3) + (30.0 if k % 17 == 5 else 0.0)
        if k == 40:
            z[1] = np.nan

        def rows(x: list[float], inputs: list[float] = inputs) -> tuple:
            return accel(x, inputs, constants.values())

        each(lambda b, z=z: b.update_force_balance("accel", z.tolist(), rows, 0.8)[0])
        if k % 3 == 1:
            h = 2.5 + rng.normal(scale=0.05) + (3.0 if k % 21 == 1 else 0.0)
            each(lambda b, h=h: b.update_scalar("range", h, height, 0.0025)[0])
        # one step from the very same arrays: copy the numpy bank's into the C bank
        for a, b in zip(banks["c"].filters, banks["numpy"].filters, strict=True):
            a.x, a.P = b.x.copy(), b.P.copy()
    assert {"fused", "gated", "nonfinite"} <= statuses


@pytest.mark.parametrize(
    "bad",
    [
        lambda a: a.astype(np.float32),
        lambda a: np.asfortranarray(a) if a.ndim == 2 else a[::-1].copy()[::-1],
        lambda a: a[:-1],
        lambda a: np.where(np.arange(a.size).reshape(a.shape) == 3, np.inf, a),
        lambda a: a.tolist(),
    ],
)
def test_arrays_it_does_not_take_are_left_to_numpy(bad) -> None:  # noqa: ANN001
    """Not float64, not C-contiguous, the wrong shape, not finite, not an array: None (the
    caller runs numpy), the outputs untouched; wrong argument counts raise TypeError."""
    rng = np.random.default_rng(2)
    x, p, q = random_start(rng)
    q = np.diag(q)
    step = _batch(rng, ModelConstants(1.5, 0.2, 0.0)).step()
    pht = np.empty((N, 3))
    h = rng.normal(size=(3, N))
    out_x, out_p = np.full(N, 7.0), np.full((N, N), 7.0)
    assert core.step(step.phi, bad(x), step.d_p, step.d_v, out_x) is None
    assert core.step_covariance(bad(step.phi), p, q, step.duration_s, out_p) is None
    assert core.step_covariance(step.phi, bad(p), q, step.duration_s, out_p) is None
    assert core.project(bad(p), h.ravel().tolist(), pht) is None
    s_inv, w = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], [0.1, 0.2, 0.3]
    assert core.update(x, bad(p), pht, s_inv, w, 13, 17, out_x, out_p) is None
    assert core.mixture([0.5, 0.5], [x, bad(x)], [p, p], out_x, out_p) is None
    assert core.mixture([0.5, 0.5], [x, x], [p, bad(p)], out_x, out_p) is None
    assert np.all(out_x == 7.0) and np.all(out_p == 7.0)
    with pytest.raises(TypeError):
        core.update(x, p, pht, s_inv, w, 13, 17, out_x)


def test_project_and_update_are_numpys_to_1e_12() -> None:
    """``P H^T``, ``H P H^T`` (H a list with int zeros, or an array) and the gain's update with
    the consider block held, against numpy's on random cases; a covariance made indefinite is
    reported (the Cholesky test, as dpotrf)."""
    rng = np.random.default_rng(4)
    for _ in range(300):
        x, p, _ = random_start(rng)
        h = rng.normal(size=(3, N))
        h[:, 11:] = 0.0
        h_list = [int(v) if v == 0.0 else float(v) for v in h.ravel()]
        pht = np.empty((N, 3))
        s = np.array(core.project(p, h_list, pht)).reshape(3, 3)
        np.testing.assert_allclose(pht, p @ h.T, rtol=0, atol=TOLERANCE * np.abs(p).max() * 10)
        s_ref = h @ p @ h.T
        np.testing.assert_allclose(s, s_ref, rtol=0, atol=TOLERANCE * np.abs(s_ref).max() * 10)
        s_inv = np.linalg.inv(s + 0.5 * np.eye(3))
        y = rng.normal(size=3)
        w = s_inv @ y
        out_x, out_p = np.empty(N), np.empty((N, N))
        ok = core.update(x, p, pht, s_inv.ravel().tolist(), w.tolist(), 13, 17, out_x, out_p)
        want_p = p - pht @ s_inv @ pht.T
        want_p = (want_p + want_p.T) * 0.5
        want_x = x + pht @ w
        want_x[13:], want_p[13:, 13:] = x[13:], p[13:, 13:]
        assert ok is True
        np.testing.assert_array_equal(out_p, out_p.T)
        assert_close(out_x, out_p, want_x, want_p)
    bad = np.diag(np.ones(N))
    bad[5, 5] = -1e-3
    pht = np.zeros((N, 1))
    out_x, out_p = np.empty(N), np.empty((N, N))
    assert core.update(np.zeros(N), bad, pht, [1.0], [0.0], 0, 0, out_x, out_p) is False


def test_a_long_chain_stays_symmetric_definite_and_near_numpy(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The C arithmetic computes each symmetric product once (upper triangle, mirrored) where
    numpy symmetrises the full one, so the two differ by rounding at each step. Fed 200 batches,
    force balances and heights with no copying back: every C member's covariance stays exactly
    symmetric and positive definite at every step, the outcomes stay numpy's and the states and
    covariances within 1e-9 of each entry's scale at the end (the rounding does not grow)."""
    rng = np.random.default_rng(23)
    x0, p0, q = random_start(rng)
    constants = ModelConstants(1.5, 0.2, 0.0)

    banks = {name: _bank(x0, p0, q, constants, 3, state.CALIBRATION) for name in ("c", "numpy")}
    accel = constants.models.accel

    def height(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        row = np.zeros((1, N))
        row[0, 2] = -1.0
        return np.array([-x[2]]), row

    for k in range(200):
        batch = _batch(rng, constants)
        rotation = rotation_ned_to_body(*rng.normal(scale=0.1, size=2), 0.05 * k)
        inputs = [*rotation.ravel().tolist(), 14.7 + rng.normal(scale=0.5)]
        z = np.array(accel(banks["numpy"].filters[0].x.tolist(), inputs, constants.values())[0])
        z += rng.normal(scale=0.9, size=3) + (30.0 if k % 17 == 5 else 0.0)
        h = 2.5 + rng.normal(scale=0.05)

        def rows(x: list[float], inputs: list[float] = inputs) -> tuple:
            return accel(x, inputs, constants.values())

        statuses = {}
        for name, b in banks.items():
            (_c if name == "c" else _numpy)(monkeypatch)
            b.predict_batch(batch, np.diag(q))
            fused = b.update_force_balance("accel", z.tolist(), rows, 0.8)[0]
            if k % 3 == 1:
                fused += b.update_scalar("range", h, height, 0.0025)[0]
            statuses[name] = [outcome.status for outcome in fused]
        assert statuses["c"] == statuses["numpy"]
        for kf in banks["c"].filters:
            np.testing.assert_array_equal(kf.P, kf.P.T)
            np.linalg.cholesky(kf.P)
    for a, b in zip(banks["c"].filters, banks["numpy"].filters, strict=True):
        sigma = np.sqrt(np.diag(b.P))
        assert np.max(np.abs(a.P - b.P) / np.outer(sigma, sigma)) <= 1e-9
        assert np.max(np.abs(a.x - b.x) / (np.abs(b.x) + sigma)) <= 1e-9


def test_the_definiteness_test_is_choleskys() -> None:
    """``update`` with no gain (``P H^T = 0``) gives ``p`` back and says whether it is positive
    definite: over random symmetric matrices with eigenvalues of either sign near zero, the
    verdict is numpy's Cholesky's (LAPACK dpotrf); the result is exactly symmetric."""
    rng = np.random.default_rng(31)
    verdicts = set()
    for _ in range(400):
        basis, _ = np.linalg.qr(rng.normal(size=(N, N)))
        eigenvalues = 10.0 ** rng.uniform(-3, 3, size=N)
        if rng.uniform() < 0.5:
            eigenvalues[rng.integers(N)] *= -rng.uniform(1e-3, 1.0)
        p = (basis * eigenvalues) @ basis.T
        p = np.triu(p) + np.triu(p, 1).T
        out_x, out_p = np.empty(N), np.empty((N, N))
        ok = core.update(np.zeros(N), p, np.zeros((N, 1)), [1.0], [0.0], 0, 0, out_x, out_p)
        try:
            np.linalg.cholesky(p)
            want = True
        except np.linalg.LinAlgError:
            want = False
        assert ok is want
        np.testing.assert_array_equal(out_p, p)
        verdicts.add(ok)
    assert verdicts == {True, False}


def test_a_process_noise_not_exactly_symmetric_is_left_to_numpy() -> None:
    """``step_covariance`` reads ``q``'s upper triangle only: a ``q`` not exactly symmetric
    gives None (numpy then), the output untouched; so does an output that is ``p`` itself."""
    rng = np.random.default_rng(3)
    _, p, q = random_start(rng)
    q = np.diag(q)
    q[2, 9] = 1e-9
    step = _batch(rng, ModelConstants(1.5, 0.2, 0.0)).step()
    out_p = np.full((N, N), 7.0)
    assert core.step_covariance(step.phi, p, q, step.duration_s, out_p) is None
    assert np.all(out_p == 7.0)
    q[9, 2] = 1e-9
    assert core.step_covariance(step.phi, p, q, step.duration_s, out_p) is True
    assert core.step_covariance(step.phi, p, q, step.duration_s, p) is None  # out must not be p
