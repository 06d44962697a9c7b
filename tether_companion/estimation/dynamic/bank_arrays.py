"""The filter bank's members' arrays stacked for one update: the helpers of
:class:`~tether_companion.estimation.dynamic.bank.FilterBank`'s updates (stacking, products,
the finiteness and Cholesky test, the innovation's log-determinant). Pure and synchronous."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.lapack import dpotrf

FloatArray = NDArray[np.float64]


def log_det_innovation(p: FloatArray, h_jac: FloatArray, r: FloatArray) -> float:
    """``log det (H P H^T + R)`` (``nan`` when not positive definite or not finite)."""
    s = h_jac @ p @ h_jac.T + r
    if not np.all(np.isfinite(s)):
        return math.nan
    chol, info = dpotrf(s, lower=1, clean=0)
    if info != 0:
        return math.nan
    return 2.0 * float(np.log(np.diag(chol)).sum())


EMPTY = np.empty


def sum_all(array: FloatArray) -> float:
    """The sum of every entry (``ndarray.sum()``'s reduction without its method wrapper)."""
    return _ADD_REDUCE(array, None)  # type: ignore[no-any-return]


_ADD_REDUCE = np.add.reduce


def stack_members(arrays: list[FloatArray]) -> FloatArray:
    """The members' arrays stacked along a new first axis; one member: its own array (no
    copy, no new axis: its products go through ``np.dot``, :func:`product`)."""
    return arrays[0] if len(arrays) == 1 else np.array(arrays)


def each_member(arrays: FloatArray, one: bool) -> tuple[FloatArray] | FloatArray:
    """Each member's array of what :func:`stack_members` made (``one``: of one member, its own)."""
    return (arrays,) if one else arrays


def apply_each(p: FloatArray, v: FloatArray) -> FloatArray:
    """``P v`` for each member: ``p`` (..., n, m) by ``v`` (..., m) (one member: ``np.dot``,
    :func:`~tether_companion.estimation.dynamic.imu_batch.product`)."""
    if p.ndim == 2:
        return _DOT(p, v)  # type: ignore[no-any-return]
    return (p @ v[:, :, None])[:, :, 0]


_DOT = np.dot


def finite_and_definite(xs: FloatArray, ps: FloatArray) -> bool:
    """Whether the states (m, n) and covariances (m, n, n) are all finite and every
    covariance passes the Cholesky test."""
    if not math.isfinite(sum_all(xs) + sum_all(ps)):
        return False
    return all(dpotrf(p, lower=1, clean=0)[1] == 0 for p in each_member(ps, ps.ndim == 2))
