"""What the tension estimator (:mod:`~tether_companion.estimation.tension_kf`) gives per IMU
tick: :class:`TensionEstimate`, its counters :class:`TensionHealth`, and ``G`` of the
unmodelled terms (:mod:`~tether_companion.estimation.tension_budget`), made when read."""

from __future__ import annotations

import math
import operator
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.tension_budget import BUDGET_COLUMNS

FloatArray = NDArray[np.float64]


@dataclass(slots=True)
class TensionHealth:
    """Counters of what the tension estimator did with its inputs (monotonic).

    Attributes
    ----------
    updates
        Observations fused.
    stale_attitude, stale_pwm
        IMU ticks without an observation because attitude / PWM was missing or stale.
    nonfinite_rejected
        Samples or observations containing NaN/inf.
    absurd_rejected
        Observations larger than ``max_observed_tension_n``.
    out_of_order
        IMU samples older than the last one.
    restarts
        Filter restarts (first observation, long gap).
    """

    updates: int = 0
    stale_attitude: int = 0
    stale_pwm: int = 0
    nonfinite_rejected: int = 0
    absurd_rejected: int = 0
    out_of_order: int = 0
    restarts: int = 0

    def copy(self) -> TensionHealth:
        """A snapshot."""
        return TensionHealth(*TENSION_HEALTH_VALUES(self))


TENSION_HEALTH_VALUES = operator.attrgetter(*TensionHealth.__slots__)


class ConsiderFactor:
    """``G`` of one fused tick (:meth:`TensionErrorBudget.factor`), computed when first read and
    shared by the ticks that follow until the next fused one."""

    __slots__ = ("_inputs", "_matrix")

    def __init__(self, matrix: FloatArray | None = None, inputs: tuple | None = None) -> None:
        self._matrix = matrix
        self._inputs = inputs
        """``(budget, rotation rows, thrust [N], tension [N])`` while ``G`` is not made."""

    @property
    def matrix(self) -> FloatArray:
        """``G``, shape (3, BUDGET_COLUMNS) [N]."""
        matrix = self._matrix
        if matrix is None:
            budget, rotation_rows, thrust_n, tension = self._inputs  # type: ignore[misc]
            values = budget.factor(rotation_rows, thrust_n, tension)
            matrix = self._matrix = np.array(values).reshape(3, BUDGET_COLUMNS)
            self._inputs = None
        return matrix


