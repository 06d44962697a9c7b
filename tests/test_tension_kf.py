"""Tension observation (eq. 50) and the constant / derivative Kalman filters (eqs. 43-53)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.config import ConfigError, from_mapping
from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.tension_kf import (
    TensionEstimator,
    TensionFilterConfig,
    TensionKalmanFilter,
    observe_tension_ned_n,
)
from tether_companion.frames import rotation_body_to_ned, rotation_ned_to_body
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample

VEHICLE = VehicleProfile()


def _readings(cable_ned_n, roll, pitch, yaw, thrust_n, mass_kg):
    """Accelerometer specific force (body) from Newton's law: a = (thrust + cable + weight)/m,
    and the accelerometer feels a - g (independent of eq. 50's algebra)."""
    thrust_ned = rotation_body_to_ned(roll, pitch, yaw) @ np.array([0.0, 0.0, -thrust_n])
    gravity_mps2 = np.array([0.0, 0.0, GRAVITY_MPS2])
    accel_ned = (thrust_ned + np.asarray(cable_ned_n)) / mass_kg + gravity_mps2
    return rotation_ned_to_body(roll, pitch, yaw) @ (accel_ned - gravity_mps2)


def test_observation_recovers_cable_force_for_any_attitude_and_motion(rng):
    """Eq. 50 in NED/FRD: exact for any attitude, thrust and (unbalanced) acceleration."""
    for _ in range(200):
        cable = rng.normal(0.0, 5.0, 3)
        roll, pitch, yaw = rng.uniform(-0.6, 0.6), rng.uniform(-0.6, 0.6), rng.uniform(-3, 3)
        thrust = rng.uniform(5.0, 30.0)
        mass = rng.uniform(0.03, 3.0)
        f_body = _readings(cable, roll, pitch, yaw, thrust, mass)
        got = observe_tension_ned_n(f_body, rotation_body_to_ned(roll, pitch, yaw), thrust, mass)
        assert np.allclose(got, cable, atol=1e-9)


def test_hover_without_cable_observes_zero():
    mass = VEHICLE.mass_kg
    thrust = mass * GRAVITY_MPS2
    f_body = np.array([0.0, 0.0, -thrust / mass])
    assert np.allclose(observe_tension_ned_n(f_body, np.eye(3), thrust, mass), 0.0, atol=1e-12)


def test_constant_model_is_the_scalar_kalman_recursion(rng):
    """A = C = I (eqs. 48-49): P- = P + q, K = P-/(P- + R), x += K (y - x), P = (1-K) P-."""
    cfg = TensionFilterConfig(model="constant", constant_process_noise_n2=0.01)
    r = 0.3
    kf = TensionKalmanFilter(cfg.transition(), cfg.process_noise(), r, 2.0)
    ys = rng.normal(1.0, 0.5, (50, 3))
    kf.restart(ys[0])
    x, p = ys[0].copy(), 2.0
    for y in ys[1:]:
        kf.predict()
        kf.update(y)
        p_prior = p + 0.01
        k = p_prior / (p_prior + r)
        x = x + k * (y - x)
        p = (1.0 - k) * p_prior
        assert np.allclose(kf.tension_ned_n, x) and kf.variance_n2 == pytest.approx(p)


def test_derivative_transition_is_eq_51():
    """The last row of eq. 52 applied to (T_{k-2}, T_{k-1}, T_k) is eq. 51."""
    a, b = 0.7, 0.15
    A = TensionFilterConfig(model="derivative", derivative_a=a, derivative_b=b).transition()
    t2, t1, t0 = 1.0, 1.5, 2.5
    nxt = A @ np.array([t2, t1, t0])
    assert nxt[0] == t1 and nxt[1] == t0
    assert nxt[2] == pytest.approx(t0 + a * (t0 - t1) + b * (t0 - t1 - (t1 - t2)))


@pytest.mark.parametrize("model", ["constant", "derivative"])
def test_filters_converge_and_keep_covariance_positive(model, rng):
    cfg = TensionFilterConfig(model=model)
    kf = TensionKalmanFilter(cfg.transition(), cfg.process_noise(), 0.04, 25.0)
    truth = np.array([-2.0, 1.0, 3.0])
    kf.restart(truth + rng.normal(0.0, 0.2, 3))
    for _ in range(3000):
        kf.predict()
        kf.update(truth + rng.normal(0.0, 0.2, 3))
        assert np.all(np.linalg.eigvalsh(kf.P) >= -1e-15)
        assert np.allclose(kf.P, kf.P.T)
    assert np.allclose(kf.tension_ned_n, truth, atol=0.1)
    assert kf.variance_n2 < 0.04 / 10.0


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("model", "kalman", "must be one of"),
        ("derivative_a", 1.5, "<= 1.0"),
        ("constant_process_noise_n2", 0.0, "> 0.0"),
        ("accel_noise_std_mps2", -0.1, "> 0.0"),
        ("max_observed_tension_n", math.nan, "finite"),
        ("unknown_key", 1.0, "unknown key"),
    ],
)
def test_config_bad_values(key, value, match):
    with pytest.raises(ConfigError, match=match):
        from_mapping(TensionFilterConfig, {key: value}, source="tension.yaml")


