"""The dynamic filter's observability status: may the position be published, and if not why.

Checked in this order (the first that applies wins): restarted this tick, not initialised,
on the ground (:func:`~tether_companion.estimation.dynamic.on_ground.on_ground_reason`), inputs
stale, cable slack, the horizontal pull no larger than the wind's drag
could be, horizontal position standard deviation beyond the bound: ``learning`` when the part of the
horizontal covariance the thrust scale and the wind do not explain is within the bound (the
position waits only for them: after the start, and in a steady hover, where the thrust scale
trades against the cable's vertical pull and the wind's drag against its horizontal pull),
otherwise ``weak_pull`` (low tension, short cable). The covariance itself grows in those cases
(nothing pins the position); the status names the cause.

The pull-against-drag rule does not trust the filter's own covariance: the bearing of the
drone from the anchor is the direction of the cable's horizontal pull, which the filter reads
as the horizontal force beyond rotor drag in the wind. When that pull is not clearly larger
than the drag of a wind of the prior's standard deviation, a filter that started on the wrong
bearing learns a wrong wind to match and then claims both with a small covariance (measured on
the realistic sagging hover at 0.6 N with the winch length: published 10 m off at a position
standard deviation of 0.3 m).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation import optional_core
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.output import (
    INITIALISING,
    LEARNING,
    OK,
    ON_GROUND,
    RESET,
    SLACK,
    STALE_INPUTS,
    WEAK_PULL,
)

FloatArray = NDArray[np.float64]


class InnovationExcess:
    """The part of a scalar sensor's innovation variance the filter does not predict (covariance
    matching, Mehra 1972), counted only when a test with a stated false-alarm rate says the
    innovations are larger than predicted.

    Over the last ``time_constant_s`` [s] (exponential weights ``w_i``, normalised) it keeps
    the average of the normalised innovation squares ``y^2 / S`` (innovation ``y``, its
    predicted variance ``S = H P H^T + R``) and of ``y^2 - S``. Under innovations exactly as
    predicted the first is ``chi2(nu) / nu`` with ``nu = (sum w)^2 / sum w^2`` degrees of
    freedom (80 for 2 s of a 20 Hz rangefinder, 40 of a 10 Hz cable angle; the
    Welch-Satterthwaite approximation of the weighted sum). The excess is the average of
    ``y^2 - S`` while that average exceeds its ``1 -`` :data:`FALSE_ALARM` quantile (Wilson-
    Hilferty: ``(1 - a + z sqrt(a))^3``, ``a = 2 / (9 nu)``, ``z`` the normal quantile; 1.56
    for ``nu`` = 80, 2.27 for 20), else 0.

    A filter whose state is off by more than its covariance says shows it in its innovations
    before anything else (the take-off's height: 0.3 m off at a standard deviation of 0.07 m,
    rangefinder innovations up to 0.8 m against a predicted 0.33 m); the excess is added to the
    published variance of what the sensor measures, so the published covariance covers the
    error the innovations reveal (the filter's own covariance is left as it is).

    Why a test and not the average alone: the average's own sampling noise (``sqrt(2 sum w^2)
    S``: 0.16 S for the rangefinder's 2 s, ten times the height's own variance on the 4 N
    circle) is what an honest filter would publish. Clipped at 0 it added 0.064 S on average;
    the former rule (2 of its standard deviations, or any time within ``time_constant_s``
    of an innovation beyond 3 sigma, which 0.27 % of honest readings are) still 0.022 S, 2x
    the height's variance on the 4 N circle (nees15); this test adds 0.0005 S, nonzero 0.09 %
    of the time (1 h of 20 Hz innovations as predicted; rng16 in docs/estimation-history.md).
    """

    FALSE_ALARM = 1e-3
    """The test's false-alarm probability under innovations as predicted (per reading)."""
    _Z = NormalDist().inv_cdf(1.0 - FALSE_ALARM)
    """The standard normal's ``1 - FALSE_ALARM`` quantile (3.09)."""

    __slots__ = ("_excess", "_last_s", "_nis", "_tau_s", "_weight", "_weights_sq", "variance")

    def __init__(self, time_constant_s: float) -> None:
        self._tau_s = time_constant_s
        self._weight = 0.0
        """The sum of the average's weights (1 once many readings are in)."""
        self._weights_sq = 0.0
        """The sum of its squared weights."""
        self._nis = 0.0
        """The weighted sum of ``y^2 / S`` [1]."""
        self._excess = 0.0
        """The weighted sum of ``y^2 - S`` [unit^2]."""
        self._last_s = math.nan
        self.variance = 0.0
        """The excess variance [unit^2]: the average of ``y^2 - S`` while the test counts it,
        else 0."""

    def add(self, innovation: float, variance: float, time_s: float) -> None:
        """One innovation [unit] with its predicted variance [unit^2] at ``time_s`` [s]."""
        if not (math.isfinite(innovation) and math.isfinite(time_s) and 0.0 < variance < math.inf):
            return
        last = self._last_s
        gap = time_s - last if math.isfinite(last) else self._tau_s
        weight = 1.0 - math.exp(-(gap if gap > 0.0 else 0.0) / self._tau_s)
        kept = 1.0 - weight
        square = innovation * innovation
        total = self._weight = kept * self._weight + weight
        self._weights_sq = kept * kept * self._weights_sq + weight * weight
        self._nis = kept * self._nis + weight * square / variance
        excess = self._excess = kept * self._excess + weight * (square - variance)
        self._last_s = time_s
        # total > 0 from the first reading on (its weight is 1 - 1/e)
        a = 2.0 * self._weights_sq / (9.0 * total * total)
        quantile = 1.0 - a + self._Z * math.sqrt(a)
        quantile *= quantile * quantile
        significant = self._nis > quantile * total and excess > 0.0
        self.variance = excess / total if significant else 0.0


