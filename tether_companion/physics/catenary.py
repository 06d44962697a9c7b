"""Catenary geometry of a tether sagging under its own weight (Martins 2019, sections 3 and 6).

All functions are pure. They work in the vertical plane through the anchor and the drone:
``x`` is the horizontal coordinate from the anchor toward the drone [m], ``y`` is the height
[m] (up), and the anchor is the origin ``(0, 0)``. The drone sits at ``(horizontal_m,
height_m)`` with ``horizontal_m >= 0``. The cable is a catenary (eq. 7)::

    y(x) = a cosh((x - x0) / a) + c

with ``a > 0`` the catenary parameter (horizontal tension over weight per length, eq. 11),
``x0`` the abscissa of the lowest point (possibly outside ``[0, horizontal_m]``), and ``c``
the vertical offset (the lowest point is at height ``a + c``, eq. 8).

Arc lengths are SIGNED (unlike the thesis' eqs. 9-10, which use ``|x - x0|``): the arc
coordinate of a point is ``s(x) = a sinh((x - x0) / a)``, measured from the lowest point and
positive toward the drone. ``s1_m = s(0)`` (anchor) is negative when the lowest point lies
between the ends; ``s2_m = s(horizontal_m)`` (drone) is negative when the drone lies before
the lowest point (drone below the anchor and the cable still descending). The cable length is
always ``s2_m - s1_m``, and the end tensions follow without case analysis (``end_tensions``).
docs/catenary.md lists where and why this departs from the printed equations.

Two ways to fix the third unknown (the thesis' two cases):

- :func:`solve_lowest_point_at_anchor` (case 1, eqs. 18-25): ``x0 = 0``, the length follows;
- :func:`solve_known_length` (case 2, eqs. 26-39): the total length is given.

Both use Newton-Raphson from the thesis' Taylor-series initial guess, kept inside a bracket
(a step that leaves the bracket is replaced by a bisection), so they converge for every valid
input. Near-vertical tethers (horizontal span below :data:`VERTICAL_RELATIVE_SPAN` of the
length scale) use the ``a -> 0`` limits (eqs. 63-64, 70-71) and return ``a_m = 0``.

The end tensions, the inverse problems of section 6 (the curve from the tension the cable
applies to the drone) and the force in the NED world frame are in
:mod:`tether_companion.physics.catenary_forces`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

VERTICAL_RELATIVE_SPAN: float = 1e-9
"""Horizontal span, relative to the length scale, below which the tether is treated as
vertical (``a -> 0`` limit). The true ``a`` is then below ``1e-9`` of the length scale, so the
limit's error in tensions and positions is below that relative size as well."""

_MAX_ITERATIONS = 200
_LOG_TOLERANCE = 4.0 * float(np.finfo(float).eps)
_LN2 = math.log(2.0)
_LN4 = math.log(4.0)


@dataclass(frozen=True, slots=True)
class CatenaryCurve:
    """A catenary ``y = a cosh((x - x0)/a) + c`` between the anchor (0, 0) and the drone.

    Attributes
    ----------
    a_m
        Catenary parameter [m], ``>= 0``: horizontal tension / weight per length. ``0`` is the
        vertical limit (both strands vertical, no horizontal tension).
    x0_m
        Horizontal coordinate of the lowest point [m] (anywhere on the real line).
    c_m
        Vertical offset [m]; the lowest point is at height ``a_m + c_m``.
    s1_m
        Signed arc coordinate of the anchor, measured from the lowest point, positive toward
        the drone [m].
    s2_m
        Signed arc coordinate of the drone [m]. ``length_m = s2_m - s1_m``.
    """

    a_m: float
    x0_m: float
    c_m: float
    s1_m: float
    s2_m: float

    @property
    def length_m(self) -> float:
        """Cable length between anchor and drone [m]."""
        return self.s2_m - self.s1_m

    @property
    def lowest_point_height_m(self) -> float:
        """Height of the lowest point of the (extended) curve above the anchor [m].

        ``a + c``, computed as ``y(x0) - y(0) = -2 a sinh^2(x0 / 2a)`` (no cancellation when
        ``a`` is large); for the vertical limit it is ``c``.
        """
        if self.a_m == 0.0:
            return self.c_m
        return -2.0 * self.a_m * math.sinh(0.5 * self.x0_m / self.a_m) ** 2

    def height_at_m(self, x_m: ArrayLike) -> FloatArray:
        """Height ``y(x)`` [m] of the curve at horizontal coordinates ``x_m`` [m] (eq. 7).

        Raises
        ------
        ValueError
            For the vertical limit (``a_m == 0``), which is not a function of ``x``.
        """
        if self.a_m == 0.0:
            raise ValueError("a vertical tether (a = 0) has no height as a function of x")
        x = np.asarray(x_m, dtype=float)
        # y(x) - y(0) = a (cosh((x - x0)/a) - cosh(x0/a)) as a product: no cancellation.
        a = self.a_m
        return 2.0 * a * np.sinh((0.5 * x - self.x0_m) / a) * np.sinh(0.5 * x / a)


