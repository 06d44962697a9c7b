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
readings' worth). The filter's own state and covariance are untouched. Pure.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

Rows = list[list[float]]
"""A 3x3 position covariance as rows of Python floats [m^2]."""


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

    __slots__ = ("_j", "_last_s", "_tau_s")

    def __init__(self, correlation_s: float) -> None:
        if not correlation_s > 0.0:
            raise ValueError(f"correlation_s must be positive, got {correlation_s!r}")
        self._tau_s = correlation_s
        self._j = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        """(nn, ne, nd, ee, ed, dd) at :attr:`_last_s`."""
        self._last_s = math.nan

    def clear(self) -> None:
        """Forget every measurement (a restart)."""
        self._j = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        self._last_s = math.nan

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

    def at(self, time_s: float) -> tuple[float, float, float, float, float, float] | None:
        """``J`` at ``time_s`` [s] as (nn, ne, nd, ee, ed, dd) [1/m^2]; None when nothing was
        ever added (the added covariance is then left exactly as it is)."""
        if math.isnan(self._last_s):
            return None
        decay = self._decay(time_s) if math.isfinite(time_s) else 1.0
        return tuple(v * decay for v in self._j)  # type: ignore[return-value]


def reduce_added_rows(
    rows: Rows, information: tuple[float, float, float, float, float, float] | None
) -> Rows:
    """``C' = (I + C J)^-1 C`` for the added position covariance ``C`` (rows, [m^2]) and the
    information ``J`` (:meth:`PositionInformation.at`, [1/m^2]); ``rows`` itself when
    ``information`` is None. Python floats (read every IMU tick by the status)."""
    if information is None:
        return rows
    jnn, jne, jnd, jee, jed, jdd = information
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
    s01, s02, s12 = 0.5 * (r01 + r10), 0.5 * (r02 + r20), 0.5 * (r12 + r21)
    return [[r00, s01, s02], [s01, r11, s12], [s02, s12, r22]]
