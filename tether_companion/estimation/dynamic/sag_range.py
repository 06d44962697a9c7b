"""The range a fused winch length leaves open on a sagging cable: :func:`sag_range_variance_m2`.

With the winch's paid-out length ``L`` fused and the height fixed by the rangefinder, the
drone's horizontal range from the anchor follows from the cable's shape, and on a cable with
weight that shape depends on the tension: at a fixed length a lower horizontal tension ``H``
sags the cable more and pulls the drone in. Near the touchdown (the cable resting on the
anchor's level, :func:`~tether_companion.estimation.dynamic.models.rests_on_ground`) the
dependence is strong and one-sided: the grounded part takes up length, so the range at the
fused length falls by about as much as the grounded part grows, while a higher tension
straightens a free cable only a little. The filter's covariance is linearised at its own
tension, so when that tension is too high (a free catenary where the real cable rests on the
ground: realistic-sagging-hover, seed 9, 2 sigma high, range 1 m long with a 0.3-0.4 m standard
deviation) it underrates the range's error.

This module evaluates the range at the fused length at ``T -+ 3 sigma_T`` (the free or
grounded catenary through the anchor and a point at the drone's height, solved for its span),
and returns the variance the published covariance must at least have along the horizontal
range: a third of the larger distance from the state's own span to those two, squared, less
what the filter already claims along that direction. From the state's span, not from the span
the state's tension gives at the length: where the filter does not follow the length (its
readings gated, or bounding a cable taken for slack) the two differ, and a third of the
spread about the latter let a state 0.5 m off the length's curve publish a 0.05 m standard
deviation (honest18, tests/test_dynamic_sag_range.py). The publisher's
``max_horizontal_std_m`` rule then withholds where the grounded regime makes the range
unknown, and the published covariance is honest where it publishes.

Pure; scalar Python floats (computed once per member step, not per tick).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.mixture import MixtureValues
from tether_companion.estimation.dynamic.models import (
    CATENARY,
    UNDEFINED,
    ModelConstants,
    rests_on_ground,
)

TENSION_SIGMAS = 3.0
"""How many of the tension's standard deviations either side are taken as plausible: the
range change there, divided by as many, is the published standard deviation along the range,
so a range error beyond 3 sigma needs a tension beyond 3 sigma (the range is monotonic in the
tension at a fixed length)."""
LOW_TENSION_FRACTION = 0.01
"""The lower plausible tension is at least this fraction of the chord tension (the curve is
defined only for a positive tension; near zero the span at the length barely changes)."""
NO_SAG = (0.0, 0.0)
""":func:`sag_range_variance_m2`'s answer where it does not apply."""
SPAN_TOLERANCE_M = 1e-4
"""The span's tolerance [m] (the bracket's width, or a Newton step a tenth of it)."""


def arc_length_m(
    span_m: float, height_m: float, horizontal_n: float, weight_n_per_m: float
) -> float:
    """The length [m] of a cable of weight ``weight_n_per_m`` [N/m] with horizontal tension
    ``horizontal_n`` [N] from the anchor to a point ``span_m`` [m] > 0 away horizontally and
    ``height_m`` [m] > 0 above it (:func:`_arc_length_and_slope`); inf where the curve is so
    slack that it overflows (far longer than any winch's cable)."""
    return _arc_length_and_slope(span_m, height_m, horizontal_n, weight_n_per_m)[0]


def _arc_length_and_slope(
    span_m: float, height_m: float, horizontal_n: float, weight_n_per_m: float
) -> tuple[float, float]:
    """The arc length [m] and its derivative along the span at a fixed horizontal tension
    [m/m] (:func:`_arc_length_and_partials`)."""
    length, slope, _ = _arc_length_and_partials(span_m, height_m, horizontal_n, weight_n_per_m)
    return length, slope


def _arc_length_and_partials(
    span_m: float, height_m: float, horizontal_n: float, weight_n_per_m: float
) -> tuple[float, float, float]:
    """The arc length [m], its derivative along the span at a fixed horizontal tension
    [m/m] and along the horizontal tension at a fixed span [m/N]: the derivation's
    winch-length model (:data:`~tether_companion.estimation.dynamic.models.CATENARY`,
    generated: the free catenary, or the one resting on the anchor's level where the free
    curve's lowest point would fall between the ends below the anchor) and its Jacobian at the
    state with the position ``(a, 0, -h)`` and the chord tension ``T = H r / a`` (``r =
    |p|``), so ``dL/da = dL/dp_n + dL/dT dT/da`` with ``dT/da = -H h^2 / (r a^2)`` and
    ``dL/dH = dL/dT r / a``; ``(inf, nan, nan)`` where the model overflows."""
    x = [0.0] * state.N_STATES
    x[0], x[2] = span_m, -height_m
    chord = math.hypot(span_m, height_m)
    x[state.TENSION] = horizontal_n * chord / span_m
    try:
        (length,), jacobian = CATENARY.winch_length(x, (), (0.0, 0.0, weight_n_per_m))
    except UNDEFINED:
        return math.inf, math.nan, math.nan
    per_tension = jacobian[state.TENSION]
    tension_per_span = -horizontal_n * height_m * height_m / (chord * span_m * span_m)
    return length, jacobian[0] + per_tension * tension_per_span, per_tension * chord / span_m


