"""A dynamic filter's state vector, and a start window on a resting cable, for unit tests."""

from __future__ import annotations

import math

import numpy as np

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.initialise import Initialiser


def state_at(position: tuple[float, float, float], tension_n: float) -> list[float]:
    """State (list of ``state.N_STATES``) at ``position`` (NED from the anchor) [m] with chord
    tension ``tension_n`` [N], thrust scale 1 and everything else zero."""
    x = [0.0] * state.N_STATES
    x[0:3] = position
    x[state.TENSION] = tension_n
    x[state.SCALE] = 1.0
    return x


def resting_window(
    config: DynamicFilterConfig,
    mass_kg: float,
    drag_per_s: float,
    horizontal_n: float,
    height_m: float,
    span_m: float,
    azimuth_rad: float,
    wind_ned_mps: np.ndarray,
    *,
    angles: bool,
    winch_tension: bool = False,
) -> tuple[Initialiser, float]:
    """1.2 s of start window: a level drone hovering ``height_m`` up and ``span_m`` out from
    the anchor on bearing ``azimuth_rad`` [rad], on a cable of ``config``'s weight per length
    that rests on the ground with ``horizontal_n`` [N] of horizontal tension (the winch's),
    in the wind ``wind_ned_mps`` (linear drag ``drag_per_s`` [1/s] on ``mass_kg``); heights at
    20 Hz, with ``angles`` the anchor's (flat, on the bearing) at 10 Hz, with
    ``winch_tension`` the winch's tension at 10 Hz. Returns the initialiser and the cable's
    length [m]."""
    weight = config.cable_weight_n_per_m
    parameter = horizontal_n / weight
    rise = math.sqrt(height_m**2 + 2.0 * height_m * parameter)
    touchdown = span_m - parameter * math.acosh(1.0 + height_m / parameter)
    assert touchdown > 0.0  # the cable rests on the ground
    length = touchdown + rise
    outward = np.array((math.cos(azimuth_rad), math.sin(azimuth_rad), 0.0))
    pull = np.array((*(-horizontal_n * outward[:2]), weight * rise))
    drag = mass_kg * drag_per_s * np.asarray(wind_ned_mps, dtype=float)
    thrust = mass_kg * GRAVITY_MPS2 + pull[2]
    specific_force = (pull + drag + np.array((0.0, 0.0, -thrust))) / mass_kg
    initialiser = Initialiser(config, mass_kg, drag_per_s, 0.15, 0.3)
    for i in range(241):
        t = i * 0.005
        if i % 10 == 0:
            initialiser.add_height(height_m)
        initialiser.add_tick(t, specific_force, np.eye(3), thrust)
        if i % 20 == 0:
            if angles:
                initialiser.add_angle(t, 0.0, azimuth_rad, 0.01, (0.007, 0.026), length)
            if winch_tension:
                initialiser.add_winch_tension(t, horizontal_n)
    return initialiser, length


def random_start(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A drawn state near (3, 1.5, -2.5) m at 4 N with wind, a random positive definite
    covariance and a process-noise density per state: a start for comparing two ways of
    stepping and fusing the same member."""
    x = np.zeros(state.N_STATES)
    x[state.POSITION] = (3.0, 1.5, -2.5)
    x[state.VELOCITY] = rng.normal(scale=0.3, size=3)
    x[state.TENSION] = 4.0
    x[state.SCALE] = 1.02
    x[state.BIAS] = rng.normal(scale=0.05, size=3)
    x[state.WIND] = (1.0, -0.5)
    a = rng.normal(size=(state.N_STATES, state.N_STATES)) * 0.05
    p0 = a @ a.T + np.diag(
        [
            0.3,
            0.3,
            0.05,
            0.2,
            0.2,
            0.2,
            1.0,
            0.01,
            0.01,
            0.01,
            0.01,
            1.0,
            1.0,
            0.01,
            1e-4,
            1e-4,
            1e-3,
        ]
    )
    q = np.array([1e-6] * 3 + [1e-4] * 3 + [2.0, 1e-5] + [1e-4] * 3 + [0.05] * 2 + [0.0] * 4)
    return x, p0, q
