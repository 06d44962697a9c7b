"""Continuous-time process and transfer-function models, fitted on simulation error.

- Process model, first order plus dead time (MATLAB ``procest`` 'P1D'): every input path is
  ``K_i exp(-T_d s) / (T_p s + 1)``, one time constant ``T_p`` and delay ``T_d`` shared by
  the motors (same motors and ESCs). The delay is rounded to whole samples; each delay
  0 .. ``MAX_DELAY`` samples is tried.
- Transfer function (MATLAB ``tfest``): every input path is ``(b_i1 s + b_i0) / (s^2 + a1 s
  + a0)`` with one denominator, kept stable by fitting ``log a1`` and ``log a0``.

Both are discretised with a first-order hold (``cont2discrete(..., "foh")``): the filtered
signals are smooth, not held between samples, and a zero-order hold would read the
half-sample shift as a shorter time constant. Both have no noise model (output error), so
their k-step prediction equals their simulation.

The numerator parameters enter the simulated output linearly, so they are solved by linear
least squares inside the search over the few denominator parameters (variable projection):
a bounded scalar search over ``log T_p`` for the process model, ``least_squares`` over
``(log a1, log a0)`` for the transfer function.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import lstsq
from scipy.optimize import least_squares, minimize_scalar
from scipy.signal import cont2discrete

from tether_companion.sysid.linear_model import steady_filter
from tether_companion.sysid.processing import IdData
from tether_companion.sysid.structures.base import FitContext, LinearFit

FloatArray = NDArray[np.float64]

MAX_DELAY = 5
"""Longest dead time tried by the process model [samples]."""
MAX_TF_EVALUATIONS = 40
"""Cap on the transfer-function pole search (it starts from the process model's pole)."""
TIME_CONSTANT_BOUNDS_S = (1e-3, 5.0)
"""Search interval of the process model's time constant [s]."""


def _discrete(num: list[float], den: list[float], dt_s: float) -> tuple[FloatArray, FloatArray]:
    """FOH discretisation of ``num(s) / den(s)``: ``(numerator, denominator)`` in ``q^-1``."""
    num_d, den_d, _ = cont2discrete((num, den), dt_s, method="foh")
    return np.ravel(num_d), np.ravel(den_d)


def _delayed(u: FloatArray, delay: int) -> FloatArray:
    """``u(t - delay)``, the first value repeated at the start, shape as ``u``."""
    if delay == 0:
        return u
    return np.concatenate([np.repeat(u[:1], delay, axis=0), u[:-delay]])


def _project(
    regressors: Sequence[FloatArray], targets: Sequence[FloatArray]
) -> tuple[FloatArray, FloatArray]:
    """Least-squares coefficients and residuals of stacked regressors and targets."""
    phi = np.vstack(regressors)
    y = np.concatenate(targets)
    # QR with column pivoting: fast, and safe with the nearly collinear cmd and cmd^2 columns
    theta, *_ = lstsq(phi, y, lapack_driver="gelsy", check_finite=False)
    return theta, y - phi @ theta


def _paths(
    centred: Sequence[tuple[FloatArray, FloatArray]],
    num: FloatArray,
    den: FloatArray,
    delay: int = 0,
) -> list[FloatArray]:
    """``num/den`` applied to every (delayed) input: one regressor matrix (n, m) per experiment."""
    regressors = []
    for u, _ in centred:
        shifted = _delayed(u, delay)
        columns = [steady_filter(num, den, shifted[:, j]) for j in range(u.shape[1])]
        regressors.append(np.column_stack(columns))
    return regressors


def first_order_search(
    centred: Sequence[tuple[FloatArray, FloatArray]], dt_s: float
) -> tuple[float, int]:
    """Time constant [s] and delay [samples] of the best first-order-plus-delay fit."""
    targets = [y for _, y in centred]
    best: tuple[float, float, int] | None = None
    lo, hi = (math.log(b) for b in TIME_CONSTANT_BOUNDS_S)
    for delay in range(MAX_DELAY + 1):

        def cost(log_tau: float, delay: int = delay) -> float:
            num, den = _discrete([1.0], [math.exp(log_tau), 1.0], dt_s)
            return float(np.sum(_project(_paths(centred, num, den, delay), targets)[1] ** 2))

        result = minimize_scalar(cost, bounds=(lo, hi), method="bounded")
        if math.isfinite(result.fun) and (best is None or result.fun < best[0]):
            best = (float(result.fun), float(result.x), delay)
    if best is None:
        raise ArithmeticError("process model: no finite fit for any dead time")
    return math.exp(best[1]), best[2]


def fit_process(experiments: Sequence[IdData], context: FitContext) -> LinearFit:
    """First-order-plus-dead-time model (see module docstring)."""
    centred = [context.centred(e) for e in experiments]
    time_constant_s, delay = first_order_search(centred, context.dt_s)
    num, den = _discrete([1.0], [time_constant_s, 1.0], context.dt_s)
    gains, _ = _project(_paths(centred, num, den, delay), [y for _, y in centred])
    b = np.zeros((gains.shape[0], delay + num.shape[0]))
    b[:, delay:] = np.outer(gains, num)
    orders = f"P1D Tp={time_constant_s * 1e3:.1f} ms Td={delay * context.dt_s * 1e3:.0f} ms"
    return LinearFit("process", orders, context.model(den, b))


def _second_order_paths(
    centred: Sequence[tuple[FloatArray, FloatArray]], log_a: FloatArray, dt_s: float
) -> tuple[list[FloatArray], FloatArray, FloatArray, FloatArray]:
    """Regressors ``[s/a(s) u_j, 1/a(s) u_j]`` per experiment and the discrete ``s/a``,
    ``1/a`` numerators and common denominator."""
    a = [1.0, math.exp(log_a[0]), math.exp(log_a[1])]
    num_s, den = _discrete([1.0, 0.0], a, dt_s)
    num_1, _ = _discrete([1.0], a, dt_s)
    by_s, by_1 = _paths(centred, num_s, den), _paths(centred, num_1, den)
    regressors = [np.column_stack([p, q]) for p, q in zip(by_s, by_1, strict=True)]
    return regressors, num_s, num_1, den


def fit_transfer_function(experiments: Sequence[IdData], context: FitContext) -> LinearFit:
    """Two-pole one-zero transfer function per input, common poles (see module docstring)."""
    centred = [context.centred(e) for e in experiments]
    targets = [y for _, y in centred]
    m = centred[0][0].shape[1]
    slow = 1.0 / first_order_search(centred, context.dt_s)[0]
    fast = 10.0 * slow
    start = np.array([math.log(slow + fast), math.log(slow * fast)])

    def residuals(log_a: FloatArray) -> FloatArray:
        return _project(_second_order_paths(centred, log_a, context.dt_s)[0], targets)[1]

    result = least_squares(
        residuals, start, method="trf", x_scale="jac", max_nfev=MAX_TF_EVALUATIONS
    )
    if not np.all(np.isfinite(result.x)):
        raise ArithmeticError(f"transfer function fit failed: {result.message}")
    regressors, num_s, num_1, den = _second_order_paths(centred, result.x, context.dt_s)
    theta, _ = _project(regressors, targets)
    width = max(len(num_s), len(num_1))
    b = np.zeros((m, width))
    for j in range(m):
        b[j, width - len(num_s) :] += theta[j] * num_s
        b[j, width - len(num_1) :] += theta[m + j] * num_1
    return LinearFit("tf", "np=2 nz=1", context.model(den, b))