def span_per_horizontal_tension(
    span_m: float, height_m: float, horizontal_n: float, weight_n_per_m: float
) -> float:
    """How far the span moves per newton of horizontal tension [m/N] with the cable's length
    and the drone's height held (``L(a, H)`` = const: ``da/dH = -(dL/dH)_a / (dL/da)_H``,
    :func:`_arc_length_and_partials`), for a cable of weight ``weight_n_per_m`` [N/m] with
    horizontal tension ``horizontal_n`` [N] to a point ``span_m`` [m] > 0 away and
    ``height_m`` [m] > 0 up: positive (a pull straightens the curve, the drone goes out), 0
    for a weightless cable (its length alone fixes the span), large near the touchdown (the
    grounded part takes up length); ``nan`` where the model overflows or the slope is not
    positive."""
    _, slope, per_horizontal = _arc_length_and_partials(
        span_m, height_m, horizontal_n, weight_n_per_m
    )
    if not slope > 0.0:
        return math.nan
    return -per_horizontal / slope


def span_at_length_m(
    length_m: float, height_m: float, horizontal_n: float, weight_n_per_m: float
) -> float:
    """The span [m] at which the cable (as :func:`arc_length_m`) is ``length_m`` [m] long at
    height ``height_m`` [m]: the arc length grows with the span, so Newton's method on the
    generated model's slope, kept inside a bracket that starts as ``[0, sqrt(L^2 - h^2)]``
    (the straight line's span bounds every curve's) and falls back to bisection, to
    :data:`SPAN_TOLERANCE_M`."""
    low, high = 0.0, math.sqrt(max(length_m * length_m - height_m * height_m, 0.0))
    span = 0.5 * (low + high)
    while high - low > SPAN_TOLERANCE_M:
        arc, slope = _arc_length_and_slope(span, height_m, horizontal_n, weight_n_per_m)
        if arc > length_m:
            high = span
        else:
            low = span
        step = (length_m - arc) / slope if slope > 0.0 else math.nan
        if abs(step) < 0.1 * SPAN_TOLERANCE_M:
            return span
        newton = span + step
        span = newton if low < newton < high else 0.5 * (low + high)
    return 0.5 * (low + high)


def sag_range_std_m(
    x: Sequence[float],
    tension_variance_n2: float,
    weight_n_per_m: float,
    length_m: float,
    tension_measured: bool = False,
) -> float:
    """The range's spread at the fused length over the plausible tensions [m]: the larger
    distance from the state's span to the spans at ``length_m`` [m] and the state's height
    (``x``: the state's values, NED position from the anchor [m], chord tension [N]) at
    ``T -+ TENSION_SIGMAS sigma_T``, divided by ``TENSION_SIGMAS`` (``tension_variance_n2``
    [N^2]; the lower end at least :data:`LOW_TENSION_FRACTION` of ``T``, and that where the
    cable rests on the ground at ``T - TENSION_SIGMAS sigma_T``: then the filter's tension,
    read from a horizontal pull of a few tenths of a newton, does not bound how much of the
    cable lies on the ground (realistic-sagging-hover seed 39: the true chord tension 3.3
    sigma below the filter's), and the range is taken as unsure down to the cable lying flat
    up to the foot of the drone; not when ``tension_measured``: a load cell's or the winch's
    tension has been fused, the tension's variance is a measurement's, and the lower end stays
    ``T - TENSION_SIGMAS sigma_T``; realistic-winch-heavy-hover-5n seed 1, the winch's
    load cell fused: 100 % published, none beyond 3 sigma, where the widening withheld 89 %).
    0 where it
    does not apply: no weight, no length, the drone at or below the anchor's level, right
    above it, a non-positive tension."""
    span = math.hypot(x[0], x[1])
    height = -x[2]
    tension = x[state.TENSION]
    if (
        weight_n_per_m <= 0.0
        or not length_m > height > 0.0
        or span <= 0.0
        or not tension > 0.0
        or not tension_variance_n2 >= 0.0
    ):
        return 0.0
    # the chord tension's horizontal part: H = T a / |p| (as rests_on_ground)
    horizontal_per_chord = span / math.hypot(span, height)
    spread = TENSION_SIGMAS * math.sqrt(tension_variance_n2)
    low_tension = max(tension - spread, LOW_TENSION_FRACTION * tension)
    if not tension_measured and grounded_plausible(x, tension_variance_n2, weight_n_per_m):
        low_tension = LOW_TENSION_FRACTION * tension
    lower = span_at_length_m(length_m, height, low_tension * horizontal_per_chord, weight_n_per_m)
    upper = span_at_length_m(
        length_m, height, (tension + spread) * horizontal_per_chord, weight_n_per_m
    )
    return max(span - lower, upper - span) / TENSION_SIGMAS


