"""TetherEstimator: time alignment, staleness, bad samples, resets, convergence.

The flight here is synthetic and exactly consistent with the paper's measurement model (a
circle above the anchor with the attitude that produces the needed force), so the filter is
tested apart from the simulator; ``test_estimation_simulate.py`` runs it on the simulator.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.config import ConfigError
from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.pipeline import TetherEstimator
from tether_companion.estimation.thrust_input import (
    HOLD_FRACTION,
    MotorLagThrustInput,
    StaticThrustInput,
)
from tether_companion.frames import rotation_ned_to_body
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample

VEHICLE = VehicleProfile()
DT_S = 0.005


def _flight(rng: np.random.Generator, tension_n: float, duration_s: float):
    """Yield (truth position, attitude, pwm, imu, range) samples at 200 Hz."""
    m, g = VEHICLE.mass_kg, GRAVITY_MPS2
    omega = 1.0 / 2.5  # 1 m/s on a 2.5 m circle
    for k in range(int(duration_s / DT_S)):
        t = k * DT_S
        p = np.array(
            [2.5 * math.cos(omega * t), 2.5 * math.sin(omega * t), -3.0 - 0.5 * math.sin(0.3 * t)]
        )
        a = np.array(
            [
                -2.5 * omega**2 * math.cos(omega * t),
                -2.5 * omega**2 * math.sin(omega * t),
                0.045 * math.sin(0.3 * t),
            ]
        )
        u = p / np.linalg.norm(p)
        thrust_ned = m * a - np.array([0.0, 0.0, m * g]) + tension_n * u
        thrust = float(np.linalg.norm(thrust_ned))
        z_body = -thrust_ned / thrust  # body z axis in NED (yaw 0)
        roll, pitch = math.asin(-z_body[1]), math.atan2(z_body[0], z_body[2])
        rot = rotation_ned_to_body(roll, pitch, 0.0)
        specific_force = rot @ (thrust_ned - tension_n * u) / m
        pwm = np.full(4, float(VEHICLE.thrust_curve.pwm_for_thrust(thrust / 4)))
        yield (
            p,
            AttitudeSample(t, roll + rng.normal(0, 0.0017), pitch + rng.normal(0, 0.0017), 0.0),
            PwmSample(t, pwm),
            ImuSample(t, specific_force + rng.normal(0, 0.1, 3), np.zeros(3)),
            RangeSample(t, -p[2] / (math.cos(roll) * math.cos(pitch)) + rng.normal(0, 0.3)),
        )


def _run(estimator: TetherEstimator, rng, tension_n=4.0, duration_s=10.0, known_tension=False):
    errors, tension_errors, last = [], [], None
    for p, att, pwm, imu, rng_sample in _flight(rng, tension_n, duration_s):
        estimator.on_attitude(att)
        estimator.on_pwm(pwm)
        if known_tension:
            estimator.set_known_tension_n(tension_n, imu.time_s)
        last = estimator.on_imu(imu)
        estimator.on_range(rng_sample)
        if imu.time_s > duration_s / 2:
            errors.append(last.position_ned_m - p)
            tension_errors.append(last.tension_n - tension_n)
    return (
        np.sqrt(np.mean(np.square(errors), axis=0)),
        math.sqrt(np.mean(np.square(tension_errors))),
        last,
    )


def test_four_state_converges_from_paper_initial_state(rng) -> None:
    estimator = TetherEstimator(EstimatorConfig(), VEHICLE)
    rmse, tension_rmse, last = _run(estimator, rng)
    assert np.all(rmse < 0.3), rmse
    assert tension_rmse < 0.3
    assert last.covariance.shape == (4, 4) and last.position_ned_m.shape == (3,)
    np.linalg.cholesky(last.covariance)
    health = last.health
    assert health.imu_ticks == 2000 and health.accel_fused > 1800 and health.range_fused > 1900
    assert last.reset_counter == 0 and health.nonfinite_rejected == 0


def test_three_state_uses_known_tension(rng) -> None:
    config = dataclasses.replace(EstimatorConfig(), kind="three_state")
    estimator = TetherEstimator(config, VEHICLE)
    rmse, tension_rmse, last = _run(estimator, rng, known_tension=True)
    assert np.all(rmse < 0.3), rmse
    assert tension_rmse == 0.0 and last.covariance.shape == (3, 3)


def test_three_state_without_tension_skips_accel_updates(rng) -> None:
    estimator = TetherEstimator(dataclasses.replace(EstimatorConfig(), kind="three_state"), VEHICLE)
    _, _, last = _run(estimator, rng, duration_s=0.5)
    assert last.health.accel_fused == 0 and last.health.stale_tension == 100
    assert math.isnan(last.tension_n)


def _primed(t: float = 0.0) -> TetherEstimator:
    estimator = TetherEstimator(EstimatorConfig(), VEHICLE)
    estimator.on_attitude(AttitudeSample(t, 0.0, 0.0, 0.0))
    estimator.on_pwm(PwmSample(t, np.full(4, 1650.0)))
    return estimator


def _imu(t: float, value: float = -9.0) -> ImuSample:
    return ImuSample(t, np.array([0.3, 0.2, value]), np.zeros(3))


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_nonfinite_samples_are_rejected_and_counted(bad: float) -> None:
    estimator = _primed()
    first = estimator.on_imu(_imu(0.0))
    assert first is not None
    assert estimator.on_imu(_imu(0.005, bad)) is None
    assert estimator.on_imu(ImuSample(bad, np.zeros(3), np.zeros(3))) is None
    estimator.on_attitude(AttitudeSample(0.005, bad, 0.0, 0.0))
    estimator.on_pwm(PwmSample(0.005, np.array([1500.0, bad, 1500.0, 1500.0])))
    estimator.on_range(RangeSample(0.005, bad))
    estimator.set_known_tension_n(bad, 0.005)
    assert estimator.health.nonfinite_rejected == 6
    after = estimator.on_imu(_imu(0.01))
    assert np.isfinite(after.position_ned_m).all() and np.isfinite(after.covariance).all()


def test_stale_attitude_or_pwm_means_no_update() -> None:
    estimator = _primed(0.0)
    estimate = estimator.on_imu(_imu(0.2))  # attitude and PWM are 0.2 s old (> 0.05 s)
    assert estimate is not None and not estimate.accel_fused
    assert estimator.health.stale_attitude == 1
    estimator.on_attitude(AttitudeSample(0.21, 0.0, 0.0, 0.0))
    assert not estimator.on_imu(_imu(0.21)).accel_fused
    assert estimator.health.stale_pwm == 1
    estimator.on_pwm(PwmSample(0.22, np.full(4, 1650.0)))
    assert estimator.on_imu(_imu(0.22)).accel_fused


def test_out_of_order_and_long_gap() -> None:
    estimator = _primed(0.0)
    estimator.on_imu(_imu(1.0))
    assert estimator.on_imu(_imu(0.5)) is None and estimator.health.out_of_order == 1
    estimate = estimator.on_imu(_imu(5.0))  # 4 s without IMU: reset
    assert estimate.reset_counter == 1 and estimate.health.resets == 1
    np.testing.assert_allclose(estimate.position_ned_m, EstimatorConfig().initial_position_ned_m)


def test_range_is_tilt_corrected_and_validated() -> None:
    estimator = TetherEstimator(EstimatorConfig(), VEHICLE)
    roll = 0.3
    estimator.on_attitude(AttitudeSample(0.0, roll, 0.0, 0.0))
    estimator.on_imu(_imu(0.0))  # no PWM: no accel update, just starts the clock
    for _ in range(200):
        estimator.on_range(RangeSample(0.0, 4.0))
    height = -estimator.filter.x[2]
    assert height == pytest.approx(4.0 * math.cos(roll), abs=0.05)
    estimator.on_range(RangeSample(0.0, 100.0))
    estimator.on_range(RangeSample(0.0, 0.01))
    assert estimator.health.range_out_of_range == 2
    estimator.on_range(RangeSample(-1.0, 4.0))
    estimator.on_range(RangeSample(1.0, 4.0))  # far ahead of the filter (IMU stalled)
    assert estimator.health.range_stale == 2
    estimator.on_attitude(AttitudeSample(0.0, 1.2, 0.0, 0.0))  # beyond max_tilt_rad
    estimator.on_range(RangeSample(0.0, 4.0))
    assert estimator.health.range_out_of_range == 3
    assert estimator.health.range_fused == 200


def test_static_thrust_input_is_the_profile_curve(rng) -> None:
    thrust_input = StaticThrustInput(VEHICLE)
    for _ in range(50):
        pwm = rng.uniform(900.0, 2100.0, 4)  # beyond both ends: clipped like the curve
        expected = float(np.sum(VEHICLE.thrust_curve.thrust_n(pwm)))
        assert thrust_input.total_thrust_n(pwm, 0.0) == pytest.approx(expected, rel=1e-12)
    with pytest.raises(ValueError, match="expected 4"):
        thrust_input.total_thrust_n(np.ones(3) * 1500.0, 0.0)


def test_motor_lag_thrust_input_is_the_exact_first_order_step_response() -> None:
    """A PWM step at 200 Hz: each value is the static thrust lagged by exp(-t / tau), read
    ``HOLD_FRACTION`` of a sample into the hold; a long gap restarts at the commanded thrust."""
    lag = MotorLagThrustInput(VEHICLE)
    static = StaticThrustInput(VEHICLE)
    tau = VEHICLE.motor_time_constant_s
    low, high = np.full(4, 1400.0), np.full(4, 1600.0)
    f_low, f_high = static.total_thrust_n(low, 0.0), static.total_thrust_n(high, 0.0)
    assert lag.total_thrust_n(low, 0.0) == pytest.approx(f_low)  # first sample: steady
    assert lag.total_thrust_n(low, DT_S) == pytest.approx(f_low)
    for k in range(2, 40):  # step to `high` at 2 DT_S
        t_read = (k - 2 + HOLD_FRACTION) * DT_S  # time since the step when the value is used
        expected = f_high + (f_low - f_high) * math.exp(-t_read / tau)
        assert lag.total_thrust_n(high, k * DT_S) == pytest.approx(expected, rel=1e-12)
    assert lag.total_thrust_n(low, 5.0) == pytest.approx(f_low)  # 5 s gap: restart
    with pytest.raises(ValueError, match="expected 4"):
        lag.total_thrust_n(np.ones(3) * 1500.0, 5.005)


def test_identified_thrust_model_file_is_used_and_bad_file_refused(tmp_path) -> None:
    model = tmp_path / "thrust.yaml"
    model.write_text("kind: static\nn_motors: 4\nthrust_curve: {coefficients_n: [0.0, 1.0, 0.0]}\n")
    config = dataclasses.replace(EstimatorConfig(), thrust_model=str(model))
    estimator = TetherEstimator(config, VEHICLE)
    pwm = np.full(4, 1500.0)  # u = 0.5 -> 0.5 N per motor on this linear curve
    assert estimator.thrust_input.total_thrust_n(pwm, 0.0) == pytest.approx(2.0)
    missing = dataclasses.replace(EstimatorConfig(), thrust_model=str(tmp_path / "none.yaml"))
    with pytest.raises(ConfigError, match="file not found"):
        TetherEstimator(missing, VEHICLE)


def test_range_stamped_ahead_of_the_imu_does_not_move_the_filter_clock() -> None:
    estimator = _primed(0.0)
    estimator.on_imu(_imu(0.0))
    estimator.on_range(RangeSample(0.004, 3.0))  # stamped after the next IMU sample below
    assert estimator.health.range_fused == 1 and estimator.time_s == 0.0
    estimator.on_attitude(AttitudeSample(0.003, 0.0, 0.0, 0.0))
    assert estimator.on_imu(_imu(0.003)) is not None
    assert estimator.health.out_of_order == 0


def test_range_before_the_first_imu_waits_for_it() -> None:
    """Streams interleave: a DISTANCE_SENSOR can arrive before the first RAW_IMU. It is fused
    right after the first IMU tick (not dropped, and it does not start the clock: that IMU
    sample, stamped a hair earlier, still ticks); of two early readings only the latest."""
    estimator = TetherEstimator(EstimatorConfig(), VEHICLE)
    estimator.on_attitude(AttitudeSample(0.0, 0.0, 0.0, 0.0))
    estimator.on_range(RangeSample(0.0, 9.0))
    estimator.on_range(RangeSample(0.001, 3.0))
    assert estimator.health.range_fused == 0 and math.isnan(estimator.time_s)
    assert estimator.on_imu(_imu(0.0005)) is not None
    assert estimator.health.range_fused == 1 and estimator.health.range_stale == 1
    assert estimator.health.out_of_order == 0 and estimator.time_s == 0.0005
    assert -estimator.filter.x[2] < 4.0  # pulled toward 3 m from x0, not toward 9 m


def test_pwm_with_wrong_motor_count_is_refused_and_counted() -> None:
    estimator = _primed(0.0)
    estimator.on_pwm(PwmSample(0.001, np.full(8, 1500.0)))
    assert estimator.health.pwm_invalid == 1
    assert estimator.on_imu(_imu(0.002)).accel_fused  # the earlier valid PWM still serves


def test_an_estimate_made_of_values_reads_as_arrays() -> None:
    """Estimate.of_values keeps Python floats and builds the arrays on first read; an estimate
    made of arrays gives the same values back as floats."""
    from tether_companion.estimation.estimate import Estimate

    state = [1.0, 2.0, -3.0, 4.5]
    covariance = np.diag([0.1, 0.2, 0.3, 0.4]).ravel().tolist()
    lazy = Estimate.of_values(1.5, state, covariance, 4.5, 2, True, (), None)
    np.testing.assert_array_equal(lazy.position_ned_m, [1.0, 2.0, -3.0])
    np.testing.assert_array_equal(lazy.covariance, np.diag([0.1, 0.2, 0.3, 0.4]))
    assert lazy.position_ned_m is lazy.position_ned_m  # built once
    np.testing.assert_array_equal(lazy.position_covariance_m2, np.diag([0.1, 0.2, 0.3]))
    eager = Estimate(1.5, np.array(state[:3]), 4.5, np.array(covariance).reshape(4, 4), 2, True, ())
    assert eager.state_values == state
    assert eager.covariance_values == covariance
