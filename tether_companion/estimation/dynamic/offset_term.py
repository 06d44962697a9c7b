"""The unmodelled force's position offset ``C`` on a cable of known length and weight:
:func:`offset_rows`, taken by both the ground station's information recursion
(:mod:`~tether_companion.estimation.dynamic.position_information`, which the cable angles
narrow) and the published covariance (:mod:`~tether_companion.estimation.dynamic.published_terms`),
at the same state and tension, so what the readings left of the offset is a part of the same
``C`` the publisher blends with (own16 found the two at different tensions, 2026-11-27).

The filter reads a horizontal force error ``dF`` (std ``force_std_n``) as the cable's pull and
moves the drone to where its cable model pulls that way (``observability.unmodelled_position_rows``:
a straight cable of the drone's range, turned by ``dF`` across it over the tension). With the
winch's length fused and a cable with weight, the filter's model gives the motion exactly,
in the cable's vertical plane ``(a, h)`` (span, height; ``r = |p|``, ``H`` the horizontal
tension, chord tension ``T = H r / a``):

* across the plane (tangential): the models depend on the span only, so a force ``dF_t``
  across it turns the whole curve about the vertical through the anchor by ``dF_t / H`` (the
  cable's horizontal pull at the drone is ``H`` along the span): the drone moves
  ``a dF_t / H = r dF_t / T`` -- the chord tension, for any weight, free or resting on the
  ground (the tension at the drone, ``sqrt(H^2 + V^2)``, is larger: 4.6 times on the heavy
  sagging hover, and its term 21 times too small);
* in the plane (radial): the length and the height (the rangefinder) are held, the pull's
  horizontal part is ``H + dF_r``, so the span moves ``da = (da/dH)_{L, h} dF_r``
  (:func:`~tether_companion.estimation.dynamic.sag_range.span_per_horizontal_tension`, the
  generated winch-length model's Jacobian): small on a taut cable, large near the touchdown.
  The straight cable's term turns the drone about the anchor at a fixed range instead, with a
  vertical part the rangefinder does not allow and the anchor's elevation reads only where
  the curve leaves the anchor steeply; on the heavy sagging hover it was 2-4 times the radial
  error (tuning seeds 5, 6).

Without a fused length, or on a weightless cable, the straight cable's term at the chord
tension: without a length the filter's range is the force balance's and the elevation's, and
the straight term's part in the plane stands for that range's error (nees10); the curve's
motion at a held elevation instead (``da/dH`` from the cable-angle model's Jacobian) was
measured and is not it (docs/estimation-history.md, heavy17: the light 5 N winch circle's
angle alone then published 1.5 % beyond 3 sigma). Pure.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence

from tether_companion.estimation import optional_core
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.observability import (
    MIN_TENSION_N,
    unmodelled_position_rows,
)
from tether_companion.estimation.dynamic.sag_range import span_per_horizontal_tension

Rows = list[list[float]]

STRAIGHT_ROWS: Callable[..., Rows] = unmodelled_position_rows
""":func:`~tether_companion.estimation.dynamic.observability.unmodelled_position_rows`, or where
the optional C extension ``_bound_core`` is built (and ``TETHER_PURE_PYTHON`` is not set) its
twin: the same floats, the Python function called where C could differ (``bound_core.c``;
it runs at every IMU tick's status read)."""
_CORE = optional_core.load("tether_companion.estimation.dynamic._bound_core")
if _CORE is not None and hasattr(_CORE, "unmodelled_rows"):  # not an extension built before it
    STRAIGHT_ROWS = functools.partial(_CORE.unmodelled_rows, unmodelled_position_rows)


def offset_rows(
    x: Sequence[float],
    weight_n_per_m: float,
    force_std_n: float,
    length_std_m: float,
    winch_fused: bool,
) -> Rows:
    """The offset's covariance ``C`` (3 rows, NED) [m^2] at the state's values ``x``
    (position from the anchor [m], chord tension [N]) on a cable of ``weight_n_per_m`` [N/m],
    for an unmodelled horizontal force of std ``force_std_n`` [N] and the winch length's
    ``length_std_m`` [m] kept along the cable (the module docstring): the catenary's motion
    at the held length with a fused length (``winch_fused``) on a cable with weight, where its
    model is defined; else the straight cable's, at the chord tension."""
    n, e, d = x[0], x[1], x[2]
    tension = x[state.TENSION]
    tension = MIN_TENSION_N if MIN_TENSION_N > tension else tension
    span = math.hypot(n, e)
    height = -d
    if winch_fused and weight_n_per_m > 0.0 and span > 0.0 and height > 0.0:
        distance = math.hypot(span, height)
        radial = span_per_horizontal_tension(
            span, height, tension * span / distance, weight_n_per_m
        )
        if math.isfinite(radial):
            return _plane_rows(n, e, d, span, distance, tension, radial, force_std_n, length_std_m)
    return STRAIGHT_ROWS(n, e, d, tension, force_std_n, length_std_m)


def _plane_rows(
    n: float,
    e: float,
    d: float,
    span: float,
    distance: float,
    tension: float,
    radial_m_per_n: float,
    force_std_n: float,
    length_std_m: float,
) -> Rows:
    """``(r sigma / T)^2 t t^T + (sigma da/dH)^2 h h^T + w u u^T`` [m^2]: ``t``, ``h`` the
    horizontal unit vectors across and along the span, ``u = p / r``, ``w`` the length's
    variance (:func:`offset_rows`'s arguments; ``span``, ``distance`` = ``a``, ``r`` > 0)."""
    h0, h1 = n / span, e / span
    u0, u1, u2 = n / distance, e / distance, d / distance
    across = distance * force_std_n / tension
    g_t = across * across
    g_r = (radial_m_per_n * force_std_n) ** 2
    w = length_std_m * length_std_m
    nn = g_t * h1 * h1 + g_r * h0 * h0 + w * u0 * u0
    ne = -g_t * h0 * h1 + g_r * h0 * h1 + w * u0 * u1
    ee = g_t * h0 * h0 + g_r * h1 * h1 + w * u1 * u1
    nd, ed, dd = w * u0 * u2, w * u1 * u2, w * u2 * u2
    return [[nn, ne, nd], [ne, ee, ed], [nd, ed, dd]]
