"""What direct position measurements of the last seconds tell about the unmodelled force's
error: :class:`PositionInformation` and :func:`reduce_added_rows`.

The published covariance adds to the filter's own what the filter leaves out: an unmodelled
horizontal force turns the cable it reads the bearing from, ``C = |p|^2 (I - u u^T) S_F
(I - u u^T) / T^2`` (``observability.unmodelled_position_rows``), because the force balance is
fused every IMU tick as if that force were white while it stays the same for about
``unmodelled_force_correlation_s``. A measurement that sees the position
directly, and whose error has nothing to do with that force (the ground station's cable angle:
the direction from the anchor), corrects such an offset within the time it lasts. So the added
term is the offset's covariance after those measurements: with ``J`` the information about the
position of the measurements fused within the correlation time (each sample's ``H_p^T R^-1
H_p``, ``H_p`` its Jacobian with respect to the position, weighted ``exp(-age / tau)``), the
Kalman (information-sum) update of the prior ``C``::

    C' = (C^-1 + J)^-1 = (I + C J)^-1 C

which needs no inverse of ``C`` (rank 2 or 3) or ``J`` (rank 2 for an angle). Without any
such measurement ``J = 0`` and ``C' = C`` exactly. ``C'`` is never larger than ``C`` and at
most ``J^-1`` in the directions ``J`` measures (a steady 10 Hz angle over 1 s: about ten
readings' worth).

That holds while the filter follows the angle. When it does not (its bearing off by more than
the readings allow: innovations beyond the gate, as in a gusty hover's first seconds), the
angle's innovations show the error directly: their variance beyond the predicted
(:class:`~tether_companion.estimation.dynamic.observability.InnovationExcess`, as for the
rangefinder's height) is added in the directions they measure, the azimuth's times the
horizontal range across the cable, the elevation's times the range in the cable's vertical
plane (a straight cable's geometry). The filter's own state and covariance are untouched. Pure.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from tether_companion.estimation.dynamic.observability import InnovationExcess

Rows = list[list[float]]
"""A 3x3 position covariance as rows of Python floats [m^2]."""
Terms = tuple[float, ...]
"""``J`` (nn, ne, nd, ee, ed, dd) [1/m^2] and the excess covariance (the same six) [m^2]."""
ANGLE_EXCESS_TIME_CONSTANT_S = 2.0
"""Averaging time of the cable angle's innovation excess [s] (the rangefinder's)."""
_ZERO6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


class PositionInformation:
    """The information ``J`` [1/m^2] about the position (NED) of the direct measurements
    fused so far, each forgotten as ``exp(-age / correlation_s)``.

    Parameters
    ----------
    correlation_s
        Time over which the unmodelled force stays the same [s]
        (``unmodelled_force_correlation_s``): a measurement older than this no longer sees
        the offset it causes now.
    """

    __slots__ = ("_azimuth", "_elevation", "_excess", "_j", "_last_s", "_tau_s")

    def __init__(self, correlation_s: float) -> None:
        if not correlation_s > 0.0:
            raise ValueError(f"correlation_s must be positive, got {correlation_s!r}")
        self._tau_s = correlation_s
        self._j = _ZERO6
        """(nn, ne, nd, ee, ed, dd) at :attr:`_last_s`."""
        self._last_s = math.nan
        self._elevation = InnovationExcess(ANGLE_EXCESS_TIME_CONSTANT_S)
        self._azimuth = InnovationExcess(ANGLE_EXCESS_TIME_CONSTANT_S)
        self._excess = _ZERO6
        """The angle innovations' excess as a position covariance (nn, ne, nd, ee, ed, dd)."""

    def clear(self) -> None:
        """Forget every measurement (a restart)."""
        self._j = _ZERO6
        self._last_s = math.nan
        self._elevation = InnovationExcess(ANGLE_EXCESS_TIME_CONSTANT_S)
        self._azimuth = InnovationExcess(ANGLE_EXCESS_TIME_CONSTANT_S)
        self._excess = _ZERO6

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
        if math.isnan(self._last_s):
            self._last_s = time_s
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

    def add(
        self, rows: Sequence[Sequence[float]], variances: Sequence[float], time_s: float
    ) -> None:
        """One measurement at ``time_s`` [s]: its Jacobian rows with respect to the position
        (each 3 values, [unit/m]) and the variance of each row's noise [unit^2] (independent
        rows). Non-finite or non-positive values are ignored."""
        if not math.isfinite(time_s):
            return
        nn = ne = nd = ee = ed = dd = 0.0
        for (a, b, c), variance in zip(rows, variances, strict=True):
            if not (variance > 0.0 and math.isfinite(a + b + c) and math.isfinite(variance)):
                return
            w = 1.0 / variance
            nn += w * a * a
            ne += w * a * b
            nd += w * a * c
            ee += w * b * b
            ed += w * b * c
            dd += w * c * c
        decay = self._decay(time_s)
        j = self._j
        self._j = (
            j[0] * decay + nn,
            j[1] * decay + ne,
            j[2] * decay + nd,
            j[3] * decay + ee,
            j[4] * decay + ed,
            j[5] * decay + dd,
        )
        self._last_s = time_s if math.isnan(self._last_s) else max(self._last_s, time_s)

    def _decay(self, time_s: float) -> float:
        last = self._last_s
        if math.isnan(last) or time_s <= last:
            return 1.0
        return math.exp(-(time_s - last) / self._tau_s)

    def at(self, time_s: float) -> Terms | None:
        """``J`` at ``time_s`` [s] (nn, ne, nd, ee, ed, dd) [1/m^2] followed by the angle
        innovations' excess covariance (the same six) [m^2]; None when nothing was ever added
        (the added covariance is then left exactly as it is)."""
        if math.isnan(self._last_s):
            return None
        decay = self._decay(time_s) if math.isfinite(time_s) else 1.0
        j = self._j
        return (
            j[0] * decay,
            j[1] * decay,
            j[2] * decay,
            j[3] * decay,
            j[4] * decay,
            j[5] * decay,
            *self._excess,
        )