def test_config_refuses_divergent_derivative_model():
    with pytest.raises(ConfigError, match="diverges"):
        from_mapping(TensionFilterConfig, {"derivative_a": -1.0, "derivative_b": -1.0}, source="t")
    with pytest.raises(ConfigError, match="diverges"):
        from_mapping(TensionFilterConfig, {"derivative_a": 0.5, "derivative_b": -0.8}, source="t")
    # marginal (constant velocity / constant acceleration: roots on the unit circle) is allowed
    from_mapping(TensionFilterConfig, {"derivative_a": 1.0, "derivative_b": 0.0}, source="t")
    from_mapping(TensionFilterConfig, {"derivative_a": 1.0, "derivative_b": 1.0}, source="t")


# ------------------------------------------------------------------------------ estimator


def _hover_samples(t, cable_ned, rng=None, noise=0.0, vehicle=VEHICLE):
    """IMU, attitude and PWM samples of a drone in force balance against ``cable_ned``."""
    mass = vehicle.mass_kg
    needed = -(np.array([0.0, 0.0, mass * GRAVITY_MPS2]) + cable_ned)  # thrust vector, NED
    thrust = float(np.linalg.norm(needed))
    z_body_ned = -needed / thrust  # body z (down) in NED = (cr sp, -sr, cr cp) at yaw 0
    roll = math.asin(-z_body_ned[1])
    pitch = math.atan2(z_body_ned[0], z_body_ned[2])
    rot = rotation_body_to_ned(roll, pitch, 0.0)
    assert np.allclose(rot[:, 2], z_body_ned, atol=1e-9)
    f_body = _readings(cable_ned, roll, pitch, 0.0, thrust, mass)
    if rng is not None:
        f_body = f_body + rng.normal(0.0, noise, 3)
    pwm = vehicle.thrust_curve.pwm_for_thrust(np.full(4, thrust / 4.0))
    return (
        ImuSample(t, f_body, np.zeros(3)),
        AttitudeSample(t, roll, pitch, 0.0),
        PwmSample(t, np.asarray(pwm, dtype=float)),
    )


def _feed(est, imu, att, pwm):
    est.on_attitude(att)
    est.on_pwm(pwm)
    return est.on_imu(imu)


def test_estimator_tracks_tension_from_samples(rng):
    est = TensionEstimator(TensionFilterConfig(), VEHICLE)
    cable = np.array([-3.0, 1.0, 2.5])
    out = None
    for k in range(2000):
        out = _feed(est, *_hover_samples(k * 0.005, cable, rng, 0.1))
    assert out is not None and out.valid and out.updated
    assert np.allclose(out.tension_ned_n, cable, atol=0.1)
    assert out.magnitude_n == pytest.approx(np.linalg.norm(cable), abs=0.1)
    assert out.horizontal_n == pytest.approx(math.hypot(3.0, 1.0), abs=0.1)
    assert out.pull_direction_rad == pytest.approx(math.atan2(1.0, -3.0), abs=0.05)
    assert out.down_n == pytest.approx(2.5, abs=0.1)
    assert out.age_s(out.time_s) == 0.0