class TensionEstimate:
    """Filtered tension at one IMU tick.

    Made by :class:`TensionEstimator` from the filter's floats: the arrays below are built
    when first read (most ticks nobody reads ``G``), then kept. Built directly (tests, other
    makers), it takes the arrays as before.

    Attributes
    ----------
    time_s
        Flight-controller time of the tick [s].
    tension_ned_n
        Force of the cable ON the drone, NED, shape (3,) [N]; ``nan`` before the first fused
        observation.
    variance_n2
        The filter's variance of each component [N^2] (white noise only).
    last_update_s
        Time of the last fused observation [s] (``nan`` if none): ``time_s - last_update_s``
        is the estimate's age.
    observation_ned_n
        This tick's raw observation (eq. 50) [N], ``nan`` when none was made.
    updated
        Whether this tick fused an observation.
    health
        Snapshot of the counters.
    consider_factor_n
        ``G``, shape (3, :data:`~tether_companion.estimation.tension_budget.BUDGET_COLUMNS`)
        [N]: the unmodelled terms of eq. 50 (thrust map, drag, attitude), one standard
        deviation per column, NED (:mod:`~tether_companion.estimation.tension_budget`).
    consider_variance_n2
        The isotropic unmodelled term (accelerometer bias times mass, squared) [N^2].
    """

    __slots__ = (
        "time_s",
        "variance_n2",
        "last_update_s",
        "updated",
        "consider_variance_n2",
        "_tension",
        "_tension_values",
        "_observation",
        "_observation_values",
        "_health",
        "_health_values",
        "_factor",
    )

    def __init__(
        self,
        time_s: float,
        tension_ned_n: FloatArray,
        variance_n2: float,
        last_update_s: float,
        observation_ned_n: FloatArray,
        updated: bool,
        health: TensionHealth,
        consider_factor_n: FloatArray | None = None,
        consider_variance_n2: float = 0.0,
    ) -> None:
        self.time_s = time_s
        self.variance_n2 = variance_n2
        self.last_update_s = last_update_s
        self.updated = updated
        self.consider_variance_n2 = consider_variance_n2
        self._tension: FloatArray | None = tension_ned_n
        self._tension_values: Sequence[float] = ()
        self._observation: FloatArray | None = observation_ned_n
        self._observation_values: Sequence[float] | None = None
        self._health: TensionHealth | None = health
        self._health_values: tuple[int, ...] = ()
        self._factor = ConsiderFactor(
            np.zeros((3, BUDGET_COLUMNS)) if consider_factor_n is None else consider_factor_n
        )

    @classmethod
    def of_values(
        cls,
        time_s: float,
        tension_values: Sequence[float],
        variance_n2: float,
        last_update_s: float,
        observation_values: Sequence[float] | None,
        updated: bool,
        health_values: tuple[int, ...],
        factor: ConsiderFactor,
        consider_variance_n2: float,
    ) -> TensionEstimate:
        """The estimator's tick: the tension and observation as 3 floats each (``None``: no
        observation), the counters' values, ``G`` as a shared :class:`ConsiderFactor`."""
        estimate = cls.__new__(cls)
        estimate.time_s = time_s
        estimate.variance_n2 = variance_n2
        estimate.last_update_s = last_update_s
        estimate.updated = updated
        estimate.consider_variance_n2 = consider_variance_n2
        estimate._tension = None
        estimate._tension_values = tension_values
        estimate._observation = None
        estimate._observation_values = observation_values
        estimate._health = None
        estimate._health_values = health_values
        estimate._factor = factor
        return estimate

    def __repr__(self) -> str:
        return (
            f"TensionEstimate(time_s={self.time_s!r}, tension_ned_n={self.tension_ned_n!r}, "
            f"variance_n2={self.variance_n2!r}, last_update_s={self.last_update_s!r}, "
            f"observation_ned_n={self.observation_ned_n!r}, updated={self.updated!r}, "
            f"consider_variance_n2={self.consider_variance_n2!r})"
        )

    @property
    def tension_ned_n(self) -> FloatArray:
        """Force of the cable on the drone, NED, shape (3,) [N] (see the class docstring)."""
        tension = self._tension
        if tension is None:
            tension = self._tension = np.array(self._tension_values, dtype=float)
        return tension

    @property
    def observation_ned_n(self) -> FloatArray:
        """This tick's raw observation (eq. 50), NED, shape (3,) [N]; ``nan`` when none."""
        observation = self._observation
        if observation is None:
            values = self._observation_values
            observation = self._observation = (
                _NAN3.copy() if values is None else np.array(values, dtype=float)
            )
        return observation

    @property
    def health(self) -> TensionHealth:
        """Snapshot of the estimator's counters at this tick."""
        health = self._health
        if health is None:
            health = self._health = TensionHealth(*self._health_values)
        return health

    @property
    def consider_factor_n(self) -> FloatArray:
        """``G``, shape (3, BUDGET_COLUMNS) [N] (see the class docstring)."""
        return self._factor.matrix

    @property
    def isotropic_variance_n2(self) -> float:
        """The filter's variance plus the accelerometer bias's, per axis [N^2]."""
        return self.variance_n2 + self.consider_variance_n2

    @property
    def covariance_ned_n2(self) -> FloatArray:
        """Covariance of :attr:`tension_ned_n`, shape (3, 3) [N^2]: ``(s_kf^2 + (m s_b)^2) I +
        G G^T`` (white noise and the consider budget)."""
        g = self.consider_factor_n
        return self.isotropic_variance_n2 * np.eye(3) + g @ g.T

    @property
    def magnitude_variance_n2(self) -> float:
        """Variance of :attr:`magnitude_n` [N^2] (along the force; the isotropic variance when
        there is no force)."""
        magnitude = self.magnitude_n
        if not magnitude > 0.0:
            return self.isotropic_variance_n2
        u = self.tension_ned_n / magnitude
        along = self.consider_factor_n.T @ u
        return self.isotropic_variance_n2 + float(along @ along)

    @property
    def magnitude_n(self) -> float:
        """Tension magnitude [N]."""
        return float(np.linalg.norm(self.tension_ned_n))

    @property
    def horizontal_n(self) -> float:
        """Magnitude of the horizontal part of the force on the drone [N]."""
        return math.hypot(float(self.tension_ned_n[0]), float(self.tension_ned_n[1]))

    @property
    def down_n(self) -> float:
        """Downward component of the force on the drone [N] (NED ``d``)."""
        return float(self.tension_ned_n[2])

    @property
    def pull_direction_rad(self) -> float:
        """Bearing of the horizontal pull on the drone from north, toward east [rad].

        The direction the cable drags the drone (toward the anchor for a free-hanging cable,
        along the tug for a pull). ``nan`` when there is no horizontal force.
        """
        n, e = float(self.tension_ned_n[0]), float(self.tension_ned_n[1])
        return math.atan2(e, n) if (n != 0.0 or e != 0.0) else math.nan

    @property
    def valid(self) -> bool:
        """Whether an estimate exists and is finite."""
        if self._tension is None:
            n, e, d = self._tension_values
            finite = math.isfinite
            return finite(n) and finite(e) and finite(d) and finite(self.variance_n2)
        return bool(np.isfinite(self._tension).all()) and math.isfinite(self.variance_n2)

    def age_s(self, now_s: float) -> float:
        """Time since the last fused observation at ``now_s`` [s] (``inf`` if none)."""
        return now_s - self.last_update_s if math.isfinite(self.last_update_s) else math.inf


_NAN3 = np.full(3, math.nan)
