"""What a steady hover in wind cannot tell the dynamic filter (issue 10, gusty hover): the
linearised model (force balance, winch length, height) at a hover equilibrium has two
unobservable directions, and one of them is the bearing traded against the wind across the
cable. A filter that claims to know the bearing there learned it from something other than the
first-order model (docs/estimation-history.md, "The gusty hover ... measured again (gust10)")."""

from __future__ import annotations

import math

import numpy as np

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.dynamic import generated, state
from tether_companion.frames import rotation_ned_to_body

MASS_KG = 1.5
ROTOR_DRAG_PER_S = 0.2
CONSTANTS = (MASS_KG, ROTOR_DRAG_PER_S, 0.0)
POSITION_M = np.array([4.0, 0.0, -2.5])
"""The realistic gusty hover's point: 4 m north of the anchor, 2.5 m above it."""
TENSION_N = 4.0
N = state.CALIBRATION.start
"""The states looked at: the ground station's calibration known (a calibrated winch)."""
NO_CALIBRATION = [0.0] * (state.N_STATES - N)
WIND_MPS = (-2.0, 2.2)
"""Its mean wind, north and east [m/s]."""


def _hover_equilibrium() -> tuple[list[float], list[float]]:
    """State and inputs ``(R_v^b row-major, thrust)`` at which the hover is at rest: the
    thrust tilted against weight, pull and rotor drag (the drag depends on the tilt: iterated)."""
    x = [*POSITION_M, 0.0, 0.0, 0.0, TENSION_N, 1.0, 0.0, 0.0, 0.0, *WIND_MPS, *NO_CALIBRATION]
    rotation = np.eye(3)
    thrust = MASS_KG * GRAVITY_MPS2
    for _ in range(60):
        u = [*rotation.ravel(), thrust]
        derivative, _ = generated.force_balance_straight(x, u, CONSTANTS)
        needed = rotation.T @ np.array([0.0, 0.0, -thrust]) - MASS_KG * np.array(derivative[3:6])
        thrust = float(np.linalg.norm(needed))
        z_body = -needed / thrust  # the body's z axis, NED
        pitch = math.atan2(z_body[0], z_body[2])
        roll = math.asin(-z_body[1])
        rotation = rotation_ned_to_body(roll, pitch, 0.0)
    return x, [*rotation.ravel(), thrust]


def _observability_matrix(x: list[float], u: list[float]) -> np.ndarray:
    """``[H; H F; ...; H F^12]`` of the force-balance formulation with the accelerometer, the
    winch length and the rangefinder's height as measurements, over the first :data:`N`
    states (the winch's calibration known)."""
    _, jac = generated.force_balance_straight(x, u, CONSTANTS)
    f = np.zeros((N, N))
    f[state.POSITION, state.VELOCITY] = np.eye(3)
    f[state.VELOCITY, :] = np.array(jac).reshape(3, state.N_STATES)[:, :N]
    rows = [
        np.array(generated.accel_straight(x, u, CONSTANTS)[1]).reshape(3, state.N_STATES),
        np.array(generated.winch_length_straight(x, (), CONSTANTS)[1]).reshape(1, -1),
        np.array(generated.height_above_ground(x, (1.0,), CONSTANTS)[1]).reshape(1, -1),
    ]
    h = np.vstack(rows)[:, :N]
    blocks, power = [], h
    for _ in range(N):
        blocks.append(power)
        power = power @ f
    return np.vstack(blocks)


def test_the_equilibrium_is_at_rest() -> None:
    x, u = _hover_equilibrium()
    derivative, _ = generated.force_balance_straight(x, u, CONSTANTS)
    assert np.allclose(derivative[3:6], 0.0, atol=1e-9)


def test_a_steady_hover_does_not_observe_the_bearing_against_the_cross_wind() -> None:
    """Rank 11 of 13: turning the drone across the cable by ``dp`` is matched by a wind across
    of ``T dp / (|p| m mu)`` (the pull turns by ``T dp / |p|``, the drag by ``m mu dw``); the
    other null direction trades the tension against the wind along the cable."""
    x, u = _hover_equilibrium()
    singular = np.linalg.svd(_observability_matrix(x, u), compute_uv=False)
    assert singular[-1] < 1e-9 * singular[0]
    assert singular[-2] < 1e-9 * singular[0]
    assert singular[-3] > 1e-3 * singular[0]  # everything else is observable

    _, _, vt = np.linalg.svd(_observability_matrix(x, u))
    null = vt[-2:].T  # (13, 2) orthonormal basis
    across = np.zeros(N)
    across[1] = 1.0  # east: across the cable of a drone north of the anchor
    across[12] = TENSION_N / (np.linalg.norm(POSITION_M) * MASS_KG * ROTOR_DRAG_PER_S)
    across /= np.linalg.norm(across)
    assert np.linalg.norm(null.T @ across) > 0.999

    bearing_alone = np.zeros(N)
    bearing_alone[1] = 1.0  # with the wind known, the bearing is observable
    assert np.linalg.norm(null.T @ bearing_alone) < 0.5
