"""The dynamic filter's posterior CRLB (estimation/dynamic/crlb.py).

* one step of the recursion equals Tichavsky et al.'s ``D`` form and, for a linear-Gaussian
  model, the Kalman filter's covariance (where the bound is attained);
* along a flight the bound equals an independent Kalman covariance recursion at the truth:
  Jacobians by central differences of the generated *values*, samples fused one by one in
  Joseph form. Dropping or double counting one sample's information breaks that agreement
  (checked: the reference with a sample counted twice differs by far more than the tolerance).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.estimation.dynamic import generated, state
from tether_companion.estimation.dynamic.crlb import (
    BoundNoise,
    CalibrationPrior,
    Gating,
    TrueTrack,
    information_step,
    posterior_bound,
)
from tether_companion.estimation.dynamic.crlb_noise import residual_density_m2ps3
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.frames import rotation_ned_to_body_rows

N = state.CALIBRATION.start
"""The bound's state (the filter's without the calibration, which the bound augments)."""
ACCEL_VAR = (0.3**2, 0.4**2, 0.2**2)


def _spd(rng: np.random.Generator, n: int, scale: float) -> np.ndarray:
    a = rng.standard_normal((n, n))
    return scale * (a @ a.T + n * np.eye(n))


def test_one_step_is_the_d_form_and_the_kalman_covariance():
    """Linear-Gaussian: ``x' = F x + w``, ``z = H x + v``. Tichavsky's
    ``D22 - D21 (J + D11)^-1 D12`` (``D11 = F^T Q^-1 F``, ``D12 = -F^T Q^-1``,
    ``D22 = Q^-1 + H^T R^-1 H``) and the Kalman filter's ``(I - K H) (F P F^T + Q)`` are the
    same matrix, and the step gives their inverse / value."""
    rng = np.random.default_rng(3)
    n, m = 5, 2
    f = np.eye(n) + 0.1 * rng.standard_normal((n, n))
    q = _spd(rng, n, 0.01)
    h = rng.standard_normal((m, n))
    r = _spd(rng, m, 0.1)
    p = _spd(rng, n, 0.3)
    j = np.linalg.inv(p)
    q_inv, r_inv = np.linalg.inv(q), np.linalg.inv(r)
    d11, d12, d22 = f.T @ q_inv @ f, -f.T @ q_inv, q_inv + h.T @ r_inv @ h
    j_next = d22 - d12.T @ np.linalg.inv(j + d11) @ d12
    predicted = f @ p @ f.T + q
    gain = predicted @ h.T @ np.linalg.inv(h @ predicted @ h.T + r)
    kalman = (np.eye(n) - gain @ h) @ predicted
    step = information_step(p, f, q, h.T @ r_inv @ h)
    np.testing.assert_allclose(step, kalman, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.linalg.inv(j_next), kalman, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(information_step(p, f, q, None), predicted, rtol=1e-12)


def _track(weight: float) -> tuple[TrueTrack, ModelConstants]:
    """1 s of a 1 m/s circle at 200 Hz, 2.5 m out and 2 m up, a 4 N pull toward the anchor
    (the chord tension the straight or catenary model reads from it), a 1 m/s wind,
    rangefinder every 10th tick, cable angle every 20th."""
    constants = ModelConstants(1.5, 0.2, weight)
    t = np.arange(200) * 0.005
    angle = t / 2.5
    position = np.stack([2.5 * np.cos(angle), 2.5 * np.sin(angle), np.full_like(t, -2.0)], 1)
    velocity = np.stack([-np.sin(angle), np.cos(angle), np.zeros_like(t)], 1)
    euler = np.stack([0.05 * np.sin(3 * t), 0.1 * np.cos(2 * t), angle], 1)
    distance = np.linalg.norm(position, axis=1, keepdims=True)
    force = -4.0 * position / distance
    wind = np.tile([1.0, 0.5, 0.0], (len(t), 1))
    track = TrueTrack(
        t,
        position,
        velocity,
        euler,
        np.full_like(t, 16.0),
        force,
        wind,
        np.arange(len(t)) % 10 == 0,
        np.zeros((len(t), 3)),
        np.arange(len(t)) % 20 == 5,
    )
    return track, constants


def _fd(model, x, u, c, rows):
    """Central differences of a generated model's values (its Jacobian not used)."""
    jac = np.zeros((rows, N))
    for i in range(N):
        step = 1e-6 * max(1.0, abs(x[i]))
        up, down = list(x), list(x)
        up[i] += step
        down[i] -= step
        jac[:, i] = (np.array(model(up, u, c)[0]) - np.array(model(down, u, c)[0])) / (2 * step)
    return jac


