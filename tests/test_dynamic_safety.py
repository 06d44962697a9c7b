"""The dynamic filter knows what it does not know: a cable resting on the ground is placed by
its winch length (or not at all), a filter that explains its pull with a wind of its own
invention does not publish the bearing, and the scorecard tells it the simulated cable's
weight."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.bench.estimators.registry import FlightContext
from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.initialise import (
    NO_COVARIANCE,
    PLACEMENT_FAILED,
    Initialiser,
)
from tether_companion.estimation.dynamic.observability import (
    InnovationExcess,
    min_horizontal_pull_n,
)
from tether_companion.estimation.dynamic.scorecard import simulated_cable_weight_n_per_m
from tether_companion.physics.cable import CableConfig, make_cable
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.scenario import load_scenario

MASS_KG = 1.5
DENSITY_KG_PER_M = 0.0167


def _window(
    position_ned_m: np.ndarray, length_m: float, density_kg_per_m: float = DENSITY_KG_PER_M
) -> Initialiser:
    """An initialiser fed 1.2 s of a level hover at ``position_ned_m`` on the simulator's
    catenary cable of ``length_m``, thrust as the map says, no bias or wind."""
    config = dataclasses.replace(
        DynamicFilterConfig(), cable_weight_n_per_m=density_kg_per_m * GRAVITY_MPS2
    )
    cable = make_cable(
        CableConfig(
            model="catenary",
            length_m=length_m,
            linear_density_kg_per_m=density_kg_per_m,
            stiffness_n_per_m=100.0,
        )
    )
    force = np.array(cable.force_components(*position_ned_m, 0.0, 0.0, 0.0))
    thrust = MASS_KG * GRAVITY_MPS2 + force[2]  # holds the hover against weight and pull
    specific_force = (force + np.array((0.0, 0.0, -thrust))) / MASS_KG  # body = NED, level
    initialiser = Initialiser(config, MASS_KG, 0.2, 0.15, 0.3)
    initialiser.add_height(-float(position_ned_m[2]))
    for i in range(241):
        initialiser.add_tick(i * 0.005, specific_force, np.eye(3), thrust)
    return initialiser


@pytest.mark.parametrize(
    ("position", "length_m", "density_kg_per_m"),
    [
        ((4.5 * math.cos(0.4), 4.5 * math.sin(0.4), -3.0), 7.0, 0.1),  # 1.3 m on the ground
        ((6.4, 0.5, -3.0), 7.5, DENSITY_KG_PER_M),  # the sagging circle: 0.2 m on the ground
    ],
)
def test_a_cable_on_the_ground_is_placed_by_its_length_and_only_by_it(
    position: tuple[float, float, float], length_m: float, density_kg_per_m: float
) -> None:
    """Its pull is the same at any span beyond the touchdown: the first second places the drone
    with the winch length (where the simulator put it), and without one it says it cannot. The
    half-weight placement before put the drone metres off on the realistic sagging circle."""
    p = np.array(position)
    start = _window(p, length_m, density_kg_per_m).solve(1.2, length_m)
    assert start.x is not None, start.reason
    np.testing.assert_allclose(start.x[state.POSITION], p, atol=1e-6)
    unknown = _window(p, length_m, density_kg_per_m).solve(1.2)
    assert unknown.x is None
    assert unknown.reason in (PLACEMENT_FAILED, NO_COVARIANCE)


def test_a_free_catenary_is_placed_by_the_height_alone() -> None:
    """Hanging free (a 5.9 m cable over a 5.83 m chord), the pull's slope and the height fix
    the span through the exact catenary."""
    p = np.array((5.0 * math.cos(-1.0), 5.0 * math.sin(-1.0), -3.0))
    start = _window(p, 5.9).solve(1.2)
    assert start.x is not None, start.reason
    np.testing.assert_allclose(start.x[state.POSITION], p, atol=1e-6)


def test_the_pull_must_dominate_the_wind_the_filter_claims() -> None:
    """The bearing is the direction of the pull beyond the drag of the wind: the bound grows
    with the filter's own wind once that exceeds the prior's standard deviation."""
    per_wind = 4.0 * MASS_KG * 0.2
    assert min_horizontal_pull_n(per_wind, 2.0, 1.0, -1.0) == pytest.approx(per_wind * 2.0)
    assert min_horizontal_pull_n(per_wind, 2.0, 6.0, -8.0) == pytest.approx(per_wind * 10.0)


@pytest.mark.parametrize(
    ("scenario", "weight_n_per_m"),
    [
        ("realistic-circle", 0.0),  # constant-tension winch: the weightless straight line
        ("realistic-takeoff-figure8", 0.0),
        ("realistic-sagging-circle", DENSITY_KG_PER_M * GRAVITY_MPS2),  # catenary
    ],
)
def test_the_scorecard_tells_the_filter_the_simulated_cables_weight(
    scenario: str, weight_n_per_m: float
) -> None:
    """The realistic scenarios all say 0.0167 kg/m, but the constant-tension winch the
    simulator flies with it has no weight; the filter is told what the simulated cable is."""
    loaded = load_scenario(scenario)
    context = FlightContext(loaded, load_vehicle(loaded.vehicle), GRAVITY_MPS2)
    assert loaded.cable.linear_density_kg_per_m == DENSITY_KG_PER_M
    assert simulated_cable_weight_n_per_m(context) == pytest.approx(weight_n_per_m)


def test_the_innovations_excess_variance_is_what_the_filter_did_not_predict() -> None:
    """Innovations drawn with the predicted variance leave no excess; innovations from a state
    0.3 m off (the take-off's height) show about 0.3^2 m^2 of it."""
    rng = np.random.default_rng(4)
    honest, biased = InnovationExcess(2.0), InnovationExcess(2.0)
    predicted = 0.105  # H P H^T + R of the rangefinder: 0.32 m noise, 0.07 m state
    for i in range(400):  # 20 s at 20 Hz
        noise = rng.normal(scale=math.sqrt(predicted))
        honest.add(noise, predicted, i * 0.05)
        biased.add(0.3 + noise, predicted, i * 0.05)
    assert honest.variance < 0.05
    assert biased.variance == pytest.approx(0.09, abs=0.05)
    biased.add(math.nan, predicted, 20.0)  # a non-finite innovation changes nothing
    assert math.isfinite(biased.variance)


def test_an_honest_filters_innovations_add_almost_no_excess() -> None:
    """Innovations exactly as predicted: the 2 s average of ``y^2 - S`` scatters by ~0.16 S;
    clipped at 0 it averaged 0.064 S over these 10 min, the former rule (2 of its standard
    deviations, or within 2 s of an innovation beyond 3 sigma) 0.022 S and nonzero 9 % of the
    time: twice the height's own variance on the realistic 4 N circle (nees15). The chi-square
    test at :attr:`InnovationExcess.FALSE_ALARM` counts it about that often."""
    rng = np.random.default_rng(11)
    predicted = 0.105
    excess = InnovationExcess(2.0)
    seen = []
    for i in range(20 * 600):  # 10 min at 20 Hz
        excess.add(rng.normal(scale=math.sqrt(predicted)), predicted, i * 0.05)
        if i >= 40:
            seen.append(excess.variance)
    assert np.mean(seen) < 0.003 * predicted
    assert np.mean(np.array(seen) > 0.0) < 3.0 * InnovationExcess.FALSE_ALARM


def test_the_test_is_sized_for_the_readings_it_has() -> None:
    """Its degrees of freedom follow the weights: right after the first reading one innovation
    of 4 sigma counts (chi2(1) beyond its 99.9 % quantile, 10.8), one of 3 sigma does not; with
    a 2 s average of 20 Hz readings in, a single reading of 4 sigma does not (nu ~ 80)."""
    predicted = 0.1
    first = InnovationExcess(2.0)
    first.add(4.0 * math.sqrt(predicted), predicted, 0.0)
    assert first.variance == pytest.approx(15.0 * predicted)
    small = InnovationExcess(2.0)
    small.add(3.0 * math.sqrt(predicted), predicted, 0.0)
    assert small.variance == 0.0
    settled = InnovationExcess(2.0)
    for i in range(200):
        settled.add(math.sqrt(predicted) * (1 if i % 2 else -1), predicted, i * 0.05)
    settled.add(4.0 * math.sqrt(predicted), predicted, 10.0)
    assert settled.variance == 0.0


def test_a_height_error_starting_counts_within_a_second_and_a_half() -> None:
    """A height 0.5 m off (the realistic 0.5 N circle's angle kind, consist10: innovations
    0.5-0.9 m against a predicted 0.32 m) counts within 30 readings (2-24 on five draws) and
    4 s in shows most of its square; innovations 5 % beyond the predicted are not counted (an
    average of 0.05 S is below the test's sampling noise)."""
    rng = np.random.default_rng(5)
    predicted = 0.105
    steady = math.sqrt(1.05 * predicted)
    excess = InnovationExcess(2.0)
    for i in range(200):
        excess.add(steady if i % 2 else -steady, predicted, i * 0.05)
    assert excess.variance == 0.0
    counted = []
    for i in range(1, 81):
        excess.add(0.5 + rng.normal(scale=math.sqrt(predicted)), predicted, 10.0 + i * 0.05)
        counted.append(excess.variance > 0.0)
    assert any(counted[:30])
    assert all(counted[30:])
    assert excess.variance == pytest.approx(0.25, abs=0.12)
