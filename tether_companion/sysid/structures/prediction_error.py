"""Output-error and Box-Jenkins models by prediction-error minimisation.

Output error: ``y = sum_i B_i/F u_i + e``; Box-Jenkins adds a noise model,
``y = sum_i B_i/F u_i + C/D e``. The parameters minimise the sum of squared one-step
prediction errors ``e = (D/C) (y - sum_i B_i/F u_i)`` (for output error, the simulation
error) with ``scipy.optimize.least_squares``. Output error starts from the ARX fit of the
same ``nb``, ``nk`` (its ``A`` as ``F``); Box-Jenkins from the output-error fit and an ARMA
model of its residual. A candidate with a pole of ``1/F``
or ``1/C`` outside the unit circle gets a large constant residual, steering the search back
to stable models.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.signal import lfilter

from tether_companion.sysid.linear_model import PolynomialModel
from tether_companion.sysid.processing import IdData
from tether_companion.sysid.structures.arx import ArxOrders, estimate_arx
from tether_companion.sysid.structures.base import FitContext, LinearFit

FloatArray = NDArray[np.float64]

_UNSTABLE_RESIDUAL = 1e3


def _stable(poly: FloatArray) -> bool:
    return len(poly) == 1 or bool(np.all(np.abs(np.roots(poly)) < 0.999))


def _unpack(
    theta: FloatArray, m: int, nf: int, nb: int, nk: int, nc: int
) -> tuple[FloatArray, ...]:
    f = np.concatenate(([1.0], theta[:nf]))
    b = np.zeros((m, nk + nb))
    b[:, nk:] = theta[nf : nf + m * nb].reshape(m, nb)
    rest = theta[nf + m * nb :]
    c = np.concatenate(([1.0], rest[:nc]))
    d = np.concatenate(([1.0], rest[nc:]))
    return f, b, c, d


def _shift(x: FloatArray, lag: int) -> FloatArray:
    """``x(t - lag)`` with zeros before the start."""
    if lag == 0:
        return x
    return np.concatenate([np.zeros(lag), x[:-lag]])


def _jacobian_block(
    u: FloatArray, y: FloatArray, polys: tuple[FloatArray, ...], shape: tuple[int, ...]
) -> FloatArray:
    """Jacobian of the residual ``r = (D/C)(G u - y)`` of one experiment (zero initial state).

    ``dr/db_ij = (D/(C F)) u_i(t-nk-j)``, ``dr/df_j = -(D/(C F)) g(t-j)`` with ``g = G u``,
    ``dr/dc_j = -(1/C) r(t-j)``, ``dr/dd_j = (1/C) s(t-j)`` with ``s = g - y``.
    """
    f, b, c, d = polys
    m, nf, nb, nk, nc = shape
    g = sum(lfilter(b[i], f, u[:, i]) for i in range(m))
    s = g - y
    r = lfilter(d, c, s)
    cf = np.convolve(c, f)
    columns = []
    w = lfilter(d, cf, g)
    columns += [-_shift(w, j) for j in range(1, nf + 1)]
    for i in range(m):
        z = lfilter(d, cf, u[:, i])
        columns += [_shift(z, nk + j) for j in range(nb)]
    if nc:
        rc, sc = lfilter([1.0], c, r), lfilter([1.0], c, s)
        columns += [-_shift(rc, j) for j in range(1, nc + 1)]
        columns += [_shift(sc, j) for j in range(1, nc + 1)]
    return np.column_stack(columns)


def _search(
    centred: Sequence[tuple[FloatArray, FloatArray]],
    theta0: FloatArray,
    shape: tuple[int, int, int, int, int],
    dt_s: float,
    max_nfev: int,
) -> FloatArray:
    """Parameters minimising the one-step prediction error from ``theta0`` (analytic
    Jacobian, see :func:`_jacobian_block`)."""
    m, nf, nb, nk, nc = shape
    total = sum(len(y) for _, y in centred)

    def residuals(theta: FloatArray) -> FloatArray:
        f, b, c, d = _unpack(theta, *shape)
        if not (_stable(f) and _stable(c)):
            return np.full(total, _UNSTABLE_RESIDUAL)
        model = PolynomialModel(f=f, b=b, c=c, d=d, u0=np.zeros(m), dt_s=dt_s)
        return np.concatenate([model.predict_deviation(u, y, 1) - y for u, y in centred])

    def jacobian(theta: FloatArray) -> FloatArray:
        polys = _unpack(theta, *shape)
        if not (_stable(polys[0]) and _stable(polys[2])):
            return np.zeros((total, theta.shape[0]))
        return np.vstack([_jacobian_block(u, y, polys, shape) for u, y in centred])

    result = least_squares(
        residuals, theta0, jac=jacobian, method="trf", x_scale="jac", max_nfev=max_nfev
    )
    f, _, c, _ = _unpack(result.x, *shape)
    if not np.all(np.isfinite(result.x)) or not (_stable(f) and _stable(c)):
        raise ArithmeticError(
            f"prediction-error search ended at an unstable model ({result.message})"
        )
    return result.x


def _noise_model(residuals: Sequence[FloatArray], nc: int) -> FloatArray:
    """``(c_1..c_nc, d_1..d_nc)`` of an ARMA model ``w = C/D e`` of the output-error residual."""
    total = sum(len(w) for w in residuals)

    def innovations(theta: FloatArray) -> FloatArray:
        c = np.concatenate(([1.0], theta[:nc]))
        d = np.concatenate(([1.0], theta[nc:]))
        if not _stable(c):
            return np.full(total, _UNSTABLE_RESIDUAL)
        return np.concatenate([lfilter(d, c, w) for w in residuals])

    return least_squares(innovations, np.zeros(2 * nc), method="trf").x


def fit_output_error(
    experiments: Sequence[IdData], context: FitContext, orders: ArxOrders
) -> LinearFit:
    """Output-error model with ``nf = orders.na``, started from the ARX fit of the same orders.

    Raises
    ------
    ArithmeticError
        When the search ends at an unstable model.
    """
    start = estimate_arx(experiments, context, orders)[0].model
    m = start.b.shape[0]
    shape = (m, orders.na, orders.nb, orders.nk, 0)
    theta0 = np.concatenate((start.f[1:], start.b[:, orders.nk :].ravel()))
    centred = [context.centred(e) for e in experiments]
    theta = _search(centred, theta0, shape, context.dt_s, 100 * len(theta0))
    f, b, _, _ = _unpack(theta, *shape)
    label = f"nb={orders.nb} nf={orders.na} nk={orders.nk}"
    return LinearFit("oe", label, context.model(f, b))


def fit_box_jenkins(
    experiments: Sequence[IdData], context: FitContext, orders: ArxOrders, noise_order: int = 2
) -> LinearFit:
    """Box-Jenkins model with ``nf = orders.na`` and ``nc = nd = noise_order``.

    Started from the output-error fit and an ARMA model of its residual, then all parameters
    are refined together for a bounded number of evaluations.

    Raises
    ------
    ArithmeticError
        When the search ends at an unstable model.
    """
    oe = fit_output_error(experiments, context, orders).model
    centred = [context.centred(e) for e in experiments]
    residuals = [y - oe.response(u) for u, y in centred]
    noise = _noise_model(residuals, noise_order)
    m = oe.b.shape[0]
    shape = (m, orders.na, orders.nb, orders.nk, noise_order)
    theta0 = np.concatenate((oe.f[1:], oe.b[:, orders.nk :].ravel(), noise))
    theta = _search(centred, theta0, shape, context.dt_s, 10 * len(theta0))
    f, b, c, d = _unpack(theta, *shape)
    label = f"nb={orders.nb} nf={orders.na} nk={orders.nk} nc=nd={noise_order}"
    return LinearFit("bj", label, context.model(f, b, c, d))