@dataclass(frozen=True)
class HoverUnknowns:
    """What the filter knows at one tick of the two things a steady hover does not tell from
    the cable's pull: the thrust scale (it trades against the cable's vertical pull) and the
    wind (its drag trades against the horizontal pull).

    Attributes
    ----------
    scale
        The thrust scale's estimate [1].
    wind_ne_mps
        The wind's estimate, north and east, shape (2,) [m/s].
    covariance
        The covariance of (scale, wind north, wind east), shape (3, 3).
    position_cross
        Their covariance with the horizontal position, shape (2, 3) [m, m^2/s].
    hypotheses
        Members of the thrust-scale bank still running (1: decided or collapsed).
    """

    scale: float
    wind_ne_mps: FloatArray
    covariance: FloatArray
    position_cross: FloatArray
    hypotheses: int

    def explains(self, horizontal_covariance_m2: FloatArray, max_std_m: float) -> bool:
        """Whether the horizontal position waits only for these: the bank is still choosing
        between thrust-scale hypotheses (their spread is the thrust scale's), or the horizontal
        covariance given the thrust scale and the wind (its Schur complement) has its larger
        standard deviation within ``max_std_m`` [m]."""
        if self.hypotheses > 1:
            return True
        (a, b), (_, c) = horizontal_covariance_m2.tolist()
        explained = _explained_2x2(self.covariance.tolist(), self.position_cross.tolist())
        if explained is None:
            return False
        return _largest_std_values(a - explained[0], b - explained[1], c - explained[2]) <= (
            max_std_m
        )

    def describe(self) -> str:
        """``thrust scale 1.041 +- 0.025, wind (-0.1, 0.5) +- 2.2 m/s`` and, while the bank
        runs, how many hypotheses are left."""
        sd = [math.sqrt(max(v, 0.0)) for v in self.covariance.diagonal().tolist()]
        north, east = self.wind_ne_mps.tolist()
        text = (
            f"thrust scale {self.scale:.3f} +- {sd[0]:.3f}, wind ({north:.1f}, {east:.1f}) +- "
            f"{max(sd[1], sd[2]):.1f} m/s"
        )
        return text + (f", {self.hypotheses} thrust hypotheses" if self.hypotheses > 1 else "")


MIN_TENSION_N = 0.01
"""Tension [N] below which :func:`unmodelled_position_covariance` takes this instead (the
cable's direction is then unknown and the variance huge but finite)."""


def unmodelled_position_covariance(
    position_ned_m: FloatArray, tension_n: float, force_std_n: float, length_std_m: float
) -> FloatArray:
    """What the filter's own covariance leaves out, as a position covariance (3, 3) [m^2].

    The filter reads the cable's direction as the horizontal force beyond the modelled
    thrust, drag and bias, and it fuses that every IMU tick as if what it leaves out (gusts'
    drag, the quadratic body drag, vibration) were white: averaged over the seconds the INS
    ties together, its covariance shrinks below the error a force correlated over seconds
    leaves. A horizontal force error ``dF`` (isotropic, std ``force_std_n`` [N]) turns the
    cable's direction by its component across the cable over the tension ``T``, which moves
    the drone by ``|p| (I - u u^T) dF / T`` (``u = p / |p|``, the range kept): the variance
    grows with the range and falls with the pull, as a bearing error does. ``length_std_m``
    [m] is kept along the cable (the winch length fused at every sample as if its error were
    white; 0 without a length).

    Parameters
    ----------
    position_ned_m
        Estimated position from the anchor, NED, shape (3,) [m] (not at the anchor).
    tension_n
        Estimated tension at the drone [N] (at least :data:`MIN_TENSION_N` is used).
    force_std_n
        Standard deviation of the unmodelled horizontal force [N].
    length_std_m
        Standard deviation kept along the cable [m].
    """
    n, e, d = (float(v) for v in position_ned_m)
    return np.array(unmodelled_position_rows(n, e, d, tension_n, force_std_n, length_std_m))


