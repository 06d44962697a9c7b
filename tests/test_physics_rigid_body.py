"""Rigid-body quadcopter (paper eqs. 3-6) against closed forms, RK4 order, ground contact."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.frames import rotation_ned_to_body
from tether_companion.physics.cable import ConstantTensionCable
from tether_companion.physics.motors import MotorLag
from tether_companion.physics.rigid_body import (
    BODY_RATES,
    EULER,
    N_RIGID_STATES,
    POS_D,
    POSITION,
    VELOCITY_BODY,
    RigidBody,
    motor_thrusts_slice,
)
from tether_companion.physics.thrust import hover_pwm_us
from tether_companion.physics.vehicle import VehicleProfile, load_vehicle

G = GRAVITY_MPS2


@pytest.fixture
def vehicle() -> VehicleProfile:
    return load_vehicle("default-quad")


def _state(vehicle: VehicleProfile, **values: float) -> list[float]:
    """A full state with named rigid-body entries and motor thrusts ``motor`` each."""
    names = ("pn", "pe", "pd", "u", "v", "w", "phi", "theta", "psi", "p", "q", "r")
    rigid = [float(values.get(n, 0.0)) for n in names]
    return rigid + [float(values.get("motor", 0.0))] * vehicle.n_motors


def _run(body: RigidBody, thrusts: list[float], dt_s: float, duration_s: float) -> None:
    for _ in range(round(duration_s / dt_s)):
        body.step(dt_s, thrusts)


def test_free_fall_matches_closed_form(vehicle: VehicleProfile) -> None:
    body = RigidBody(vehicle)
    body.set_state(_state(vehicle, pd=-100.0, u=1.0))
    _run(body, [0.0] * 4, 0.002, 2.0)
    x = body.state
    # p_d(t) = p0 + g t^2 / 2, north drifts at 1 m/s; body w grows as g t (level body)
    assert x[POS_D] == pytest.approx(-100.0 + 0.5 * G * 4.0, abs=1e-9)
    assert x[0] == pytest.approx(2.0, abs=1e-9)
    assert x[VELOCITY_BODY][2] == pytest.approx(2.0 * G, abs=1e-9)
    assert body.specific_force_body_mps2() == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)


def test_hover_at_hover_pwm_is_an_equilibrium(vehicle: VehicleProfile) -> None:
    pwm = hover_pwm_us(vehicle.thrust_curve, vehicle.mass_kg, vehicle.n_motors, G)
    thrust = float(vehicle.thrust_curve.thrust_n(pwm))
    assert thrust * vehicle.n_motors == pytest.approx(vehicle.mass_kg * G, rel=1e-12)
    body = RigidBody(vehicle)
    body.set_state(_state(vehicle, pd=-3.0, psi=0.7, motor=thrust))
    _run(body, [thrust] * 4, 0.001, 5.0)
    x = body.state
    assert x[POSITION] == pytest.approx([0.0, 0.0, -3.0], abs=1e-9)
    assert x[EULER] == pytest.approx([0.0, 0.0, 0.7], abs=1e-12)
    assert body.specific_force_body_mps2() == pytest.approx((0.0, 0.0, -G), abs=1e-9)


def test_torque_gives_angular_acceleration_tau_over_j(vehicle: VehicleProfile) -> None:
    body = RigidBody(vehicle)
    jx, jy, jz = vehicle.inertia_kg_m2
    x = _state(vehicle, pd=-5.0)[:N_RIGID_STATES]
    d = body.derivative(x, 10.0, 0.3, -0.2, 0.05)
    assert d[9:12] == pytest.approx((0.3 / jx, -0.2 / jy, 0.05 / jz), rel=1e-12)
    # thrust along body -z: level body accelerates up at T/m - g
    assert d[5] == pytest.approx(-10.0 / vehicle.mass_kg + G, rel=1e-12)


def test_gyroscopic_coupling_matches_eq6(vehicle: VehicleProfile) -> None:
    body = RigidBody(vehicle)
    jx, jy, jz = vehicle.inertia_kg_m2
    x = _state(vehicle, pd=-5.0, p=1.0, q=2.0, r=3.0)[:N_RIGID_STATES]
    d = body.derivative(x, 0.0, 0.0, 0.0, 0.0)
    assert d[9:12] == pytest.approx(
        ((jy - jz) / jx * 6.0, (jz - jx) / jy * 3.0, (jx - jy) / jz * 2.0), abs=1e-12
    )


def test_torque_free_rotation_conserves_energy_and_angular_momentum() -> None:
    asym = VehicleProfile(inertia_kg_m2=(0.01, 0.02, 0.03))
    body = RigidBody(asym)
    body.set_state(_state(asym, pd=-1000.0, phi=0.1, theta=0.2, psi=0.3, p=0.5, q=0.3, r=-0.4))
    inertia = np.array(asym.inertia_kg_m2)

    def invariants() -> tuple[float, np.ndarray]:
        x = body.state
        omega = x[BODY_RATES]
        energy = 0.5 * float(omega @ (inertia * omega))
        r_ned_to_body = rotation_ned_to_body(*x[EULER])
        momentum_ned = r_ned_to_body.T @ (inertia * omega)
        return energy, momentum_ned

    e0, h0 = invariants()
    _run(body, [0.0] * 4, 0.001, 3.0)
    e1, h1 = invariants()
    assert e1 == pytest.approx(e0, rel=1e-9)
    assert h1 == pytest.approx(h0, abs=1e-10)


def test_rk4_converges_with_fourth_order(vehicle: VehicleProfile) -> None:
    """Error at h and h/2 against a fine reference: the ratio is about 2^4 = 16."""
    cable = ConstantTensionCable(6.0)

    def final_state(dt_s: float) -> np.ndarray:
        body = RigidBody(vehicle, cable.force_components)
        body.set_state(_state(vehicle, pn=2.0, pd=-3.0, u=1.0, phi=0.2, q=0.5, r=0.3, motor=2.0))
        thrusts = [4.5, 3.5, 4.0, 4.2]  # torques and a lag transient from motor=2.0
        _run(body, thrusts, dt_s, 0.8)
        return body.state

    reference = final_state(0.0005)
    errors = [np.max(np.abs(final_state(h) - reference)) for h in (0.016, 0.008)]
    ratio = errors[0] / errors[1]
    assert 12.0 < ratio < 20.0, (errors, ratio)


def test_motor_lag_is_exact_first_order(vehicle: VehicleProfile) -> None:
    body = RigidBody(vehicle)
    body.set_state(_state(vehicle, pd=-100.0, motor=1.0))
    _run(body, [3.0] * 4, 0.001, 0.1)
    tau = vehicle.motor_time_constant_s
    expected = 3.0 + (1.0 - 3.0) * math.exp(-0.1 / tau)
    assert body.state[motor_thrusts_slice(4)] == pytest.approx([expected] * 4, rel=1e-12)


def test_specific_force_in_tethered_hover_is_thrust_plus_cable_over_mass(
    vehicle: VehicleProfile,
) -> None:
    """Paper eq. 20: a_SF = (f_thrust + f_cable)/m; in equilibrium that equals -g (body)."""
    cable = ConstantTensionCable(4.0)
    body = RigidBody(vehicle, cable.force_components)
    position = np.array([2.0, 1.0, -3.0])
    f_cable = np.array(cable.force_components(*position, 0.0, 0.0, 0.0))
    thrust_ned = -f_cable - np.array([0.0, 0.0, vehicle.mass_kg * G])
    collective = float(np.linalg.norm(thrust_ned))
    roll = math.asin(thrust_ned[1] / collective)
    pitch = math.atan2(-thrust_ned[0], -thrust_ned[2])
    per_motor = collective / 4
    body.set_state(_state(vehicle, pn=2.0, pe=1.0, pd=-3.0, phi=roll, theta=pitch, motor=per_motor))
    d = body.derivative(body.state[:N_RIGID_STATES].tolist(), collective, 0.0, 0.0, 0.0)
    assert d[:6] == pytest.approx([0.0] * 6, abs=1e-12)  # at rest: an equilibrium
    specific = np.array(body.specific_force_body_mps2())
    r = rotation_ned_to_body(roll, pitch, 0.0)
    eq20 = (np.array([0.0, 0.0, -collective]) + r @ f_cable) / vehicle.mass_kg
    assert specific == pytest.approx(eq20, abs=1e-12)
    assert specific == pytest.approx(r @ np.array([0.0, 0.0, -G]), abs=1e-12)
    # the cable is felt: the body z reading is not -g, the thrust is larger than the weight
    assert collective > vehicle.mass_kg * G


def test_landed_drone_rests_then_lifts_off_when_thrust_beats_weight_and_cable(
    vehicle: VehicleProfile,
) -> None:
    cable = ConstantTensionCable(4.0)
    body = RigidBody(vehicle, cable.force_components)
    body.set_state(_state(vehicle, pn=1.0, psi=0.5), landed=True)
    weight_per_motor = vehicle.mass_kg * G / 4
    _run(body, [weight_per_motor * 0.99] * 4, 0.001, 0.5)
    assert body.landed
    assert body.state[POSITION] == pytest.approx([1.0, 0.0, 0.0])
    assert body.specific_force_body_mps2() == pytest.approx((0.0, 0.0, -G), abs=1e-12)
    # the cable lies along the ground (no downward pull): thrust above weight lifts off
    _run(body, [weight_per_motor * 1.2] * 4, 0.001, 0.5)
    assert not body.landed
    assert body.state[POS_D] < -0.05


def test_descending_drone_lands_and_stays_level(vehicle: VehicleProfile) -> None:
    body = RigidBody(vehicle)
    body.set_state(_state(vehicle, pd=-0.5, w=1.0, phi=0.05, psi=1.0))
    _run(body, [0.0] * 4, 0.001, 1.0)
    x = body.state
    assert body.landed
    assert x[POS_D] == 0.0
    assert x[EULER] == pytest.approx([0.0, 0.0, 1.0])
    assert np.all(x[VELOCITY_BODY] == 0.0) and np.all(x[BODY_RATES] == 0.0)


def test_set_state_refuses_wrong_size_and_non_finite(vehicle: VehicleProfile) -> None:
    body = RigidBody(vehicle)
    with pytest.raises(ValueError, match="16 values"):
        body.set_state([0.0] * 12)
    with pytest.raises(ValueError, match="finite"):
        body.set_state([math.nan] + [0.0] * 15)


def test_linear_drag_pulls_toward_the_wind_velocity() -> None:
    draggy = VehicleProfile(drag_coefficient_n_s_per_m=0.3)
    body = RigidBody(draggy)
    body.wind_ned_m_s = (2.0, -1.0, 0.0)
    x = _state(draggy, pd=-5.0, u=0.5, psi=math.pi / 2)[:N_RIGID_STATES]  # flying east
    d = body.derivative(x, draggy.mass_kg * G, 0.0, 0.0, 0.0)
    air_ned = np.array([0.0, 0.5, 0.0]) - [2.0, -1.0, 0.0]
    accel_ned = -0.3 * air_ned / draggy.mass_kg
    r = rotation_ned_to_body(0.0, 0.0, math.pi / 2)
    # body frame: du/dt = (r v - q w) + f/m with zero rates
    assert d[3:6] == pytest.approx(r @ accel_ned, abs=1e-12)
    body.tug_force_ned_n = (0.0, 0.0, -3.0)
    d = body.derivative(x, draggy.mass_kg * G, 0.0, 0.0, 0.0)
    assert d[5] == pytest.approx((r @ accel_ned)[2] - 3.0 / draggy.mass_kg, abs=1e-12)


@pytest.mark.parametrize("profile", ["default-quad", "realistic-quad"])
def test_generated_step_is_rk4_of_the_derivative_bit_for_bit(profile: str) -> None:
    """The generated step (stages inlined) gives the same floats as RK4 built from
    ``derivative`` stage by stage, with the wrench lagging toward the targets' at the stage
    times; with and without the body drag, under a cable, a tug and a wind."""
    vehicle = load_vehicle(profile)
    cable = ConstantTensionCable(3.0)
    body = RigidBody(vehicle, cable.force_components)
    body.wind_ned_m_s = (1.5, -0.7, 0.2)
    body.tug_force_ned_n = (0.3, 0.1, -0.2)
    rng = np.random.default_rng(3)
    for _ in range(20):
        rigid = (rng.normal(0.0, 1.0, N_RIGID_STATES) * 0.5).tolist()
        rigid[POS_D] = -abs(rigid[POS_D]) - 2.0
        motors = rng.uniform(1.0, 4.0, vehicle.n_motors).tolist()
        targets = rng.uniform(1.0, 4.0, vehicle.n_motors).tolist()
        body.set_state(rigid + motors)
        dt = 1.0 / 600.0
        w0, goal = body.wrench(motors), body.wrench(targets)
        half = MotorLag(vehicle.motor_time_constant_s).decay(0.5 * dt)
        full = MotorLag(vehicle.motor_time_constant_s).decay(dt)
        mid = [s + (w - s) * half for s, w in zip(goal, w0, strict=True)]
        end = [s + (w - s) * full for s, w in zip(goal, w0, strict=True)]
        k1 = body.derivative(rigid, *w0)
        k2 = body.derivative(rigid, *mid, k1, 0.5 * dt)
        k3 = body.derivative(rigid, *mid, k2, 0.5 * dt)
        k4 = body.derivative(rigid, *end, k3, dt)
        want = [
            a + dt / 6.0 * (b1 + b4 + 2.0 * (b2 + b3))
            for a, b1, b2, b3, b4 in zip(rigid, k1, k2, k3, k4, strict=True)
        ]
        body.step(dt, targets)
        assert body.x == want


@pytest.mark.parametrize("profile", ["default-quad", "realistic-quad"])
def test_step_after_the_accelerometer_reuses_its_derivative_bit_for_bit(profile: str) -> None:
    """A step right after ``specific_force_body_mps2`` takes that derivative as its first RK4
    stage: the same state as a body that did not read it; a cable changed in place in between
    (``forget_forces``) is evaluated afresh."""
    vehicle = load_vehicle(profile)
    cables = [ConstantTensionCable(3.0), ConstantTensionCable(3.0)]
    reading, plain = (RigidBody(vehicle, cable.force_components) for cable in cables)
    rng = np.random.default_rng(4)
    rigid = (rng.normal(0.0, 1.0, N_RIGID_STATES) * 0.5).tolist()
    rigid[POS_D] = -abs(rigid[POS_D]) - 2.0
    motors = rng.uniform(1.0, 4.0, vehicle.n_motors).tolist()
    for body in (reading, plain):
        body.set_state(rigid + motors)
        body.wind_ned_m_s = (1.5, -0.7, 0.2)
    for k in range(30):
        targets = rng.uniform(1.0, 4.0, vehicle.n_motors).tolist()
        reading.specific_force_body_mps2()
        if k == 10:  # a new set-point between the read and the step
            for body, cable in zip((reading, plain), cables, strict=True):
                cable.set_tension_n(5.0)
                body.forget_forces()
        reading.step(1.0 / 600.0, targets)
        plain.step(1.0 / 600.0, targets)
        assert reading.x == plain.x
    body = plain  # the generated step given its first stage, against all four stages
    k1 = body.derivative(body.x, *body.wrench(motors))
    args = (
        body.wrench(targets),
        body.wrench(motors),
        1e-3,
        body._coefficients,
        cables[1].force_components,
    )
    assert body._rk4_after(body.x, k1, *args) == body._rk4(body.x, body.wrench(motors), *args)
