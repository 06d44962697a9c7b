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

import functools
import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation import alignment, optional_core
from tether_companion.estimation.alignment import AlignedInputs, InputAligner
from tether_companion.estimation.tension_budget import BUDGET_COLUMNS
from tether_companion.estimation.tension_config import (  # noqa: F401 (also imported from here)
    CONSTANT,
    DERIVATIVE,
    TensionFilterConfig,
    load_tension_filter_config,
)
from tether_companion.estimation.tension_estimate import (  # noqa: F401 (also imported from here)
    TENSION_HEALTH_VALUES,
    ConsiderFactor,
    TensionEstimate,
    TensionHealth,
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


OBSERVE_TENSION: Callable[..., tuple[float, float, float]] = observe_tension_ned_values
""":func:`observe_tension_ned_values`, or where the optional C extension ``_tension_core`` is
built (and ``TETHER_PURE_PYTHON`` is not set) its twin ``observe_tension``: the same floats,
the Python function called where C could differ (arguments not exact floats in lists/tuples
of three, a non-finite result). Once per IMU tick."""
_CORE = optional_core.load("tether_companion.estimation._tension_core")
if _CORE is not None and hasattr(_CORE, "observe_tension"):
    OBSERVE_TENSION = functools.partial(_CORE.observe_tension, observe_tension_ned_values)


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


_NAN_VALUES = (math.nan, math.nan, math.nan)


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
        self._consider_factor = ConsiderFactor(np.zeros((3, BUDGET_COLUMNS)))
        """``G`` of the last fused tick (zeros before the first), made when first read."""
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
            tension = kf.tension_values()
            self._consider_factor = ConsiderFactor(
                inputs=(self.budget, self.aligner.rotation_rows, aligned.thrust_n, tension)
            )
        else:
            tension = kf.tension_values() if kf.started else _NAN_VALUES
        return TensionEstimate.of_values(
            t,
            tension,
            kf.variance_n2 if kf.started else math.inf,
            self._last_update_s,
            observation,
            updated,
            TENSION_HEALTH_VALUES(health),
            self._consider_factor,
            self._consider_variance_n2,
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
        observation = OBSERVE_TENSION(
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