def unmodelled_position_rows(
    n: float, e: float, d: float, tension_n: float, force_std_n: float, length_std_m: float
) -> list[list[float]]:
    """:func:`unmodelled_position_covariance` as rows of Python floats, for the position
    ``(n, e, d)`` NED [m] (the same arithmetic: the array is made from these)."""
    distance = math.sqrt(n * n + e * e + d * d)
    if distance == 0.0:
        return [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
    u0, u1, u2 = n / distance, e / distance, d / distance
    # the columns of I - u u^T a horizontal force acts through (north, east)
    an0, an1, an2 = 1.0 - u0 * u0, -u1 * u0, -u2 * u0
    ae0, ae1, ae2 = -u0 * u1, 1.0 - u1 * u1, -u2 * u1
    gain = distance * force_std_n / (MIN_TENSION_N if MIN_TENSION_N > tension_n else tension_n)
    g, w = gain * gain, length_std_m * length_std_m
    # entry (i, j): g (an_i an_j + ae_i ae_j) + w u_i u_j, written out (runs every IMU tick)
    return [
        [
            g * (an0 * an0 + ae0 * ae0) + w * u0 * u0,
            g * (an0 * an1 + ae0 * ae1) + w * u0 * u1,
            g * (an0 * an2 + ae0 * ae2) + w * u0 * u2,
        ],
        [
            g * (an1 * an0 + ae1 * ae0) + w * u1 * u0,
            g * (an1 * an1 + ae1 * ae1) + w * u1 * u1,
            g * (an1 * an2 + ae1 * ae2) + w * u1 * u2,
        ],
        [
            g * (an2 * an0 + ae2 * ae0) + w * u2 * u0,
            g * (an2 * an1 + ae2 * ae1) + w * u2 * u1,
            g * (an2 * an2 + ae2 * ae2) + w * u2 * u2,
        ],
    ]


def horizontal_pull_n(x: list[float]) -> float:
    """The cable's horizontal pull at the drone, ``T_ch |p_ne| / |p|`` [N], from the state's
    values ``x`` (position NED from the anchor [m], chord tension [N])."""
    distance = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])
    if distance == 0.0:
        return 0.0
    return x[state.TENSION] * math.hypot(x[0], x[1]) / distance


def min_horizontal_pull_n(
    pull_per_wind_n_s_per_m: float, wind_std_mps: float, wind_n_mps: float, wind_e_mps: float
) -> float:
    """The least horizontal pull that fixes the bearing [N]: ``pull_per_wind_n_s_per_m``
    (``min_pull_over_wind_drag`` times the drag per unit airspeed, ``m mu`` [N s/m]) times the
    larger of the wind prior's standard deviation and the wind the filter itself estimates
    [m/s]. A filter that started on a wrong bearing explains the pull it reads with a wind it
    invents (realistic sagging circle, winch length given: 6-8 m/s of wind against 1.8 m/s
    blown, estimated pull 4.5 N against 1.3 N): the bearing it claims is then no better than
    that wind's drag."""
    speed = math.hypot(wind_n_mps, wind_e_mps)  # max(wind_std_mps, speed), the builtin's order
    return pull_per_wind_n_s_per_m * (speed if speed > wind_std_mps else wind_std_mps)


