"""Drone position from the tether's pull and the catenary shape (Martins 2019, section 6).

Fed by the tension filter (:class:`~tether_companion.estimation.tension_kf.TensionEstimate`)
and, for the known-length case, by the paid-out length of the winch, this estimator turns the
force of the cable on the drone into the drone's NED position relative to the anchor:

* ``lowest_point_at_anchor`` (section 6.1, eqs. 57-64): a ground controller keeps the
  tether's lowest point at the anchor;
* ``known_length`` (section 6.2, eqs. 65-71): the paid-out length ``L`` is known. With
  ``anchor_on_ground`` (the usual ground station, and the simulator's cable), a cable whose
  free catenary would dip below the anchor lies on the ground from the anchor to a touchdown
  point instead and rises from there as a case-1 catenary: for ``s2 <= L`` the drone is at
  ``r = (L - s2) + a asinh(s2/a)``, ``z = sqrt(a^2 + s2^2) - a``; for ``s2 > L`` the cable
  hangs free with its lowest point behind the anchor (the thesis' case 2). The two branches
  meet at ``s2 = L``. Without ``anchor_on_ground`` the free case-2 curve is used throughout
  (anchor raised above the lowest point, as the thesis' experiments with ``z_i = 0.754 m``).

The horizontal direction of the drone from the anchor is that of the **negated** horizontal
force on the drone (the cable pulls toward the anchor). Cable stretch is ignored.

A cable lying on the ground with (almost) no horizontal pull rises straight up from wherever
it leaves the ground: its pull says nothing about the drone's horizontal position, and the
estimator reports ``unobservable`` rather than guess (the thesis' ``a -> 0`` limit would put
the drone over the anchor).

The position covariance maps every uncertain input through the Jacobian of the position
(:func:`position_jacobian`, the closed form of the geometry below, checked against finite
differences in the tests): the force (the tension filter's covariance ``Sigma_F``: its white
noise plus the consider budget of the terms eq. 50 leaves out, thrust map, drag, accelerometer
bias and attitude, :mod:`~tether_companion.estimation.tension_budget`), the paid-out length
(``length_std_m``, known-length case) and the weight per length
(``weight_per_length_rel_std``), plus ``min_position_std_m^2 I``::

    P = J_f Sigma_F J_f^T + s_L^2 j_L j_L^T + s_w^2 j_w j_w^T + D + s_min^2 I

built as ``G G^T`` from ``G = [J_f s_F I, J_f G_F, s_L j_L, s_w j_w]`` (``Sigma_F = s_F^2 I +
G_F G_F^T``; symmetric by construction). The force term alone is singular where the geometry
pins a direction: a cable lying on the ground over most of its length puts the drone at
``r = L`` whatever the pull (``dr/dF ~ 0``), and its azimuth is uncertain while its range is
not. ``J_f J_f^T`` is then rank deficient, rounding makes it indefinite (negative NEES), and
the estimate claims to know the range exactly while it is only as good as the winch's length.
The length and weight terms put that uncertainty back; the floor keeps ``P`` positive definite
where even they vanish (a cable hanging straight down from a drone above the anchor).

**Geometry.** With ``a = H / w`` (``H`` the horizontal pull), ``s2 = F_d / w`` and
``s1 = s2 - L``, ``g(s) = a asinh(s / a)``, ``h(s) = sqrt(a^2 + s^2)``, the drone is at
``r = g(s2) - g(s1)``, ``z = h(s2) - h(s1)`` (free cable; ``lowest_point_at_anchor`` has
``s1 = 0``), or ``r = (L - s2) + g(s2)``, ``z = h(s2) - a`` (grounded, ``s2 <= L``), and at
``(-r u, -z)`` in NED with ``u`` the horizontal pull's direction. The partials are
``dg/ds = a / h``, ``dg/da = asinh(s / a) - s / h``, ``dh/ds = s / h``, ``dh/da = a / h``; the two
known-length branches meet with equal first derivatives at ``s2 = L``. Across the pull the
position turns with the azimuth: ``dp/dF`` has ``-(r / H) (I - u u^T)`` horizontally, so the
position's lateral standard deviation is ``r`` times the azimuth's ``s_psi = s_perp / H``.

**Ill-conditioned geometry.** The Jacobian is a linearisation. Where the geometry curves
over the force's uncertainty it under-states the spread: a cable lying mostly on the ground
has ``dz/dF_d ~ 0`` at the estimate, yet half a newton more pull lifts metres of it. The
covariance therefore adds the linearisation's residual ``D``: the second moment of
``p(F + d_i) - p(F) - J_f d_i`` over the unscented transform's six points
``d_i = +-sqrt(3) S e_i`` (``Sigma_F = S S^T``), measured about the estimate, so that it
counts the curvature's bias as well as its spread (small where the geometry is straight over
the force's error; six position solutions a tick). A point the geometry cannot explain (a
force the catenary of this length cannot produce) makes the tick ``weak_pull``. The azimuth's
error is the other non-linearity: once ``s_psi`` is not small it is not Gaussian (a pull as
weak as its error can point anywhere, and the drone's estimate flips to the other side of the
anchor). Above ``max_azimuth_std_rad`` the estimator says ``weak_pull``
(the service withholds, or inflates by ``publish.on_unhealthy``); the position is still
returned for inspection and scoring, with its covariance inflated by ``r^2`` on each
horizontal axis: the azimuth is given up, the drone is somewhere on the circle of radius ``r``
about the anchor (an error up to ``2 r``).

Pure and synchronous. The service can run it beside or instead of the tether EKF.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.config import spec
from tether_companion.estimation.tension_kf import TensionEstimate
from tether_companion.physics.catenary import solve_known_length, solve_lowest_point_at_anchor
from tether_companion.physics.catenary_forces import (
    curve_from_tension_known_length,
    curve_from_tension_lowest_point_at_anchor,
    drone_point,
    end_tensions,
    plane_coordinates,
)

FloatArray = NDArray[np.float64]

LOWEST_POINT_AT_ANCHOR = "lowest_point_at_anchor"
KNOWN_LENGTH = "known_length"

OK = "ok"
NO_TENSION = "no_tension"
STALE_TENSION = "stale_tension"
NO_LENGTH = "no_length"
INCONSISTENT = "inconsistent"
UNOBSERVABLE = "unobservable"
WEAK_PULL = "weak_pull"

JACOBIAN_COLUMNS = ("force_n", "force_e", "force_d", "length", "weight_per_length")
"""Columns of :func:`position_jacobian`."""


@dataclass(frozen=True)
class CatenaryPositionConfig:
    """Settings of the catenary position estimator."""

    case: str = spec(
        KNOWN_LENGTH,
        choices=(LOWEST_POINT_AT_ANCHOR, KNOWN_LENGTH),
        doc="which extra information fixes the curve (Martins section 6.1 or 6.2)",
    )
    weight_per_length_n_per_m: float = spec(
        0.164, exclusive_minimum=0.0, doc="cable weight per length w = rho g [N/m]"
    )
    anchor_on_ground: bool = spec(
        True, doc="known_length: slack cable lies on the ground at the anchor's level"
    )
    default_length_m: float = spec(
        10.0, exclusive_minimum=0.0, doc="known_length: paid-out length until one is reported [m]"
    )
    max_tension_age_s: float = spec(
        0.3, exclusive_minimum=0.0, doc="tension estimates older than this are not used [s]"
    )
    max_length_age_s: float = spec(
        5.0, exclusive_minimum=0.0, doc="paid-out length reports older than this are not used [s]"
    )
    min_horizontal_tension_n: float = spec(
        0.02,
        minimum=0.0,
        doc="known_length on the ground: a weaker horizontal pull leaves the drone's horizontal "
        "position unobservable [N]",
    )
    max_azimuth_std_rad: float = spec(
        0.35,
        exclusive_minimum=0.0,
        doc="a pull whose direction's standard deviation (its error across the pull over its "
        "horizontal size) exceeds this is weak_pull: the geometry is ill-conditioned [rad]",
    )
    length_std_m: float = spec(
        0.1,
        minimum=0.0,
        doc="known_length: standard deviation of the reported paid-out length (drum layering, "
        "stretch; about 1-2 % of a 5-10 m tether) [m]",
    )
    weight_per_length_rel_std: float = spec(
        0.05,
        minimum=0.0,
        maximum=1.0,
        doc="relative standard deviation of the weight per length (datasheet tolerance, "
        "moisture) [-]",
    )
    min_position_std_m: float = spec(
        0.01,
        exclusive_minimum=0.0,
        doc="floor of the position standard deviation per axis, keeps the covariance positive "
        "definite [m]",
    )


@dataclass(frozen=True, slots=True)
class CatenaryPosition:
    """Output of :class:`CatenaryPositionEstimator` at one tension tick.

    Attributes
    ----------
    time_s
        Time of the tension estimate [s].
    position_ned_m
        Drone position relative to the anchor, NED, shape (3,) [m]; ``nan`` when invalid.
    covariance_m2
        Position covariance, shape (3, 3) [m^2]; ``nan`` when invalid.
    status
        ``ok`` or why no position was produced (``no_tension``, ``stale_tension``,
        ``no_length``, ``inconsistent``: the geometry cannot explain the force,
        ``unobservable``: a slack cable lying on the ground with no horizontal pull), or
        ``weak_pull``: the pull's direction is too uncertain for the linearised covariance
        (module docstring); position and (inflated) covariance are given but not to be
        published.
    azimuth_std_rad
        Standard deviation of the pull's horizontal direction [rad] (``nan`` when none).
    """

    time_s: float
    position_ned_m: FloatArray
    covariance_m2: FloatArray
    status: str
    azimuth_std_rad: float = math.nan

    @property
    def valid(self) -> bool:
        """Whether the position is fit to publish."""
        return self.status == OK


def position_from_force_ned_m(
    force_on_drone_ned_n: FloatArray,
    case: str,
    weight_per_length_n_per_m: float,
    length_m: float = math.nan,
    anchor_on_ground: bool = True,
) -> FloatArray:
    """Drone position (NED, anchor origin) [m], shape (3,), from the cable's force on it.

    Parameters
    ----------
    force_on_drone_ned_n
        Force of the cable on the drone, NED, shape (3,) [N].
    case
        ``lowest_point_at_anchor`` or ``known_length``.
    weight_per_length_n_per_m
        Cable weight per length [N/m].
    length_m
        Paid-out length [m] (``known_length`` only).
    anchor_on_ground
        ``known_length`` only: see the module docstring.

    Raises
    ------
    ValueError
        Inputs the geometry cannot explain (see
        :func:`~tether_companion.physics.catenary_forces.curve_from_tension_lowest_point_at_anchor`).
    """
    fn, fe, fd = (float(v) for v in force_on_drone_ned_n)
    horizontal_n = math.hypot(fn, fe)
    w = weight_per_length_n_per_m
    if case == LOWEST_POINT_AT_ANCHOR:
        r, z = drone_point(curve_from_tension_lowest_point_at_anchor(horizontal_n, fd, w))
    else:
        curve = curve_from_tension_known_length(horizontal_n, fd, length_m, w)
        if _grounded(case, anchor_on_ground, curve.s2_m, length_m):
            grounded = length_m - curve.s2_m
            rise = curve_from_tension_lowest_point_at_anchor(horizontal_n, fd, w)
            r, z = drone_point(rise)
            r += grounded
        else:
            r, z = drone_point(curve)
    if horizontal_n > 0.0:
        return np.array((-r * fn / horizontal_n, -r * fe / horizontal_n, -z))
    return np.array((0.0, 0.0, -z))


def _grounded(case: str, anchor_on_ground: bool, s2: float, length_m: float) -> bool:
    return case == KNOWN_LENGTH and anchor_on_ground and s2 <= length_m


def position_jacobian(
    force_on_drone_ned_n: FloatArray,
    case: str,
    weight_per_length_n_per_m: float,
    length_m: float = math.nan,
    anchor_on_ground: bool = True,
) -> FloatArray:
    """Jacobian of :func:`position_from_force_ned_m`, shape (3, 5): NED position [m] by the
    force (three columns, [m/N]), the paid-out length ([m/m], zero for
    ``lowest_point_at_anchor``) and the weight per length ([m per N/m]); see
    :data:`JACOBIAN_COLUMNS` and the module docstring for the closed form.

    Raises
    ------
    ValueError
        No horizontal pull (the direction, and so the derivative across it, is undefined), or
        a non-positive weight per length.
    """
    fn, fe, fd = (float(v) for v in force_on_drone_ned_n)
    w = float(weight_per_length_n_per_m)
    horizontal = math.hypot(fn, fe)
    if not (horizontal > 0.0 and w > 0.0):
        raise ValueError("the Jacobian needs a horizontal pull and a weight per length > 0")
    a, s2 = horizontal / w, fd / w
    h2 = math.hypot(a, s2)
    g_a2 = math.asinh(s2 / a) - s2 / h2  # dg/da at s2
    if case == LOWEST_POINT_AT_ANCHOR or _grounded(case, anchor_on_ground, s2, length_m):
        grounded = case == KNOWN_LENGTH
        r = (length_m - s2 if grounded else 0.0) + a * math.asinh(s2 / a)
        r_a, r_s, r_l = g_a2, a / h2 - (1.0 if grounded else 0.0), (1.0 if grounded else 0.0)
        z_a, z_s, z_l = a / h2 - 1.0, s2 / h2, 0.0
    else:
        s1 = s2 - length_m
        h1 = math.hypot(a, s1)
        r = a * (math.asinh(s2 / a) - math.asinh(s1 / a))
        r_a, r_s, r_l = g_a2 - (math.asinh(s1 / a) - s1 / h1), a / h2 - a / h1, a / h1
        z_a, z_s, z_l = a / h2 - a / h1, s2 / h2 - s1 / h1, s1 / h1
    un, ue = fn / horizontal, fe / horizontal
    # d/dH = (1/w) d/da, d/dF_d = (1/w) d/ds2, d/dw = -(a d/da + s2 d/ds2) / w at fixed L
    r_h, r_d, r_w = r_a / w, r_s / w, -(a * r_a + s2 * r_s) / w
    z_h, z_d, z_w = z_a / w, z_s / w, -(a * z_a + s2 * z_s) / w
    across = r / horizontal  # the azimuth's lever: p_ne turns with the pull
    return np.array(
        (
            (-r_h * un * un - across * ue * ue, -(r_h - across) * un * ue, -r_d * un,
             -r_l * un, -r_w * un),
            (-(r_h - across) * un * ue, -r_h * ue * ue - across * un * un, -r_d * ue,
             -r_l * ue, -r_w * ue),
            (-z_h * un, -z_h * ue, -z_d, -z_l, -z_w),
        )
    )  # fmt: skip


def force_from_position_ned_n(
    position_ned_m: FloatArray,
    length_m: float,
    weight_per_length_n_per_m: float,
    anchor_on_ground: bool = True,
) -> FloatArray:
    """Force of the cable on a drone at ``position_ned_m`` (NED, anchor origin) [N], shape (3,).

    The forward model that :func:`position_from_force_ned_m` (``known_length``) inverts: the
    free case-2 catenary, or, with ``anchor_on_ground`` and a cable slack enough to touch the
    ground, a grounded stretch from the anchor to a touchdown point ``t`` and a case-1
    catenary from there (``t`` solves ``t + L1(X - t, H) = L`` by bisection; ``L1`` is the
    case-1 length, increasing as ``t`` grows). Used for goal tensions (section 5.2).

    Raises
    ------
    ValueError
        Cable not longer than the anchor-drone distance, drone not above the ground (with
        ``anchor_on_ground``), or invalid numbers.
    """
    horizontal, height, unit = plane_coordinates(position_ned_m)
    w = weight_per_length_n_per_m
    curve = solve_known_length(horizontal, height, length_m)
    if anchor_on_ground and curve.s1_m < 0.0:
        if height <= 0.0:
            raise ValueError(f"the drone must be above the ground, got height {height!r} m")
        if length_m >= horizontal + height:
            curve = solve_lowest_point_at_anchor(0.0, height)  # lies on the ground, rises
        else:
            low, high = 0.0, horizontal
            for _ in range(200):
                mid = 0.5 * (low + high)
                rest = solve_lowest_point_at_anchor(horizontal - mid, height).length_m
                if mid + rest < length_m:
                    low = mid
                else:
                    high = mid
                if high - low <= 1e-12 * max(1.0, horizontal):
                    break
            curve = solve_lowest_point_at_anchor(horizontal - 0.5 * (low + high), height)
    tensions = end_tensions(curve, w)
    pull = tensions.on_drone_horizontal_n
    return np.array((pull * unit[0], pull * unit[1], -tensions.on_drone_vertical_n))


class CatenaryPositionEstimator:
    """Position from the filtered tension and the catenary (see the module docstring).

    Parameters
    ----------
    config
        Which case, the cable's weight per length, staleness bounds.
    """

    def __init__(self, config: CatenaryPositionConfig) -> None:
        self.config = config
        self._length_m = config.default_length_m
        self._length_time_s = math.nan
        self.rejected = 0

    @property
    def length_m(self) -> float:
        """Paid-out length in use [m]."""
        return self._length_m

    def set_paid_out_length_m(self, length_m: float, time_s: float) -> None:
        """Report the winch's paid-out length [m] at ``time_s`` [s] (refused if not > 0)."""
        if not (math.isfinite(length_m) and math.isfinite(time_s) and length_m > 0.0):
            self.rejected += 1
            return
        self._length_m = float(length_m)
        self._length_time_s = float(time_s)

    def on_tension(self, estimate: TensionEstimate) -> CatenaryPosition:
        """The position at the time of ``estimate``."""
        cfg = self.config
        t = estimate.time_s
        if not estimate.valid:
            return self._invalid(t, NO_TENSION)
        if not estimate.age_s(t) <= cfg.max_tension_age_s:
            return self._invalid(t, STALE_TENSION)
        length = math.nan
        if cfg.case == KNOWN_LENGTH:
            length = self._length_m
            reported = self._length_time_s
            if math.isfinite(reported) and not t - reported <= cfg.max_length_age_s:
                return self._invalid(t, NO_LENGTH)
        force = estimate.tension_ned_n
        if (
            cfg.case == KNOWN_LENGTH
            and cfg.anchor_on_ground
            and math.hypot(force[0], force[1]) < cfg.min_horizontal_tension_n
            and force[2] < cfg.weight_per_length_n_per_m * length
        ):
            return self._invalid(t, UNOBSERVABLE)
        azimuth_std = _azimuth_std_rad(force, estimate)
        if not math.isfinite(azimuth_std):  # no horizontal pull: no direction at all
            return self._invalid(t, WEAK_PULL)
        try:
            position = self._position(force, length)
            jacobian = position_jacobian(
                force, cfg.case, cfg.weight_per_length_n_per_m, length, cfg.anchor_on_ground
            )
        except ValueError:
            return self._invalid(t, INCONSISTENT)
        factor = self._covariance_factor(jacobian, estimate)
        curvature, explained = self._curvature(force, length, position, jacobian, estimate)
        covariance = factor @ factor.T + curvature + cfg.min_position_std_m**2 * np.eye(3)
        if explained and azimuth_std <= cfg.max_azimuth_std_rad:
            return CatenaryPosition(t, position, covariance, OK, azimuth_std)
        self.rejected += 1
        covariance[:2, :2] += float(position[0] ** 2 + position[1] ** 2) * np.eye(2)
        return CatenaryPosition(t, position, covariance, WEAK_PULL, azimuth_std)

    def _covariance_factor(self, jacobian: FloatArray, estimate: TensionEstimate) -> FloatArray:
        """``G`` with ``P = G G^T + s_min^2 I`` (module docstring): the position's sensitivity
        [m] to one standard deviation of each of the force's error terms (isotropic, then the
        consider budget's columns), the length and the weight per length."""
        cfg = self.config
        force_part = jacobian[:, :3]
        columns = [
            force_part * math.sqrt(estimate.isotropic_variance_n2),
            force_part @ estimate.consider_factor_n,
        ]
        if cfg.case == KNOWN_LENGTH:
            columns.append(jacobian[:, 3:4] * cfg.length_std_m)
        columns.append(
            jacobian[:, 4:5] * (cfg.weight_per_length_rel_std * cfg.weight_per_length_n_per_m)
        )
        return np.hstack(columns)

    def _curvature(
        self,
        force: FloatArray,
        length_m: float,
        position: FloatArray,
        jacobian: FloatArray,
        estimate: TensionEstimate,
    ) -> tuple[FloatArray, bool]:
        """What the linearisation misses over the force's uncertainty, and whether the geometry
        explains all of it (module docstring): the second moment ``D`` [m^2], shape (3, 3), of
        ``p(F + d_i) - p(F) - J_f d_i`` over the six points ``d_i = +-sqrt(3) S e_i``
        (``Sigma_F = S S^T``; the unscented transform's points, weight 1/6 each), and False when
        a point is a force the catenary cannot explain (then D is over the points that are)."""
        root = np.linalg.cholesky(estimate.covariance_ned_n2) * math.sqrt(3.0)
        force_part = jacobian[:, :3]
        curvature = np.zeros((3, 3))
        explained = True
        for column in (*root.T, *(-root.T)):
            try:
                residual = self._position(force + column, length_m) - position
            except ValueError:
                explained = False
                continue
            residual -= force_part @ column
            curvature += np.outer(residual, residual) / 6.0
        return curvature, explained

    def _position(self, force: FloatArray, length_m: float) -> FloatArray:
        cfg = self.config
        return position_from_force_ned_m(
            force, cfg.case, cfg.weight_per_length_n_per_m, length_m, cfg.anchor_on_ground
        )

    def _invalid(self, time_s: float, status: str) -> CatenaryPosition:
        self.rejected += 1
        return CatenaryPosition(time_s, np.full(3, math.nan), np.full((3, 3), math.nan), status)


def _azimuth_std_rad(force: FloatArray, estimate: TensionEstimate) -> float:
    """Standard deviation of the horizontal pull's direction [rad]: the force's error across
    the pull, horizontally, over the pull's size (``inf`` without a horizontal pull)."""
    horizontal = math.hypot(force[0], force[1])
    if not horizontal > 0.0:
        return math.inf
    across = np.array((-force[1], force[0], 0.0)) / horizontal
    spread = estimate.consider_factor_n.T @ across
    return math.sqrt(estimate.isotropic_variance_n2 + float(spread @ spread)) / horizontal