@dataclass(frozen=True, slots=True)
class EndTensions:
    """Forces at the two ends of a catenary (Martins 2019 eqs. 11-13), in the curve's plane.

    Horizontal components point along +x (anchor toward drone), vertical ones up [N].

    Attributes
    ----------
    horizontal_n
        Horizontal tension ``w a`` [N], the same all along the cable (eq. 11).
    on_anchor_vertical_n
        Vertical force the cable applies to the anchor, ``w s1`` [N] (eq. 12, signed).
    on_drone_vertical_n
        Vertical force the cable applies to the drone, ``-w s2`` [N] (eq. 12, signed).
    anchor_n, drone_n
        Tension magnitudes at the anchor and at the drone, ``w sqrt(a^2 + s^2)`` [N] (eq. 13).
    """

    horizontal_n: float
    on_anchor_vertical_n: float
    on_drone_vertical_n: float
    anchor_n: float
    drone_n: float

    @property
    def on_drone_horizontal_n(self) -> float:
        """Horizontal force on the drone [N], along +x: ``-w a`` (toward the anchor)."""
        return -self.horizontal_n

    @property
    def on_anchor_horizontal_n(self) -> float:
        """Horizontal force on the anchor [N], along +x: ``+w a`` (toward the drone)."""
        return self.horizontal_n


# ---------------------------------------------------------------------------------------------
# validation


