"""Simulated sensors: accelerometer, gyro, attitude, PWM outputs and a downward rangefinder.

Noise defaults follow Al-Radaideh & Sun (2021), section 6, read as variances in SI units
(see docs/simulator.md): accelerometer sigma^2 = 0.01 (m/s^2)^2 per axis (sigma = 0.1 m/s^2),
ultrasound sigma^2 = 0.1 m^2 (sigma = 0.316 m), gyro and attitude sigma^2 = 0.01 deg^2
(sigma = 0.1 deg, per second for the gyro). All randomness comes from one
``numpy.random.Generator`` (drawn in blocks by :class:`NormalStream`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.config import ConfigError, spec
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample

FloatArray = NDArray[np.float64]

_PAPER_ACCEL_STD_MPS2 = math.sqrt(0.01)
_PAPER_RANGE_STD_M = math.sqrt(0.1)
_PAPER_ANGLE_STD_RAD = math.radians(math.sqrt(0.01))
_MIN_TILT_COSINE = 0.1
"""Rangefinder beam tilted beyond acos(0.1) ~ 84 deg from vertical never sees the ground."""


@dataclass(frozen=True)
class SensorConfig:
    """The ``sensors`` section of a scenario: rates and noise (SI units)."""

    imu_rate_hz: float = spec(
        200.0, exclusive_minimum=0.0, maximum=2000.0, doc="IMU sample rate [Hz]"
    )
    attitude_rate_hz: float = spec(
        200.0, exclusive_minimum=0.0, maximum=2000.0, doc="attitude rate [Hz]"
    )
    pwm_rate_hz: float = spec(
        200.0, exclusive_minimum=0.0, maximum=2000.0, doc="PWM output report rate [Hz]"
    )
    range_rate_hz: float = spec(
        200.0, exclusive_minimum=0.0, maximum=2000.0, doc="rangefinder rate [Hz]"
    )
    accel_noise_std_mps2: float = spec(
        _PAPER_ACCEL_STD_MPS2, minimum=0.0, doc="accelerometer white noise sigma per axis [m/s^2]"
    )
    accel_bias_mps2: tuple[float, float, float] = spec(
        (0.0, 0.0, 0.0), minimum=-5.0, maximum=5.0, doc="constant accelerometer bias, FRD [m/s^2]"
    )
    accel_turn_on_bias_std_mps2: float = spec(
        0.0,
        minimum=0.0,
        maximum=2.0,
        doc="sigma of the per-axis bias drawn at start, on top of accel_bias_mps2 [m/s^2]",
    )
    accel_bias_random_walk_mps2_per_sqrt_s: float = spec(
        0.0, minimum=0.0, maximum=1.0, doc="accelerometer bias random walk [m/s^2/sqrt(s)]"
    )
    accel_vibration_amplitude_mps2: float = spec(
        0.0,
        minimum=0.0,
        doc="amplitude of a sinusoidal vibration on each accelerometer axis [m/s^2]",
    )
    accel_vibration_frequency_hz: float = spec(
        120.0, exclusive_minimum=0.0, doc="vibration frequency [Hz]"
    )
    gyro_noise_std_rad_s: float = spec(
        _PAPER_ANGLE_STD_RAD, minimum=0.0, doc="gyro white noise sigma per axis [rad/s]"
    )
    gyro_bias_rad_s: tuple[float, float, float] = spec(
        (0.0, 0.0, 0.0), minimum=-1.0, maximum=1.0, doc="constant gyro bias, FRD [rad/s]"
    )
    gyro_turn_on_bias_std_rad_s: float = spec(
        0.0, minimum=0.0, maximum=1.0, doc="sigma of the per-axis gyro bias drawn at start [rad/s]"
    )
    gyro_bias_random_walk_rad_s_per_sqrt_s: float = spec(
        0.0, minimum=0.0, maximum=1.0, doc="gyro bias random walk [rad/s/sqrt(s)]"
    )
    attitude_error_std_rad: float = spec(
        0.0,
        minimum=0.0,
        maximum=0.2,
        doc="the flight controller's attitude-estimate error: stationary sigma per axis of a "
        "first-order Gauss-Markov process [rad]",
    )
    attitude_error_time_constant_s: float = spec(
        30.0, exclusive_minimum=0.0, doc="correlation time of the attitude-estimate error [s]"
    )
    heading_error_std_rad: float | None = spec(
        None,
        minimum=0.0,
        maximum=0.5,
        doc="the heading's own stationary sigma of that error (a compass-aided yaw is worse "
        "than roll and pitch) [rad]; unset: attitude_error_std_rad",
    )
    heading_error_time_constant_s: float | None = spec(
        None,
        exclusive_minimum=0.0,
        doc="correlation time of the heading error [s]; unset: attitude_error_time_constant_s",
    )
    attitude_noise_std_rad: float = spec(
        _PAPER_ANGLE_STD_RAD, minimum=0.0, doc="attitude (roll, pitch, yaw) noise sigma [rad]"
    )
    range_noise_std_m: float = spec(
        _PAPER_RANGE_STD_M, minimum=0.0, doc="rangefinder noise sigma [m]"
    )
    range_min_m: float = spec(
        0.05, minimum=0.0, doc="shortest distance the rangefinder reports [m]"
    )
    range_max_m: float = spec(
        20.0, exclusive_minimum=0.0, doc="longest distance the rangefinder reports [m]"
    )
    range_offset_frd_m: tuple[float, float, float] = spec(
        (0.0, 0.0, 0.0),
        minimum=-2.0,
        maximum=2.0,
        doc="rangefinder mounting point from the centre of mass, body FRD [m]",
    )

    def attitude_error_std_per_axis_rad(self) -> tuple[float, float, float]:
        """Stationary sigma of the flight controller's roll, pitch and heading errors [rad]."""
        tilt = self.attitude_error_std_rad
        heading = tilt if self.heading_error_std_rad is None else self.heading_error_std_rad
        return (tilt, tilt, heading)

    def attitude_error_time_constant_per_axis_s(self) -> tuple[float, float, float]:
        """Correlation times of the roll, pitch and heading errors [s]."""
        tilt = self.attitude_error_time_constant_s
        heading = self.heading_error_time_constant_s
        return (tilt, tilt, tilt if heading is None else heading)

    def validate(self) -> None:
        """The rangefinder's range must not be empty."""
        if self.range_max_m <= self.range_min_m:
            raise ConfigError(
                "", "range_max_m", self.range_max_m, f"must be > range_min_m ({self.range_min_m})"
            )


