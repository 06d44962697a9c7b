"""State-space model by subspace identification (PO-MOESP, Verhaegen 1994), in innovations
form ``x(t+1) = A x + B u + K e``, ``y = C x + D u + e`` (paper eq. A7-A8).

Steps, with ``i`` block rows of past and of future data, block Hankel matrices pooled over
experiments:

1. LQ factorisation of ``[U_f; W_p; Y_f]`` with ``W_p = [U_p; Y_p]`` the past inputs and
   outputs used as instruments (this makes the estimate of the column space of the
   observability matrix consistent under coloured noise, as after our low-pass filter);
2. SVD of the block ``L32``: its leading ``n`` left singular vectors span the extended
   observability matrix ``Gamma``; ``C`` is its first row and ``A`` solves the shift
   equation ``Gamma_up A = Gamma_down`` in least squares;
3. with ``A``, ``C`` fixed the output is linear in ``B``, ``D`` and each experiment's initial
   state: linear least squares on the simulation error;
4. ``K`` minimises the one-step prediction error (``scipy.optimize.least_squares``; the
   predictor's poles are the eigenvalues of ``A - K C``, kept inside the unit circle).

Without a given order every ``n`` in 1 .. MAX_ORDER is identified and the least description
length (one-step error on the estimation data) wins. The result is held in polynomial form
(``ss2tf``, exact for these low orders).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.signal import BadCoefficients, lfilter, ss2tf

from tether_companion.sysid.processing import IdData
from tether_companion.sysid.structures.base import FitContext, LinearFit

FloatArray = NDArray[np.float64]

MAX_ORDER = 8
BLOCK_ROWS = 15


def _hankel(signal: FloatArray, rows: int, columns: int) -> FloatArray:
    """Block Hankel matrix, shape (rows * width, columns), of ``signal`` shape (n, width)."""
    return np.vstack([signal[r : r + columns].T for r in range(rows)])


def observability_basis(experiments: Sequence[tuple[FloatArray, FloatArray]], i: int) -> FloatArray:
    """Left singular vectors and values of PO-MOESP's ``L32`` block: ``(U, s)``."""
    blocks = []
    for u, y in experiments:
        columns = len(y) - 2 * i + 1
        if columns > 0:
            uh, yh = _hankel(u, 2 * i, columns), _hankel(y[:, None], 2 * i, columns)
            m = u.shape[1]
            blocks.append(np.vstack([uh[i * m :], uh[: i * m], yh[:i], yh[i:]]))
    if not blocks:
        raise ArithmeticError("too few samples for the subspace block rows")
    stacked = np.hstack(blocks)
    r = np.linalg.qr(stacked.T / math.sqrt(stacked.shape[1]), mode="r")
    lower = r.T
    m = experiments[0][0].shape[1]
    f_rows, p_rows = i * m, i * m + i
    l32 = lower[f_rows + p_rows :, f_rows : f_rows + p_rows]
    left, singular, _ = np.linalg.svd(l32, full_matrices=False)
    return left, singular


def _state_regressors(a: FloatArray, c: FloatArray, u: FloatArray) -> FloatArray:
    """Columns of ``y`` linear in ``vec(B)`` (state k, input j), ``D`` and ``x0``: shape
    (n_samples, n m + m + n)."""
    n, m = a.shape[0], u.shape[1]
    z = np.zeros((n, n * m))
    p = c.copy()
    rows = np.empty((u.shape[0], n * m + m + n))
    identity = np.eye(n)
    for t in range(u.shape[0]):
        rows[t, : n * m] = (c @ z)[0]
        rows[t, n * m : n * m + m] = u[t]
        rows[t, n * m + m :] = p[0]
        z = a @ z + np.kron(u[t], identity)
        p = p @ a
    return rows


def _input_matrices(
    a: FloatArray, c: FloatArray, experiments: Sequence[tuple[FloatArray, FloatArray]]
) -> tuple[FloatArray, FloatArray]:
    """Least-squares ``B`` (n, m) and ``D`` (1, m) given ``A``, ``C`` (initial states free)."""
    n, m = a.shape[0], experiments[0][0].shape[1]
    shared = n * m + m
    blocks, targets = [], []
    for k, (u, y) in enumerate(experiments):
        rows = _state_regressors(a, c, u)
        block = np.zeros((len(y), shared + n * len(experiments)))
        block[:, :shared] = rows[:, :shared]
        block[:, shared + k * n : shared + (k + 1) * n] = rows[:, shared:]
        blocks.append(block)
        targets.append(y)
    theta, *_ = np.linalg.lstsq(np.vstack(blocks), np.concatenate(targets), rcond=None)
    b = theta[: n * m].reshape(m, n).T
    d = theta[n * m : shared].reshape(1, m)
    return b, d