def check_finite(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return value


def _check_endpoint(horizontal_m: float, height_m: float) -> tuple[float, float]:
    horizontal_m = check_finite("horizontal_m", horizontal_m)
    height_m = check_finite("height_m", height_m)
    if horizontal_m < 0.0:
        raise ValueError(f"horizontal_m is a distance and must be >= 0, got {horizontal_m!r}")
    return horizontal_m, height_m


def check_weight(weight_per_length_n_per_m: float) -> float:
    w = check_finite("weight_per_length_n_per_m", weight_per_length_n_per_m)
    if w <= 0.0:
        raise ValueError(f"weight_per_length_n_per_m must be > 0, got {w!r}")
    return w


# ---------------------------------------------------------------------------------------------
# numerics shared by both cases


def _sinh_minus_identity(k: float) -> float:
    """``sinh(k) - k`` without cancellation for small ``k`` (series up to k^9)."""
    if abs(k) < 0.1:
        k2 = k * k
        return k * k2 * (1.0 / 6.0 + k2 * (1.0 / 120.0 + k2 * (1.0 / 5040.0 + k2 / 362880.0)))
    return math.sinh(k) - k


def _log_sinh(z: float) -> float:
    """``ln(sinh(z))`` for ``z > 0`` without overflow."""
    if z < 1.0:
        return math.log(math.sinh(z))
    return z + math.log1p(-math.exp(-2.0 * z)) - _LN2


def _newton_in_bracket(residual: Callable[[float], tuple[float, float]], a_guess_m: float) -> float:
    """Root ``a > 0`` of an equation written as ``G(t) = 0`` in ``t = ln(a)``.

    ``residual(t)`` returns ``(G(t), dG/dt)``; ``G`` must increase with ``t`` and change sign.
    Newton-Raphson starts from the thesis' Taylor estimate ``a_guess_m``. A bracket is grown
    geometrically around it first, and a Newton step that would leave the bracket is replaced
    by a bisection: the safeguard the thesis leaves to a good initial guess alone ("this
    method does not guarantee the convergence"). Working in ``ln(a)`` on the logarithm of the
    thesis' equations keeps the step well scaled both when ``a`` is large (near-straight
    cable, polynomial regime) and when it is small (steep cable, where ``cosh(x/a)``
    dominates and a plain Newton step in ``a`` advances only by about ``a^2/x`` per iteration).
    """
    t = math.log(a_guess_m) if (math.isfinite(a_guess_m) and a_guess_m > 0.0) else 0.0
    g, dg = residual(t)  # evaluated once at the start: both bracket tests and step 1 use it
    lo = hi = t
    g_end = g
    while g_end > 0.0:
        lo -= _LN4
        g_end = residual(lo)[0]
    g_end = g
    while g_end < 0.0:
        hi += _LN4
        g_end = residual(hi)[0]
    for iteration in range(_MAX_ITERATIONS):
        if iteration:
            g, dg = residual(t)
        if g == 0.0:
            break
        if g < 0.0:
            lo = t
        else:
            hi = t
        t_new = t - g / dg if dg > 0.0 else math.nan
        if not (lo <= t_new <= hi):
            t_new = 0.5 * (lo + hi)
        converged = abs(t_new - t) <= _LOG_TOLERANCE or hi - lo <= _LOG_TOLERANCE
        t = t_new
        if converged:
            break
    return math.exp(t)


def _cardano_real_root(alpha: float, beta: float, gamma: float) -> float:
    """The real root of ``x^3 + alpha x^2 + beta x + gamma = 0`` when it has exactly one.

    Cardano's formula (eqs. 22-24) with the depressed cubic ``y^3 + p y + q = 0``,
    ``x = y - alpha/3``. With a positive discriminant ``q^2/4 + p^3/27`` there is one real
    root and the two cube roots must be taken REAL (``numpy.cbrt``; Python's ``** (1/3)`` of
    a negative number is a complex principal root). The second cube root is computed as
    ``-p / (3 u)`` to avoid cancellation.
    """
    p = beta - alpha * alpha / 3.0
    q = gamma + 2.0 * alpha**3 / 27.0 - alpha * beta / 3.0
    disc = q * q / 4.0 + p**3 / 27.0
    # the two terms can nearly cancel: a discriminant within rounding of zero counts as zero
    if disc < -1e-12 * (q * q / 4.0 + abs(p**3) / 27.0):
        raise ValueError("cubic has three real roots; Cardano's single-root form does not apply")
    root = math.sqrt(max(disc, 0.0))
    big = -q / 2.0 + math.copysign(root, -q / 2.0) if q != 0.0 else root
    u = float(np.cbrt(big))
    y = u - p / (3.0 * u) if u != 0.0 else 0.0
    return y - alpha / 3.0


# ---------------------------------------------------------------------------------------------
# case 1: lowest point at the anchor


def initial_guess_lowest_point_at_anchor(horizontal_m: float, height_m: float) -> float:
    """Cardano initial guess of ``a`` [m] for case 1 (eqs. 21-25).

    The 4th-order Taylor form of eq. 20, ``dy - x^2/(2a) - x^4/(24 a^3) = 0``, times
    ``a^3/dy`` is ``a^3 + alpha a^2 + gamma = 0`` with ``alpha = -x^2/(2 dy)``, ``beta = 0``,
    ``gamma = -x^4/(24 dy)``. (The thesis prints ``alpha`` and ``gamma`` positive, which has no
    positive root; see docs/catenary.md.) Its discriminant is positive: one real root.
    """
    alpha = -(horizontal_m**2) / (2.0 * height_m)
    gamma = -(horizontal_m**4) / (24.0 * height_m)
    return _cardano_real_root(alpha, 0.0, gamma)


def solve_lowest_point_at_anchor(horizontal_m: float, height_m: float) -> CatenaryCurve:
    """Case 1 (Martins 2019, section 3.2): the lowest point of the tether is at the anchor.

    Solves eq. 20, ``f(a) = dy - (a cosh(x2/a) - a) = 0``, by Newton-Raphson from the Cardano
    initial guess (eqs. 21-25); then ``x0 = 0`` (eq. 18) and ``c = -a`` (eq. 19).

    Parameters
    ----------
    horizontal_m
        Horizontal distance from the anchor to the drone [m], ``>= 0``.
    height_m
        Height of the drone above the anchor [m]; must be ``> 0`` (the whole cable rises from
        its lowest point, the anchor).

    Returns
    -------
    CatenaryCurve
        With ``x0_m = 0``, ``c_m = -a_m``, ``s1_m = 0`` and ``s2_m`` the cable length. A
        near-vertical tether (``horizontal_m <= VERTICAL_RELATIVE_SPAN * height_m``) gives the
        limit ``a_m = 0``, ``s2_m = height_m`` (eqs. 63-64).

    Raises
    ------
    ValueError
        Non-finite input, ``horizontal_m < 0``, or ``height_m <= 0`` (a cable whose lowest
        point is the anchor cannot reach a drone at or below the anchor's height with a finite
        tension).
    """
    x, dy = _check_endpoint(horizontal_m, height_m)
    if dy <= 0.0:
        raise ValueError(
            f"height_m must be > 0 when the lowest point is at the anchor, got {dy!r} "
            "(the drone must be above the anchor)"
        )
    return lowest_point_at_anchor(x, dy)


def lowest_point_at_anchor(x: float, dy: float) -> CatenaryCurve:
    """:func:`solve_lowest_point_at_anchor` without its input checks, for callers whose
    horizontal distance ``x >= 0`` [m] and height ``dy > 0`` [m] are finite floats by
    construction (a root search over the touchdown point calls it a dozen times a force)."""
    if x <= VERTICAL_RELATIVE_SPAN * dy:
        return CatenaryCurve(a_m=0.0, x0_m=0.0, c_m=0.0, s1_m=0.0, s2_m=dy)

    log_ratio = math.log(dy / x)

    def residual(t: float) -> tuple[float, float]:
        # eq. 20 as ln(dy/x) = ln((cosh(k) - 1)/k) = ln(2 sinh^2(k/2) / k), k = x/a = x e^-t
        k = x * math.exp(-t)
        g = log_ratio - (2.0 * _log_sinh(0.5 * k) + _LN2 - math.log(k))
        dg = k / math.tanh(0.5 * k) - 1.0
        return g, dg

    a = _newton_in_bracket(residual, initial_guess_lowest_point_at_anchor(x, dy))
    return CatenaryCurve(a_m=a, x0_m=0.0, c_m=-a, s1_m=0.0, s2_m=a * math.sinh(x / a))


# ---------------------------------------------------------------------------------------------
# case 2: known length


def initial_guess_known_length(horizontal_m: float, height_m: float, length_m: float) -> float:
    """Quadratic initial guess of ``a`` [m] for case 2 (eqs. 35-39).

    The 5th-order Taylor form of eq. 34 is ``A a^4 + B a^2 + C = 0`` with
    ``A = dY / (2 sinh(atanh(dY/L))) - dx = sqrt(L^2 - dY^2)/2 - dx`` (the level limit
    ``dY -> 0`` is ``L/2 - dx``), ``B = -dx^3/3!``, ``C = -dx^5/5!`` and ``dx`` half the
    horizontal span. ``A > 0`` and ``C < 0``, so exactly one root ``alpha = a^2`` is positive;
    ``a = sqrt(alpha)`` (eq. 39).
    """
    excess = _excess_over_span(horizontal_m, height_m, length_m)
    return _guess_known_length(0.5 * horizontal_m, excess)


def _guess_known_length(half_span: float, excess_m: float) -> float:
    """:func:`initial_guess_known_length` from half the span [m] and ``sqrt(L^2 - dY^2) -
    span`` [m] (:func:`_excess_over_span`)."""
    a_coef = 0.5 * excess_m
    b_coef = -(half_span**3) / 6.0
    c_coef = -(half_span**5) / 120.0
    disc = b_coef * b_coef - 4.0 * a_coef * c_coef
    # Positive root of A alpha^2 + B alpha + C; written as 2C / (-B - sqrt(disc)) (same value,
    # no cancellation since -B > 0).
    alpha = 2.0 * c_coef / (-b_coef - math.sqrt(disc))
    return math.sqrt(alpha)


def _excess_over_span(horizontal_m: float, height_m: float, length_m: float) -> float:
    """``sqrt(L^2 - dY^2) - span`` [m] computed without cancellation (> 0 iff L > chord)."""
    # L^2 - chord^2 = (L - m)(L + m) - n^2 with m the larger leg: L - m is exact for a nearly
    # taut cable (Sterbenz), so the slack survives rounding of the chord
    major, minor = max(horizontal_m, abs(height_m)), min(horizontal_m, abs(height_m))
    length_sq_minus_chord_sq = (length_m - major) * (length_m + major) - minor * minor
    level_length = math.sqrt((length_m - abs(height_m)) * (length_m + abs(height_m)))
    return length_sq_minus_chord_sq / (level_length + horizontal_m)


def solve_known_length(horizontal_m: float, height_m: float, length_m: float) -> CatenaryCurve:
    """Case 2 (Martins 2019, section 3.3): the total tether length is known.

    Eq. 34 is ``dY (1 - 2a sinh(dx/a) / sqrt(L^2 - dY^2)) = 0`` once ``sinh(atanh(t)) =
    t / sqrt(1 - t^2)`` is used: it carries the factor ``dY``, which is why the thesis finds it
    useless in the level case. We run Newton-Raphson on the remaining factor,
    ``F(a) = sqrt(L^2 - dY^2) - 2a sinh(dx/a) = 0``, which is eq. 34 divided by that factor for
    ``dY != 0`` and exactly eq. 32 with ``x0 = x_average`` for ``dY = 0``: one equation for
    both, well conditioned. The start is the quadratic guess (eqs. 36-39). Then ``x0`` from
    eq. 33 and ``c`` from eq. 26 (anchor on the curve).

    Parameters
    ----------
    horizontal_m
        Horizontal distance from the anchor to the drone [m], ``>= 0``.
    height_m
        Height of the drone above the anchor [m] (negative: drone below the anchor).
    length_m
        Cable length between anchor and drone [m]; must exceed the chord
        ``hypot(horizontal_m, height_m)``.

    Returns
    -------
    CatenaryCurve
        The curve; near-vertical spans (``horizontal_m <= VERTICAL_RELATIVE_SPAN * length_m``)
        give the folded limit ``a_m = 0`` with the lowest point at height
        ``(height_m - length_m)/2`` (eqs. 70-71).

    Raises
    ------
    ValueError
        Non-finite input, negative ``horizontal_m`` or ``length_m``, or ``length_m`` not longer
        than the chord (a taut weighted cable would need infinite tension).
    """
    x, dy = _check_endpoint(horizontal_m, height_m)
    length = check_finite("length_m", length_m)
    if length < 0.0:
        raise ValueError(f"length_m must be >= 0, got {length!r}")
    chord = math.hypot(x, dy)
    if length <= chord:
        raise ValueError(
            f"length_m = {length!r} is not longer than the anchor-to-drone chord {chord!r}: "
            "no catenary of finite tension fits (the tether would have to stretch)"
        )
    if x <= VERTICAL_RELATIVE_SPAN * length:
        low = 0.5 * (dy - length)
        return CatenaryCurve(a_m=0.0, x0_m=0.5 * x, c_m=low, s1_m=low, s2_m=dy - low)

    half_span = 0.5 * x
    excess = _excess_over_span(x, dy, length)

    log_ratio = math.log1p(excess / x)  # ln(sqrt(L^2 - dY^2) / span)

    def residual(t: float) -> tuple[float, float]:
        # eq. 34 over its factor dY: ln(sqrt(L^2 - dY^2)/span) = ln(sinh(k)/k), k = dx/a
        k = half_span * math.exp(-t)
        if k < 1.0:
            log_sinhc = math.log1p(_sinh_minus_identity(k) / k)
        else:
            log_sinhc = _log_sinh(k) - math.log(k)
        if k < 0.1:  # k coth(k) - 1 by its series (the closed form cancels)
            dg = k * k * (1.0 / 3.0 - k * k * (1.0 / 45.0 - k * k * 2.0 / 945.0))
        else:
            dg = k / math.tanh(k) - 1.0
        return log_ratio - log_sinhc, dg

    a = _newton_in_bracket(residual, _guess_known_length(half_span, excess))
    # eq. 33; atanh(dY/L) = ln((L + dY)/(L - dY))/2 keeps L - |dY| exact for steep cables
    x0 = half_span - 0.5 * a * math.log((length + dy) / (length - dy))
    u1 = -x0 / a
    u2 = (x - x0) / a
    c = -2.0 * a * math.sinh(0.5 * u1) ** 2 - a  # 0 = a cosh(u1) + c
    return CatenaryCurve(a_m=a, x0_m=x0, c_m=c, s1_m=a * math.sinh(u1), s2_m=a * math.sinh(u2))


# ---------------------------------------------------------------------------------------------
# tensions