def _turn_on(rng: np.random.Generator, std: float | tuple[float, float, float]) -> list[float]:
    """Three values drawn with sigma ``std`` (one for all three or one per axis; no draw,
    zeros, when every sigma is 0)."""
    sigma = np.broadcast_to(np.asarray(std, dtype=float), (3,))
    return [float(v) for v in rng.normal(0.0, sigma)] if np.any(sigma > 0.0) else [0.0, 0.0, 0.0]


def _random_walk(values: list[float], rate: float, dt_s: float, take: Callable[[], float]) -> None:
    """Add a random-walk increment of ``rate * sqrt(dt_s)`` sigma to each of ``values``."""
    if rate > 0.0 and dt_s > 0.0:
        step = rate * math.sqrt(dt_s)
        for i in range(len(values)):
            values[i] += step * take()


class NormalStream:
    """Standard normal numbers drawn from a Generator in blocks (cheap per-sample draws).

    The sequence is a deterministic function of the Generator's state: the same seed gives the
    same numbers. A block is drawn when the first number past the previous block is taken, so
    other users of the Generator see it in the same state as with draws one by one at those
    moments.
    """

    def __init__(self, rng: np.random.Generator, block: int = 4096) -> None:
        self._rng = rng
        self._block = block
        self.take: Callable[[], float] = self._numbers().__next__
        """The next standard normal number (a generator's ``__next__``: no method call)."""

    def _numbers(self) -> Iterator[float]:
        while True:
            yield from self._rng.standard_normal(self._block).tolist()