def _kalman_gain(a: FloatArray, c: FloatArray, residuals: Sequence[FloatArray]) -> FloatArray:
    """``K`` minimising the one-step prediction error of the noise ``y - G u``."""
    n = a.shape[0]
    den = np.poly(a)

    def errors(k: FloatArray) -> FloatArray:
        closed = a - np.outer(k, c[0])
        if np.max(np.abs(np.linalg.eigvals(closed))) >= 0.999:
            return np.full(sum(len(r) for r in residuals), 1e3)
        num = np.poly(closed)
        return np.concatenate([lfilter(den, num, r) for r in residuals])

    result = least_squares(errors, np.zeros(n), method="trf", x_scale="jac")
    return result.x.reshape(n, 1)


def identify_state_space(
    experiments: Sequence[tuple[FloatArray, FloatArray]],
    order: int,
    basis: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """``(A, B, C, D, K)`` of the given order from centred ``(u, y)`` experiments.

    ``basis``: the left singular vectors of :func:`observability_basis` when already known
    (they do not depend on the order).
    """
    if basis is None:
        basis, _ = observability_basis(experiments, BLOCK_ROWS)
    gamma = basis[:, :order]
    c = gamma[:1]
    a, *_ = np.linalg.lstsq(gamma[:-1], gamma[1:], rcond=None)
    b, d = _input_matrices(a, c, experiments)
    deterministic = [
        sum(lfilter(*_tf(a, b, c, d, j), u[:, j]) for j in range(u.shape[1]))
        for u, _ in experiments
    ]
    k = _kalman_gain(a, c, [y - g for (_, y), g in zip(experiments, deterministic, strict=True)])
    return a, b, c, d, k


def _tf(
    a: FloatArray, b: FloatArray, c: FloatArray, d: FloatArray, j: int
) -> tuple[FloatArray, FloatArray]:
    with warnings.catch_warnings():
        # ss2tf warns when a leading numerator coefficient is ~0 (no direct feedthrough)
        warnings.simplefilter("ignore", BadCoefficients)
        num, den = ss2tf(a, b, c, d, input=j)
    return num[0], den


def _polynomial(
    context: FitContext, a: FloatArray, b: FloatArray, c: FloatArray, d: FloatArray, k: FloatArray
) -> LinearFit:
    """The innovations model as ``B_i/F`` input paths and ``C/D`` noise (``F = D = det``)."""
    numerators = [_tf(a, b, c, d, j)[0] for j in range(b.shape[1])]
    den = np.poly(a)
    model = context.model(den, np.array(numerators), np.poly(a - k @ c), den)
    return LinearFit("ss", f"n={a.shape[0]} (PO-MOESP)", model)


def fit_state_space(
    experiments: Sequence[IdData], context: FitContext, order: int | None = None
) -> LinearFit:
    """Subspace state-space model in innovations form (see module docstring).

    Raises
    ------
    ArithmeticError
        When no order gives a stable model.
    """
    centred = [context.centred(e) for e in experiments]
    best: tuple[float, LinearFit] | None = None
    failures = []
    try:
        basis, _ = observability_basis(centred, BLOCK_ROWS)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ArithmeticError(f"subspace identification failed: {exc}") from None
    for n in range(1, MAX_ORDER + 1) if order is None else (order,):
        try:
            a, b, c, d, k = identify_state_space(centred, n, basis)
        except (np.linalg.LinAlgError, ValueError) as exc:
            failures.append(f"n={n}: {exc}")
            continue
        if np.max(np.abs(np.linalg.eigvals(a))) >= 1.0:
            failures.append(f"n={n}: unstable A")
            continue
        fit = _polynomial(context, a, b, c, d, k)
        errors = np.concatenate([fit.model.predict(e, 1) - e.thrust_n for e in experiments])
        if not np.all(np.isfinite(errors)):
            failures.append(f"n={n}: prediction not finite")
            continue
        count = errors.size
        mdl = float(np.mean(errors**2)) * (1.0 + fit.n_params * math.log(count) / count)
        if best is None or mdl < best[0]:
            best = (mdl, fit)
    if best is None:
        raise ArithmeticError("subspace identification failed: " + "; ".join(failures))
    return best[1]