def sag_range_variance_m2(
    x: Sequence[float],
    horizontal_covariance_m2: tuple[float, float, float],
    tension_variance_n2: float,
    weight_n_per_m: float,
    length_m: float,
    tension_measured: bool = False,
) -> tuple[float, float]:
    """:func:`sag_range_std_m` [m] and the variance [m^2] to add along the horizontal range
    direction ``(n, e)/|(n, e)|`` so that the published covariance there is at least that
    squared: that squared less what ``horizontal_covariance_m2`` (nn, ne, ee) [m^2] already
    holds along it, never negative (the linearised part the filter claims is not counted
    twice); ``tension_measured`` as :func:`sag_range_std_m`."""
    std = sag_range_std_m(x, tension_variance_n2, weight_n_per_m, length_m, tension_measured)
    if std == 0.0:
        return NO_SAG
    span = math.hypot(x[0], x[1])
    h0, h1 = x[0] / span, x[1] / span
    nn, ne, ee = horizontal_covariance_m2
    along = h0 * h0 * nn + 2.0 * h0 * h1 * ne + h1 * h1 * ee
    return std, max(std * std - along, 0.0)


def grounded_plausible(
    x: Sequence[float], tension_variance_n2: float, weight_n_per_m: float
) -> bool:
    """Whether the cable of the state's values ``x`` may rest on the ground: it does
    (:func:`~tether_companion.estimation.dynamic.models.rests_on_ground`) at the state's
    position with the chord tension ``TENSION_SIGMAS`` standard deviations
    (``tension_variance_n2`` [N^2]) below the state's (at least
    :data:`LOW_TENSION_FRACTION` of it; a lower tension sags the cable more)."""
    tension = x[state.TENSION]
    if not tension > 0.0 or not tension_variance_n2 >= 0.0:
        return False
    low = list(x)
    low[state.TENSION] = max(
        tension - TENSION_SIGMAS * math.sqrt(tension_variance_n2), LOW_TENSION_FRACTION * tension
    )
    return rests_on_ground(low, (0.0, 0.0, weight_n_per_m))


def mixture_sag(
    mixture: MixtureValues, constants: ModelConstants, winch: bool
) -> tuple[float, float]:
    """What the sag leaves open of the range at the bank's mixture (its state, horizontal
    position covariance and chord tension variance) on the cable of ``constants``: with a
    fused winch length (``winch``), :func:`sag_range_variance_m2` at the length the reading
    ``constants.length_m`` [m] means with the mixture's calibration states, ``(L - o) / (1 +
    s)`` (the encoder reads ``o + (1 + s) L``);
    without one, ``(inf, 0)`` where the cable may rest on the ground
    (:func:`grounded_plausible`: the pull at the drone and the anchor's angle then do not
    depend on the range, only the grounded part's length does; the estimate is withheld),
    else :data:`NO_SAG`. :data:`NO_SAG` for a mixture with non-finite values."""
    if not mixture.finite:
        return NO_SAG
    p = mixture.p
    tension_variance = float(p[state.TENSION, state.TENSION])
    if not winch:
        if grounded_plausible(mixture.x_values, tension_variance, constants.weight_n_per_m):
            return math.inf, 0.0
        return NO_SAG
    x = mixture.x_values
    length_m = (constants.length_m - x[state.WINCH_OFFSET]) / (1.0 + x[state.WINCH_SCALE])
    return sag_range_variance_m2(
        x,
        (float(p[0, 0]), float(p[0, 1]), float(p[1, 1])),
        tension_variance,
        constants.weight_n_per_m,
        length_m,
        constants.tension_measured,
    )


class SagMemo:
    """:func:`mixture_sag` computed once per mixture and winch length reading."""

    def __init__(self) -> None:
        self._key: tuple[MixtureValues, float] | None = None
        self._value = NO_SAG

    def at(
        self, mixture: MixtureValues, constants: ModelConstants, winch_fused: bool
    ) -> tuple[float, float]:
        """The range's standard deviation [m] over the tensions the filter cannot rule out at
        the fused winch length (``winch_fused``) and the variance [m^2] the published
        covariance then needs along the horizontal range (:func:`mixture_sag`)."""
        key = (mixture, constants.length_m if winch_fused else math.nan)
        if self._key != key:
            self._key = key
            self._value = mixture_sag(mixture, constants, winch_fused)
        return self._value
