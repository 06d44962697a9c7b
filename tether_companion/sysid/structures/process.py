"""Continuous-time process and transfer-function models, fitted on simulation error.

- Process model, first order plus dead time (MATLAB ``procest`` 'P1D'): every input path is
  ``K_i exp(-T_d s) / (T_p s + 1)``, one time constant ``T_p`` and delay ``T_d`` shared by
  the motors (same motors and ESCs). Discretised exactly with a zero-order hold, the delay
  rounded to whole samples; each whole-sample delay 0 .. ``MAX_DELAY`` is tried.
- Transfer function (MATLAB ``tfest``): every input path is ``(b_i1 s + b_i0) / (s^2 + a1 s
  + a0)`` with one denominator, poles kept in the left half plane by fitting ``log a0`` and
  ``log a1``; discretised with a zero-order hold. Started from the process model.

Both have no noise model (output error), so their k-step prediction equals their simulation.
Parameters minimise the simulation error with ``scipy.optimize.least_squares``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.signal import cont2discrete

from tether_companion.sysid.linear_model import PolynomialModel
from tether_companion.sysid.processing import IdData
from tether_companion.sysid.structures.base import FitContext, LinearFit

FloatArray = NDArray[np.float64]

MAX_DELAY = 5
"""Longest dead time tried by the process model [samples]."""


def _first_order(
    gains: FloatArray, time_constant_s: float, delay: int, dt_s: float
) -> tuple[FloatArray, FloatArray]:
    """ZOH discretisation of ``K_i e^{-delay dt s} / (T s + 1)``: ``(F, B)``."""
    pole = math.exp(-dt_s / time_constant_s)
    b = np.zeros((gains.shape[0], delay + 2))
    b[:, delay + 1] = (1.0 - pole) * gains
    return np.array([1.0, -pole]), b


def _simulation_residuals(
    centred: Sequence[tuple[FloatArray, FloatArray]], f: FloatArray, b: FloatArray, dt_s: float
) -> FloatArray:
    model = PolynomialModel(f=f, b=b, u0=np.zeros(b.shape[0]), y0_n=0.0, dt_s=dt_s)
    return np.concatenate([model.deterministic(u) - y for u, y in centred])


def _gain_guess(centred: Sequence[tuple[FloatArray, FloatArray]]) -> FloatArray:
    u = np.vstack([c[0] for c in centred])
    y = np.concatenate([c[1] for c in centred])
    gains, *_ = np.linalg.lstsq(u, y, rcond=None)
    return gains


def fit_process(experiments: Sequence[IdData], context: FitContext) -> LinearFit:
    """First-order-plus-dead-time model (see module docstring)."""
    centred = [context.centred(e) for e in experiments]
    gains0 = _gain_guess(centred)
    dt_s = context.dt_s
    best: tuple[float, FloatArray, int] | None = None
    for delay in range(MAX_DELAY + 1):

        def residuals(theta: FloatArray, delay: int = delay) -> FloatArray:
            f, b = _first_order(theta[1:], math.exp(theta[0]), delay, dt_s)
            return _simulation_residuals(centred, f, b, dt_s)

        theta0 = np.concatenate(([math.log(0.05)], gains0))
        result = least_squares(residuals, theta0, method="trf", x_scale="jac")
        cost = float(result.cost)
        if np.all(np.isfinite(result.x)) and (best is None or cost < best[0]):
            best = (cost, result.x, delay)
    if best is None:
        raise ArithmeticError("process model: no finite fit for any dead time")
    _, theta, delay = best
    time_constant_s = math.exp(theta[0])
    f, b = _first_order(theta[1:], time_constant_s, delay, dt_s)
    model = context.model(f, b)
    return LinearFit(
        "process", f"P1D Tp={time_constant_s * 1e3:.1f} ms Td={delay * dt_s * 1e3:.0f} ms", model
    )


def _second_order(theta: FloatArray, m: int, dt_s: float) -> tuple[FloatArray, FloatArray]:
    """ZOH discretisation of ``(b_i1 s + b_i0) / (s^2 + a1 s + a0)``: ``(F, B)``."""
    a1, a0 = math.exp(theta[0]), math.exp(theta[1])
    numerators = theta[2:].reshape(m, 2)
    rows, f = [], None
    for b1, b0 in numerators:
        num, den, _ = cont2discrete(([b1, b0], [1.0, a1, a0]), dt_s, method="zoh")
        rows.append(np.ravel(num))
        f = np.ravel(den)
    width = max(len(r) for r in rows)
    b = np.array([np.pad(r, (width - len(r), 0)) for r in rows])
    return np.asarray(f), b


def fit_transfer_function(experiments: Sequence[IdData], context: FitContext) -> LinearFit:
    """Two-pole one-zero transfer function per input, common poles (see module docstring)."""
    centred = [context.centred(e) for e in experiments]
    m = centred[0][0].shape[1]
    start = fit_process(experiments, context).model
    pole = -math.log(-start.f[1]) / context.dt_s
    fast = 10.0 * pole
    gains = start.b.sum(axis=1) / (1.0 + start.f[1])
    theta0 = np.concatenate(
        (
            [math.log(pole + fast), math.log(pole * fast)],
            np.column_stack([np.zeros(m), gains * pole * fast]).ravel(),
        )
    )

    def residuals(theta: FloatArray) -> FloatArray:
        f, b = _second_order(theta, m, context.dt_s)
        return _simulation_residuals(centred, f, b, context.dt_s)

    result = least_squares(residuals, theta0, method="trf", x_scale="jac")
    if not np.all(np.isfinite(result.x)):
        raise ArithmeticError(f"transfer function fit failed: {result.message}")
    f, b = _second_order(result.x, m, context.dt_s)
    model = context.model(f, b)
    return LinearFit("tf", "np=2 nz=1", model)