def _reference(track, constants, noise, *, repeat_range: int = 1) -> np.ndarray:
    """An EKF covariance along the truth, samples fused one at a time (Joseph form), the
    Jacobians by differences; the rangefinder fused ``repeat_range`` times per sample. With
    ``noise.calibration`` the state has the four calibration errors after the 13 (winch offset
    and scale, elevation and azimuth zero errors), written here from the readings' own
    equations: ``offset + (1 + scale) L`` and ``angle + bias``."""
    models = constants.models
    c = constants.values()
    calibration = noise.calibration
    extra = 0 if calibration is None else 4
    n = N + extra
    prior = noise.prior_std if calibration is None else np.r_[noise.prior_std, calibration.std()]
    p = np.diag(prior**2)
    out = np.empty((len(track.time_s), N))

    def wide(h, calibration_columns=()):
        full = np.zeros((h.shape[0], n))
        full[:, :N] = h
        for row, column, value in calibration_columns:
            full[row, column] = value
        return full

    previous = track.time_s[0]
    for k in range(len(track.time_s)):
        x = track.state_at(k)
        rows = rotation_ned_to_body_rows(*track.euler_rad[k])
        rotation = (*rows[0], *rows[1], *rows[2])
        dt = track.time_s[k] - previous
        previous = track.time_s[k]
        a = np.zeros((N, N))
        a[0:3, 3:6] = np.eye(3)
        a[3:6] = _fd(
            lambda xs, u, cc: (generated.inertial(xs, u, cc)[0][3:6], ()),
            x,
            (*rotation, 0.0, 0.0, 0.0),
            c,
            3,
        )
        f = np.eye(n)
        f[:N, :N] += dt * a
        p = f @ p @ f.T + np.diag(np.r_[noise.process_density, np.zeros(extra)] * dt)
        accel = _fd(models.accel, x, (*rotation, 16.0), c, 3)
        samples = [(wide(accel), np.diag(noise.force_balance_var_mps2))]
        if track.range_seen[k]:
            height = _fd(generated.height_above_ground, x, (0.0,), (0.0, 0.0, 0.0), 1)
            samples += [(wide(height), np.array([[noise.range_var_m2]]))] * repeat_range
        if track.winch_seen is None or track.winch_seen[k]:
            length = models.winch_length(x, (), c)[0][0]
            winch_columns = () if extra == 0 else ((0, N, 1.0), (0, N + 1, length))
            h = wide(_fd(models.winch_length, x, (), c, 1), winch_columns)
            samples.append((h, np.array([[noise.winch_var_m2]])))
        if track.angle_seen[k]:
            elevation = models.cable_angle(x, (), c)[0][0]
            var = noise.cable_angle_var_rad2
            r = np.diag([var, var / math.cos(elevation) ** 2])
            angle_columns = () if extra == 0 else ((0, N + 2, 1.0), (1, N + 3, 1.0))
            samples.append((wide(_fd(models.cable_angle, x, (), c, 2), angle_columns), r))
        for h, r in samples:
            s = h @ p @ h.T + r
            gain = p @ h.T @ np.linalg.inv(s)
            joseph = np.eye(n) - gain @ h
            p = joseph @ p @ joseph.T + gain @ r @ gain.T
        out[k] = np.diag(p)[:N]
    return out


