"""ARX: ``A(q) y = sum_i B_i(q) u_i(t - nk) + e`` by linear least squares, with order selection.

The paper's preferred structure (Appendix A: na = 2, nb = 2, nk = 1 for four PWM inputs).
Least squares gives the global minimum of the one-step prediction error in closed form.
Orders are chosen by Rissanen's minimum description length on the estimation data,
``V (1 + d ln N / N)``, which penalises parameters harder than Akaike's criterion.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.sysid.processing import IdData
from tether_companion.sysid.structures.base import FitContext, LinearFit

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ArxOrders:
    """``na`` output lags, ``nb`` taps per input, ``nk`` input delay [samples]."""

    na: int
    nb: int
    nk: int

    def __str__(self) -> str:
        return f"na={self.na} nb={self.nb} nk={self.nk}"


ORDER_GRID = tuple(
    ArxOrders(na, nb, nk) for na, nb, nk in itertools.product(range(1, 5), range(1, 5), range(0, 3))
)
"""Candidate orders searched by :func:`fit_arx` when none is given."""


def regression(u: FloatArray, y: FloatArray, orders: ArxOrders) -> tuple[FloatArray, FloatArray]:
    """Regressor matrix and target of one experiment.

    Parameters
    ----------
    u
        Inputs, shape (n, m). y : outputs, shape (n,).

    Returns
    -------
    phi : shape (n - start, na + m nb), rows ``[-y(t-1..t-na), u_i(t-nk..t-nk-nb+1) ...]``
    target : shape (n - start,)
    """
    start = max(orders.na, orders.nk + orders.nb - 1)
    n = y.shape[0]
    columns = [-y[start - j : n - j] for j in range(1, orders.na + 1)]
    for i in range(u.shape[1]):
        columns += [u[start - orders.nk - j : n - orders.nk - j, i] for j in range(orders.nb)]
    return np.column_stack(columns), y[start:]


def estimate_arx(
    experiments: Sequence[IdData], context: FitContext, orders: ArxOrders
) -> tuple[LinearFit, float, int]:
    """Least-squares ARX of the given orders.

    Returns
    -------
    fit, loss, n_samples
        The model, mean squared one-step error on the estimation data [N^2], sample count.
    """
    pieces = [regression(*context.centred(e), orders) for e in experiments]
    phi = np.vstack([p[0] for p in pieces])
    target = np.concatenate([p[1] for p in pieces])
    theta, *_ = np.linalg.lstsq(phi, target, rcond=None)
    loss = float(np.mean((target - phi @ theta) ** 2))
    m = len(context.u0)
    a = np.concatenate(([1.0], theta[: orders.na]))
    b = np.zeros((m, orders.nk + orders.nb))
    b[:, orders.nk :] = theta[orders.na :].reshape(m, orders.nb)
    model = context.model(a, b, d=a)
    return LinearFit("arx", str(orders), model), loss, target.shape[0]


def fit_arx(
    experiments: Sequence[IdData], context: FitContext, orders: ArxOrders | None = None
) -> LinearFit:
    """ARX of the given orders, or of the orders in :data:`ORDER_GRID` with least MDL."""
    if orders is not None:
        return estimate_arx(experiments, context, orders)[0]
    best: tuple[float, LinearFit] | None = None
    for candidate in ORDER_GRID:
        fit, loss, n = estimate_arx(experiments, context, candidate)
        if not fit.model.is_stable():
            continue
        mdl = loss * (1.0 + fit.n_params * math.log(n) / n)
        if best is None or mdl < best[0]:
            best = (mdl, fit)
    if best is None:
        raise ArithmeticError("no stable ARX model among the candidate orders")
    return best[1]
