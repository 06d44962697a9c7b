"""The published estimate's values in Python floats with bounds of their error, for deciding
the status and the publisher's checks without a matrix product:
:func:`approximation`, for
:meth:`~tether_companion.estimation.dynamic.published.TickSource.approximate`.

Between two member steps the tick's estimate is the mixture stepped over the batch's ticks
(``Phi x + (D_p, D_v, 0...)``, ``Phi P Phi^T + T Q``); here the state is stepped exactly in
floats and the position block bounded: the velocity terms exactly, the bias terms by
Cauchy-Schwarz (``|P_kl| <= sd_k sd_l``), plus the rounding. The module docstring of
:mod:`~tether_companion.estimation.dynamic.published` says how the bounds are used.

Pure.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence

from tether_companion.estimation import optional_core
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.imu_batch import BatchStep
from tether_companion.estimation.dynamic.mixture import ROUNDING, MixtureValues, ProcessNoise
from tether_companion.estimation.dynamic.models import UNDEFINED, ModelConstants
from tether_companion.estimation.dynamic.output import Approximation

FINITE_BOUND = 1e150
"""Approximate magnitudes below this are the rounding of finite exact values."""


def approximation(
    mixture: MixtureValues,
    step: BatchStep | None,
    noise: ProcessNoise,
    constants: ModelConstants,
    added: Callable[[list[float]], tuple[float, ...]],
) -> tuple[Approximation, float, float] | None:
    """The tick's approximation, the bias terms' largest spread ``f`` [m] and the stepped
    covariance's largest standard deviation scale [SI], from the ``mixture`` stepped by the
    batch's ``step`` (None: not stepped) with its process ``noise``; ``added(x)``
    gives the unmodelled-force position terms (north-north, north-east, _, east-east, _,
    down-down) [m^2]. None when the mixture's arrays are not finite."""
    bounds = mixture.bounds()
    if not bounds.finite:
        return None
    x = mixture.x_values
    block, linear, quadratic = mixture.position_terms()
    if step is None:
        north, north_east, east, down = block
        t = spread = moved = offset = 0.0
        row_sum = 1.0
    else:
        t = step.duration_s
        x, north, north_east, east, down, spread, moved, row_sum, offset = STEPPED_TERMS(
            x,
            t,
            step.d_p,
            step.d_v,
            step.b_p,
            step.b_v,
            bounds.sd,
            bounds.position_sd,
            bounds.velocity_sd,
            noise.diagonal,
            linear,
            quadratic,
            block,
        )
    tension, jac = _tension_and_jacobian(constants, x)
    return APPROXIMATION_TAIL(
        x,
        t,
        north,
        north_east,
        east,
        down,
        spread,
        moved,
        row_sum,
        offset,
        bounds.largest_sd,
        bounds.largest_value,
        noise.largest,
        tension,
        jac,
        added(x),
    )