class SensorSuite:
    """Turns noise-free truth into sensor samples (pure apart from the noise stream).

    Parameters
    ----------
    config
        Noise levels, biases, vibration and rangefinder limits.
    rng
        The simulator's Generator; vibration phases are drawn from it at construction.
    """

    def __init__(self, config: SensorConfig, rng: np.random.Generator) -> None:
        self.config = config
        self._noise = NormalStream(rng)
        self._vibration_phase_rad = tuple(float(v) for v in rng.uniform(0.0, 2.0 * math.pi, 3))
        self.accel_bias_drift_mps2 = _turn_on(rng, config.accel_turn_on_bias_std_mps2)
        """Bias on top of ``accel_bias_mps2``: turn-on draw plus random walk, FRD [m/s^2]."""
        self.gyro_bias_drift_rad_s = _turn_on(rng, config.gyro_turn_on_bias_std_rad_s)
        """Gyro bias on top of ``gyro_bias_rad_s``: turn-on draw plus random walk [rad/s]."""
        self.attitude_error_rad = _turn_on(rng, config.attitude_error_std_per_axis_rad())
        """The flight controller's attitude-estimate error (roll, pitch, yaw) now [rad]."""
        self._last_imu_s: float | None = None
        self._last_attitude_s: float | None = None

    @property
    def config(self) -> SensorConfig:
        """Noise levels, biases, vibration and rangefinder limits (may be replaced at run time)."""
        return self._config

    @config.setter
    def config(self, config: SensorConfig) -> None:
        self._config = config
        self._vibration_omega_rad_s = 2.0 * math.pi * config.accel_vibration_frequency_hz
        self._attitude_error_axes = tuple(
            zip(
                config.attitude_error_std_per_axis_rad(),
                config.attitude_error_time_constant_per_axis_s(),
                strict=True,
            )
        )
        self._attitude_error_on = any(std > 0.0 for std, _ in self._attitude_error_axes)

    def imu(
        self,
        time_s: float,
        specific_force_body_mps2: tuple[float, float, float],
        body_rates_rad_s: tuple[float, float, float],
    ) -> ImuSample:
        """Accelerometer (truth + bias + vibration + noise) and gyro (truth + bias + noise)."""
        c = self._config
        take = self._noise.take
        dt = 0.0 if self._last_imu_s is None else time_s - self._last_imu_s
        dt = 0.0 if 0.0 > dt else dt  # max(dt, 0.0) without the builtin's call
        self._last_imu_s = time_s
        _random_walk(self.accel_bias_drift_mps2, c.accel_bias_random_walk_mps2_per_sqrt_s, dt, take)
        _random_walk(self.gyro_bias_drift_rad_s, c.gyro_bias_random_walk_rad_s_per_sqrt_s, dt, take)
        sa, sg = c.accel_noise_std_mps2, c.gyro_noise_std_rad_s
        amp = c.accel_vibration_amplitude_mps2
        # in scalars, each axis in turn (the noise stream's order: accel x, y, z, gyro x, y, z)
        fx, fy, fz = specific_force_body_mps2
        bx, by, bz = c.accel_bias_mps2
        dx, dy, dz = self.accel_bias_drift_mps2
        ax = fx + bx + dx + sa * take()
        ay = fy + by + dy + sa * take()
        az = fz + bz + dz + sa * take()
        if amp > 0.0:
            wt = self._vibration_omega_rad_s * time_s
            px, py, pz = self._vibration_phase_rad
            ax = ax + amp * math.sin(wt + px)
            ay = ay + amp * math.sin(wt + py)
            az = az + amp * math.sin(wt + pz)
        wx, wy, wz = body_rates_rad_s
        bx, by, bz = c.gyro_bias_rad_s
        dx, dy, dz = self.gyro_bias_drift_rad_s
        gx = wx + bx + dx + sg * take()
        gy = wy + by + dy + sg * take()
        gz = wz + bz + dz + sg * take()
        return ImuSample(time_s, np.array((ax, ay, az)), np.array((gx, gy, gz)))

    def attitude(
        self, time_s: float, roll_rad: float, pitch_rad: float, yaw_rad: float
    ) -> AttitudeSample:
        """The flight controller's attitude estimate: truth + its slowly varying error + white
        noise; yaw wrapped to [-pi, pi)."""
        c = self._config
        s = c.attitude_noise_std_rad
        take = self._noise.take
        err = self.attitude_error_rad
        if self._attitude_error_on:
            dt = 0.0 if self._last_attitude_s is None else max(time_s - self._last_attitude_s, 0.0)
            for i, (std, tau) in enumerate(self._attitude_error_axes):
                a = math.exp(-dt / tau)
                err[i] = a * err[i] + std * math.sqrt(max(1.0 - a * a, 0.0)) * take()
        self._last_attitude_s = time_s
        yaw = yaw_rad + err[2] + s * take()
        yaw = (yaw + math.pi) % (2.0 * math.pi) - math.pi
        return AttitudeSample(
            time_s, roll_rad + err[0] + s * take(), pitch_rad + err[1] + s * take(), yaw
        )

    @staticmethod
    def pwm(time_s: float, pwm_us: FloatArray) -> PwmSample:
        """The motor outputs as commanded: whole microseconds, shape (n_motors,)."""
        return PwmSample(time_s, np.rint(pwm_us))

    def rangefinder(
        self, time_s: float, height_m: float, roll_rad: float, pitch_rad: float
    ) -> RangeSample | None:
        """Downward rangefinder along the body z axis.

        ``height_m`` is the sensor's height above the ground under it (the simulator takes
        the mounting offset and the terrain into account). The true distance is
        ``height / (cos(roll) cos(pitch))``; ``None`` when it lies outside
        [range_min_m, range_max_m] or the beam points nearly horizontal (or up). The reported
        value is the true distance plus noise, clipped to the sensor's range.
        """
        c = self._config
        tilt = math.cos(roll_rad) * math.cos(pitch_rad)
        if tilt < _MIN_TILT_COSINE:
            return None
        distance = height_m / tilt
        if not c.range_min_m <= distance <= c.range_max_m:
            return None
        noisy = distance + c.range_noise_std_m * self._noise.take()
        low, high = c.range_min_m, c.range_max_m  # min(max(noisy, low), high), written out
        noisy = low if low > noisy else noisy
        return RangeSample(time_s, high if high < noisy else noisy)
