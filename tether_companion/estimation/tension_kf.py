"""Tension of the tether on the drone from attitude, thrust and acceleration, Kalman filtered.

Martins (2019) section 4. The observation (eq. 50) in our frames: the accelerometer measures
the specific force ``f_sf = (F_thrust + F_cable) / m`` in the FRD body frame (gravity is not
felt), with ``F_thrust = [0, 0, -T]`` (total rotor thrust along body -z). Hence the force of
the cable ON the drone, in NED::

    F_cable_ned = R_b^v (m f_sf - [0, 0, -T])                                (eq. 50)

Airframe drag (``F_ext`` of eq. 50) is not modelled: it is absorbed into the observation.
Neither are the thrust map's error, the accelerometer's bias and the attitude's error; the
estimate carries them as a consider covariance
(:mod:`~tether_companion.estimation.tension_budget`): :attr:`TensionEstimate.covariance_ned_n2`
is the filter's white-noise variance plus that budget.

Two filters smooth the observation, both plain linear Kalman filters (eqs. 43-47) stepped once
per observation (IMU sample), run by
:class:`~tether_companion.estimation.tension_filter.TensionKalmanFilter`:

* ``constant`` (eqs. 48-49): ``x = (T_n, T_e, T_d)``, ``A = C = I``;
* ``derivative`` (eqs. 51-53): per axis ``x = (T_{k-2}, T_{k-1}, T_k)`` with the companion
  matrix ``A`` of eq. 52 (coefficients ``a``, ``b``) and ``C = (0, 0, 1)``.

With process and measurement noise the same on each axis and uncorrelated between axes (as
the thesis' diagonal Q and R are), the three axes share one covariance matrix, so both models
run as one filter over an ``(n, 3)`` state: the constant model is the ``n = 1`` case with
``A = [[1]]``, exactly eqs. 48-49 for the 3-vector. The update uses the Joseph form, which
keeps P symmetric positive semi-definite in floating point. The per-tick arithmetic (the
observation, both filter steps) is scalar Python, as the tether EKF's is.

:class:`TensionEstimator` aligns samples through an
:class:`~tether_companion.estimation.alignment.InputAligner` (latest attitude and PWM within
staleness bounds at each IMU tick, as :class:`~tether_companion.estimation.pipeline.TetherEstimator`
does; the two can share one) and emits a :class:`TensionEstimate` per tick. Pure and
synchronous.
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation import alignment
from tether_companion.estimation.alignment import AlignedInputs, InputAligner
from tether_companion.estimation.tension_budget import BUDGET_COLUMNS
from tether_companion.estimation.tension_config import (  # noqa: F401 (also imported from here)
    CONSTANT,
    DERIVATIVE,
    TensionFilterConfig,
    load_tension_filter_config,
)
from tether_companion.estimation.tension_filter import TensionKalmanFilter
from tether_companion.estimation.thrust_input import StaticThrustInput, ThrustInput
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample

FloatArray = NDArray[np.float64]

# ---------------------------------------------------------------------------------------------
# observation (eq. 50)


def observe_tension_ned_values(
    specific_force: list[float],
    rotation_rows: list[list[float]],
    thrust_n: float,
    mass_kg: float,
) -> tuple[float, float, float]:
    """Force of the cable on the drone, NED [N], from one set of readings (eq. 50), in scalars.

    Parameters
    ----------
    specific_force
        Accelerometer specific force, FRD body frame, 3 values [m/s^2].
    rotation_rows
        ``R_v^b`` (NED to body) row by row; eq. 50 applies its transpose ``R_b^v``.
    thrust_n
        Total rotor thrust along body -z [N].
    mass_kg
        Vehicle mass [kg].
    """
    f0, f1, f2 = specific_force
    c0, c1, c2 = mass_kg * f0, mass_kg * f1, mass_kg * f2 + thrust_n  # cable force, body
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rotation_rows
    return (
        r00 * c0 + r10 * c1 + r20 * c2,
        r01 * c0 + r11 * c1 + r21 * c2,
        r02 * c0 + r12 * c1 + r22 * c2,
    )


def observe_tension_ned_n(
    specific_force_body_mps2: FloatArray,
    rotation_body_to_ned: FloatArray,
    thrust_n: float,
    mass_kg: float,
) -> FloatArray:
    """:func:`observe_tension_ned_values` on arrays: the cable force, NED [N], shape (3,), from
    the specific force (FRD, shape (3,) [m/s^2]) and ``R_b^v`` (shape (3, 3))."""
    rotation_rows = np.asarray(rotation_body_to_ned, dtype=float).T.tolist()
    force = np.asarray(specific_force_body_mps2, dtype=float).tolist()
    return np.array(observe_tension_ned_values(force, rotation_rows, float(thrust_n), mass_kg))


# ---------------------------------------------------------------------------------------------
# the sample-driven estimator


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
        return TensionHealth(*_TENSION_HEALTH_VALUES(self))


_TENSION_HEALTH_VALUES = operator.attrgetter(*TensionHealth.__slots__)


@dataclass(frozen=True, slots=True)
class TensionEstimate:
    """Filtered tension at one IMU tick.

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

    time_s: float
    tension_ned_n: FloatArray
    variance_n2: float
    last_update_s: float
    observation_ned_n: FloatArray
    updated: bool
    health: TensionHealth = field(repr=False)
    consider_factor_n: FloatArray = field(
        default_factory=lambda: np.zeros((3, BUDGET_COLUMNS)), repr=False
    )
    consider_variance_n2: float = 0.0

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
        return bool(np.isfinite(self.tension_ned_n).all()) and math.isfinite(self.variance_n2)

    def age_s(self, now_s: float) -> float:
        """Time since the last fused observation at ``now_s`` [s] (``inf`` if none)."""
        return now_s - self.last_update_s if math.isfinite(self.last_update_s) else math.inf