@pytest.mark.parametrize("weight", [0.0, 0.164])
def test_the_bound_is_the_kalman_covariance_at_the_truth(weight):
    track, constants = _track(weight)
    prior = np.array([5.0, 5, 5, 0.5, 0.5, 0.5, 3.0, 0.1, 0.2, 0.2, 0.2, 2.0, 2.0])
    density = np.array(
        [1e-6, 1e-6, 1e-6, 1e-4, 1e-4, 1e-4, 2.0, 1e-5, 1e-4, 1e-4, 1e-4, 0.04, 0.04]
    )
    noise = BoundNoise(
        density, prior, ACCEL_VAR, 0.05**2, winch_var_m2=0.05**2, cable_angle_var_rad2=0.01**2
    )
    gating = Gating(ticks_per_fusion=1, min_distance_m=0.3, min_thrust_n=5.0)
    bound = posterior_bound(track, constants, noise, gating)
    reference = _reference(track, constants, noise)
    np.testing.assert_allclose(bound, reference, rtol=1e-4)
    doubled = _reference(track, constants, noise, repeat_range=2)
    assert np.max(np.abs(doubled[:, 2] / reference[:, 2] - 1.0)) > 0.05
    only_sensors = posterior_bound(
        track, constants, BoundNoise(density, prior, ACCEL_VAR, 0.05**2), gating
    )
    assert np.max(np.abs(only_sensors[:, 0] / bound[:, 0] - 1.0)) > 0.05


def test_calibration_errors_are_estimated_beside_the_state_and_widen_the_bound():
    """With the ground station's calibration errors (winch offset 0.1 m and scale 1 %, angle
    zero errors 0.4 and 1.5 degrees) the bound is the augmented Kalman covariance at the truth
    (the winch at its reports only); it is wider than without them, and equal as their priors
    go to zero."""
    track, constants = _track(0.0)
    track = dataclasses.replace(track, winch_seen=np.arange(len(track.time_s)) % 20 == 3)
    prior = np.array([5.0, 5, 5, 0.5, 0.5, 0.5, 3.0, 0.1, 0.2, 0.2, 0.2, 2.0, 2.0])
    density = np.array(
        [1e-6, 1e-6, 1e-6, 1e-4, 1e-4, 1e-4, 2.0, 1e-5, 1e-4, 1e-4, 1e-4, 0.04, 0.04]
    )
    gating = Gating(ticks_per_fusion=1, min_distance_m=0.3, min_thrust_n=5.0)

    def noise(calibration):
        return BoundNoise(
            density,
            prior,
            ACCEL_VAR,
            0.05**2,
            winch_var_m2=0.003**2,
            cable_angle_var_rad2=0.01**2,
            calibration=calibration,
        )

    calibrated = noise(CalibrationPrior(0.1, 0.01, 0.007, 0.026))
    bound = posterior_bound(track, constants, calibrated, gating)
    np.testing.assert_allclose(bound, _reference(track, constants, calibrated), rtol=1e-4)
    exact = posterior_bound(track, constants, noise(None), gating)
    np.testing.assert_allclose(exact, _reference(track, constants, noise(None)), rtol=1e-4)
    horizontal = slice(0, 2)
    assert np.all(bound[-1, horizontal] > 1.5 * exact[-1, horizontal])
    tiny = posterior_bound(
        track, constants, noise(CalibrationPrior(1e-9, 1e-9, 1e-9, 1e-9)), gating
    )
    np.testing.assert_allclose(tiny, exact, rtol=1e-5)


def test_residual_density_is_two_sigma_squared_tau():
    """A first-order Gauss-Markov residual (std 0.1 m/s^2, tau 1 s) sampled at 50 Hz for
    2000 s: ``2 sigma^2 tau`` = 0.02 m^2/s^3 within 20 %; a constant residual (a bias the state
    has) carries no loss: 0; too few samples: the fallback."""
    rng = np.random.default_rng(5)
    dt, tau, sigma, n = 0.02, 1.0, 0.1, 100_000
    a = math.exp(-dt / tau)
    x = np.zeros((n, 3))
    drive = sigma * math.sqrt(1 - a * a) * rng.standard_normal((n, 3))
    for k in range(1, n):
        x[k] = a * x[k - 1] + drive[k]
    x[:, 2] = 0.3
    density = residual_density_m2ps3(x, dt, 0.5)
    assert density[0] == pytest.approx(0.02, rel=0.2)
    assert density[1] == pytest.approx(0.02, rel=0.2)
    assert density[2] < 1e-20
    assert residual_density_m2ps3(x[:10], dt, 0.5) == (0.5, 0.5, 0.5)