def test_estimator_stale_nonfinite_absurd_out_of_order():
    est = TensionEstimator(TensionFilterConfig(), VEHICLE)
    cable = np.array([1.0, 0.0, 1.0])
    imu, att, pwm = _hover_samples(1.0, cable)
    # no attitude yet: no estimate, counted
    est.on_pwm(pwm)
    out = est.on_imu(imu)
    assert out is not None and not out.valid and out.health.stale_attitude == 1
    assert out.age_s(1.0) == math.inf
    est.on_attitude(att)
    assert est.on_imu(imu).valid
    # stale PWM (0.2 s old) -> no update, estimate ages
    imu2, att2, _ = _hover_samples(1.2, cable)
    est.on_attitude(att2)
    out = est.on_imu(imu2)
    assert not out.updated and out.health.stale_pwm == 1 and out.age_s(1.2) == pytest.approx(0.2)
    # NaN samples rejected
    est.on_attitude(AttitudeSample(1.3, math.nan, 0.0, 0.0))
    assert est.on_imu(ImuSample(1.3, np.array([math.nan, 0.0, 0.0]), np.zeros(3))) is None
    assert est.health.nonfinite_rejected == 2
    # out of order
    assert est.on_imu(ImuSample(0.5, np.zeros(3), np.zeros(3))) is None
    assert est.health.out_of_order == 1
    # absurd observation (1 kN) rejected, estimate unchanged
    before = est.filter.tension_ned_n
    _, att3, pwm3 = _hover_samples(1.25, cable)
    est.on_attitude(att3)
    est.on_pwm(pwm3)
    out = est.on_imu(ImuSample(1.25, np.array([700.0, 0.0, -GRAVITY_MPS2]), np.zeros(3)))
    assert not out.updated and out.health.absurd_rejected == 1
    assert np.allclose(out.tension_ned_n, before)


def test_estimator_restarts_after_gap():
    cfg = TensionFilterConfig(max_gap_s=0.5)
    est = TensionEstimator(cfg, VEHICLE)
    _feed(est, *_hover_samples(0.0, np.array([1.0, 0.0, 1.0])))
    _feed(est, *_hover_samples(0.01, np.array([1.0, 0.0, 1.0])))
    out = _feed(est, *_hover_samples(2.0, np.array([-4.0, 0.0, 1.0])))
    assert out.health.restarts == 2
    assert np.allclose(out.tension_ned_n, [-4.0, 0.0, 1.0], atol=1e-6)


class _NumpyTensionKF:
    """The filter as it was written in numpy before the generated scalar code (issue 12): the
    reference the scalar filter must reproduce."""

    def __init__(self, a, q, r, p0):
        self.A, self.Q, self.R, self.n = a, q, r, a.shape[0]
        self.x = np.zeros((self.n, 3))
        self.P = np.eye(self.n) * p0

    def restart(self, y, p0):
        self.x = np.tile(y, (self.n, 1))
        self.P = np.eye(self.n) * p0

    def predict(self):
        self.x = self.A @ self.x
        p = self.A @ self.P @ self.A.T + self.Q
        self.P = 0.5 * (p + p.T)

    def update(self, y):
        innovation = y - self.x[-1]
        s = self.P[-1, -1] + self.R
        gain = self.P[:, -1] / s
        self.x = self.x + np.outer(gain, innovation)
        i_kc = np.eye(self.n)
        i_kc[:, -1] -= gain
        p = i_kc @ self.P @ i_kc.T + self.R * np.outer(gain, gain)
        self.P = 0.5 * (p + p.T)
        return innovation


