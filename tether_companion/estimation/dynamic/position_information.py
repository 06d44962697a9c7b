"""What the ground station's cable angle tells about the unmodelled force's error in the
published position: :class:`PositionInformation` and :func:`reduce_added_rows`.

The published covariance adds to the filter's own what the filter leaves out: an unmodelled
horizontal force turns the cable it reads the bearing from, ``C = |p|^2 (I - u u^T) S_F
(I - u u^T) / T^2`` on a straight cable (``observability.unmodelled_position_rows``, with the
winch length's accuracy along the cable; on a cable with weight the curve's motion,
``offset_term.offset_rows``, which both the readings here and the publisher take), because
the force balance is fused every IMU tick as if that force were white while it stays the same
for about ``tau = unmodelled_force_correlation_s``.

That offset ``d`` is a stationary process of covariance ``C`` correlated over ``tau``. It is
a displacement of the estimated position, which the filter moves only through its velocity:
``d`` is smooth (its change over ``dt`` is the velocity error times ``dt``), so its correlation
is the second-order Gauss-Markov one, ``rho(dt) = (1 + dt / tau) exp(-dt / tau)`` (Matern 3/2:
``1 - rho^2 ~ (dt / tau)^2`` for a short ``dt``), not the first-order ``exp(-dt / tau)``, whose
increments grow as ``sqrt(dt)``: that one let ``d`` jump ``0.43 sqrt(C)`` between two 10 Hz
readings (0.08 m across the cable on the 4 N circle: a velocity error of 0.8 m/s where the
filter's is 0.06 m/s) and kept the term at 0.6-1.4 times the error's variance across the
cable where the filter's own variance already matched it (36 times at 0.5 N; nees15,
docs/estimation-history.md). A measurement that sees the
position directly, and whose error has nothing to do with that force (the cable angle: the
direction from the anchor), measures it; so the added term is the offset's covariance given
the readings, a small Kalman filter of ``d`` (the variance recursion of the scalar-Markov
approximation of that correlation):

* between readings ``P <- a P + (1 - a) C`` with ``a = rho(dt)^2`` (the old readings'
  knowledge fades as the force changes, back to ``C`` within a few ``tau``);
* at a fused reading, for each of its rows ``h`` (the position columns of the angle's
  Jacobian) with noise ``r``: ``P <- P - P h h^T P / (h^T P h + r)``.

Without any reading the term is ``C`` exactly. ``P`` never exceeds ``C``; with a steady 10 Hz
angle and ``tau`` = 1 s it settles at ``sqrt((1 - a) C r)`` across the cable (a few readings'
accuracy where ``C`` is small, well below ``C`` where it is large: a weak pull).

That holds while the filter follows the angle. When it does not (its bearing off by more than
the readings allow: innovations beyond the gate, as in a gusty hover's first seconds), the
angle's innovations show the error directly: their variance beyond the predicted
(:class:`~tether_companion.estimation.dynamic.observability.InnovationExcess`, as for the
rangefinder's height) is added in the directions they measure, the azimuth's times the
horizontal range across the cable, the elevation's times the range in the cable's vertical
plane (a straight cable's geometry).

The ground station's calibration errors (zero and scale) are not here: they are states of the
filter (``state.py``), whose own covariance carries what it has not learnt of them.

The filter's own state and covariance are untouched. Pure.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from tether_companion.estimation.dynamic.observability import InnovationExcess

Rows = list[list[float]]
"""A 3x3 position covariance as rows of Python floats [m^2]."""
Terms = tuple[float, ...]
"""The offset's covariance at the last reading (nn, ne, nd, ee, ed, dd) [m^2], the weight
``a`` it keeps now [1], and the innovation excess (the same six) [m^2]."""
ANGLE_EXCESS_TIME_CONSTANT_S = 2.0
"""Averaging time of the cable angle's innovation excess [s] (the rangefinder's)."""
_ZERO6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def _upper(rows: Rows) -> list[float]:
    return [rows[0][0], rows[0][1], rows[0][2], rows[1][1], rows[1][2], rows[2][2]]


def height_excess(
    position_ned_m: Sequence[float], variance_m2: float, range_held: bool
) -> tuple[float, ...]:
    """The position covariance (nn, ne, nd, ee, ed, dd) [m^2] of a height error of variance
    ``variance_m2`` [m^2] (the rangefinder innovations' excess: the height error they show
    beyond the filter's covariance) at ``position_ned_m`` (NED from the anchor [m]).

    With a winch length fused (``range_held``) it is the height's alone (down). Without one
    the filter's range is its height carried along the cable's direction (the force
    balance's or the cable angle's: the range is ``h / tan(el)``), so a height off by ``dd``
    moves the drone along the line from the anchor, ``dp = p dd / d``: the variance goes
    along ``p / d``, its down part the variance itself, its horizontal part ``rho / |d|``
    times larger per axis (``|d|`` at least a tenth of ``|p|``).
    Measured on the realistic 0.5 N circle with the angle alone, tuning seed 2: the height
    0.5 m off for 2 s (rangefinder innovations 0.5-0.9 m, the excess 0.36 m), the range
    0.75 m short at a published 0.22 m, 89 ticks beyond 3 sigma; none with this term."""
    v = float(variance_m2)
    if not v > 0.0:
        return _ZERO6
    n, e, d = (float(x) for x in position_ned_m)
    distance = math.sqrt(n * n + e * e + d * d)
    if range_held or not math.isfinite(distance) or distance == 0.0:
        return (0.0, 0.0, 0.0, 0.0, 0.0, v)
    floor = 0.1 * distance
    if abs(d) < floor:
        d = math.copysign(floor, d)
    un, ue = n / d, e / d
    return (v * un * un, v * un * ue, v * un, v * ue * ue, v * ue, v)


class PositionInformation:
    """The unmodelled offset's covariance given the fused cable angles, and the angle
    innovations' excess.

    Parameters
    ----------
    correlation_s
        Time over which the unmodelled force stays the same [s]
        (``unmodelled_force_correlation_s``).
    """

    __slots__ = (
        "_azimuth",
        "_elevation",
        "_excess",
        "_last_s",
        "_p",
        "_tau_s",
    )

    def __init__(self, correlation_s: float) -> None:
        if not correlation_s > 0.0:
            raise ValueError(f"correlation_s must be positive, got {correlation_s!r}")
        self._tau_s = correlation_s
        self._p: list[float] | None = None
        """The offset's covariance after the last reading (nn, ne, nd, ee, ed, dd) [m^2]."""
        self._last_s = math.nan
        self._elevation = InnovationExcess(ANGLE_EXCESS_TIME_CONSTANT_S)
        self._azimuth = InnovationExcess(ANGLE_EXCESS_TIME_CONSTANT_S)
        self._excess = _ZERO6
        """The angle innovations' excess as a position covariance (nn, ne, nd, ee, ed, dd)."""

    def clear(self) -> None:
        """Forget every reading (a restart)."""
        self._p = None
        self._last_s = math.nan
        self._elevation = InnovationExcess(ANGLE_EXCESS_TIME_CONSTANT_S)
        self._azimuth = InnovationExcess(ANGLE_EXCESS_TIME_CONSTANT_S)
        self._excess = _ZERO6

    def _kept(self, time_s: float) -> float:
        """The weight ``a = rho(dt)^2``, ``rho = (1 + dt / tau) exp(-dt / tau)``, the last
        reading's covariance keeps at ``time_s`` [s] (the module docstring)."""
        last = self._last_s
        if math.isnan(last) or not time_s > last:
            return 1.0
        x = (time_s - last) / self._tau_s
        rho = (1.0 + x) * math.exp(-x)
        return rho * rho

    def add(
        self,
        rows: Sequence[Sequence[float]],
        variances: Sequence[float],
        time_s: float,
        added_rows: Rows,
    ) -> None:
        """A fused reading at ``time_s`` [s]: its Jacobian rows with respect to the position
        (each 3 values, [unit/m]), each row's noise variance [unit^2] (independent rows), and
        the unmodelled term ``C`` at the reading's state (rows [m^2]). Non-finite or
        non-positive values are ignored."""
        if not math.isfinite(time_s):
            return
        for (a, b, c), variance in zip(rows, variances, strict=True):
            if not (variance > 0.0 and math.isfinite(a + b + c + variance)):
                return
        c6 = _upper(added_rows)
        if not all(math.isfinite(v) for v in c6):
            return
        p = self._p
        if p is None:
            p = c6
        else:
            kept = self._kept(time_s)
            p = [kept * pi + (1.0 - kept) * ci for pi, ci in zip(p, c6, strict=True)]
        for (a, b, c), variance in zip(rows, variances, strict=True):
            nn, ne, nd, ee, ed, dd = p
            # P h and h^T P h + r
            g0 = nn * a + ne * b + nd * c
            g1 = ne * a + ee * b + ed * c
            g2 = nd * a + ed * b + dd * c
            s = a * g0 + b * g1 + c * g2 + variance
            p = [
                nn - g0 * g0 / s,
                ne - g0 * g1 / s,
                nd - g0 * g2 / s,
                ee - g1 * g1 / s,
                ed - g1 * g2 / s,
                dd - g2 * g2 / s,
            ]
        self._p = p
        self._last_s = time_s if math.isnan(self._last_s) else max(self._last_s, time_s)

    def add_angle_innovation(
        self,
        innovation_rad: Sequence[float],
        variance_rad2: Sequence[float],
        position_ned_m: Sequence[float],
        time_s: float,
    ) -> None:
        """A cable-angle reading's (elevation, azimuth) innovation [rad] and its predicted
        variance [rad^2] (fused or gated) at the estimated position (NED [m]): the excess,
        mapped to the position at that position."""
        self._elevation.add(float(innovation_rad[0]), float(variance_rad2[0]), time_s)
        self._azimuth.add(float(innovation_rad[1]), float(variance_rad2[1]), time_s)
        n, e, d = (float(v) for v in position_ned_m)
        rho = math.hypot(n, e)
        distance = math.sqrt(rho * rho + d * d)
        if not (rho > 0.0 and math.isfinite(distance)):
            return
        across = self._azimuth.variance * rho * rho  # along (-e, n, 0) / rho
        vertical = self._elevation.variance * distance * distance
        # the cable's vertical plane: perpendicular to p, (n d, e d, -rho^2) / (rho |p|)
        tn, te = -e / rho, n / rho
        vn, ve, vd = n * d / (rho * distance), e * d / (rho * distance), -rho / distance
        self._excess = (
            across * tn * tn + vertical * vn * vn,
            across * tn * te + vertical * vn * ve,
            vertical * vn * vd,
            across * te * te + vertical * ve * ve,
            vertical * ve * vd,
            vertical * vd * vd,
        )

    def at(self, time_s: float) -> Terms | None:
        """The terms at ``time_s`` [s] (:data:`Terms`); None before any fused angle (the
        added covariance is then left exactly as it is)."""
        p = self._p
        if p is None:
            return None
        return (*p, self._kept(time_s) if math.isfinite(time_s) else 1.0, *self._excess)


def reduce_added_rows(rows: Rows, information: Terms | None) -> Rows:
    """The added position covariance ``C`` (rows, [m^2], at the tick's state) given the
    readings: ``a P + (1 - a) C`` plus the angle innovations' excess, from the terms of
    :meth:`PositionInformation.at`; ``rows`` itself when ``information`` is None. Python
    floats (read every IMU tick by the status)."""
    if information is None:
        return rows
    pnn, pne, pnd, pee, ped, pdd, kept, enn, ene, end, eee, eed, edd = information
    fresh = 1.0 - kept
    (c00, c01, c02), (_, c11, c12), (_, _, c22) = rows
    r01 = kept * pne + fresh * c01 + ene
    r02 = kept * pnd + fresh * c02 + end
    r12 = kept * ped + fresh * c12 + eed
    return [
        [kept * pnn + fresh * c00 + enn, r01, r02],
        [r01, kept * pee + fresh * c11 + eee, r12],
        [r02, r12, kept * pdd + fresh * c22 + edd],
    ]