def approximation_tail(
    x: list[float],
    t: float,
    north: float,
    north_east: float,
    east: float,
    down: float,
    spread: float,
    moved: float,
    row_sum: float,
    offset: float,
    largest_sd: float,
    largest_value: float,
    noise_largest: float,
    tension: float,
    jac: Sequence[float] | None,
    added_terms: tuple[float, ...],
) -> tuple[Approximation, float, float]:
    """:func:`approximation`'s result from the stepped state ``x`` over ``t`` [s], its
    position block (``north``, ``north_east``, ``east``, ``down`` [m^2]) and
    :func:`stepped_terms`' ``spread``, ``moved``, ``row_sum`` and ``offset``; the mixture's
    largest standard deviation and ``|x_i|`` [SI], the process noise's largest [SI/s], the
    tension [N] and its Jacobian row (None: the chord tension's own variance) and the added
    position terms (north-north, north-east, _, east-east, _, down-down [m^2]).

    The reference: :data:`APPROXIMATION_TAIL` is what runs."""
    # every row of Phi has sum_k |Phi_ik| <= row_sum, so with |P_kl| <= sd_k sd_l
    # (Cauchy-Schwarz) the terms of (Phi P Phi^T)_ij are below (row_sum max sd)^2, and those
    # of the stepped state below row_sum max |x| + |(D_p, D_v)|
    largest = largest_sd * row_sum
    position_scale = largest_value * row_sum + offset
    added_nn, added_ne, _, added_ee, _, added_dd = added_terms
    north += added_nn
    north_east += added_ne
    east += added_ee
    down += added_dd
    scale = largest * largest + t * noise_largest
    scale += added_nn + added_ee + added_dd
    # the tension's variance j^T (Phi P Phi^T + T Q) j, bounded the same way
    if jac is None:
        tension_bound = largest * largest + t * noise_largest
    else:
        jac_sum = sum(map(abs, jac))
        tension_bound = (jac_sum * largest) ** 2 + t * noise_largest * jac_sum * jac_sum
    finite = (  # nan fails
        scale < FINITE_BOUND
        and tension_bound < FINITE_BOUND
        and position_scale < FINITE_BOUND
        and abs(tension) < FINITE_BOUND
    )
    approx = Approximation(
        x,
        t,
        (north, north_east, east),
        down,
        tension,
        finite,
        ROUNDING * position_scale,
        ROUNDING * scale + (1.0 + ROUNDING) * moved if finite else math.inf,
    )
    return approx, spread, largest


def _tension_and_jacobian(
    constants: ModelConstants, x: list[float]
) -> tuple[float, Sequence[float] | None]:
    """The tension at the drone [N] and its Jacobian row as
    :meth:`~tether_companion.estimation.dynamic.models.ModelConstants.tension_at_drone`
    takes them (None: the chord tension's own variance)."""
    tension = x[state.TENSION]
    tension = 0.0 if 0.0 > tension else tension  # max(tension, 0.0), nan kept
    if tension > 0.0:
        try:
            (tension,), jac = constants.models.tension(x, (), constants.values())
        except UNDEFINED:
            return tension, None
        return tension, jac
    return tension, None


