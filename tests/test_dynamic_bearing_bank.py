"""The bank's bearing hypotheses: members started at the bearings the wind's drag could give
the first second's pull, kept while the data cannot tell them apart, and the pull rule relaxed
only once the data left one (docs/estimation-history.md, "The bearing hypotheses (bearing10)")."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.initialise import Initialiser
from tether_companion.sim.scenario import load_scenario

MASS_KG = 1.5
DRAG_PER_S = 0.2
LENGTH_M = math.sqrt(13.0)
"""The winch length of a straight cable to (3, 0, -2) [m]."""


def _hover_window(position_ned_m: np.ndarray, tension_n: float, drag_per_s: float) -> Initialiser:
    """1.2 s of a level hover at ``position_ned_m`` on a light straight cable of
    ``tension_n``, thrust as the map says, no bias or wind; rangefinder height."""
    pull = -tension_n * position_ned_m / np.linalg.norm(position_ned_m)
    thrust = MASS_KG * GRAVITY_MPS2 + pull[2]
    specific_force = (pull + np.array((0.0, 0.0, -thrust))) / MASS_KG
    initialiser = Initialiser(DynamicFilterConfig(), MASS_KG, drag_per_s, 0.15, 0.3)
    initialiser.add_height(-float(position_ned_m[2]))
    for i in range(241):
        initialiser.add_tick(i * 0.005, specific_force, np.eye(3), thrust)
    return initialiser


def _bearing(x: np.ndarray) -> float:
    return math.atan2(float(x[1]), float(x[0]))


def test_the_ring_of_winds_starts_the_bearings_the_drag_could_turn_the_pull_to() -> None:
    """Beside the five thrust-scale members, four at the prior thrust scale whose window force
    is less the drag of a wind on the ring (4 m/s: 1.2 N at m mu = 0.3 N s/m): each one's wind
    state is that wind, its pull that much turned, its log prior the ring's density."""
    p = np.array((3.0, 0.0, -2.0))
    tension = 1.5  # a weak pull: 1.25 N horizontally
    initial = DynamicFilterConfig().initial
    starts = _hover_window(p, tension, DRAG_PER_S).hypotheses(1.2, initial, LENGTH_M)
    central = [s for s in starts if not s.bearing_rival]
    rivals = [s for s in starts if s.bearing_rival]
    assert 1 <= len(central) <= initial.thrust_scale_hypotheses  # the low scales: no rise
    assert all(s.log_prior == 0.0 for s in central)
    (own,) = [s for s in central if s.x[state.SCALE] == initial.thrust_scale]
    assert abs(_bearing(own.x)) < 1e-6  # the prior's own start: the true bearing
    assert len(rivals) == initial.wind_hypotheses
    speed = initial.wind_hypothesis_radius_std * initial.wind_std_mps
    drag = MASS_KG * DRAG_PER_S * speed
    horizontal = tension * 3.0 / math.sqrt(13.0)
    for start in rivals:
        wind = start.x[state.WIND]
        assert math.hypot(*wind) == np.float64(speed)
        assert start.log_prior == -0.5 * initial.wind_hypothesis_radius_std**2
        # the cable's pull is the force less the wind's drag: -H u - m mu w
        pull = np.array((-horizontal, 0.0)) - MASS_KG * DRAG_PER_S * wind
        expected = math.atan2(-pull[1], -pull[0])
        assert math.isclose(_bearing(start.x), expected, abs_tol=1e-6)
    turned = [abs(_bearing(s.x)) for s in rivals]
    assert max(turned) > math.asin(min(1.0, 0.5 * drag / horizontal))  # tens of degrees


def test_without_rotor_drag_the_wind_cannot_turn_the_pull_and_no_ring_is_started() -> None:
    starts = _hover_window(np.array((3.0, 0.0, -2.0)), 4.0, 0.0).hypotheses(
        1.2, DynamicFilterConfig().initial, LENGTH_M
    )
    assert starts and not any(s.bearing_rival for s in starts)


def test_without_a_winch_length_no_ring_is_started() -> None:
    """The range is then as unknown as the bearing: ring members left undecided when the bank
    collapses only widen it (the IMU-only 4 N circle published half as often)."""
    starts = _hover_window(np.array((3.0, 0.0, -2.0)), 4.0, DRAG_PER_S).hypotheses(
        1.2, DynamicFilterConfig().initial, math.nan
    )
    assert starts and not any(s.bearing_rival for s in starts)


def test_the_ring_can_be_switched_off() -> None:
    initial = dataclasses.replace(DynamicFilterConfig().initial, wind_hypotheses=0)
    starts = _hover_window(np.array((3.0, 0.0, -2.0)), 4.0, DRAG_PER_S).hypotheses(
        1.2, initial, LENGTH_M
    )
    assert starts and not any(s.bearing_rival for s in starts)


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="not since the realistic ground station (79ec8f5: the encoder's scale, offset and "
    "0.1 s latency) and the late readings' velocity taken as known (9a632a6; with the exact "
    "winch alone the test passed before that commit and fails after it, latency told 0 or "
    "not): seed 18 with the winch alone never publishes in the 9 s flown. The pull rule needs "
    ">= 2.4 N of horizontal pull against the wind's drag, the take-off's is 1.4-2.84 N, and "
    "the own-model bound is 0.35-0.59 m in the first 5 s against the 0.5 m publish bound "
    "(docs/estimation-history.md, takeoff11)",
)
def test_a_take_off_publishes_within_five_seconds_of_the_cable_becoming_taut() -> None:
    """Tuning seed 18 of the realistic take-off with the winch length: the bearing
    hypotheses converge to one during the fly-out and the pull rule relaxes, so the position
    is published 3.7 s after the cable became taut (before: nothing within the 9 s flown; the
    replay of the whole flight first published at 8.2 s), and nothing published is beyond
    3 sigma."""
    pytest.importorskip("distributed", reason="bench estimators needs dask.distributed")
    from tether_companion.bench.estimators.flight import fly
    from tether_companion.bench.estimators.registry import kinds
    from tether_companion.bench.estimators.scores import published_after_taut_s

    scenario = dataclasses.replace(
        load_scenario("realistic-takeoff-figure8"), duration_s=9.0, seed=18
    )
    record = fly(scenario, [kinds()["dynamic-winch"]])
    trace = record.traces["dynamic-winch"]
    published = trace.published
    after = published_after_taut_s(record.time_s, record.landed, record.tension_n, published)
    assert after <= 5.0
    error = trace.position_ned_m[published] - record.position_ned_m[published]
    std = np.sqrt(np.diagonal(trace.position_covariance_m2[published], axis1=1, axis2=2))
    assert published.any() and not (np.abs(error) > 3.0 * std).any()