def assess(
    *,
    initialised_reason: str | None,
    reset_reason: str | None,
    on_ground: str,
    inputs_stale: bool,
    tension_n: float,
    slack_tension_n: float,
    position_covariance_m2: FloatArray,
    max_horizontal_std_m: float,
    horizontal_pull_n: float = math.inf,
    min_horizontal_pull_n: float = 0.0,
    hover_unknowns: HoverUnknowns | None = None,
    sag_std_m: float = 0.0,
) -> tuple[str, str]:
    """``(status, reason)`` of one tick (reason empty when ``ok``): :func:`decide` on these
    values, in words.

    Parameters
    ----------
    initialised_reason
        Why there is no state yet (None once initialised).
    reset_reason
        Why the filter restarted this tick (None if it did not).
    on_ground
        Why the drone is on the ground this tick
        (:func:`~tether_companion.estimation.dynamic.on_ground.on_ground_reason`; empty: it is
        not).
    inputs_stale
        Attitude or PWM stale.
    tension_n, slack_tension_n
        Estimated tension at the drone and the slack threshold [N].
    position_covariance_m2
        Position block of the covariance, shape (3, 3) [m^2].
    max_horizontal_std_m
        Bound on the larger horizontal standard deviation [m].
    horizontal_pull_n, min_horizontal_pull_n
        The cable's estimated horizontal pull at the drone and the least that fixes the
        bearing (a multiple of the wind drag's prior standard deviation) [N].
    hover_unknowns
        What the filter knows of the thrust scale and the wind (None: not told; then never
        ``learning``).
    sag_std_m
        The range's standard deviation over the plausible tensions at a fused winch length
        on a sagging cable [m] (:mod:`~tether_companion.estimation.dynamic.sag_range`);
        beyond ``max_horizontal_std_m`` the reason says the cable may rest on the ground;
        ``inf``: no winch length, and the cable may rest on the ground (withheld).
    """
    horizontal = position_covariance_m2[:2, :2]
    (a, b), (_, c) = horizontal.tolist()
    status = decide(
        initialised=initialised_reason is None,
        reset=reset_reason is not None,
        on_ground=on_ground,
        inputs_stale=inputs_stale,
        tension_n=tension_n,
        slack_tension_n=slack_tension_n,
        horizontal_m2=(a, b, c),
        max_horizontal_std_m=max_horizontal_std_m,
        horizontal_pull_n=horizontal_pull_n,
        min_horizontal_pull_n=min_horizontal_pull_n,
        explained=None
        if hover_unknowns is None
        else lambda: hover_unknowns.explains(horizontal, max_horizontal_std_m),
        range_unknown=sag_std_m == math.inf,
    )
    assert status is not None  # no margin: always decided
    if status == OK:
        return OK, ""
    if status == RESET:
        return RESET, reset_reason or ""
    if status == INITIALISING:
        return INITIALISING, initialised_reason or ""
    if status == ON_GROUND:
        return ON_GROUND, on_ground
    if status == STALE_INPUTS:
        return STALE_INPUTS, "attitude or motor outputs stale: prediction only"
    if status == SLACK:
        return SLACK, f"cable slack ({tension_n:.2f} N < {slack_tension_n:g} N)"
    if sag_std_m == math.inf:
        return WEAK_PULL, (
            "sagging cable, may rest on the ground: without the winch's length the range is"
            f" unknown ({tension_n:.1f} N)"
        )
    if horizontal_pull_n < min_horizontal_pull_n:
        return WEAK_PULL, (
            f"horizontal pull {horizontal_pull_n:.2f} N < {min_horizontal_pull_n:.2f} N: the"
            " wind's drag could turn the bearing"
        )
    std = _largest_std_values(a, b, c)
    if status == LEARNING:
        assert hover_unknowns is not None
        return LEARNING, (
            f"learning the thrust scale and the wind ({hover_unknowns.describe()}): horizontal"
            f" std {std:.2f} m > {max_horizontal_std_m:g} m; a steady hover does not tell"
            " them from the cable's pull, motion (a climb, a turn) or a load cell does"
        )
    if sag_std_m > max_horizontal_std_m:
        return WEAK_PULL, (
            f"sagging cable, may rest on the ground: at the winch's length the range depends"
            f" on the tension ({tension_n:.1f} N; range std {sag_std_m:.2f} m >"
            f" {max_horizontal_std_m:g} m)"
        )
    return WEAK_PULL, (
        f"horizontal std {std:.2f} m > {max_horizontal_std_m:g} m: pull too weak "
        f"({tension_n:.1f} N)"
    )


