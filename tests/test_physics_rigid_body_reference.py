"""The rigid body's scalar derivative and RK4 step against a plain numpy statement of eqs. 3-6.

The simulator's :meth:`RigidBody.derivative` is hand-flattened scalar code (for speed); these
tests pin it, and a whole trajectory, to the matrix form of the equations to 1e-9, with every
force term on: an elastic damped cable, tug, wind, linear, rotor and quadratic body drag.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.frames import rotation_ned_to_body
from tether_companion.physics.aerodynamics import drag_accel_body_mps2
from tether_companion.physics.cable import ElasticCable
from tether_companion.physics.motors import MotorLag
from tether_companion.physics.rigid_body import N_RIGID_STATES, RigidBody
from tether_companion.physics.vehicle import VehicleProfile

WIND = (2.0, -1.5, 0.3)
TUG = (0.5, -0.2, 1.0)


def _vehicle() -> VehicleProfile:
    return VehicleProfile(
        drag_coefficient_n_s_per_m=0.3, rotor_drag_per_s=0.4, ballistic_coefficient_kg_per_m2=3.0
    )


def _body(vehicle: VehicleProfile) -> tuple[RigidBody, ElasticCable]:
    cable = ElasticCable(20.0, 300.0, 4.0, 0.02)
    body = RigidBody(vehicle, cable.force_components)
    body.wind_ned_m_s = WIND
    body.tug_force_ned_n = TUG
    return body, cable


def _reference_derivative(
    vehicle: VehicleProfile, cable: ElasticCable, x: np.ndarray, wrench: np.ndarray
) -> np.ndarray:
    """Eqs. 3-6 in matrix form (the module docstring of rigid_body, term by term)."""
    position, velocity_body = x[0:3], x[3:6]
    phi, theta, psi = x[6:9]
    rates = x[9:12]
    rotation = rotation_ned_to_body(phi, theta, psi)
    velocity_ned = rotation.T @ velocity_body
    mass = vehicle.mass_kg
    force_ned = (
        np.array(cable.force_components(*position, *velocity_ned))
        + np.array(TUG)
        + np.array([0.0, 0.0, mass * GRAVITY_MPS2])
        - vehicle.drag_coefficient_n_s_per_m * (velocity_ned - np.array(WIND))
    )
    air_body = rotation @ (velocity_ned - np.array(WIND))
    drag_x, drag_y = drag_accel_body_mps2(
        air_body[0],
        air_body[1],
        vehicle.rotor_drag_per_s,
        vehicle.ballistic_coefficient_kg_per_m2,
    )
    force_body = np.array([0.0, 0.0, -wrench[0]]) + rotation @ force_ned
    force_body += mass * np.array([drag_x, drag_y, 0.0])
    d_velocity = np.cross(velocity_body, rates) + force_body / mass
    euler_rates = np.array(
        [
            [1.0, math.sin(phi) * math.tan(theta), math.cos(phi) * math.tan(theta)],
            [0.0, math.cos(phi), -math.sin(phi)],
            [0.0, math.sin(phi) / math.cos(theta), math.cos(phi) / math.cos(theta)],
        ]
    )
    inertia = np.diag(vehicle.inertia_kg_m2)
    d_rates = np.linalg.solve(inertia, wrench[1:4] - np.cross(rates, inertia @ rates))
    return np.concatenate([velocity_ned, d_velocity, euler_rates @ rates, d_rates])


def _random_state(rng: np.random.Generator) -> np.ndarray:
    return np.concatenate(
        [
            rng.uniform(-6.0, 6.0, 2).tolist() + [rng.uniform(-24.0, -16.0)],
            rng.uniform(-3.0, 3.0, 3),
            rng.uniform(-0.6, 0.6, 2).tolist() + [rng.uniform(-math.pi, math.pi)],
            rng.uniform(-1.0, 1.0, 3),
        ]
    )


def test_derivative_equals_the_matrix_form_of_eqs_3_to_6() -> None:
    vehicle = _vehicle()
    body, cable = _body(vehicle)
    rng = np.random.default_rng(7)
    for _ in range(200):
        x = _random_state(rng)
        wrench = np.array([rng.uniform(5.0, 30.0), *rng.uniform(-0.5, 0.5, 3)])
        expected = _reference_derivative(vehicle, cable, x, wrench)
        got = body.derivative(x.tolist(), *wrench.tolist())
        assert np.array(got) == pytest.approx(expected, rel=1e-9, abs=1e-9)
        # an RK4 stage: the derivative at x + h k
        slope = rng.uniform(-1.0, 1.0, N_RIGID_STATES)
        staged = body.derivative(x.tolist(), *wrench.tolist(), slope.tolist(), 0.01)
        expected = _reference_derivative(vehicle, cable, x + 0.01 * slope, wrench)
        assert np.array(staged) == pytest.approx(expected, rel=1e-9, abs=1e-9)


def test_rk4_trajectory_with_motor_lag_equals_the_reference_integration() -> None:
    """2 s at 600 Hz from a tilted, moving state, motors spinning up toward new targets
    (the wrench follows the exact first-order lag, evaluated at each RK4 stage time)."""
    vehicle = _vehicle()
    body, cable = _body(vehicle)
    n = vehicle.n_motors
    hover = vehicle.mass_kg * GRAVITY_MPS2 / n
    start = _random_state(np.random.default_rng(3))
    body.set_state(start.tolist() + [0.8 * hover] * n)
    targets = [1.3 * hover, 1.1 * hover, 1.25 * hover, 1.05 * hover]
    allocation = vehicle.allocation_matrix()
    lag = MotorLag(vehicle.motor_time_constant_s)
    dt = 1.0 / 600.0
    x = start.copy()
    motors = np.array([0.8 * hover] * n)
    for _ in range(1200):
        body.step(dt, targets)
        w_ss = allocation @ np.array(targets)
        w_0 = allocation @ motors
        w_half = w_ss + (w_0 - w_ss) * lag.decay(0.5 * dt)
        w_full = w_ss + (w_0 - w_ss) * lag.decay(dt)
        k1 = _reference_derivative(vehicle, cable, x, w_0)
        k2 = _reference_derivative(vehicle, cable, x + 0.5 * dt * k1, w_half)
        k3 = _reference_derivative(vehicle, cable, x + 0.5 * dt * k2, w_half)
        k4 = _reference_derivative(vehicle, cable, x + dt * k3, w_full)
        x = x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        motors = np.array(targets) + (motors - np.array(targets)) * lag.decay(dt)
    assert not body.landed
    assert np.array(body.x) == pytest.approx(x, rel=1e-9, abs=1e-9)
    assert body.motor_thrusts_n == pytest.approx(motors.tolist(), rel=1e-12)
