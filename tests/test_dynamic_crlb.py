"""The dynamic filter's posterior CRLB (estimation/dynamic/crlb.py, crlb_nuisance.py).

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
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.crlb import (
    BoundNoise,
    Gating,
    TrueTrack,
    consider_step,
    information_step,
    posterior_bound,
)
from tether_companion.estimation.dynamic.crlb_noise import bound_noise, residual_density_m2ps3
from tether_companion.estimation.dynamic.crlb_nuisance import (
    AZIMUTH_BIAS,
    CalibrationPrior,
    HeadingError,
    TerrainNoise,
    yaw_column_of_model,
    yaw_column_of_specific_force,
)
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.frames import rotation_ned_to_body_rows
from tether_companion.sim.scenario import load_scenario

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


SPECIFIC_FORCE = (0.8, -0.5, -9.6)
"""The track's specific force, FRD [m/s^2] (what the heading error's prediction column turns)."""


def _track(weight: float) -> tuple[TrueTrack, ModelConstants]:
    """1 s of a 1 m/s circle at 200 Hz, 2.5 m out and 2 m up, a 4 N pull toward the anchor
    (the chord tension the straight or catenary model reads from it), a 1 m/s wind,
    rangefinder every 10th tick, cable angle every 20th, a constant specific force."""
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
        np.tile(SPECIFIC_FORCE, (len(t), 1)),
        np.arange(len(t)) % 20 == 5,
    )
    return track, constants


def _rotation(euler: np.ndarray, yaw_step: float = 0.0) -> tuple[float, ...]:
    rows = rotation_ned_to_body_rows(euler[0], euler[1], euler[2] + yaw_step)
    return (*rows[0], *rows[1], *rows[2])


def _yaw_fd(value, euler: np.ndarray, step: float = 1e-6) -> np.ndarray:
    """Central difference of ``value(rotation inputs)`` in the yaw."""
    up = np.array(value(_rotation(euler, step)), dtype=float)
    down = np.array(value(_rotation(euler, -step)), dtype=float)
    return (up - down) / (2 * step)


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


def _reference(track, constants, noise, *, repeat_range: int = 1) -> np.ndarray:  # noqa: C901
    """An EKF covariance along the truth, samples fused one at a time (Joseph form), the
    Jacobians by differences; the rangefinder fused ``repeat_range`` times per sample. With
    ``noise.calibration`` the state has the four calibration errors after the 13 (winch offset
    and scale, elevation and azimuth zero errors), written here from the readings' own
    equations: ``offset + (1 + scale) L`` and ``angle + bias``. With ``noise.heading`` a
    heading-error state follows (its columns the differences of the prediction's and the force
    balance's values in the yaw input), then with ``noise.terrain`` the ground's elevation
    (the height reading's column 1); both first-order Gauss-Markov."""
    models = constants.models
    c = constants.values()
    calibration = noise.calibration
    extra = 0 if calibration is None else 4
    prior = noise.prior_std if calibration is None else np.r_[noise.prior_std, calibration.std()]
    heading, terrain = noise.heading, noise.terrain
    yaw_at = terrain_at = None
    if heading is not None:
        yaw_at = N + extra
        extra += 1
        prior = np.r_[prior, heading.std_rad]
    if terrain is not None:
        terrain_at = N + extra
        extra += 1
        prior = np.r_[prior, terrain.std_m]
    n = N + extra
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
        q = np.r_[noise.process_density, np.zeros(extra)] * dt
        euler = track.euler_rad[k]
        if yaw_at is not None:
            specific_force = track.specific_force_body_mps2[k]
            f[3:6, yaw_at] = dt * _yaw_fd(
                lambda r, sf=specific_force: np.reshape(r, (3, 3)).T @ sf, euler
            )
            decay = math.exp(-dt / heading.time_constant_s)
            f[yaw_at, yaw_at] = decay
            q[yaw_at] = heading.std_rad**2 * (1 - decay**2)
        if terrain_at is not None:
            decay = math.exp(-dt * np.hypot(*track.velocity_ned_mps[k][:2]) / terrain.correlation_m)
            f[terrain_at, terrain_at] = decay
            q[terrain_at] = terrain.std_m**2 * (1 - decay**2)
        p = f @ p @ f.T + np.diag(q)
        accel = wide(_fd(models.accel, x, (*rotation, 16.0), c, 3))
        if yaw_at is not None:
            accel[:, yaw_at] = _yaw_fd(lambda r, xs=x: models.accel(xs, (*r, 16.0), c)[0], euler)
        samples = [(accel, np.diag(noise.force_balance_var_mps2))]
        if track.range_seen[k]:
            height = wide(_fd(generated.height_above_ground, x, (0.0,), (0.0, 0.0, 0.0), 1))
            if terrain_at is not None:
                height[0, terrain_at] = 1.0
            samples += [(height, np.array([[noise.range_var_m2]]))] * repeat_range
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


PRIOR_STD = np.array([5.0, 5, 5, 0.5, 0.5, 0.5, 3.0, 0.1, 0.2, 0.2, 0.2, 2.0, 2.0])
"""The state's prior standard deviations in the bound's tests (its units per state)."""
DENSITY = np.array([1e-6, 1e-6, 1e-6, 1e-4, 1e-4, 1e-4, 2.0, 1e-5, 1e-4, 1e-4, 1e-4, 0.04, 0.04])
"""The state's process-noise densities in the bound's tests (its units per state per s)."""


def _ground_station_noise(**nuisance) -> BoundNoise:
    """The bound's noise with the winch (3 mm) and the cable angle (0.01 rad) and the given
    nuisance (``calibration``, ``heading``, ``terrain``)."""
    return BoundNoise(
        DENSITY,
        PRIOR_STD,
        ACCEL_VAR,
        0.05**2,
        winch_var_m2=0.003**2,
        cable_angle_var_rad2=0.01**2,
        **nuisance,
    )


@pytest.mark.parametrize("weight", [0.0, 0.164])
def test_the_bound_is_the_kalman_covariance_at_the_truth(weight):
    track, constants = _track(weight)
    noise = BoundNoise(
        DENSITY, PRIOR_STD, ACCEL_VAR, 0.05**2, winch_var_m2=0.05**2, cable_angle_var_rad2=0.01**2
    )
    gating = Gating(ticks_per_fusion=1, min_distance_m=0.3, min_thrust_n=5.0)
    bound = posterior_bound(track, constants, noise, gating)
    reference = _reference(track, constants, noise)
    np.testing.assert_allclose(bound, reference, rtol=1e-4)
    doubled = _reference(track, constants, noise, repeat_range=2)
    assert np.max(np.abs(doubled[:, 2] / reference[:, 2] - 1.0)) > 0.05
    only_sensors = posterior_bound(
        track, constants, BoundNoise(DENSITY, PRIOR_STD, ACCEL_VAR, 0.05**2), gating
    )
    assert np.max(np.abs(only_sensors[:, 0] / bound[:, 0] - 1.0)) > 0.05


def test_calibration_errors_are_estimated_beside_the_state_and_widen_the_bound():
    """With the ground station's calibration errors (winch offset 0.1 m and scale 1 %, angle
    zero errors 0.4 and 1.5 degrees) the bound is the augmented Kalman covariance at the truth
    (the winch at its reports only); it is wider than without them, and equal as their priors
    go to zero."""
    track, constants = _track(0.0)
    track = dataclasses.replace(track, winch_seen=np.arange(len(track.time_s)) % 20 == 3)
    gating = Gating(ticks_per_fusion=1, min_distance_m=0.3, min_thrust_n=5.0)

    def noise(calibration):
        return _ground_station_noise(calibration=calibration)

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


@pytest.mark.parametrize("weight", [0.0, 0.164])
def test_yaw_columns_are_the_derivatives_in_the_yaw_input(weight):
    """The heading error's columns: the prediction's NED acceleration ``R^T f`` and the
    generated force balance (straight and catenary cable, rotor drag in a wind) differenced in
    their yaw input equal the chain rule through the state's NED vectors."""
    track, constants = _track(weight)
    c = constants.values()
    for k in (0, 77, 199):
        euler = track.euler_rad[k]
        x = track.state_at(k)
        f = track.specific_force_body_mps2[k]
        np.testing.assert_allclose(
            yaw_column_of_specific_force(euler, f),
            _yaw_fd(lambda r, sf=f: np.reshape(r, (3, 3)).T @ sf, euler),
            atol=1e-7,
        )
        _, jac = constants.models.accel(x, (*_rotation(euler), 16.0), c)
        jacobian = np.reshape(np.array(jac), (3, state.N_STATES))
        expected = _yaw_fd(lambda r, xs=x: constants.models.accel(xs, (*r, 16.0), c)[0], euler)
        assert np.max(np.abs(expected)) > 0.1
        np.testing.assert_allclose(yaw_column_of_model(jacobian, x), expected, atol=1e-6)


def test_heading_error_and_terrain_are_gauss_markov_states_of_the_bound():
    """With the flight controller's heading error (0.02 rad over 20 s) and the ground's
    undulation (0.05 m over 0.6 m) as states, the bound is the augmented Kalman covariance at
    the truth (their columns by differences in the yaw input, the height's 1); both widen it,
    and it equals the bound without them as their standard deviations go to zero."""
    track, constants = _track(0.0)
    gating = Gating(ticks_per_fusion=1, min_distance_m=0.3, min_thrust_n=5.0)

    def noise(heading, terrain):
        return _ground_station_noise(
            calibration=CalibrationPrior(0.1, 0.01, 0.007, 0.026), heading=heading, terrain=terrain
        )

    full = noise(HeadingError(0.02, 20.0), TerrainNoise(0.05, 0.6))
    bound = posterior_bound(track, constants, full, gating)
    np.testing.assert_allclose(bound, _reference(track, constants, full), rtol=1e-4)
    without = posterior_bound(track, constants, noise(None, None), gating)
    assert np.all(bound[-1, :3] > without[-1, :3])
    tiny = noise(HeadingError(1e-9, 20.0), TerrainNoise(1e-9, 0.6))
    np.testing.assert_allclose(posterior_bound(track, constants, tiny, gating), without, rtol=1e-5)


def test_terrain_under_a_hover_is_not_averaged_away():
    """A drone hovering 10 s over one spot, its velocity and accelerometer bias known,
    rangefinder at 20 Hz (0.3 m) over ground undulating by 0.05 m: the height's bound stays
    above the ground's 0.05 m (the same ground every reading), where white it would average
    down to about 0.3 / sqrt(200) = 0.021 m; the same readings flown across the undulations at
    2 m/s (0.6 m correlation) average it below."""
    n = 2000
    t = np.arange(n) * 0.005
    constants = ModelConstants(1.5, 0.2, 0.0)

    def bound(speed_mps, terrain):
        position = np.stack([3.0 + 0 * t, speed_mps * t, np.full_like(t, -2.0)], 1)
        velocity = np.tile([0.0, speed_mps, 0.0], (n, 1))
        track = TrueTrack(
            t,
            position,
            velocity,
            np.zeros((n, 3)),
            np.full(n, 16.0),
            np.tile([-4.0, 0.0, 0.0], (n, 1)),
            np.zeros((n, 3)),
            np.arange(n) % 10 == 0,
            np.tile(SPECIFIC_FORCE, (n, 1)),
        )
        noise = BoundNoise(
            np.array(
                [1e-9, 1e-9, 1e-9, 1e-9, 1e-9, 1e-9, 2.0, 1e-5, 1e-12, 1e-12, 1e-12, 0.04, 0.04]
            ),
            np.array([5.0, 5, 5, 1e-3, 1e-3, 1e-3, 3.0, 0.1, 1e-4, 1e-4, 1e-4, 2.0, 2.0]),
            (10.0, 10.0, 10.0),
            0.3**2 if terrain else 0.3**2 + 0.05**2,
            terrain=TerrainNoise(0.05, 0.6) if terrain else None,
        )
        gating = Gating(ticks_per_fusion=4, min_distance_m=0.3, min_thrust_n=5.0)
        return math.sqrt(posterior_bound(track, constants, noise, gating)[-1, 2])

    assert bound(0.0, terrain=False) < 0.025
    assert bound(0.0, terrain=True) > 0.05
    assert bound(2.0, terrain=True) < 0.035


def test_a_consider_step_holding_nothing_is_the_bound_and_holding_widens_it():
    """A Schmidt step with no state held is the bound's step; holding one leaves that state's
    variance as predicted and every other at least as wide."""
    rng = np.random.default_rng(8)
    n = 6
    f = np.eye(n) + 0.05 * rng.standard_normal((n, n))
    q, p = _spd(rng, n, 0.01), _spd(rng, n, 0.3)
    samples = [
        (rng.standard_normal((2, n)), np.array([4.0, 9.0])),
        (rng.standard_normal((1, n)), np.array([2.0])),
    ]
    information = sum(h.T @ (w[:, None] * h) for h, w in samples)
    optimal = information_step(p, f, q, information)
    np.testing.assert_allclose(consider_step(p, f, q, samples, []), optimal, rtol=1e-9, atol=1e-12)
    held = consider_step(p, f, q, samples, [4])
    predicted = f @ p @ f.T + q
    assert held[4, 4] == pytest.approx(predicted[4, 4], rel=1e-12)
    assert np.all(np.diag(held) >= np.diag(optimal) - 1e-12)


def test_the_azimuth_zero_held_widens_the_bound_across_the_cable_until_released():
    """On the 1 s circle with winch and angle: holding the angle sensor's azimuth zero (1.5
    degrees) as a consider state widens the horizontal bound (by 19 % at 1 s: what the
    circle's first second tells of it), released at the first tick it is
    the bound; started at a later tick the bound is that of the flight cut there."""
    track, constants = _track(0.0)
    noise = _ground_station_noise(calibration=CalibrationPrior(0.1, 0.01, 0.007, 0.026))
    gating = Gating(ticks_per_fusion=4, min_distance_m=0.3, min_thrust_n=5.0)
    learnt = posterior_bound(track, constants, noise, gating)
    held = posterior_bound(track, constants, noise, gating, held={AZIMUTH_BIAS: None})
    horizontal = slice(0, 2)
    assert np.all(held[:, horizontal] >= learnt[:, horizontal] * (1 - 1e-9))
    assert np.sum(held[-1, horizontal]) > 1.1 * np.sum(learnt[-1, horizontal])
    released = posterior_bound(track, constants, noise, gating, held={AZIMUTH_BIAS: 0})
    np.testing.assert_allclose(released, learnt, rtol=1e-6)
    later = posterior_bound(track, constants, noise, gating, start_tick=100)
    assert np.isnan(later[:100]).all()
    cut = dataclasses.replace(
        track,
        **{
            name: getattr(track, name)[100:]
            for name in (
                "time_s",
                "position_ned_m",
                "velocity_ned_mps",
                "euler_rad",
                "thrust_n",
                "cable_force_ned_n",
                "wind_ned_mps",
                "range_seen",
                "specific_force_body_mps2",
                "angle_seen",
            )
        },
    )
    np.testing.assert_allclose(
        later[100:], posterior_bound(cut, constants, noise, gating), rtol=1e-9
    )


def test_the_bound_takes_the_scenarios_heading_error_not_its_tilt_error():
    """A scenario whose heading error has its own sigma and time constant (a compass-aided
    yaw) gives the bound's heading state those, not the roll and pitch error's; unset, the
    attitude error's."""
    base = load_scenario("realistic-circle")

    def heading_of(std_rad, time_constant_s):
        sensors = dataclasses.replace(
            base.sensors,
            heading_error_std_rad=std_rad,
            heading_error_time_constant_s=time_constant_s,
        )
        scenario = dataclasses.replace(base, sensors=sensors)
        config = DynamicFilterConfig()
        return bound_noise(scenario, config, (0.0, 0.0, 0.0), winch=True, angle=True).heading

    own = heading_of(0.03, 90.0)
    assert (own.std_rad, own.time_constant_s) == (0.03, 90.0)
    unset = heading_of(None, None)
    assert unset.std_rad == base.sensors.attitude_error_std_rad
    assert unset.time_constant_s == base.sensors.attitude_error_time_constant_s
