"""Which members of an undecided thrust-scale bank one Gaussian represents: the mixture
reduction at ``max_bank_s`` (:meth:`~tether_companion.estimation.dynamic.bank.FilterBank.
maybe_decide`).

Why: the bank exists because one EKF started from a Gaussian that reaches where the model is
not linear linearises at its mean and can converge into a wrong, over-confident mode
(bank.py). Replacing members by their moment-matched Gaussian ``(m, P)`` is sound only where
the model is linear over them. The model's nonlinearity in the position is the cable's: its
direction ``p / |p|`` (the force balance's pull) and its chord ``|p|`` (the winch's length),
both the sphere's curvature about the anchor. A Gaussian in Cartesian NED cannot follow a
spread along that sphere: linearised at the mean, the chord of member ``i`` (position
``p_i``) is predicted as ``|p_m| + u_m . (p_i - p_m) = u_m . p_i`` (``u_m = p_m / |p_m|``),
short of the true ``|p_i|`` by the sagitta

    ``r_i = |p_i| - u_m . p_i = |p_i| (1 - cos delta_i)``   [m]

(``delta_i`` the angle at the anchor between ``p_i`` and ``p_m``; the converted-measurement
bias ``r sigma_theta^2 / 2`` of Lerro and Bar-Shalom's consistency test, member by member).
Member ``i`` resolves its chord to ``sigma_i^2 = u_i^T P_i u_i`` (``u_i = p_i / |p_i|``), so the
Gaussian represents it when the sagitta is not a significant error at that precision:
``r_i^2 / sigma_i^2`` within the chi-square quantile (1 degree of freedom) at
:data:`REPRESENT_PROBABILITY`, the level of the 95 % NEES band the covariance is judged by.
Members that differ along a chord-preserving line (the thrust scale a hover does not observe
moves the drone along the cable's sphere only as far as the members' own spread) merge;
members far apart in bearing do not (drag21: six members at -33 .. +133 deg collapsed to
+85 +- 71 deg and one EKF converged into the wrong wind, the light 5 N circle's tuning seed 7;
seed 6 the same at +130 / +31 deg). The wind and the thrust scale enter the model linearly
(the rotor drag, ``s T``) and are not tested. Where the radius is not resolved (no length:
the angle alone early) ``sigma_i`` is wide and the sets merge.

Pure.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.aid_status import chi2_threshold
from tether_companion.estimation.ekf import ExtendedKalmanFilter

FloatArray = NDArray[np.float64]


REPRESENT_PROBABILITY = 0.95
"""Probability at which a member's chord sagitta against its own chord variance is not a
significant error (chi-square, 1 degree of freedom): the 95 % of the NEES band."""


@functools.lru_cache(maxsize=1)
def threshold() -> float:
    """The chi-square quantile of :data:`REPRESENT_PROBABILITY` with 1 degree of freedom
    (3.84; made on first use: scipy.special's import)."""
    return chi2_threshold(REPRESENT_PROBABILITY, 1)


def moments(
    weights: Sequence[float], xs: Sequence[FloatArray], ps: Sequence[FloatArray]
) -> tuple[FloatArray, FloatArray]:
    """Mean (n,) and covariance (n, n) of the mixture of ``N(xs[i], ps[i])`` with
    ``weights`` (normalised here): ``sum w_i P_i + sum w_i (x_i - m)(x_i - m)^T``."""
    w = np.asarray(weights, dtype=float)
    w = w / w.sum()
    x = np.array(xs)
    mean = w @ x
    spread = x - mean
    cov = np.tensordot(w, np.array(ps), axes=1) + (spread.T * w) @ spread
    return mean, 0.5 * (cov + cov.T)


def chord_nis(mean: FloatArray, xs: Sequence[FloatArray], ps: Sequence[FloatArray]) -> list[float]:
    """Each member's chord linearisation NIS at ``mean`` (see the module docstring):
    ``r_i = |p_i| - u_m . p_i`` [m] (``= |p_i| (1 - cos delta_i)``, ``delta_i`` the angle
    between the member's and the mean's position, NED from the anchor) over the member's own
    variance along its chord, ``u_i^T P_i u_i`` [m^2]; NaN where a position is at the anchor
    (no chord direction) or that variance is not positive."""
    p_m = mean[:3]
    rho_m = math.sqrt(float(p_m @ p_m))
    out = []
    for x, p in zip(xs, ps, strict=True):
        p_i = x[:3]
        rho = math.sqrt(float(p_i @ p_i))
        if not (rho > 0.0 and rho_m > 0.0):
            out.append(math.nan)
            continue
        u = p_i / rho
        variance = float(u @ p[:3, :3] @ u)
        r = rho - float(p_m @ p_i) / rho_m
        out.append(r * r / variance if variance > 0.0 else math.nan)
    return out


def one_gaussian(
    weights: Sequence[float],
    xs: Sequence[FloatArray],
    ps: Sequence[FloatArray],
    threshold: float,
) -> tuple[FloatArray, FloatArray] | None:
    """The moments of the members ``xs``, ``ps`` with ``weights`` when one Gaussian represents
    them (every member's :func:`chord_nis` at the moments' mean within ``threshold``), else
    None (a NaN: not shown to be linear, None)."""
    mean, cov = moments(weights, xs, ps)
    if len(xs) == 1 or all(nis <= threshold for nis in chord_nis(mean, xs, ps)):
        return mean, cov
    return None


def clusters(
    weights: Sequence[float],
    xs: Sequence[FloatArray],
    ps: Sequence[FloatArray],
    threshold: float,
) -> list[tuple[list[int], tuple[FloatArray, FloatArray]]]:
    """Members grouped into sets that one Gaussian each represents (:func:`one_gaussian`),
    greedily from the heaviest: each member joins the first set (in order of creation) whose
    moments with it still pass, else starts its own. Returns each set's member indices
    (heaviest first) and moments."""
    order = sorted(range(len(weights)), key=lambda i: -weights[i])
    groups: list[tuple[list[int], tuple[FloatArray, FloatArray]]] = []
    for i in order:
        for k, (members, _) in enumerate(groups):
            trial = [*members, i]
            merged = one_gaussian(
                [weights[j] for j in trial],
                [xs[j] for j in trial],
                [ps[j] for j in trial],
                threshold,
            )
            if merged is not None:
                groups[k] = (trial, merged)
                break
        else:
            groups.append(([i], (xs[i], ps[i])))
    return groups


def reduce(
    filters: list[ExtendedKalmanFilter],
    log_weight: list[float],
    bearings: list[int],
    weights: list[float],
    drop_weight: float,
) -> tuple[list[ExtendedKalmanFilter], list[float], list[int]] | None:
    """The bank's members, log weights and bearings after the reduction (None: nothing
    dropped or merged): the members below ``drop_weight`` (normalised ``weights``) go, the
    rest form :func:`clusters`; each set of several becomes its heaviest member reset to the
    set's moments (a merge is not a restart: its reset count kept), with the set's summed
    weight. One set left: that member alone, log weight 0 and bearing 0 (decided)."""
    kept = [i for i, wi in enumerate(weights) if wi >= drop_weight]
    found = clusters(
        [weights[i] for i in kept],
        [filters[i].x for i in kept],
        [filters[i].P for i in kept],
        threshold(),
    )
    if len(found) == len(weights):
        return None
    top = max(log_weight)
    members, merged_weights, merged_bearings = [], [], []
    for indices, (mean, cov) in found:
        first = kept[indices[0]]  # the heaviest of the set
        kf = filters[first]
        if len(indices) > 1:
            resets = kf.resets
            kf.reset(mean, cov)
            kf.resets = resets
        members.append(kf)
        total = sum(math.exp(log_weight[kept[j]] - top) for j in indices)
        merged_weights.append(top + math.log(total))
        merged_bearings.append(bearings[first])
    if len(members) == 1:
        return members, [0.0], [0]
    return members, merged_weights, merged_bearings
