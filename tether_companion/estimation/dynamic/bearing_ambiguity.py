"""The published covariance of a tick whose bearing the pull does not fix (issue 10: "when the
horizontal pull is too weak for the position to be known, the covariance grows to say so").

The filter reads the drone's bearing from the anchor as the direction of the cable's
horizontal pull ``H``, the horizontal force beyond the rotor drag in the wind. When ``H`` is
not clearly larger than the drag of the wind the filter cannot rule out
(:func:`~tether_companion.estimation.dynamic.observability.min_horizontal_pull_n`), the
estimate is withheld as ``weak_pull``, but the filter's own covariance still claims the
bearing it settled on: a filter that took a wrong wind turns its bearing by up to
``drag / H`` and holds it with a covariance of the size it would have with the right wind
(realistic 0.5 N circle with the winch's length, tuning seeds 1-3: 0.7-5 m off, the drone
on the other side of the anchor on seed 3, at a published 0.3-1.4 m: NEES 6, 88 and 456).

On such a tick the bearing is taken as unknown to ``s = drag / H`` [rad] (``drag`` the
rotor drag of the larger of the wind prior's standard deviation and the filter's own wind),
its error ``theta ~ N(0, s^2)``; the drone then lies on its horizontal circle of radius
``rho`` about the anchor, off the estimate by ``rho (cos theta - 1)`` along the range and
``rho sin theta`` across it, whose mean squares are

* across: ``rho^2 (1 - exp(-2 s^2)) / 2`` (``rho^2 s^2`` for a small ``s``),
* along: ``rho^2 (3/2 - 2 exp(-s^2 / 2) + exp(-2 s^2) / 2)`` (the far side of the circle,
  ``2 rho``, within reach once ``s`` is near a radian).

Added to the published covariance of the ticks the pull rule withholds (never to a published
tick: the rule then holds), so the withheld estimate says how little it knows. Pure.
"""

from __future__ import annotations

import math

_ZERO3 = (0.0, 0.0, 0.0)


def bearing_ambiguity(
    north_m: float, east_m: float, pull_n: float, drag_n: float
) -> tuple[float, float, float]:
    """The horizontal position covariance (nn, ne, ee) [m^2] of a bearing unknown to
    ``drag_n / pull_n`` [rad] (module docstring) at the estimated position ``(north_m,
    east_m)`` from the anchor [m], the horizontal pull ``pull_n`` [N] (0 or less: the bearing
    is not known at all) against a drag ``drag_n`` [N]. Zeros right above the anchor or
    without a drag."""
    rho_sq = north_m * north_m + east_m * east_m
    if not (rho_sq > 0.0 and drag_n > 0.0 and math.isfinite(rho_sq + drag_n)):
        return _ZERO3
    s_sq = (drag_n / pull_n) ** 2 if pull_n > 0.0 else math.inf
    across = rho_sq * 0.5 * (1.0 - math.exp(-2.0 * s_sq))
    along = rho_sq * (1.5 - 2.0 * math.exp(-0.5 * s_sq) + 0.5 * math.exp(-2.0 * s_sq))
    un, ue = north_m * north_m / rho_sq, east_m * east_m / rho_sq
    cross = north_m * east_m / rho_sq
    return (along * un + across * ue, (along - across) * cross, along * ue + across * un)
