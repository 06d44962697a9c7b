"""Motor mixing (quad X), saturation, PWM outputs and the first-order lag."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.physics.motors import MotorLag, MotorMixer
from tether_companion.physics.vehicle import load_vehicle


@pytest.fixture(params=["default-quad", "crazyflie"])
def mixer(request: pytest.FixtureRequest) -> MotorMixer:
    return MotorMixer(load_vehicle(request.param))


def test_mixing_reproduces_the_requested_wrench(mixer: MotorMixer) -> None:
    hover = 0.6 * mixer.max_thrust_n * mixer.n_motors
    torque = np.array([0.02, -0.01, 0.005]) * mixer.max_thrust_n * mixer.vehicle.arm_length_m
    thrusts = mixer.motor_thrusts_n(hover, torque.tolist())
    assert mixer.wrench(thrusts) == pytest.approx([hover, *torque], rel=1e-9, abs=1e-15)


def test_quad_x_signs_follow_ardupilot_layout() -> None:
    mixer = MotorMixer(load_vehicle("default-quad"))
    thrusts = mixer.motor_thrusts_n(20.0, (0.5, 0.0, 0.0))  # roll right: left motors push more
    # motors 2 (back-left) and 3 (front-left) have y < 0
    assert thrusts[1] > thrusts[0] and thrusts[2] > thrusts[3]
    thrusts = mixer.motor_thrusts_n(20.0, (0.0, 0.5, 0.0))  # pitch up: front motors push more
    assert thrusts[0] > thrusts[1] and thrusts[2] > thrusts[3]
    thrusts = mixer.motor_thrusts_n(20.0, (0.0, 0.0, 0.1))  # yaw right: ccw motors 1, 2
    assert thrusts[0] > thrusts[2] and thrusts[1] > thrusts[3]


def test_saturation_keeps_motors_in_range_and_torque_direction(mixer: MotorMixer) -> None:
    collective = 0.9 * mixer.max_thrust_n * mixer.n_motors
    torque = np.array([1.0, 0.5, 0.2]) * mixer.max_thrust_n * mixer.vehicle.arm_length_m
    thrusts = np.array(mixer.motor_thrusts_n(collective, torque.tolist()))
    assert np.all(thrusts >= mixer.min_thrust_n - 1e-12)
    assert np.all(thrusts <= mixer.max_thrust_n + 1e-12)
    got = mixer.wrench(thrusts)[1:]
    # scaled down uniformly: same direction
    assert got / np.linalg.norm(got) == pytest.approx(torque / np.linalg.norm(torque), rel=1e-9)


def test_pwm_outputs_are_whole_microseconds_inverting_the_curve(mixer: MotorMixer) -> None:
    thrusts = (np.array([0.3, 0.5, 0.55, 0.7]) * mixer.max_thrust_n).tolist()
    pwm = np.array(mixer.pwm_us(thrusts))
    assert np.all(pwm == np.round(pwm))
    # nearest whole microsecond in thrust: no neighbouring pulse is closer
    for p, f in zip(pwm, thrusts, strict=True):
        err = abs(float(mixer.curve.thrust_n(p)) - f)
        assert err <= abs(float(mixer.curve.thrust_n(p - 1)) - f)
        assert err <= abs(float(mixer.curve.thrust_n(p + 1)) - f)
        assert p == pytest.approx(float(mixer.curve.pwm_for_thrust(f)), abs=1.0)
    assert mixer.thrusts_for_pwm_us(pwm) == pytest.approx(mixer.curve.thrust_n(pwm).tolist())
    # out of range: clipped to the end pulses
    low, high = mixer.curve.pwm_min_us, mixer.curve.pwm_max_us
    assert mixer.pwm_us([-1.0, 1e9]) == [low, high]
    assert mixer.thrusts_for_pwm_us([low - 50, high + 50]) == [
        mixer.min_thrust_n,
        mixer.max_thrust_n,
    ]
    assert mixer.idle_pwm_us() == [low] * mixer.n_motors


def test_motor_lag_matches_exponential_and_refuses_bad_tau() -> None:
    lag = MotorLag(0.05)
    assert lag.decay(0.1) == pytest.approx(math.exp(-2.0), rel=1e-15)
    assert lag.decay(0.0) == 1.0
    with pytest.raises(ValueError, match="> 0"):
        MotorLag(0.0)


def _mix_with_builtins(collective_share, torque_rows, collective_n, torque, f_min, f_max):
    """The mixing rule with the min/max builtins (the generated code's former form)."""
    tl, tm, tn = torque
    bases = [min(max(c * collective_n, f_min), f_max) for c in collective_share]
    shares = [a * tl + b * tm + e * tn for a, b, e in torque_rows]
    scale = 1.0
    for base, share in zip(bases, shares, strict=True):
        if share > 0.0 and base + share > f_max:
            scale = min(scale, (f_max - base) / share)
        elif share < 0.0 and base + share < f_min:
            scale = min(scale, (f_min - base) / share)
    scale = max(scale, 0.0)
    return [base + scale * share for base, share in zip(bases, shares, strict=True)]


def test_generated_mixing_is_the_builtins_rule_bit_for_bit() -> None:
    """The generated code's comparisons (perf15: no min/max calls) give the builtins' floats,
    saturated, negative, nan and infinite requests included."""
    import itertools
    import struct

    from tether_companion.physics.motors import _mixing_function

    share = (0.25, 0.25, 0.25, 0.25)
    rows = ((-1.3, 1.1, 0.4), (1.3, -1.1, 0.4), (1.3, 1.1, -0.4), (-1.3, -1.1, -0.4))
    mix = _mixing_function(share, rows)
    rng = np.random.default_rng(5)
    specials = (0.0, -0.0, 3.0, 40.0, -5.0, math.inf, -math.inf, math.nan)
    cases = [
        (float(rng.uniform(-10, 60)), tuple(float(v) for v in rng.normal(0, 2, 3)))
        for _ in range(300)
    ]
    cases += [(c, (t, -t, 0.5 * t)) for c, t in itertools.product(specials, repeat=2)]

    def bits(values):
        return [struct.pack("<d", v) if not math.isnan(v) else b"nan" for v in values]

    for collective, torque in cases:
        got = mix(collective, torque, 0.4, 9.0)
        expected = _mix_with_builtins(share, rows, collective, torque, 0.4, 9.0)
        assert bits(got) == bits(expected), (collective, torque)
