"""What every tick between two member steps reads of the bank's mixture, made once per
mixture: :class:`MixtureValues` (its mean and covariance as Python floats, with the bounds the
published estimate's approximation needs) and :class:`HoverAnchor` (the thrust scale and the
wind's part of the horizontal covariance, with a bound on how far the ticks' steps can move
it); and the process noise as floats (:class:`ProcessNoise`).

The members step once per IMU batch and replace their arrays when they do, so a tick's
published estimate is the mixture stepped over the batch's ticks so far (``Phi P Phi^T + T
Q``, ``Phi = I + E``). The published status compares a few of its entries with thresholds;
each tick bounds how far its step moved them from the mixture's own (Cauchy-Schwarz,
``|P_kl| <= sd_k sd_l``), and :meth:`HoverAnchor.explains` carries that bound through the
Schur complement's ``X C^-1 X^T`` (spectral norms), so the mixture's numbers decide every
tick of the batch where they are clear by more than the bound. Pure.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation import optional_core
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.observability import _largest_std_values

FloatArray = NDArray[np.float64]

ROUNDING = 1e-12
"""Bound on a float computation's rounding, relative to its terms' magnitude (the products of
13 terms differ from the exact ones by a few 1e-16 of it)."""
HOVER_UNKNOWNS = (state.SCALE, state.WIND.start, state.WIND.start + 1)
"""State indices of the thrust scale and the wind (what a steady hover does not observe)."""
_HOVER_BLOCK_ROWS = np.array((0, 1, 3, 4, *HOVER_UNKNOWNS))[:, None]
_HOVER_BLOCK_COLUMNS = np.array(HOVER_UNKNOWNS)
"""The rows and columns of :meth:`MixtureValues.hover_block` (a gather's indices)."""
_SMALLEST_SHARE = 0.9
"""Share of ``4 det C / tr(C)^2`` taken as the lower bound of ``C``'s smallest eigenvalue
(it is one; the share leaves room for the rounding of ``det``, which the singularity test
keeps below 1e-6 of it)."""


class ProcessNoise:
    """The process noise spectral density ``q`` (13, 13, diagonal) with its diagonal as
    floats, their largest, and the largest of the thrust scale's and the wind's (made once
    per filter)."""

    __slots__ = ("diagonal", "hover_largest", "largest", "matrix")

    def __init__(self, matrix: FloatArray) -> None:
        self.matrix = matrix
        self.diagonal: list[float] = np.diagonal(matrix).tolist()
        self.largest = max(map(abs, self.diagonal))
        self.hover_largest = max(abs(self.diagonal[i]) for i in HOVER_UNKNOWNS)


class MixtureBounds(NamedTuple):
    """What bounds a mixture's terms, in Python floats (:meth:`MixtureValues.bounds`)."""

    finite: bool
    """Whether the arrays are finite with a diagonal >= 0 (else: no approximation)."""
    sd: list[float]
    """Standard deviations [SI units]: ``|P_ij| <= sd_i sd_j`` bounds the terms."""
    largest_sd: float
    """The largest standard deviation [SI units]."""
    position_sd: float
    """The largest position standard deviation [m]."""
    velocity_sd: float
    """The largest velocity standard deviation [m/s]."""
    largest_value: float
    """The largest ``|x_i|`` [SI units]."""


def sd_bounds(
    diagonal: list[float], x_values: list[float]
) -> tuple[list[float], float, float, float, float]:
    """:class:`MixtureBounds`' fields after ``finite`` from the covariance's ``diagonal`` and the
    state's values: the standard deviations (NaN for a negative variance), their largest, the
    largest position and velocity ones, the largest ``|x_i|``. The reference of
    ``_bound_core.sd_bounds`` (:data:`SD_BOUNDS`)."""
    sd = [math.sqrt(v) if v >= 0.0 else math.nan for v in diagonal]
    return (
        sd,
        max(sd),
        max(sd[0], sd[1], sd[2]),
        max(sd[3], sd[4], sd[5]),
        max(max(x_values), -min(x_values)),
    )


SD_BOUNDS: Callable[..., tuple] = sd_bounds
""":func:`sd_bounds`, or where the optional C extension ``_bound_core`` is built (and
``TETHER_PURE_PYTHON`` is not set) its twin: the same floats, :func:`sd_bounds` called for
anything but a finite state and a finite non-negative diagonal (``bound_core.c``)."""
_CORE = optional_core.load("tether_companion.estimation.dynamic._bound_core")
if _CORE is not None and hasattr(_CORE, "sd_bounds"):
    SD_BOUNDS = functools.partial(_CORE.sd_bounds, sd_bounds)


class MixtureValues:
    """The mixture's mean and covariance with what every tick between two member steps reads
    of them as Python floats (made once per mixture: the members replace their arrays when
    they step; the bounds' scalars, :meth:`bounds`, on first use: only a read status needs
    them)."""

    __slots__ = (
        "_bounds",
        "_hover",
        "_position",
        "p",
        "x",
        "x_values",
    )

    def __init__(self, x: FloatArray, p: FloatArray) -> None:
        self.x = x
        self.p = p
        self.x_values: list[float] = x.tolist()
        self._bounds: MixtureBounds | None = None
        self._hover: HoverAnchor | None | bool = False
        self._position: tuple[tuple[float, ...], ...] | None = None

    def bounds(self) -> MixtureBounds:
        """The bounds' scalars (made on first use)."""
        bounds = self._bounds
        if bounds is None:
            x_values, p = self.x_values, self.p
            diagonal = p.diagonal().tolist()
            bounds = self._bounds = MixtureBounds(
                math.isfinite(sum(x_values))
                and bool(np.isfinite(p).all())
                and min(diagonal) >= 0.0,
                *SD_BOUNDS(diagonal, x_values),
            )
        return bounds

    @property
    def finite(self) -> bool:
        """Whether the arrays are finite with a diagonal >= 0 (else: no approximation)."""
        return self.bounds().finite

    @property
    def sd(self) -> list[float]:
        """Standard deviations [SI units]: ``|P_ij| <= sd_i sd_j`` bounds the terms."""
        return self.bounds().sd

    def position_terms(self) -> tuple[tuple[float, ...], ...]:
        """``P``'s north, north-east, east and down position entries [m^2]; the same entries'
        change per second of a batch step's velocity terms, ``P_i,3+j + P_3+i,j`` [m^2/s];
        and per second squared, ``P_3+i,3+j`` [m^2/s^2] (made on first use)."""
        terms = self._position
        if terms is None:
            pv = self.p[:6, :6].tolist()
            terms = self._position = (
                (pv[0][0], pv[0][1], pv[1][1], pv[2][2]),
                (
                    pv[0][3] + pv[3][0],
                    pv[0][4] + pv[3][1],
                    pv[1][4] + pv[4][1],
                    pv[2][5] + pv[5][2],
                ),
                (pv[3][3], pv[3][4], pv[4][4], pv[5][5]),
            )
        return terms

    def hover_block(self) -> list[list[float]]:
        """The covariance's columns of the thrust scale and the wind (:data:`HOVER_UNKNOWNS`)
        in the rows north, east, velocity north, velocity east and the three unknowns (7x3,
        floats; what :class:`HoverAnchor` reads of it, one gather instead of every row)."""
        return self.p[_HOVER_BLOCK_ROWS, _HOVER_BLOCK_COLUMNS].tolist()

    def hover(self) -> HoverAnchor | None:
        """The thrust scale and the wind's part of the horizontal covariance (made on first
        use; None where their covariance is too close to singular for the bound)."""
        hover = self._hover
        if hover is False:
            hover = self._hover = HoverAnchor.of(self)
        return hover  # type: ignore[return-value]


class HoverAnchor:
    """``X C^-1 X^T`` of the mixture stepped by a batch's velocity terms (``C``: the
    covariance of the thrust scale and the wind, ``X``: theirs with the horizontal position;
    the explained part of the horizontal covariance, :meth:`~tether_companion.estimation.
    dynamic.observability.HoverUnknowns.explains`), with a bound on what the rest of the step
    changes. ``C = L L^T``; a step of ``T`` moves ``X`` to ``X0 + T V + dX`` (``V``: the
    velocity rows' cross terms; ``dX``: the bias terms, each entry of row ``i`` within
    ``f_i sd_h``, ``f_i = sum_m |B_p,im| sd_8+m``) and ``C`` to ``C + T Q_h``; so with
    ``Y = L^-1 (X0 + T V)^T`` the explained part is ``Y^T Y`` up to the bound of
    :meth:`explains`, worked in the unknowns scaled by their standard deviations ``D``
    (``C' = D^-1 C D^-1``, a correlation matrix; ``X C^-1 X^T = X' C'^-1 X'^T``, ``X' = X
    D^-1``)."""

    __slots__ = ("largest_sd", "noise_scale", "sd", "smallest", "smallest_sd", "y0", "yv")

    def __init__(
        self,
        y0: tuple[float, ...],
        yv: tuple[float, ...],
        smallest: float,
        sd: tuple[float, float, float],
    ) -> None:
        self.y0 = y0
        """``L^-1 X0^T``'s columns for the north and east rows, flat (6) [m]."""
        self.yv = yv
        """``L^-1 V^T``'s, flat (6) [m/s]."""
        self.smallest = smallest
        """A lower bound of ``C'``'s smallest eigenvalue [1]."""
        self.sd = sd
        """The standard deviations of the thrust scale and the wind (``D``)."""
        self.noise_scale = (1.0 / (sd[0] * sd[0]), 1.0 / (sd[1] * sd[1]), 1.0 / (sd[2] * sd[2]))
        """``1 / sd_h^2``: ``T q_h`` scaled into ``C'``."""
        self.smallest_sd, self.largest_sd = min(sd), max(sd)
        """The smallest and the largest of :attr:`sd` (read at every tick)."""

    @classmethod
    def of(cls, mixture: MixtureValues) -> HoverAnchor | None:
        n, e, vn, ve, row0, row1, row2 = mixture.hover_block()
        h0, h1, h2 = HOVER_UNKNOWNS
        # written out (made at every member step): the unknowns' covariance C (upper
        # triangle), their standard deviations, and X0, V (the north and east rows)
        c00, c01, c02, c11, c12, c22 = row0[0], row0[1], row0[2], row1[1], row1[2], row2[2]
        msd = mixture.sd
        s0, s1, s2 = sd = (msd[h0], msd[h1], msd[h2])
        if not min(sd) > 0.0:
            return None
        trace = c00 + c11 + c22
        det = c00 * (c11 * c22 - c12 * c12) - c01 * (c01 * c22 - c12 * c02)
        det += c02 * (c01 * c12 - c11 * c02)
        # C nearly singular: the rounding of its factor is not bounded
        if not 4.0 * det / (trace * trace) > 1e3 * (3.0 * ROUNDING * max(sd) ** 2 + 1e-12 * trace):
            return None
        # C' = D^-1 C D^-1 (unit diagonal to rounding) and a bound of its smallest eigenvalue
        r01, r02, r12 = c01 / (s0 * s1), c02 / (s0 * s2), c12 / (s1 * s2)
        d00, d11, d22 = c00 / (s0 * s0), c11 / (s1 * s1), c22 / (s2 * s2)
        trace = d00 + d11 + d22
        det = d00 * (d11 * d22 - r12 * r12) - r01 * (r01 * d22 - r12 * r02)
        det += r02 * (r01 * r12 - d11 * r02)
        smallest = 4.0 * det / (trace * trace)
        if not smallest > 1e-6:
            return None
        factor = _cholesky_3x3(c00, c01, c02, c11, c12, c22)
        if factor is None:
            return None
        y0 = (*_forward(factor, *n), *_forward(factor, *e))
        yv = (*_forward(factor, *vn), *_forward(factor, *ve))
        return cls(y0, yv, _SMALLEST_SHARE * smallest, sd)

    def explains(
        self,
        horizontal_m2: tuple[float, float, float],
        horizontal_tol: float,
        spread: float,
        duration_s: float,
        noise: ProcessNoise,
        row_scale: float,
        max_std_m: float,
        margin: float,
    ) -> bool | None:
        """Whether the thrust scale and the wind explain the horizontal covariance at a tick
        (its larger standard deviation given them within ``max_std_m`` [m]), as the exact
        values say, or None when they could say otherwise.

        Parameters
        ----------
        horizontal_m2, horizontal_tol
            The tick's horizontal covariance entries (north-north, north-east, east-east)
            [m^2], each within ``horizontal_tol`` of the exact one's.
        spread
            ``max_i f_i`` over the north and east rows [m]: the step's bias terms move
            ``X'``'s entries by at most that.
        duration_s
            The step's ``T`` [s].
        noise
            The process noise.
        row_scale
            A bound of ``sum_k |Phi_ik| sd_k`` over ``Phi``'s rows (the exact cross terms'
            rounding scale).
        max_std_m, margin
            The bound and the relative margin of the comparison.

        With ``dC'`` (spectral norm <= ``delta``: ``T q_h / sd_h^2`` and the rounding),
        ``dX'`` (Frobenius <= ``dx``), ``l`` <= ``C'``'s smallest eigenvalue, ``m = l -
        delta`` > 0 and ``y^2 = tr(Y^T Y) >= |Y^T Y|``: ``|d(X C^-1 X^T)| <= (y^2 delta + 2 y
        dx sqrt(l) + dx^2) / m``.
        """
        t = duration_s
        n0, n1, n2, e0, e1, e2 = self.y0
        v = self.yv
        n0 += t * v[0]
        n1 += t * v[1]
        n2 += t * v[2]
        e0 += t * v[3]
        e1 += t * v[4]
        e2 += t * v[5]
        x_nn = n0 * n0 + n1 * n1 + n2 * n2
        x_ne = n0 * e0 + n1 * e1 + n2 * e2
        x_ee = e0 * e0 + e1 * e1 + e2 * e2
        y_sq = x_nn + x_ee
        smallest_sd, largest_sd = self.smallest_sd, self.largest_sd
        # the exact entries' rounding (absolute), scaled by the smallest sd_h sd_h'
        rounding = ROUNDING * (largest_sd * largest_sd + t * noise.largest)
        q = noise.diagonal
        w0, w1, w2 = self.noise_scale
        s, n, e = HOVER_UNKNOWNS
        d0, d1, d2 = q[s] * w0, q[n] * w1, q[e] * w2
        d1 = d1 if d1 > d0 else d0  # max(d0, d1, d2) without the builtin's call
        delta = t * (d2 if d2 > d1 else d1)
        delta += 3.0 * rounding / (smallest_sd * smallest_sd)
        dx = math.sqrt(6.0) * (spread + ROUNDING * row_scale * largest_sd / smallest_sd)
        smallest = self.smallest
        m = smallest - delta
        if not m > 0.0:
            return None
        moved = (y_sq * delta + 2.0 * math.sqrt(y_sq * smallest) * dx + dx * dx) / m
        a, b, c = horizontal_m2
        std = _largest_std_values(a - x_nn, b - x_ne, c - x_ee)
        bound_sq = max_std_m * max_std_m
        tol = 2.0 * (moved + 2.0 * horizontal_tol)
        tol += margin * (abs(a) + abs(b) + abs(c) + y_sq + bound_sq)
        if not abs(std * std - bound_sq) > tol:
            return None
        return std <= max_std_m


def _cholesky_3x3(
    c00: float, c01: float, c02: float, c11: float, c12: float, c22: float
) -> tuple[float, ...] | None:
    """The lower Cholesky factor of the symmetric 3x3 with upper triangle ``c00 .. c22``
    (row-major) as ``(l00, l10, l11, l20, l21, l22)``; None when it is not positive
    definite."""
    if not c00 > 0.0:
        return None
    l00 = math.sqrt(c00)
    l10, l20 = c01 / l00, c02 / l00
    d11 = c11 - l10 * l10
    if not d11 > 0.0:
        return None
    l11 = math.sqrt(d11)
    l21 = (c12 - l20 * l10) / l11
    d22 = c22 - l20 * l20 - l21 * l21
    if not d22 > 0.0:
        return None
    return l00, l10, l11, l20, l21, math.sqrt(d22)


def _forward(factor: tuple[float, ...], x0: float, x1: float, x2: float) -> tuple[float, ...]:
    """``L^-1 x`` for the factor of :func:`_cholesky_3x3`."""
    l00, l10, l11, l20, l21, l22 = factor
    y0 = x0 / l00
    y1 = (x1 - l10 * y0) / l11
    return y0, y1, (x2 - l20 * y0 - l21 * y1) / l22
