"""An upper bound fused as what it is: the Gaussian prior truncated to the bound, moment-matched.

A reading that says only ``g <= z`` (``g = h(x) + v``, ``v ~ N(0, r)``: the straight chord of
a cable that may be slack is no longer than the length paid out, as the encoder reads it)
is not a measurement of ``h``: fused as ``g = z`` it puts the state ON the bound with the
reading's noise, wherever the truth is inside it. With the state Gaussian, ``g`` is Gaussian
with mean ``m = h(x)`` and variance ``s = H P H^T + r``; the prior conditioned on ``g <= z`` has
``g`` truncated at ``z`` (``beta = (z - m) / sqrt(s)``, ``lambda = phi(beta) / Phi(beta)``,
the inverse Mills ratio):

    E[g | g <= z]   = m - sqrt(s) lambda
    Var[g | g <= z] = s (1 - kappa),   kappa = lambda (beta + lambda)  in (0, 1)

and the state, jointly Gaussian with ``g`` (cross-covariance ``P H^T``), moves with it:
``x' = x + P H^T (E[g|.] - m) / s``, ``P' = P - P H^T H P kappa / s`` (Simon and Simon,
"Constrained Kalman filtering via density function truncation", 2010). That is a Kalman
update with the pseudo innovation ``y* = -sqrt(s) / (beta + lambda)`` and innovation variance
``s* = s / kappa`` (:func:`pseudo_measurement`), so every member's own update (gain, consider
hold, checks) runs it unchanged. The reading's likelihood under a member's prior is
``Phi(beta)`` (:func:`log_probability_within`), not a Gaussian density.

Far beyond the bound (``beta -> -inf``) the truncated ``g`` sits at the bound with spread
``sqrt(s) / |beta|``; at ``beta = 0`` it is ``m - 0.80 sqrt(s)`` with ``0.60 sqrt(s)``; far inside
the prior is unchanged."""

from __future__ import annotations

import math

_SQRT_HALF = math.sqrt(0.5)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)


def inverse_mills(beta: float) -> float:
    """``phi(beta) / Phi(beta)`` of the standard normal (> 0): the truncated mean's shift in
    standard deviations for a bound ``beta`` standard deviations above the mean; the
    asymptotic series where ``Phi`` underflows (``beta < -37``)."""
    tail = 0.5 * math.erfc(-beta * _SQRT_HALF)
    if tail > 0.0:
        return _INV_SQRT_2PI * math.exp(-0.5 * beta * beta) / tail
    inv2 = 1.0 / (beta * beta)
    return -beta / (1.0 - inv2 + 3.0 * inv2 * inv2)


def pseudo_measurement(innovation: float, variance: float) -> tuple[float, float]:
    """The Kalman update's innovation and innovation variance that move a Gaussian state as
    conditioning it on ``g <= z`` does, for ``innovation = z - m`` [the measurement's unit]
    and ``variance = s = H P H^T + r`` > 0 of ``g``: ``(-sqrt(s) / (beta + lambda),
    s / kappa)``. ``kappa`` may underflow to 0 far inside the bound (``beta > 37``): then
    ``(0, inf)``, no update."""
    sd = math.sqrt(variance)
    beta = innovation / sd
    lam = inverse_mills(beta)
    kappa = lam * (beta + lam)
    if not kappa > 0.0:
        return 0.0, math.inf
    return -sd / (beta + lam), variance / min(kappa, 1.0)


def log_probability_within(innovation: float, variance: float) -> float:
    """``log Phi(beta)``: the log-probability under the prior that ``g <= z`` (the bound's
    likelihood for a member's weight), ``innovation = z - m``, ``variance = s``."""
    beta = innovation / math.sqrt(variance)
    tail = 0.5 * math.erfc(-beta * _SQRT_HALF)
    if tail > 0.0:
        return math.log(tail)
    return -0.5 * beta * beta - math.log(-beta) - 0.5 * math.log(2.0 * math.pi)