@pytest.mark.parametrize(
    "cfg",
    [
        TensionFilterConfig(model="constant", constant_process_noise_n2=0.01),
        TensionFilterConfig(model="derivative"),
        TensionFilterConfig(model="derivative", derivative_a=0.5, derivative_b=-0.3),
    ],
)
def test_scalar_filter_equals_the_numpy_filter(cfg, rng):
    """Outputs of the generated scalar filter equal the former numpy filter's within 1e-9."""
    r, p0 = 0.37, 25.0
    fast = TensionKalmanFilter(cfg.transition(), cfg.process_noise(), r, p0)
    ref = _NumpyTensionKF(cfg.transition(), cfg.process_noise(), r, p0)
    truth = np.array([-3.0, 1.0, 2.5])
    for k in range(600):
        y = truth + 0.5 * np.sin(0.02 * k) + rng.normal(0.0, 0.3, 3)
        if k % 250 == 0:  # (re)starts
            fast.restart(y)
            ref.restart(y, p0)
            continue
        fast.predict()
        ref.predict()
        np.testing.assert_allclose(fast.P, ref.P, rtol=0, atol=1e-9)
        innovation = fast.update(y)
        np.testing.assert_allclose(innovation, ref.update(y), rtol=0, atol=1e-9)
        np.testing.assert_allclose(fast.x, ref.x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(fast.P, ref.P, rtol=0, atol=1e-9)
        assert np.array_equal(fast.P, fast.P.T)
        assert fast.variance_n2 == pytest.approx(ref.P[-1, -1], abs=1e-9)
        np.testing.assert_allclose(fast.tension_ned_n, ref.x[-1], rtol=0, atol=1e-9)


def test_estimates_read_late_equal_the_tick_they_were_made_at(rng):
    """An estimate keeps the filter's floats and makes its arrays, counters and ``G`` when
    read: read after the run (the estimator long moved on), every one equals what the tick
    had: the filter's tension, this tick's observation, the counters, and ``G`` of the last
    fused tick as :meth:`TensionErrorBudget.factor` gives it from that tick's rotation,
    thrust and tension. Stale, fused and not-yet-started ticks alike."""
    est = TensionEstimator(TensionFilterConfig(model="derivative"), VEHICLE)
    budget = est.budget
    kept, expected = [], []
    factor = np.zeros((3, 6))
    cable = np.array([-2.0, 1.5, 3.0])
    for k in range(300):
        imu, att, pwm = _hover_samples(k * 0.005, cable, rng, 0.2)
        if k % 7 != 3:  # some ticks with a stale attitude (none at all before the first)
            est.on_attitude(att) if k > 2 else None
        est.on_pwm(pwm)
        out = est.on_imu(imu)
        assert out is not None
        started = est.filter.started
        tension = est.filter.tension_values() if started else [math.nan] * 3
        if out.updated:
            rows, thrust = est.aligner.rotation_rows, est.aligner.thrust_n
            factor = np.array(budget.factor(rows, thrust, tension)).reshape(3, 6)
        health = est.health.copy()
        kept.append(out)
        expected.append((tension, out.variance_n2, out.updated, health, factor))
    assert any(e[2] for e in expected) and not all(e[2] for e in expected)
    for out, (tension, variance, updated, health, factor) in zip(kept, expected, strict=True):
        np.testing.assert_array_equal(out.tension_ned_n, tension)
        assert out.variance_n2 == variance and out.updated == updated
        assert out.health == health
        np.testing.assert_array_equal(out.consider_factor_n, factor)
        assert np.isnan(out.observation_ned_n).all() != updated
        assert out.valid == (math.isfinite(sum(tension)) and math.isfinite(variance))


def test_an_estimate_built_from_arrays_keeps_them():
    """Tests and other makers build an estimate from arrays, as before (G zeros by default)."""
    from tether_companion.estimation.tension_kf import TensionEstimate, TensionHealth

    tension, observation = np.array([1.0, -2.0, 3.0]), np.array([1.5, -2.5, 2.0])
    factor = np.arange(18.0).reshape(3, 6)
    out = TensionEstimate(
        time_s=2.0,
        tension_ned_n=tension,
        variance_n2=0.5,
        last_update_s=1.5,
        observation_ned_n=observation,
        updated=True,
        health=TensionHealth(updates=3),
        consider_factor_n=factor,
        consider_variance_n2=0.25,
    )
    assert out.tension_ned_n is tension and out.observation_ned_n is observation
    assert out.consider_factor_n is factor and out.health == TensionHealth(updates=3)
    np.testing.assert_allclose(out.covariance_ned_n2, 0.75 * np.eye(3) + factor @ factor.T)
    plain = TensionEstimate(2.0, tension, 0.5, 1.5, observation, True, TensionHealth())
    np.testing.assert_array_equal(plain.consider_factor_n, np.zeros((3, 6)))
    assert plain.valid and plain.age_s(2.5) == 1.0
