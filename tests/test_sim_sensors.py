"""Simulated sensors: noise statistics (seeded), bias, vibration, rangefinder geometry, PWM."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.sim.sensors import NormalStream, SensorConfig, SensorSuite

N = 20000


def _imu_samples(config: SensorConfig, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    suite = SensorSuite(config, rng)
    truth_f = (0.5, -1.0, -9.8)
    truth_w = (0.1, 0.0, -0.2)
    samples = [suite.imu(k / 200.0, truth_f, truth_w) for k in range(N)]
    accel = np.array([s.specific_force_body_mps2 for s in samples]) - truth_f
    gyro = np.array([s.angular_rate_body_rad_s for s in samples]) - truth_w
    return accel, gyro


def test_default_noise_is_the_papers_section_6(rng: np.random.Generator) -> None:
    config = SensorConfig()
    assert config.accel_noise_std_mps2**2 == pytest.approx(0.01)
    assert config.range_noise_std_m**2 == pytest.approx(0.1)
    assert math.degrees(config.attitude_noise_std_rad) ** 2 == pytest.approx(0.01)
    assert math.degrees(config.gyro_noise_std_rad_s) ** 2 == pytest.approx(0.01)
    accel, gyro = _imu_samples(config, rng)
    # sample variance of N normal draws: relative standard error sqrt(2/N) ~ 1 %
    assert accel.var(axis=0) == pytest.approx([0.01] * 3, rel=0.06)
    assert np.all(np.abs(accel.mean(axis=0)) < 5 * 0.1 / math.sqrt(N))
    assert gyro.std(axis=0) == pytest.approx([config.gyro_noise_std_rad_s] * 3, rel=0.03)
    # independent axes
    corr = np.corrcoef(accel.T)
    assert np.max(np.abs(corr - np.eye(3))) < 0.05


def test_bias_and_vibration_are_added(rng: np.random.Generator) -> None:
    config = SensorConfig(
        accel_noise_std_mps2=0.0,
        gyro_noise_std_rad_s=0.0,
        accel_bias_mps2=(0.2, -0.1, 0.05),
        gyro_bias_rad_s=(0.01, 0.02, -0.03),
        accel_vibration_amplitude_mps2=0.5,
        accel_vibration_frequency_hz=37.0,
    )
    accel, gyro = _imu_samples(config, rng)
    assert gyro == pytest.approx(np.tile([0.01, 0.02, -0.03], (N, 1)))
    vibration = accel - np.array([0.2, -0.1, 0.05])
    assert np.max(np.abs(vibration), axis=0) == pytest.approx([0.5] * 3, rel=0.01)
    rms = np.sqrt(np.mean(vibration**2, axis=0))
    assert rms == pytest.approx([0.5 / math.sqrt(2)] * 3, rel=0.02)
    spectrum = np.abs(np.fft.rfft(vibration[:, 0]))
    peak_hz = np.argmax(spectrum) * 200.0 / N
    assert peak_hz == pytest.approx(37.0, abs=0.05)


def test_attitude_noise_and_yaw_wrap(rng: np.random.Generator) -> None:
    suite = SensorSuite(SensorConfig(attitude_noise_std_rad=0.01), rng)
    samples = [suite.attitude(0.0, 0.1, -0.2, math.pi - 1e-4) for _ in range(N)]
    roll = np.array([s.roll_rad for s in samples])
    yaw = np.array([s.yaw_rad for s in samples])
    assert roll.mean() == pytest.approx(0.1, abs=5 * 0.01 / math.sqrt(N))
    assert roll.std() == pytest.approx(0.01, rel=0.03)
    assert np.all((yaw >= -math.pi) & (yaw < math.pi))
    assert np.any(yaw < 0.0)  # some wrapped past +pi


def test_rangefinder_reads_along_the_tilted_body_axis(rng: np.random.Generator) -> None:
    suite = SensorSuite(SensorConfig(range_noise_std_m=0.0), rng)
    sample = suite.rangefinder(1.5, 3.0, math.radians(20.0), math.radians(-10.0))
    assert sample is not None and sample.time_s == 1.5
    expected = 3.0 / (math.cos(math.radians(20.0)) * math.cos(math.radians(10.0)))
    assert sample.distance_m == pytest.approx(expected, rel=1e-12)


def test_rangefinder_is_none_out_of_range_and_clipped_inside(rng: np.random.Generator) -> None:
    suite = SensorSuite(SensorConfig(range_min_m=0.2, range_max_m=8.0, range_noise_std_m=1.0), rng)
    assert suite.rangefinder(0.0, 0.1, 0.0, 0.0) is None  # too close (on the ground)
    assert suite.rangefinder(0.0, 8.5, 0.0, 0.0) is None  # too far
    assert suite.rangefinder(0.0, 7.0, math.radians(40.0), math.radians(40.0)) is None  # tilt
    assert suite.rangefinder(0.0, 3.0, math.radians(89.0), 0.0) is None  # beam near horizontal
    readings = [suite.rangefinder(0.0, 7.9, 0.0, 0.0) for _ in range(2000)]
    values = np.array([r.distance_m for r in readings if r is not None])
    assert len(values) == 2000
    assert values.max() == 8.0 and values.min() >= 0.2


def test_rangefinder_noise_statistics(rng: np.random.Generator) -> None:
    suite = SensorSuite(SensorConfig(), rng)
    values = np.array([suite.rangefinder(0.0, 5.0, 0.0, 0.0).distance_m for _ in range(N)])
    assert values.var() == pytest.approx(0.1, rel=0.06)
    assert values.mean() == pytest.approx(5.0, abs=5 * math.sqrt(0.1 / N))


def test_pwm_is_whole_microseconds() -> None:
    sample = SensorSuite.pwm(2.0, np.array([1500.4, 1620.6, 1000.0, 1999.5]))
    assert np.all(sample.pwm_us == np.round(sample.pwm_us))
    assert sample.pwm_us.tolist() == [1500.0, 1621.0, 1000.0, 2000.0]


def test_noise_stream_is_deterministic_across_block_boundaries() -> None:
    a = NormalStream(np.random.default_rng(7), block=5)
    b = NormalStream(np.random.default_rng(7), block=5)
    xs = [a.take() for _ in range(23)]
    assert xs == [b.take() for _ in range(23)]
    assert xs[:5] == np.random.default_rng(7).standard_normal(5).tolist()
    assert len(set(xs)) == 23