def reduce_added_rows(rows: Rows, information: Terms | None) -> Rows:
    """``C' = (I + C J)^-1 C`` plus the angle innovations' excess for the added position
    covariance ``C`` (rows, [m^2]) and the terms of :meth:`PositionInformation.at`; ``rows``
    itself when ``information`` is None. Python floats (read every IMU tick by the status)."""
    if information is None:
        return rows
    jnn, jne, jnd, jee, jed, jdd, enn, ene, end, eee, eed, edd = information
    (c00, c01, c02), (_, c11, c12), (_, _, c22) = rows
    # M = I + C J (C and J symmetric)
    m00 = 1.0 + c00 * jnn + c01 * jne + c02 * jnd
    m01 = c00 * jne + c01 * jee + c02 * jed
    m02 = c00 * jnd + c01 * jed + c02 * jdd
    m10 = c01 * jnn + c11 * jne + c12 * jnd
    m11 = 1.0 + c01 * jne + c11 * jee + c12 * jed
    m12 = c01 * jnd + c11 * jed + c12 * jdd
    m20 = c02 * jnn + c12 * jne + c22 * jnd
    m21 = c02 * jne + c12 * jee + c22 * jed
    m22 = 1.0 + c02 * jnd + c12 * jed + c22 * jdd
    # cofactors of M (its inverse times det M)
    a00 = m11 * m22 - m12 * m21
    a01 = m02 * m21 - m01 * m22
    a02 = m01 * m12 - m02 * m11
    a10 = m12 * m20 - m10 * m22
    a11 = m00 * m22 - m02 * m20
    a12 = m02 * m10 - m00 * m12
    a20 = m10 * m21 - m11 * m20
    a21 = m01 * m20 - m00 * m21
    a22 = m00 * m11 - m01 * m10
    det = m00 * a00 + m01 * a10 + m02 * a20
    if not (det > 0.0 and math.isfinite(det)):  # I + C J has eigenvalues >= 1: never here
        return rows
    # (M^-1 C), symmetrised: the product is symmetric in exact arithmetic
    r00 = (a00 * c00 + a01 * c01 + a02 * c02) / det
    r01 = (a00 * c01 + a01 * c11 + a02 * c12) / det
    r02 = (a00 * c02 + a01 * c12 + a02 * c22) / det
    r10 = (a10 * c00 + a11 * c01 + a12 * c02) / det
    r11 = (a10 * c01 + a11 * c11 + a12 * c12) / det
    r12 = (a10 * c02 + a11 * c12 + a12 * c22) / det
    r20 = (a20 * c00 + a21 * c01 + a22 * c02) / det
    r21 = (a20 * c01 + a21 * c11 + a22 * c12) / det
    r22 = (a20 * c02 + a21 * c12 + a22 * c22) / det
    s01, s02, s12 = 0.5 * (r01 + r10) + ene, 0.5 * (r02 + r20) + end, 0.5 * (r12 + r21) + eed
    return [[r00 + enn, s01, s02], [s01, r11 + eee, s12], [s02, s12, r22 + edd]]
