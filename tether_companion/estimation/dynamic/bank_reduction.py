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

While sets run on the bank re-tests them at every force-balance fusion (50 Hz), so the test is
scalar: each member's :class:`Chord` is read once, a trial set's mean position alone is formed,
and the full moments only for a set that merges.

Pure.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

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


@dataclass(frozen=True, slots=True)
class Chord:
    """What :func:`chord_nis` reads of a member: its position and how well it resolves its
    chord (computed once per reduction, not per trial set)."""

    position: tuple[float, float, float]
    """The member's position, NED from the anchor [m]."""
    length_m: float
    """``|p_i|``, the chord [m]."""
    variance_m2: float
    """``u_i^T P_i u_i`` (``u_i = p_i / |p_i|``), the member's variance along its chord [m^2];
    NaN where the position is at the anchor (no chord direction)."""


def chord(x: FloatArray, p: FloatArray) -> Chord:
    """A member's :class:`Chord` from its state (n,) and covariance (n, n)."""
    n, e, d = x[:3].tolist()
    rho = math.sqrt(n * n + e * e + d * d)
    if not rho > 0.0:
        return Chord((n, e, d), rho, math.nan)
    un, ue, ud = n / rho, e / rho, d / rho
    (pnn, pne, pnd), (pen, pee, ped), (pdn, pde, pdd) = p[:3, :3].tolist()
    variance = (
        un * (pnn * un + pne * ue + pnd * ud)
        + ue * (pen * un + pee * ue + ped * ud)
        + ud * (pdn * un + pde * ue + pdd * ud)
    )
    return Chord((n, e, d), rho, variance)


def chord_nis(mean_position: Sequence[float], chords: Sequence[Chord]) -> list[float]:
    """Each member's chord linearisation NIS at the position ``mean_position`` (NED from the
    anchor [m]; see the module docstring): ``r_i = |p_i| - u_m . p_i`` [m] (``= |p_i| (1 - cos
    delta_i)``, ``delta_i`` the angle at the anchor between the member's and the mean's
    position) over the member's own variance along its chord [m^2]; NaN where a position is at
    the anchor (no chord direction) or that variance is not positive."""
    mn, me, md = mean_position
    rho_m = math.sqrt(mn * mn + me * me + md * md)
    out = []
    for c in chords:
        variance = c.variance_m2
        if not (rho_m > 0.0 and variance > 0.0):  # NaN too
            out.append(math.nan)
            continue
        pn, pe, pd = c.position
        r = c.length_m - (mn * pn + me * pe + md * pd) / rho_m
        out.append(r * r / variance)
    return out


def one_gaussian(weights: Sequence[float], chords: Sequence[Chord], threshold: float) -> bool:
    """Whether one Gaussian represents the members ``chords`` with ``weights``: every member's
    :func:`chord_nis` at the weighted mean position within ``threshold`` (a NaN: not shown to
    be linear, False). Only the mean position is computed here; the set's moments
    (:func:`moments`) when it is merged."""
    if len(chords) == 1:
        return True
    total = sum(weights)
    mn = me = md = 0.0
    for w, c in zip(weights, chords, strict=True):
        share = w / total
        pn, pe, pd = c.position
        mn += share * pn
        me += share * pe
        md += share * pd
    return all(nis <= threshold for nis in chord_nis((mn, me, md), chords))


def clusters(
    weights: Sequence[float], chords: Sequence[Chord], threshold: float
) -> list[list[int]]:
    """Members grouped into sets that one Gaussian each represents (:func:`one_gaussian`),
    greedily from the heaviest: each member joins the first set (in order of creation) that
    still passes with it, else starts its own. Returns each set's member indices (heaviest
    first)."""
    order = sorted(range(len(weights)), key=lambda i: -weights[i])
    groups: list[list[int]] = []
    for i in order:
        for members in groups:
            trial = [*members, i]
            if one_gaussian([weights[j] for j in trial], [chords[j] for j in trial], threshold):
                members.append(i)
                break
        else:
            groups.append([i])
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
    set's :func:`moments` (a merge is not a restart: its reset count kept), with the set's
    summed weight. One set left: that member alone, log weight 0 and bearing 0 (decided)."""
    kept = [i for i, wi in enumerate(weights) if wi >= drop_weight]
    found = clusters(
        [weights[i] for i in kept], [chord(filters[i].x, filters[i].P) for i in kept], threshold()
    )
    if len(found) == len(weights):
        return None
    top = max(log_weight)
    members, merged_weights, merged_bearings = [], [], []
    for indices in found:
        first = kept[indices[0]]  # the heaviest of the set
        kf = filters[first]
        if len(indices) > 1:
            mean, cov = moments(
                [weights[kept[j]] for j in indices],
                [filters[kept[j]].x for j in indices],
                [filters[kept[j]].P for j in indices],
            )
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
