"""A heavy cable's elevation at the anchor is a hinge: the censored (Tobit) reading, fused as
its moment-matched pseudo reading. Pure.

Where a cable with weight rests on the ground it leaves the anchor flat, whatever the drone's
range beyond the touchdown; where it hangs free its elevation at the anchor rises with the
free catenary's, ``u(x)`` (derive.py; negative where that curve would dip below the anchor's
level, i.e. where the cable rests). The sensor reads ``z = e0 + max(u, 0) + v`` (``e0`` the
elevation zero, ``v ~ N(0, r)``). A reading near ``e0`` (flat) therefore says only
``u <= 0``: the drone is at or beyond the touchdown distance of the state's tension. Fused
as the free curve's ``z = e0 + u`` it puts the state ON the kink (``u = 0``) with the
reading's noise, ``r / (du/dx)^2`` ~ (0.01 rad / 0.25 rad/m)^2, wherever beyond it the truth
is: on the heavy 5 N winch figure-8 (angle alone, tuning seed 7, 1.0 s) one flat reading
took the best member's radial deviation 2.1 -> 0.14 m with the drone 1.4 m beyond
(docs/estimation.md, angle21).

With the state Gaussian and the free elevation linearised, ``t = e0 + u`` is Gaussian,
``N(m, s)`` (``s = J P J^T``). Two pieces, with the hinge at the zero's mean ``e``:

* resting (``t < e``): the prior of ``t`` truncated above at ``e``; the reading is the zero's,
  likelihood ``N(z; e, r + var e0)``, times ``Phi((e - m)/sqrt(s))``;
* free (``t > e``): the Kalman posterior ``N(m_f, s_f)`` (``s_f = s r/(s + r)``,
  ``m_f = m + s (z - m)/(s + r)``) truncated below at ``e``; likelihood
  ``N(z; m, s + r)`` times ``Phi((m_f - e)/sqrt(s_f))``.

Their mixture's mean ``m'`` and variance ``s'`` of ``t`` move the state as conditioning on
``t`` does (``x' = x + P J^T (m' - m)/s``, ``P' = P - P J^T J P (s - s')/s^2``): a Kalman
update with the pseudo reading ``m + (m' - m) s/(s - s')`` of variance ``s s'/(s - s')``
(:func:`pseudo_reading`), so the member's own update (gate, consider hold, checks) runs it.
Far from the hinge it is the free reading itself (``r``, ``z``); a flat reading with the
state far inside the resting side moves nothing. The resting piece's reading would also
measure ``e0``; that is left out (the zero's learning there is the resting model's, used
where the member's state rests: :class:`~.cable_angle.CableAngleAid`).
"""

from __future__ import annotations

import math

from tether_companion.estimation.dynamic.truncation import inverse_mills

_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)
_SQRT_HALF = math.sqrt(0.5)
NO_INFORMATION = 1e12
"""A pseudo reading's variance over the prior's ``s`` that moves nothing (a finite stand-in
for an infinite variance in the member's 2 x 2 update)."""


def _log_phi_cdf(beta: float) -> float:
    """``log Phi(beta)`` of the standard normal, without underflow: ``log(phi / lambda)``
    below 0 (the lower tail), ``log1p(-Phi(-beta))`` above."""
    if beta > 0.0:
        return math.log1p(-0.5 * math.erfc(beta * _SQRT_HALF))
    return -0.5 * beta * beta - _LOG_SQRT_2PI - math.log(inverse_mills(beta))


def _truncated_above(mean: float, variance: float, bound: float) -> tuple[float, float, float]:
    """``(log P(t < bound), E[t | t < bound], Var[t | t < bound])`` of ``t ~ N(mean,
    variance)`` (truncation.py's moments)."""
    sd = math.sqrt(variance)
    beta = (bound - mean) / sd
    lam = inverse_mills(beta)
    kappa = min(max(lam * (beta + lam), 0.0), 1.0)
    return _log_phi_cdf(beta), mean - sd * lam, variance * (1.0 - kappa)


def _truncated_below(mean: float, variance: float, bound: float) -> tuple[float, float, float]:
    """``(log P(t > bound), E[t | t > bound], Var[t | t > bound])`` of ``t ~ N(mean,
    variance)`` (the mirror image of :func:`_truncated_above`)."""
    log_p, mirrored, var = _truncated_above(-mean, variance, -bound)
    return log_p, -mirrored, var


def _log_normal(y: float, variance: float) -> float:
    """``log N(y; 0, variance)`` without its ``-log sqrt(2 pi)`` (the bank's convention,
    :meth:`~tether_companion.estimation.dynamic.bank.FilterBank.add_evidence`)."""
    return -0.5 * y * y / variance - 0.5 * math.log(variance)


def hinge_moments(
    z: float, m: float, s: float, r: float, hinge: float, r_flat: float
) -> tuple[float, float, float]:
    """``(m', s', log L)``: the mean and variance of ``t ~ N(m, s)`` [rad, rad^2] given the
    reading ``z`` [rad] of noise ``r`` [rad^2] where ``t > hinge`` and of the resting
    cable, ``N(hinge, r_flat)``, where ``t < hinge`` (module docstring), and the reading's
    log-likelihood (without the ``2 pi`` term)."""
    log_rest, mean_rest, var_rest = _truncated_above(m, s, hinge)
    log_rest += _log_normal(z - hinge, r_flat)
    s_free = s * r / (s + r)
    m_free = m + s * (z - m) / (s + r)
    log_free, mean_free, var_free = _truncated_below(m_free, s_free, hinge)
    log_free += _log_normal(z - m, s + r)
    top = max(log_rest, log_free)
    w_rest, w_free = math.exp(log_rest - top), math.exp(log_free - top)
    total = w_rest + w_free
    w_rest, w_free = w_rest / total, w_free / total
    mean = w_rest * mean_rest + w_free * mean_free
    variance = w_rest * (var_rest + (mean_rest - mean) ** 2) + w_free * (
        var_free + (mean_free - mean) ** 2
    )
    return mean, variance, top + math.log(total)


def pseudo_reading(
    z: float, m: float, s: float, r: float, hinge: float, r_flat: float
) -> tuple[float, float, float]:
    """``(z*, r*, log L)``: the reading [rad] and its noise variance [rad^2] whose Kalman
    update of ``t ~ N(m, s)`` gives :func:`hinge_moments`' mean and variance (module
    docstring), and the reading's log-likelihood. ``r*`` is vast (no update) where the
    mixture is not narrower than the prior: :data:`NO_INFORMATION` times ``s`` then)."""
    mean, variance, log_likelihood = hinge_moments(z, m, s, r, hinge, r_flat)
    narrowed = s - variance
    if not narrowed > s / NO_INFORMATION:
        return m, NO_INFORMATION * s, log_likelihood
    return m + (mean - m) * s / narrowed, s * variance / narrowed, log_likelihood