def decide(
    *,
    initialised: bool,
    reset: bool,
    on_ground: str,
    inputs_stale: bool,
    tension_n: float,
    slack_tension_n: float,
    horizontal_m2: tuple[float, float, float],
    max_horizontal_std_m: float,
    horizontal_pull_n: float,
    min_horizontal_pull_n: float,
    explained: Callable[[], bool | None] | None,
    margin: float = 0.0,
    variance_tol: float = 0.0,
    range_unknown: bool = False,
) -> str | None:
    """The status of one tick (the order of the module's docstring), or None when ``margin``
    > 0 and a comparison it needs is within ``margin`` (relative) of its threshold or not a
    number, or ``explained`` says it cannot tell: then only the exact values decide.

    Parameters
    ----------
    horizontal_m2
        The horizontal position covariance's entries (north-north, north-east, east-east)
        [m^2].
    explained
        Whether the horizontal covariance waits only for the thrust scale and the wind
        (:meth:`HoverUnknowns.explains`; None from it: cannot tell), asked only when the
        standard deviation is beyond the bound; None: never ``learning``.
    margin
        Relative margin of approximate values (0: the values are exact).
    variance_tol
        Bound of the approximate ``horizontal_m2`` entries' rounding [m^2] (0: exact).
    range_unknown
        The cable may rest on the ground and no winch length bounds the range: neither the
        pull at the drone nor the anchor's angle depends on the range there (only the
        grounded part's length does), so ``weak_pull``.
    Other parameters as for :func:`assess`.
    """
    if reset:
        return RESET
    if not initialised:
        return INITIALISING
    if on_ground:
        return ON_GROUND
    if inputs_stale:
        return STALE_INPUTS
    slack = _less(tension_n, slack_tension_n, margin)
    if slack is None or slack:
        return None if slack is None else SLACK
    if range_unknown:
        return WEAK_PULL
    weak = _less(horizontal_pull_n, min_horizontal_pull_n, margin)
    if weak is None or weak:
        return None if weak is None else WEAK_PULL
    std = _largest_std_values(*horizontal_m2)
    if margin > 0.0 or variance_tol > 0.0:  # the larger eigenvalue moves by <= 2 tol
        bound_sq = max_horizontal_std_m * max_horizontal_std_m
        if not abs(std * std - bound_sq) > 4.0 * variance_tol + margin * (std * std + bound_sq):
            return None
    if std <= max_horizontal_std_m:
        return OK
    if explained is None:
        return WEAK_PULL
    learning = explained()
    if learning is None:
        return None
    return LEARNING if learning else WEAK_PULL


DECIDE: Callable[..., str | None] = decide
""":func:`decide`, or where the optional C extension ``_status_core`` is built (and
``TETHER_PURE_PYTHON`` is not set) its twin: the same status, :func:`decide` called where C could
differ (``status_core.c``; the approximate status read calls it at every IMU tick)."""
_CORE = optional_core.load("tether_companion.estimation.dynamic._status_core")
if _CORE is not None:
    DECIDE = functools.partial(_CORE.decide, decide)


def _less(a: float, b: float, margin: float) -> bool | None:
    """``a < b``; None when ``margin`` > 0 and ``a`` is within ``margin`` (relative) of ``b``
    or either is not a number."""
    if margin > 0.0 and not abs(a - b) > margin * (abs(a) + abs(b)):
        return None
    return a < b


def _largest_std_values(a: float, b: float, c: float) -> float:
    """Square root of the larger eigenvalue of the symmetric 2x2 ``[[a, b], [b, c]]``."""
    largest = 0.5 * (a + c) + math.sqrt(0.25 * (a - c) ** 2 + b * b)
    return math.sqrt(0.0 if 0.0 > largest else largest)  # max(largest, 0.0), nan kept


def _explained_2x2(
    covariance: list[list[float]], cross: list[list[float]]
) -> tuple[float, float, float] | None:
    """``X C^-1 X^T`` as its entries (11, 12, 22): the part of a 2x2 covariance that three
    quantities of covariance ``C`` (3x3, symmetric positive definite) with cross-covariance
    ``X`` (2x3) explain, through the Cholesky factor ``C = L L^T`` (``Y = L^-1 X^T``,
    ``X C^-1 X^T = Y^T Y``). None when ``C`` is not positive definite."""
    (c00, c01, c02), (_, c11, c12), (_, _, c22) = covariance
    if c00 <= 0.0:
        return None
    l00 = math.sqrt(c00)
    l10, l20 = c01 / l00, c02 / l00
    d11 = c11 - l10 * l10
    if d11 <= 0.0:
        return None
    l11 = math.sqrt(d11)
    l21 = (c12 - l20 * l10) / l11
    d22 = c22 - l20 * l20 - l21 * l21
    if d22 <= 0.0:
        return None
    l22 = math.sqrt(d22)
    ys = []
    for x0, x1, x2 in cross:  # forward substitution L y = x, per row of X
        y0 = x0 / l00
        y1 = (x1 - l10 * y0) / l11
        y2 = (x2 - l20 * y0 - l21 * y1) / l22
        ys.append((y0, y1, y2))
    (p0, p1, p2), (q0, q1, q2) = ys
    return (p0 * p0 + p1 * p1 + p2 * p2, p0 * q0 + p1 * q1 + p2 * q2, q0 * q0 + q1 * q1 + q2 * q2)