_NAN3 = np.full(3, math.nan)


class TensionEstimator:
    """Tension KF fed by typed samples, one step per IMU tick (Martins 2019 section 4).

    Parameters
    ----------
    config
        Filter settings (``model`` selects constant or derivative).
    vehicle
        Vehicle profile (mass; thrust curve for the default thrust input).
    thrust_input
        PWM-to-thrust map; default :class:`StaticThrustInput` of ``vehicle``.
    aligner
        Time alignment shared with the tether EKF (same samples, same staleness bounds as
        ``config``; its thrust input replaces the default); ``ValueError`` if it does not
        match. Default: a private :class:`InputAligner`.
    """

    def __init__(
        self,
        config: TensionFilterConfig,
        vehicle: VehicleProfile,
        thrust_input: ThrustInput | None = None,
        *,
        aligner: InputAligner | None = None,
    ) -> None:
        self.config = config
        self.mass_kg = vehicle.mass_kg
        self.aligner = alignment.aligner_for(
            aligner,
            config.attitude_staleness_s,
            config.pwm_staleness_s,
            thrust_input,
            lambda: StaticThrustInput(vehicle),
        )
        self.thrust_input: ThrustInput = self.aligner.thrust_input
        self.filter = TensionKalmanFilter(
            config.transition(),
            config.process_noise(),
            config.measurement_variance_n2(vehicle.mass_kg),
            config.initial_variance_n2,
        )
        self.budget = config.error_budget(vehicle)
        self._consider_variance_n2 = self.budget.bias_force_std_n**2
        self._consider_factor = np.zeros((3, BUDGET_COLUMNS))
        self.health = TensionHealth()
        self._time_s = math.nan
        self._last_update_s = math.nan

    def on_attitude(self, sample: AttitudeSample) -> None:
        """Store the latest attitude (rejected and counted when not finite)."""
        if self.aligner.on_attitude(sample) is not None:
            self.health.nonfinite_rejected += 1

    def on_pwm(self, sample: PwmSample) -> None:
        """Store the total thrust of the latest motor outputs (rejected when not finite).

        Raises
        ------
        ValueError
            From the thrust input, when the number of pulse widths is wrong.
        """
        if self.aligner.on_pwm(sample) is not None:
            self.health.nonfinite_rejected += 1

    def on_imu(self, sample: ImuSample) -> TensionEstimate | None:
        """Step the filter at the IMU time and fuse an observation when inputs are fresh.

        Returns ``None`` when the sample is rejected (non-finite or out of order).
        """
        aligned = self.aligner.align(sample)
        health = self.health
        if aligned is alignment.NONFINITE_INPUT:
            health.nonfinite_rejected += 1
            return None
        t = sample.time_s
        if math.isfinite(self._time_s) and t < self._time_s:
            health.out_of_order += 1
            return None
        self._time_s = t
        observation = self._observe(aligned)
        kf = self.filter
        updated = False
        if observation is not None:
            gap = t - self._last_update_s
            if not kf.started or not gap <= self.config.max_gap_s:
                kf.restart(observation)
                health.restarts += 1
            else:
                kf.predict()
                kf.update(observation)
            self._last_update_s = t
            health.updates += 1
            updated = True
            tension = kf.tension_ned_n
            self._consider_factor = np.array(
                self.budget.factor(self.aligner.rotation_rows, aligned.thrust_n, tension.tolist())
            ).reshape(3, BUDGET_COLUMNS)
        else:
            tension = kf.tension_ned_n if kf.started else _NAN3.copy()
        return TensionEstimate(
            time_s=t,
            tension_ned_n=tension,
            variance_n2=kf.variance_n2 if kf.started else math.inf,
            last_update_s=self._last_update_s,
            observation_ned_n=np.array(observation) if observation is not None else _NAN3.copy(),
            updated=updated,
            health=health.copy(),
            consider_factor_n=self._consider_factor,
            consider_variance_n2=self._consider_variance_n2,
        )

    def _observe(self, aligned: AlignedInputs | str) -> tuple[float, float, float] | None:
        health = self.health
        if aligned is alignment.STALE_ATTITUDE:
            health.stale_attitude += 1
            return None
        if aligned is alignment.STALE_PWM:
            health.stale_pwm += 1
            return None
        aligner = self.aligner
        observation = observe_tension_ned_values(
            aligner.specific_force_values, aligner.rotation_rows, aligned.thrust_n, self.mass_kg
        )
        n, e, d = observation
        if not math.isfinite(n + e + d):  # NaN/inf in any
            health.nonfinite_rejected += 1
            return None
        if math.sqrt(n * n + e * e + d * d) > self.config.max_observed_tension_n:
            health.absurd_rejected += 1
            return None
        return observation
