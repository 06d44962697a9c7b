"""A heavy cable at a low tension (slack12): the models below a chord tension of zero, the
winch's measured tension lifting a filter that went slack, and the start placed by the cable
angle (and the winch length) where the wind turns a heavy cable's weak pull.

On the light cable (0.0167 kg/m) at the winch's 1 N the filter's chord tension went below
zero on tuning seeds of the figure-8; the free catenary there is its mirror image, whose
tension at the drone grows without bound as ``T_ch -> 0-``, so the winch's readings moved
nothing and the filter held "slack" for the whole flight. Its start, placed by the force
alone (1 N of pull against the drag of a 2 m/s wind), was up to 7 m off.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from filter_states import resting_window, state_at

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import generated, state
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.initialise import Initialiser
from tether_companion.estimation.dynamic.models import CATENARY, SLACK_FLOOR_N
from tether_companion.estimation.dynamic.offline import run_dynamic
from tether_companion.estimation.dynamic.output import SLACK
from tether_companion.estimation.dynamic.start_placement import heavy_by_elevation, place
from tether_companion.samples import AttitudeSample, ImuSample
from tether_companion.sim.scenario import load_scenario

WEIGHT_N_PER_M = 0.0167 * GRAVITY_MPS2
"""The light cable [N/m]."""
CONSTANTS = (1.5, 0.2, WEIGHT_N_PER_M)
"""Mass [kg], drag [1/s], weight per length [N/m]."""


def test_below_zero_tension_a_heavy_cable_continues_as_the_resting_one() -> None:
    """At ``T_ch`` below zero the tension at the drone is the resting cable's ``w b + H``
    continued (``H = T_ch a / |p|``), its tension derivative ``a / |p|``; the free catenary's
    mirror there gave 0.8-1.6 N with derivatives of 11-110. Continuous at the floor."""
    position = (4.0, -0.9, -3.1)
    span, distance = math.hypot(4.0, -0.9), math.dist(position, (0.0, 0.0, 0.0))
    for tension in (-0.5, -0.15, -0.01, 0.0):
        (value,), jac = CATENARY.tension(state_at(position, tension), (), CONSTANTS)
        expected = WEIGHT_N_PER_M * 3.1 + tension * span / distance
        assert value == pytest.approx(expected, abs=1e-6)
        assert jac[state.TENSION] == pytest.approx(span / distance, rel=1e-3)
    at_floor = state_at(position, SLACK_FLOOR_N)
    below = state_at(position, SLACK_FLOOR_N * (1.0 - 1e-9))
    for name in ("tension", "accel", "winch_length", "cable_angle"):
        model = getattr(CATENARY, name)
        u = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 14.0) if name == "accel" else ()
        above_value, _ = model(at_floor, u, CONSTANTS)
        below_value, _ = model(below, u, CONSTANTS)
        assert np.allclose(above_value, below_value, atol=1e-6), name
    grounded, _ = generated.tension_grounded(at_floor, (), CONSTANTS)
    assert CATENARY.tension(at_floor, (), CONSTANTS)[0] == pytest.approx(grounded)


def test_the_winch_tension_lifts_a_filter_gone_slack_on_a_heavy_cable() -> None:
    """A filter on the light cable 4 m out and 3 m up at a chord tension of -0.15 +- 0.3 N
    (the 1 N figure-8's went there) hears the winch's 1.5 N at the drone: ten readings bring
    its tension above 0.7 N and the estimate leaves ``slack``. On the free catenary's mirror the
    readings were fused and the tension stayed below zero (there the tension at the drone
    grows without bound toward ``T_ch = 0``: every reading is met just below it)."""
    scenario = dataclasses.replace(load_scenario("paper-circle"), duration_s=3.0, seed=1)
    run = run_dynamic(scenario, EstimatorConfig(), DynamicFilterConfig(load_cell_noise_std_n=0.2))
    est = run.estimator
    est.constants.weight_n_per_m = WEIGHT_N_PER_M
    for member in est.bank.filters:
        x, p = member.x.copy(), member.P.copy()
        x[state.POSITION] = (4.0, -0.9, -3.1)
        x[state.TENSION] = -0.15
        p[state.TENSION, :] = p[:, state.TENSION] = 0.0
        p[state.TENSION, state.TENSION] = 0.3**2
        member.x, member.P = x, p
    t = float(run.time_s[-1])
    for k in range(10):
        est.set_known_tension_n(1.5, t + 0.001 * k)
    assert est.ground_station.load_cell.status.fused >= 8
    assert float(est.bank.best.x[state.TENSION]) > 0.7
    est.on_attitude(AttitudeSample(t + 0.011, 0.0, 0.0, 0.0))
    estimate = est.on_imu(ImuSample(t + 0.011, np.array([0.0, 0.0, -9.8]), np.zeros(3)))
    assert estimate.status != SLACK


MASS_KG, DRAG_PER_S = 1.5, 0.2
HORIZONTAL_N = 1.0
"""The winch's tension: on the ground it is the horizontal pull everywhere [N]."""
HEIGHT_M, SPAN_M = 3.0, 6.5
CROSS_WIND = np.array((0.0, 2.5, 0.0))
"""A cross wind [m/s]: 0.75 N of drag across the 1 N pull, turning it by 37 degrees."""


def _resting_window(*, angles: bool) -> tuple[Initialiser, float]:
    """1.2 s of a level drone hovering 6.5 m north of the anchor, 3 m up, on the light cable
    resting on the ground with 1 N of horizontal tension, in :data:`CROSS_WIND`; heights at
    20 Hz, with ``angles`` the anchor's (flat, azimuth north) at 10 Hz; and the winch length
    [m]."""
    config = dataclasses.replace(DynamicFilterConfig(), cable_weight_n_per_m=WEIGHT_N_PER_M)
    return resting_window(
        config, MASS_KG, DRAG_PER_S, HORIZONTAL_N, HEIGHT_M, SPAN_M, 0.0, CROSS_WIND, angles=angles
    )


def test_a_heavy_cable_start_takes_its_bearing_from_the_cable_angle() -> None:
    """The window's force points 37 degrees off the bearing: placed by it the drone starts
    metres off; with the anchor's azimuth the bearing is the azimuth, the span the resting
    cable's at the winch length, within 5 cm, and the covariance covers it."""
    truth = np.array((SPAN_M, 0.0, -HEIGHT_M))
    initialiser, length = _resting_window(angles=False)
    forced = initialiser.solve(1.2, length)
    assert forced.x is not None
    assert np.linalg.norm(forced.x[:2] - truth[:2]) > 2.0  # what the force alone does
    initialiser, length = _resting_window(angles=True)
    start = initialiser.solve(1.2, length)
    assert start.x is not None and start.p is not None, start.reason
    assert np.allclose(start.x[state.POSITION], truth, atol=0.05)
    sd = np.sqrt(np.diag(start.p)[:3])
    assert np.all(np.abs(start.x[state.POSITION] - truth) < 3.0 * sd)


@pytest.mark.parametrize("anchor_over_c", [-0.3, 0.5, 1.0])
def test_the_cable_angle_and_length_place_a_heavy_drone_without_its_pull(
    anchor_over_c: float,
) -> None:
    """A free catenary (``y = c cosh(x/c)``, the anchor at ``x = anchor_over_c c``, the drone
    5 m beyond): from its elevation at the anchor, its arc length and the height the span and
    the chord tension come back exactly, and on the azimuth's bearing even where the window's
    force points away from the anchor (the light 1 N hover's seed 9: the wind's drag and the
    thrust map's error outweigh 1 N of pull, and a start from that force failed for 15 s)."""
    parameter = HORIZONTAL_N / WEIGHT_N_PER_M
    x0, x1 = anchor_over_c * parameter, anchor_over_c * parameter + 5.0
    height = parameter * (math.cosh(x1 / parameter) - math.cosh(x0 / parameter))
    length = parameter * (math.sinh(x1 / parameter) - math.sinh(x0 / parameter))
    elevation = math.atan(math.sinh(x0 / parameter))
    chord_tension = HORIZONTAL_N * math.hypot(5.0, height) / 5.0
    span, tension = heavy_by_elevation(height, length, WEIGHT_N_PER_M, elevation)
    assert span == pytest.approx(5.0, abs=1e-9)
    assert tension == pytest.approx(chord_tension, rel=1e-9)
    away = np.array((0.2, 0.25, 0.4))  # north-east and down: no pull toward the anchor
    azimuth = 2.0
    if math.sin(elevation) >= 0.1:
        placed = place(away, height, length, WEIGHT_N_PER_M, elevation, azimuth)
        assert placed is not None
        expected = (5.0 * math.cos(azimuth), 5.0 * math.sin(azimuth), -height, chord_tension)
        assert np.allclose(placed, expected, atol=1e-9)
    else:  # leaving the anchor flat or downward: the force's pull along the bearing places it
        assert place(away, height, length, WEIGHT_N_PER_M, elevation, azimuth) is None