def stepped_terms(
    x: list[float],
    t: float,
    d_p: Sequence[float],
    d_v: Sequence[float],
    b: Sequence[float],
    b_v: Sequence[float],
    sd: Sequence[float],
    position_sd: float,
    velocity_sd: float,
    q: Sequence[float],
    linear: Sequence[float],
    quadratic: Sequence[float],
    block: Sequence[float],
) -> tuple[list[float], float, float, float, float, float, float, float, float]:
    """The mixture's state ``x`` stepped over a batch of ``t`` [s] (``Phi x + (D_p, D_v,
    0...)``: the step's position and velocity sums ``d_p``, ``d_v`` and bias blocks ``b``,
    ``b_v``, row-major 3 x 3) and its position block ``block`` (north-north, north-east,
    east-east, down-down [m^2]) with the velocity terms ``linear`` [m^2/s], ``quadratic``
    [m^2/s^2] and the noise diagonal ``q`` [SI/s]; with the bias terms' largest spread ``f``'s
    parts: returns ``(x, north, north_east, east, down, spread, moved, row_sum, offset)``
    (:func:`approximation`'s comments say what each is). ``sd``: the standard deviations,
    ``position_sd``/``velocity_sd`` their largest over position/velocity.

    The reference: :data:`STEPPED_TERMS` is what runs."""
    north, north_east, east, down = block
    b0, b1, b2 = x[8], x[9], x[10]
    v0, v1, v2 = x[3], x[4], x[5]
    x = list(x)  # stepped: Phi x + (D_p, D_v, 0...)
    x[0] = x[0] + t * v0 + d_p[0] + (b[0] * b0 + b[1] * b1 + b[2] * b2)
    x[1] = x[1] + t * v1 + d_p[1] + (b[3] * b0 + b[4] * b1 + b[5] * b2)
    x[2] = x[2] + t * v2 + d_p[2] + (b[6] * b0 + b[7] * b1 + b[8] * b2)
    x[3] = v0 + d_v[0] + (b_v[0] * b0 + b_v[1] * b1 + b_v[2] * b2)
    x[4] = v1 + d_v[1] + (b_v[3] * b0 + b_v[4] * b1 + b_v[5] * b2)
    x[5] = v2 + d_v[2] + (b_v[6] * b0 + b_v[7] * b1 + b_v[8] * b2)
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = map(abs, b)
    s8, s9, s10 = sd[8], sd[9], sd[10]
    # Phi P Phi^T - P = the velocity terms (exact below) + the bias terms, whose
    # entries (i, j) are within f_i sd_j + f_j sd_i + T (v_i f_j + f_i v_j) + f_i f_j,
    # f_i = sum_m |B_p,im| sd_8+m (Cauchy-Schwarz: |P_kl| <= sd_k sd_l)
    f0 = a0 * s8 + a1 * s9 + a2 * s10
    f1 = a3 * s8 + a4 * s9 + a5 * s10
    f2 = a6 * s8 + a7 * s9 + a8 * s10
    # max(), min() and sum() written out as comparisons (the builtins cost ~10x a
    # comparison per call; the same floats, nan included: a later value replaces the
    # first only when greater)
    spread = f1 if f1 > f0 else f0
    f = f2 if f2 > spread else spread
    moved = f * (2.0 * (position_sd + t * velocity_sd) + f)
    row_sum = 1.0 + t + (a0 + a1 + a2 + a3 + a4 + a5 + a6 + a7 + a8)
    bv0, bv1, bv2, bv3, bv4, bv5, bv6, bv7, bv8 = map(abs, b_v)
    row_sum += bv0 + bv1 + bv2 + bv3 + bv4 + bv5 + bv6 + bv7 + bv8
    o0, o1, o2, o3, o4, o5 = map(abs, (*d_p, *d_v))
    offset = o1 if o1 > o0 else o0
    offset = o2 if o2 > offset else offset
    offset = o3 if o3 > offset else offset
    offset = o4 if o4 > offset else offset
    offset = o5 if o5 > offset else offset
    ln, lne, le, ld = linear
    qn, qne, qe, qd = quadratic
    north += t * (ln + t * qn) + t * q[0]
    north_east += t * (lne + t * qne)
    east += t * (le + t * qe) + t * q[1]
    down += t * (ld + t * qd) + t * q[2]
    return x, north, north_east, east, down, spread, moved, row_sum, offset


STEPPED_TERMS: Callable[..., tuple] = stepped_terms
""":func:`stepped_terms`, or where the optional C extension ``_bound_core`` is built (and
``TETHER_PURE_PYTHON`` is not set) its twin: the same floats, :func:`stepped_terms` called
where C could differ (``bound_core.c``)."""
CORE = optional_core.load("tether_companion.estimation.dynamic._bound_core")
"""The C extension when it runs."""
if CORE is not None:
    STEPPED_TERMS = functools.partial(CORE.stepped_terms, stepped_terms)


APPROXIMATION_TAIL: Callable[..., tuple[Approximation, float, float]] = approximation_tail
""":func:`approximation_tail`, or where ``_bound_core`` is built (and ``TETHER_PURE_PYTHON``
is not set) its twin, bound to :class:`Approximation`, :data:`ROUNDING` and
:data:`FINITE_BOUND`: the same floats and object, :func:`approximation_tail` called where C
could differ (``bound_core.c``). An extension built before the function existed leaves the
Python."""
if CORE is not None and hasattr(CORE, "approximation_tail"):
    APPROXIMATION_TAIL = functools.partial(
        CORE.approximation_tail, approximation_tail, Approximation, ROUNDING, FINITE_BOUND
    )
