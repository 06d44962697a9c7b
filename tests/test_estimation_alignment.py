"""InputAligner: latest attitude and PWM at IMU ticks, staleness, bad samples, sharing."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.estimation.alignment import (
    NONFINITE_INPUT,
    STALE_ATTITUDE,
    STALE_PWM,
    AlignedInputs,
    InputAligner,
)
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.pipeline import TetherEstimator
from tether_companion.estimation.tension_kf import TensionEstimator, TensionFilterConfig
from tether_companion.estimation.thrust_input import MotorLagThrustInput, StaticThrustInput
from tether_companion.frames import rotation_body_to_ned, rotation_ned_to_body
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample

VEHICLE = VehicleProfile()
HOVER_PWM = np.full(4, 1500.0)


class CountingThrust:
    """Static thrust of VEHICLE that counts its calls (with their times)."""

    def __init__(self) -> None:
        self.static = StaticThrustInput(VEHICLE)
        self.times_s: list[float] = []

    def total_thrust_n(self, pwm_us: np.ndarray, time_s: float) -> float:
        self.times_s.append(time_s)
        return self.static.total_thrust_n(pwm_us, time_s)


def _imu(t: float, force=(0.1, -0.2, -9.8)) -> ImuSample:
    return ImuSample(t, np.array(force, dtype=float), np.zeros(3))


def test_aligned_inputs_are_the_latest_converted_once_per_sample() -> None:
    thrust = CountingThrust()
    aligner = InputAligner(0.05, 0.04, thrust)
    assert aligner.on_attitude(AttitudeSample(1.0, 0.1, -0.2, 0.3)) is None
    assert aligner.on_pwm(PwmSample(1.0, HOVER_PWM)) is None
    rotation = aligner.rotation_ned_to_body
    for k in range(5):  # ticks reuse the stored conversions
        aligned = aligner.align(_imu(1.0 + 0.005 * k))
        assert isinstance(aligned, AlignedInputs)
        assert aligned.rotation_ned_to_body is rotation
    assert thrust.times_s == [1.0]
    np.testing.assert_allclose(aligned.rotation_ned_to_body, rotation_ned_to_body(0.1, -0.2, 0.3))
    np.testing.assert_allclose(aligned.rotation_body_to_ned, rotation_body_to_ned(0.1, -0.2, 0.3))
    assert aligned.thrust_n == pytest.approx(
        StaticThrustInput(VEHICLE).total_thrust_n(HOVER_PWM, 0)
    )
    assert aligned.time_s == 1.02
    np.testing.assert_array_equal(aligned.specific_force_body_mps2, (0.1, -0.2, -9.8))
    assert aligner.cos_tilt == pytest.approx(math.cos(0.1) * math.cos(-0.2))


def test_staleness_reasons_in_order_and_both_directions() -> None:
    aligner = InputAligner(0.05, 0.04, StaticThrustInput(VEHICLE))
    assert aligner.align(_imu(1.0)) == STALE_ATTITUDE  # nothing yet
    aligner.on_pwm(PwmSample(1.0, HOVER_PWM))
    assert aligner.align(_imu(1.0)) == STALE_ATTITUDE  # attitude first
    aligner.on_attitude(AttitudeSample(1.0, 0.0, 0.0, 0.0))
    assert isinstance(aligner.align(_imu(1.035)), AlignedInputs)  # within both bounds
    assert isinstance(aligner.align(_imu(0.965)), AlignedInputs)  # newer inputs than the IMU
    assert aligner.align(_imu(1.045)) == STALE_PWM
    assert aligner.align(_imu(0.955)) == STALE_PWM
    assert aligner.align(_imu(1.06)) == STALE_ATTITUDE
    assert (
        InputAligner(0.05, 0.04, StaticThrustInput(VEHICLE)).align(_imu(math.nan))
        == NONFINITE_INPUT
    )


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_nonfinite_samples_are_reported_and_not_stored(bad: float) -> None:
    thrust = CountingThrust()
    aligner = InputAligner(0.05, 0.05, thrust)
    aligner.on_attitude(AttitudeSample(1.0, 0.0, 0.0, 0.0))
    aligner.on_pwm(PwmSample(1.0, HOVER_PWM))
    assert aligner.on_attitude(AttitudeSample(1.01, 0.0, bad, 0.0)) == NONFINITE_INPUT
    assert aligner.on_attitude(AttitudeSample(bad, 0.0, 0.0, 0.0)) == NONFINITE_INPUT
    assert (
        aligner.on_pwm(PwmSample(1.01, np.array([1500.0, bad, 1500.0, 1500.0]))) == NONFINITE_INPUT
    )
    assert aligner.on_pwm(PwmSample(bad, HOVER_PWM)) == NONFINITE_INPUT
    both = np.array([math.inf, -math.inf, 1500.0, 1500.0])  # a sum check must not cancel them
    assert aligner.on_pwm(PwmSample(1.02, both)) == NONFINITE_INPUT
    assert thrust.times_s == [1.0]  # non-finite PWM never reaches the thrust input
    assert aligner.attitude.time_s == 1.0 and aligner.pwm_time_s == 1.0
    assert aligner.align(_imu(1.0, (0.0, bad, -9.8))) == NONFINITE_INPUT


def test_nonfinite_thrust_is_reported() -> None:
    class NanThrust:
        def total_thrust_n(self, pwm_us: np.ndarray, time_s: float) -> float:
            return math.nan

    aligner = InputAligner(0.05, 0.05, NanThrust())
    assert aligner.on_pwm(PwmSample(1.0, HOVER_PWM)) == NONFINITE_INPUT
    assert math.isnan(aligner.pwm_time_s)


def test_refused_pwm_raises_and_is_offered_again() -> None:
    thrust = CountingThrust()
    aligner = InputAligner(0.05, 0.05, thrust)
    wrong = PwmSample(1.0, np.full(3, 1500.0))
    for _ in range(2):  # the second estimator sharing the aligner sees the same refusal
        with pytest.raises(ValueError, match="expected 4"):
            aligner.on_pwm(wrong)
    assert thrust.times_s == [1.0, 1.0] and math.isnan(aligner.pwm_time_s)


def test_the_same_sample_object_is_converted_once() -> None:
    thrust = CountingThrust()
    aligner = InputAligner(0.05, 0.05, thrust)
    pwm, att = PwmSample(1.0, HOVER_PWM), AttitudeSample(1.0, 0.1, 0.0, 0.0)
    bad = AttitudeSample(1.0, math.nan, 0.0, 0.0)
    for _ in range(2):
        assert aligner.on_pwm(pwm) is None
        assert aligner.on_attitude(att) is None
        assert aligner.on_attitude(bad) == NONFINITE_INPUT
    assert thrust.times_s == [1.0]
    aligner.on_pwm(dataclasses.replace(pwm))  # equal but a new sample: converted
    assert thrust.times_s == [1.0, 1.0]


def test_a_repeated_tick_sees_inputs_that_arrived_in_between() -> None:
    aligner = InputAligner(0.05, 0.05, StaticThrustInput(VEHICLE))
    imu = _imu(1.0)
    aligner.on_attitude(AttitudeSample(1.0, 0.0, 0.0, 0.0))
    assert aligner.align(imu) == STALE_PWM
    assert aligner.align(imu) == STALE_PWM
    aligner.on_pwm(PwmSample(1.0, HOVER_PWM))
    first = aligner.align(imu)
    assert isinstance(first, AlignedInputs) and aligner.align(imu) is first
    aligner.on_attitude(AttitudeSample(1.0, 0.2, 0.0, 0.0))
    again = aligner.align(imu)
    np.testing.assert_allclose(again.rotation_ned_to_body, rotation_ned_to_body(0.2, 0.0, 0.0))


def test_an_aligner_is_shared_only_when_it_matches() -> None:
    config = EstimatorConfig()
    thrust = StaticThrustInput(VEHICLE)
    aligner = InputAligner(config.staleness.attitude_s, config.staleness.pwm_s, thrust)
    estimator = TetherEstimator(config, VEHICLE, aligner=aligner)
    assert estimator.aligner is aligner and estimator.thrust_input is thrust
    assert TetherEstimator(config, VEHICLE, thrust, aligner=aligner).aligner is aligner
    with pytest.raises(ValueError, match="own thrust input"):
        TetherEstimator(config, VEHICLE, StaticThrustInput(VEHICLE), aligner=aligner)
    with pytest.raises(ValueError, match="staleness bounds"):
        TensionEstimator(TensionFilterConfig(attitude_staleness_s=0.02), VEHICLE, aligner=aligner)


def _hover_samples(rng: np.random.Generator, n: int):
    """Hover-ish samples at 200 Hz with a PWM step and noisy attitude (tension ~ 5 N down)."""
    for k in range(n):
        t = 0.005 * k
        pwm = HOVER_PWM + (60.0 if k > n // 2 else 0.0) + rng.normal(0.0, 5.0, 4)
        att = AttitudeSample(t, rng.normal(0.0, 0.02), rng.normal(0.0, 0.02), 0.1)
        force = np.array((0.0, 0.0, -9.0)) + rng.normal(0.0, 0.1, 3)
        yield att, PwmSample(t, pwm), ImuSample(t, force, np.zeros(3))


def test_estimators_sharing_an_aligner_match_separate_ones(rng: np.random.Generator) -> None:
    """A shared aligner (one motor-lag thrust input, advanced once per PWM sample) gives both
    estimators exactly what private aligners with their own motor-lag inputs give them."""
    config, tension_config = EstimatorConfig(), TensionFilterConfig()
    lag = MotorLagThrustInput(VEHICLE)
    shared = InputAligner(config.staleness.attitude_s, config.staleness.pwm_s, lag)
    pairs = {
        "shared": (
            TetherEstimator(config, VEHICLE, aligner=shared),
            TensionEstimator(tension_config, VEHICLE, aligner=shared),
        ),
        "separate": (
            TetherEstimator(config, VEHICLE, MotorLagThrustInput(VEHICLE)),
            TensionEstimator(tension_config, VEHICLE, MotorLagThrustInput(VEHICLE)),
        ),
    }
    out: dict[str, list] = {name: [] for name in pairs}
    for att, pwm, imu in _hover_samples(rng, 400):
        for name, (ekf, tension) in pairs.items():
            ekf.on_attitude(att)
            tension.on_attitude(att)
            ekf.on_pwm(pwm)
            tension.on_pwm(pwm)
            estimate, filtered = ekf.on_imu(imu), tension.on_imu(imu)
            out[name].append((estimate.position_ned_m, estimate.covariance, filtered.tension_ned_n))
    for a, b in zip(out["shared"], out["separate"], strict=True):
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)
    ekf, tension = pairs["shared"]
    assert ekf.health.accel_fused + ekf.health.accel_gated == 400
    assert tension.health.updates == 400
