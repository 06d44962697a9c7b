"""Output-error and Box-Jenkins models by prediction-error minimisation.

Output error: ``y = sum_i B_i/F u_i + e``; Box-Jenkins adds a noise model,
``y = sum_i B_i/F u_i + C/D e``. The parameters minimise the sum of squared one-step
prediction errors ``e = (D/C) (y - sum_i B_i/F u_i)`` (for output error, the simulation
error) with ``scipy.optimize.least_squares``, started from the ARX fit of the same ``nb``,
``nk`` (its ``A`` as ``F``) and zero noise coefficients. A candidate with a pole of ``1/F``
or ``1/C`` outside the unit circle gets a large constant residual, steering the search back
to stable models.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

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


def fit_prediction_error(
    experiments: Sequence[IdData],
    context: FitContext,
    structure: str,
    orders: ArxOrders,
    noise_order: int = 0,
) -> LinearFit:
    """Fit output error (``noise_order = 0``) or Box-Jenkins (``nc = nd = noise_order``).

    Raises
    ------
    ArithmeticError
        When the optimiser fails or ends at an unstable model.
    """
    start = estimate_arx(experiments, context, orders)[0].model
    m = start.b.shape[0]
    nf, nb, nk, nc = orders.na, orders.nb, orders.nk, noise_order
    theta0 = np.concatenate((start.f[1:], start.b[:, nk:].ravel(), np.zeros(2 * nc)))
    centred = [context.centred(e) for e in experiments]
    total = sum(len(y) for _, y in centred)

    def residuals(theta: FloatArray) -> FloatArray:
        f, b, c, d = _unpack(theta, m, nf, nb, nk, nc)
        if not (_stable(f) and _stable(c)):
            return np.full(total, _UNSTABLE_RESIDUAL)
        model = PolynomialModel(f=f, b=b, c=c, d=d, u0=np.zeros(m), y0_n=0.0, dt_s=context.dt_s)
        return np.concatenate([model.predict(u, y, 1) - y for u, y in centred])

    result = least_squares(
        residuals, theta0, method="trf", x_scale="jac", max_nfev=200 * len(theta0)
    )
    f, b, c, d = _unpack(result.x, m, nf, nb, nk, nc)
    if not np.all(np.isfinite(result.x)) or not (_stable(f) and _stable(c)):
        raise ArithmeticError(
            f"{structure}: prediction-error search ended at an unstable model ({result.message})"
        )
    noise = f" nc=nd={nc}" if nc else ""
    model = context.model(f, b, c, d)
    return LinearFit(structure, f"nb={nb} nf={nf} nk={nk}{noise}", model)


def fit_output_error(
    experiments: Sequence[IdData], context: FitContext, orders: ArxOrders
) -> LinearFit:
    """Output-error model with ``nf = orders.na``."""
    return fit_prediction_error(experiments, context, "oe", orders, noise_order=0)


def fit_box_jenkins(
    experiments: Sequence[IdData], context: FitContext, orders: ArxOrders, noise_order: int = 2
) -> LinearFit:
    """Box-Jenkins model with ``nf = orders.na`` and ``nc = nd = noise_order``."""
    return fit_prediction_error(experiments, context, "bj", orders, noise_order=noise_order)
