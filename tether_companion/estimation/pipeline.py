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

import dataclasses
import math
import operator
from dataclasses import dataclass

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


@dataclass(slots=True)
class EstimatorHealth:
    """Counters of what the pipeline did with its inputs (all monotonic except the flags).

    Attributes
    ----------
    imu_ticks
        IMU samples that advanced the filter.
    accel_fused, accel_gated, accel_forced
        Accelerometer updates fused, rejected by the innovation gate, fused after the gate
        yielded (see ``gate.max_consecutive_rejections``).
    stale_attitude, stale_pwm, stale_tension
        IMU ticks without an accelerometer update because the attitude, PWM or known
        tension (3-state) was missing or older than its staleness bound.
    near_anchor
        IMU ticks without an accelerometer update because the estimate was closer to the
        anchor than ``min_cable_length_m`` (cable direction undefined).
    range_fused, range_gated, range_out_of_range, range_stale
        Rangefinder samples fused, gated, outside the valid range or tilt, or without a
        fresh attitude / older than the filter.
    nonfinite_rejected
        Samples (any kind) or derived inputs containing NaN/inf, rejected before the filter.
    pwm_invalid
        PWM samples the thrust input refused (not one pulse width per motor).
    out_of_order
        Samples older than the filter time, dropped.
    resets
        Filter restarts (long IMU gap, non-finite state); equals ``reset_counter``.
    pd_repairs
        Covariances repaired after losing positive definiteness.
    last_accel_nis, last_range_nis
        Normalised innovation squared of the last accelerometer / rangefinder sample.
    """

    imu_ticks: int = 0
    accel_fused: int = 0
    accel_gated: int = 0
    accel_forced: int = 0
    stale_attitude: int = 0
    stale_pwm: int = 0
    stale_tension: int = 0
    near_anchor: int = 0
    range_fused: int = 0
    range_gated: int = 0
    range_out_of_range: int = 0
    range_stale: int = 0
    nonfinite_rejected: int = 0
    pwm_invalid: int = 0
    out_of_order: int = 0
    resets: int = 0
    pd_repairs: int = 0
    last_accel_nis: float = math.nan
    last_range_nis: float = math.nan

    def copy(self) -> EstimatorHealth:
        """A snapshot."""
        return EstimatorHealth(*_HEALTH_VALUES(self))

    def values(self) -> tuple:
        """All fields in declaration order (a cheap snapshot)."""
        return _HEALTH_VALUES(self)


_HEALTH_VALUES = operator.attrgetter(*(f.name for f in dataclasses.fields(EstimatorHealth)))


class Estimate:
    """The estimator's output at one IMU tick (read-only).

    Attributes
    ----------
    time_s
        Flight-controller time of the tick [s].
    position_ned_m
        Drone position relative to the tether anchor, NED, shape (3,) [m].
    tension_n
        Cable tension [N]: the state's (4-state) or the known one (3-state).
    covariance
        State covariance, shape (n, n): position block [m^2] first, then tension [N^2].
    reset_counter
        Increments each time the filter restarts (for VISION_POSITION_ESTIMATE.reset_counter).
    accel_fused
        Whether this tick fused the accelerometer.
    health_values
        The pipeline's counters at this tick, in :class:`EstimatorHealth` field order; read
        them as ``estimate.health`` (kept as a tuple: an estimate is made at every IMU tick).
    missing_input
        The input whose absence leaves part of the position unobserved (``"rangefinder"``:
        no height fused for ``observability.range_lost_after_s``; the covariance along the
        cable grows meanwhile), or None.

    The estimator makes it from the filter's state and covariance as Python floats
    (:meth:`of_values`, also readable as :attr:`state_values` and :attr:`covariance_values`)
    and builds the arrays only when ``position_ned_m`` or ``covariance`` is first read: an
    estimate is made at every IMU tick and most consumers offline read a few numbers.
    """

    __slots__ = (
        "time_s",
        "tension_n",
        "reset_counter",
        "accel_fused",
        "health_values",
        "missing_input",
        "_state",
        "_covariance_values",
        "_position",
        "_covariance",
    )

    def __init__(
        self,
        time_s: float,
        position_ned_m: FloatArray,
        tension_n: float,
        covariance: FloatArray,
        reset_counter: int,
        accel_fused: bool,
        health_values: tuple,
        missing_input: str | None = None,
    ) -> None:
        self.time_s = time_s
        self.tension_n = tension_n
        self.reset_counter = reset_counter
        self.accel_fused = accel_fused
        self.health_values = health_values
        self.missing_input = missing_input
        self._position: FloatArray | None = position_ned_m
        self._covariance: FloatArray | None = covariance
        self._state: list[float] | None = None
        self._covariance_values: list[float] | None = None

    @classmethod
    def of_values(
        cls,
        time_s: float,
        state: list[float],
        covariance: list[float],
        tension_n: float,
        reset_counter: int,
        accel_fused: bool,
        health_values: tuple,
        missing_input: str | None,
    ) -> Estimate:
        """An estimate from the state (n values, position first) and covariance (n*n values,
        row-major) as lists the estimate keeps (give it copies)."""
        estimate = cls.__new__(cls)
        estimate.time_s = time_s
        estimate.tension_n = tension_n
        estimate.reset_counter = reset_counter
        estimate.accel_fused = accel_fused
        estimate.health_values = health_values
        estimate.missing_input = missing_input
        estimate._state = state
        estimate._covariance_values = covariance
        estimate._position = None
        estimate._covariance = None
        return estimate

    @property
    def position_ned_m(self) -> FloatArray:
        """Drone position relative to the tether anchor, NED, shape (3,) [m]."""
        position = self._position
        if position is None:
            state = self._state
            assert state is not None
            position = self._position = np.array(state[POSITION])
        return position

    @property
    def covariance(self) -> FloatArray:
        """State covariance, shape (n, n): position block [m^2] first, then tension [N^2]."""
        covariance = self._covariance
        if covariance is None:
            n = len(self._state)  # type: ignore[arg-type]
            covariance = np.array(self._covariance_values).reshape(n, n)
            self._covariance = covariance
        return covariance

    @property
    def state_values(self) -> list[float]:
        """The position (3 values, NED [m]) followed by the state's tension [N] if it has one,
        as Python floats (a list the caller must not change)."""
        state = self._state
        if state is None:
            state = self._state = self._position.tolist()  # type: ignore[union-attr]
            n = self.covariance.shape[0]
            if n > len(state):
                state.append(self.tension_n)
        return state

    @property
    def covariance_values(self) -> list[float]:
        """The covariance's n*n entries row-major as Python floats (a list the caller must not
        change)."""
        values = self._covariance_values
        if values is None:
            values = self._covariance_values = self.covariance.ravel().tolist()
        return values

    @property
    def health(self) -> EstimatorHealth:
        """Snapshot of the pipeline's counters at this tick."""
        return EstimatorHealth(*self.health_values)

    @property
    def position_covariance_m2(self) -> FloatArray:
        """Position block of the covariance, shape (3, 3) [m^2]."""
        return self.covariance[POSITION, POSITION]

    def __repr__(self) -> str:
        return (
            f"Estimate(time_s={self.time_s!r}, position_ned_m={self.position_ned_m!r}, "
            f"tension_n={self.tension_n!r}, reset_counter={self.reset_counter!r}, "
            f"accel_fused={self.accel_fused!r}, missing_input={self.missing_input!r})"
        )


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
