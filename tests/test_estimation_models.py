"""Tether measurement models: physics of h_acc, analytic Jacobians vs finite differences."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tether_companion.estimation.tether_models import (
    F_C,
    FourStateModel,
    ThreeStateModel,
    altimeter,
)
from tether_companion.frames import rotation_body_to_ned, rotation_ned_to_body

MASS_KG = 1.5

coordinate = st.floats(-10.0, 10.0, allow_nan=False)
angle = st.floats(-0.6, 0.6, allow_nan=False)
positions = st.tuples(coordinate, coordinate, coordinate).filter(
    lambda p: math.dist(p, (0, 0, 0)) > 0.5
)
attitudes = st.tuples(angle, angle, st.floats(-math.pi, math.pi, allow_nan=False))
tensions = st.floats(0.0, 20.0, allow_nan=False)
thrusts = st.floats(0.0, 40.0, allow_nan=False)


def _fd_jacobian(func, x: np.ndarray, step: float = 1e-6) -> np.ndarray:
    columns = []
    for i in range(x.size):
        dx = np.zeros_like(x)
        dx[i] = step
        columns.append((func(x + dx) - func(x - dx)) / (2.0 * step))
    return np.stack(columns, axis=1)


@settings(max_examples=150, deadline=None)
@given(positions, tensions, attitudes, thrusts)
def test_four_state_jacobian_matches_finite_differences(
    position, tension, attitude, thrust
) -> None:
    model = FourStateModel(MASS_KG)
    rot = rotation_ned_to_body(*attitude)
    x = np.array([*position, tension])
    _, jac = model.accel(x, rot, thrust)
    numeric = _fd_jacobian(lambda s: model.accel(s, rot, thrust)[0], x)
    np.testing.assert_allclose(jac, numeric, rtol=1e-5, atol=1e-7)


@settings(max_examples=100, deadline=None)
@given(positions, tensions, attitudes, thrusts)
def test_three_state_jacobian_matches_finite_differences(
    position, tension, attitude, thrust
) -> None:
    model = ThreeStateModel(MASS_KG)
    rot = rotation_ned_to_body(*attitude)
    x = np.array(position)
    _, jac = model.accel(x, rot, thrust, tension)
    numeric = _fd_jacobian(lambda s: model.accel(s, rot, thrust, tension)[0], x)
    np.testing.assert_allclose(jac, numeric, rtol=1e-5, atol=1e-7)
    four = FourStateModel(MASS_KG).accel(np.array([*position, tension]), rot, thrust)[1]
    np.testing.assert_allclose(jac, four[:, :3])


@settings(max_examples=100, deadline=None)
@given(positions, tensions, attitudes, thrusts)
def test_accel_is_specific_force_of_thrust_and_cable(position, tension, attitude, thrust) -> None:
    """Independent derivation: specific force = (thrust + cable force) / m, rotated to body."""
    p = np.array(position)
    thrust_ned = rotation_body_to_ned(*attitude) @ np.array([0.0, 0.0, -thrust])
    cable_ned = -tension * p / np.linalg.norm(p)
    expected = rotation_ned_to_body(*attitude) @ (thrust_ned + cable_ned) / MASS_KG
    got, _ = FourStateModel(MASS_KG).accel(
        np.array([*p, tension]), rotation_ned_to_body(*attitude), thrust
    )
    np.testing.assert_allclose(got, expected, atol=1e-9)


def test_accel_in_g_units_is_the_architecture_form() -> None:
    """Level, straight above the anchor: the cable pulls down (+z body), so the specific force
    is (0, 0, -T + f_c) / m [m/s^2] (divide by g for the architecture's units of g)."""
    x = np.array([0.0, 0.0, -3.0, 2.0])
    accel, jac = FourStateModel(MASS_KG).accel(x, np.eye(3), 12.0)
    np.testing.assert_allclose(accel, [0.0, 0.0, (-12.0 + 2.0) / MASS_KG])
    np.testing.assert_allclose(jac[:, F_C], [0.0, 0.0, 1.0 / MASS_KG])


@settings(max_examples=30, deadline=None)
@given(positions)
def test_altimeter_is_height_above_anchor(position) -> None:
    for x in (np.array(position), np.array([*position, 1.0])):
        z, jac = altimeter(x)
        assert z.shape == (1,) and z[0] == -position[2]
        np.testing.assert_allclose(jac, _fd_jacobian(lambda s: altimeter(s)[0], x), atol=1e-9)
