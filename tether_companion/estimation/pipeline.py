"""Time alignment and sensor fusion around the tether EKF: samples in, estimates out.

:class:`TetherEstimator` is the one pipeline used offline (simulate, bench), by the live
service and by replay. It is pure and synchronous: the caller hands it samples in time order
and it returns an :class:`Estimate` per IMU tick.

* ``on_attitude``, ``on_pwm`` hand the sample to an
  :class:`~tether_companion.estimation.alignment.InputAligner` (the latest attitude's rotation,
  the latest PWM's thrust through a :class:`ThrustInput`), ``set_known_tension_n`` stores the
  latest value; non-finite samples are rejected and counted.
* ``on_imu`` ticks the filter: predict to the IMU time, then fuse the accelerometer with the
  aligner's inputs if attitude and PWM are each within their staleness bound of the IMU time;
  otherwise the update is skipped and counted.
* ``on_range`` tilt-corrects the rangefinder with the latest attitude (``d cos(phi) cos(theta)``,
  flat ground), adds the sensor's mounting offset and takes off the anchor's height above the
  ground (:mod:`tether_companion.estimation.altimeter_geometry`), and fuses it as the height
  above the anchor at the filter's time (the last IMU
  tick; the random walk makes a few milliseconds' offset immaterial, and the filter's clock
  only ever moves with the IMU, so a range stamped slightly ahead cannot make the next IMU
  sample look out of order); out-of-range or stale readings are dropped and counted.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.alignment import (
    NONFINITE_INPUT,
    STALE_ATTITUDE,
    STALE_PWM,
    AlignedInputs,
    InputAligner,
    aligner_for,
)
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.ekf import FUSED, GATED, NONFINITE, ExtendedKalmanFilter
from tether_companion.estimation.estimate import Estimate, EstimatorHealth
from tether_companion.estimation.inputs import InputFeed, range_height_m, range_reading_ok
from tether_companion.estimation.observability import RANGEFINDER, RangeWatch, grow_for_imu_gap
from tether_companion.estimation.tether_models import (
    F_C,
    P_D,
    POSITION,
    FourStateModel,
    ThreeStateModel,
    altimeter,
)
from tether_companion.estimation.thrust_input import StaticThrustInput, ThrustInput
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.samples import ImuSample, RangeSample

FloatArray = NDArray[np.float64]

ACCEL = "accel"
ALTIMETER = "altimeter"


def default_thrust_input(config: EstimatorConfig, vehicle: VehicleProfile) -> ThrustInput:
    """The identified model of ``config.thrust_model`` if set, else the profile's static curve.

    Raises
    ------
    ConfigError
        When the thrust-model file is missing or invalid.
    """
    if config.thrust_model is None:
        return StaticThrustInput(vehicle)
    from tether_companion.sysid.thrust_model import load_thrust_model  # sysid builds on us

    return load_thrust_model(config.thrust_model)


def _finite(value: float) -> bool:
    return math.isfinite(value)


class TetherEstimator(InputFeed):
    """The tether EKF (3- or 4-state) fed by typed samples, ticking at the IMU rate.

    Parameters
    ----------
    config
        Estimator settings (``kind`` selects the model).
    vehicle
        Vehicle profile (mass, thrust curve, motor count).
    thrust_input
        PWM-to-thrust map; default: the model file of ``config.thrust_model`` (written by
        ``tether-companion sysid``), else :class:`StaticThrustInput` of ``vehicle``.
    aligner
        An :class:`InputAligner` shared with another estimator fed the same samples (its
        bounds must equal ``config.staleness``'s; its thrust input is used); default: a
        private one.

    Raises
    ------
    ValueError
        When ``aligner`` does not match ``config`` or comes with another ``thrust_input``.
    """

    def __init__(
        self,
        config: EstimatorConfig,
        vehicle: VehicleProfile,
        thrust_input: ThrustInput | None = None,
        *,
        aligner: InputAligner | None = None,
    ) -> None:
        if config.kind not in ("four_state", "three_state"):
            raise ValueError(f"TetherEstimator runs the paper's models, not kind {config.kind!r}")
        self.config = config
        self.vehicle = vehicle
        stale = config.staleness
        self.aligner = aligner_for(
            aligner,
            stale.attitude_s,
            stale.pwm_s,
            thrust_input,
            lambda: default_thrust_input(config, vehicle),
        )
        self.thrust_input: ThrustInput = self.aligner.thrust_input
        model_cls = FourStateModel if config.kind == "four_state" else ThreeStateModel
        self.model = model_cls(vehicle.mass_kg, config.min_cable_length_m)
        self.filter = ExtendedKalmanFilter(
            config.x0(),
            config.p0(),
            config.q_density(),
            gate_probability=config.gate.probability,
            max_consecutive_rejections=config.gate.max_consecutive_rejections,
        )
        self.health = EstimatorHealth()
        self._r_accel_variance = config.accel_noise.variance_mps2_sq
        """Accelerometer noise variance per axis [(m/s^2)^2] (``R = r I``)."""
        self._r_alt = config.altimeter_noise_variance_m2
        self._altimeter_jacobian = tuple(altimeter(self.filter.x)[1].ravel().tolist())
        """The altimeter's Jacobian, n entries (constant: ``h_alt = -p_d``)."""
        self._stale = config.staleness
        self._time_s = math.nan
        self._early_range: RangeSample | None = None
        self._tension_time_s = math.nan
        self._known_tension_n = math.nan
        self._tension_from_measurement = (
            model_cls is FourStateModel and config.initial_tension_n is None
        )
        self._needs_tension_init = self._tension_from_measurement
        self._range_watch = RangeWatch(config.observability)

    # ------------------------------------------------------------------ inputs
    @property
    def time_s(self) -> float:
        """Filter time [s] (``nan`` before the first IMU tick)."""
        return self._time_s

    @property
    def reset_counter(self) -> int:
        """Number of filter restarts so far."""
        return self.filter.resets

    def set_known_tension_n(self, tension_n: float, time_s: float) -> None:
        """Known cable tension [N] at ``time_s`` [s] (load cell; used by the 3-state model)."""
        if not (_finite(tension_n) and _finite(time_s)) or tension_n < 0.0:
            self.health.nonfinite_rejected += 1
            return
        self._known_tension_n = float(tension_n)
        self._tension_time_s = time_s

    # ------------------------------------------------------------------ ticks
    def on_imu(self, sample: ImuSample) -> Estimate | None:
        """Predict to the IMU time and fuse the accelerometer; return the estimate.

        Returns ``None`` when the sample is rejected (non-finite, or older than the filter).
        """
        aligned = self.aligner.align(sample)
        if aligned is NONFINITE_INPUT:
            self.health.nonfinite_rejected += 1
            return None
        if not self._advance_to(sample.time_s):
            return None
        self.health.imu_ticks += 1
        estimate = self._estimate(self._fuse_accel(aligned))
        early = self._early_range
        if early is not None:  # arrived before the first tick: fused right after it
            self._early_range = None
            self.on_range(early)
        return estimate

    def on_range(self, sample: RangeSample) -> None:
        """Fuse a downward rangefinder reading as the height above the anchor [m].

        Fused at the filter time (the last IMU tick): the filter's clock moves only with the
        IMU, so a reading stamped a little after the last IMU sample (DISTANCE_SENSOR carries
        milliseconds, RAW_IMU microseconds) cannot make the pipeline drop the next one. A
        reading that arrives before the first IMU tick (no clock yet) waits for that tick (the
        latest one only; a replaced one counts as stale).
        """
        health = self.health
        cfg = self.config.rangefinder
        if not range_reading_ok(sample, cfg, health):
            return
        if math.isnan(self._time_s):
            if self._early_range is not None:
                health.range_stale += 1
            self._early_range = sample
            return
        if abs(sample.time_s - self._time_s) > self._stale.range_s:
            health.range_stale += 1
            return
        height_m = range_height_m(
            sample,
            self.aligner,
            cfg,
            self._stale.attitude_s,
            self.config.ground_station.anchor_height_m,
            health,
        )
        if height_m is None:
            return
        kf = self.filter
        result = kf.update_values(
            ALTIMETER,
            [height_m + kf.x_values()[P_D]],
            self._altimeter_jacobian,
            self._r_alt,
            constant=True,
        )
        health.last_range_nis = result.nis
        if result.status == FUSED:
            health.range_fused += 1
            self._range_watch.on_fused(self._time_s)
        elif result.status == GATED:
            health.range_gated += 1
        elif result.status == NONFINITE:
            health.nonfinite_rejected += 1
        self._sync_filter_counters()

    # ------------------------------------------------------------------ internals
    def _advance_to(self, t: float) -> bool:
        """Predict the filter to time ``t``; reset after a long gap; False if ``t`` is old."""
        if math.isnan(self._time_s):
            self._time_s = t
            return True
        dt = t - self._time_s
        if dt < 0.0:
            self.health.out_of_order += 1
            return False
        if dt > self._stale.max_gap_s:
            self.filter.reset()
            self._sync_filter_counters()
        else:
            kf = self.filter
            kf.predict(dt)
            # both grow P in place, and only now and then: reading kf.P converts the scalar
            # path's lists, so it is read only when they will
            observability = self.config.observability
            if dt > observability.imu_gap_s:
                grow_for_imu_gap(kf.P, dt, observability)
            if self._range_watch.lost(t):
                self._range_watch.grow(kf.P, kf.x[POSITION], t, dt)
        self._time_s = t
        return True

    def _fuse_accel(self, aligned: AlignedInputs | str) -> bool:
        health = self.health
        if aligned is STALE_ATTITUDE:
            health.stale_attitude += 1
            return False
        if aligned is STALE_PWM:
            health.stale_pwm += 1
            return False
        t, accel, thrust_n = aligned.time_s, aligned.specific_force_body_mps2, aligned.thrust_n
        model = self.model
        tension_n = self._known_tension_n
        if not model.has_tension_state and (
            math.isnan(self._tension_time_s)
            or abs(t - self._tension_time_s) > self._stale.tension_s
        ):
            health.stale_tension += 1
            return False
        if self._needs_tension_init:
            self._initialise_tension(accel, thrust_n)
        x = self.filter.x_values()
        if x[0] * x[0] + x[1] * x[1] + x[2] * x[2] < model.min_cable_length_m**2:
            health.near_anchor += 1
            return False
        aligner = self.aligner
        (hx, hy, hz), jacobian = model.accel_values(x, aligner.rotation_rows, thrust_n, tension_n)
        ax, ay, az = aligner.specific_force_values
        result = self.filter.update_values(
            ACCEL, [ax - hx, ay - hy, az - hz], jacobian, self._r_accel_variance
        )
        health.last_accel_nis = result.nis
        status = self.filter.sensors[ACCEL]
        health.accel_forced = status.forced
        self._sync_filter_counters()
        if result.status == FUSED:
            health.accel_fused += 1
            return True
        if result.status == GATED:
            health.accel_gated += 1
        elif result.status == NONFINITE:
            health.nonfinite_rejected += 1
        return False

    def _initialise_tension(self, accel: FloatArray, thrust_n: float) -> None:
        """Set the 4-state tension to the magnitude of the unexplained specific force [N].

        The body-frame specific force minus the thrust's is the cable's force per unit mass;
        its magnitude times the mass is the tension, whatever the direction.
        """
        cable_body = accel.copy()
        cable_body[2] += thrust_n / self.model.mass_kg
        x = self.filter.x.copy()
        x[F_C] = self.model.mass_kg * float(np.linalg.norm(cable_body))
        self.filter.x = x
        self._needs_tension_init = False

    def _sync_filter_counters(self) -> None:
        if self.filter.resets != self.health.resets:  # the filter restarted: measure again
            self._needs_tension_init = self._tension_from_measurement
            self._range_watch.reset()
        self.health.resets = self.filter.resets
        self.health.pd_repairs = self.filter.pd_repairs

    def _estimate(self, accel_fused: bool) -> Estimate:
        kf = self.filter
        x, covariance = kf.values()
        return Estimate.of_values(
            self._time_s,
            x,
            covariance,
            self.model.tension_n(x, self._known_tension_n),
            kf.resets,
            accel_fused,
            self.health.values(),
            RANGEFINDER if self._range_watch.lost(self._time_s) else None,
        )
