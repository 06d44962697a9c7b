"""A heavy cable's start without a winch length waits until every cable angle of the window
reads the cable lifted at the anchor (initialise.py, start_angle.py ``all_lifted``): a cable
resting on the ground leaves the anchor flat whatever the drone's range beyond its
touchdown, and the pull placed on the free curve puts the drone at the touchdown kink. On the
heavy 5 N winch figure-8 (angle alone) that started the filter 1-4 m short with its
covariance 1-4 sd narrower, and 4-11 % of the published ticks were beyond 3 sigma on tuning
seeds 1-10 (docs/estimation-history.md, angle21)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.bench.estimators.flight import fly
from tether_companion.bench.estimators.registry import kinds
from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.initialise import RESTING, Initialiser
from tether_companion.estimation.dynamic.start_angle import AngleReadings
from tether_companion.sim.scenario import load_scenario

NOISE_RAD = 0.01
CALIBRATION_RAD = (0.007, 0.026)
"""One reading's error: 3 sd of it is 0.037 rad of elevation."""


def _readings(elevations: list[float]) -> AngleReadings:
    readings = AngleReadings()
    for i, elevation in enumerate(elevations):
        readings.add(0.1 * i, elevation, 0.0, NOISE_RAD, CALIBRATION_RAD, 3.0, math.nan)
    return readings


def test_every_reading_must_show_the_cable_lifted() -> None:
    assert _readings([0.3, 0.2, 0.04]).all_lifted()
    assert not _readings([0.3, 0.2, 0.03]).all_lifted()  # one within 3 sd of flat
    assert not _readings([]).all_lifted()


def _window(weight_n_per_m: float, elevation_rad: float) -> Initialiser:
    """1.2 s of a drone hovering 5 m north and 3 m up pulled by 5 N along the chord, a height
    at 20 Hz, the cable angle ``elevation_rad`` at 10 Hz, on a cable of ``weight_n_per_m``."""
    config = dataclasses.replace(DynamicFilterConfig(), cable_weight_n_per_m=weight_n_per_m)
    mass = 1.5
    initialiser = Initialiser(config, mass, 0.2, 0.15, 0.3)
    position = np.array((5.0, 0.0, -3.0))
    pull = -5.0 * position / np.linalg.norm(position)
    thrust = mass * GRAVITY_MPS2 + pull[2]
    for i in range(241):
        t = i * 0.005
        if i % 10 == 0:
            initialiser.add_height(3.0)
        initialiser.add_tick(t, (pull + np.array((0.0, 0.0, -thrust))) / mass, np.eye(3), thrust)
        if i % 20 == 0:
            initialiser.add_angle(t, elevation_rad, 0.0, NOISE_RAD, CALIBRATION_RAD, math.nan)
    return initialiser


def test_a_heavy_cable_read_flat_does_not_start_without_a_length() -> None:
    heavy = 0.1 * GRAVITY_MPS2
    assert _window(heavy, 0.0).solve(1.2).reason == RESTING
    assert _window(heavy, 0.0).solve(1.2, 7.0).reason != RESTING  # a length places it
    assert _window(0.0, 0.0).solve(1.2).reason != RESTING  # a weightless cable: no ground rest
    assert _window(heavy, 0.3).solve(1.2).reason != RESTING


@pytest.mark.parametrize("seed", [4, 7])
def test_the_heavy_figure8s_angle_alone_publishes_within_3_sigma(seed: int) -> None:
    """Tuning seeds 4 and 7, the first 9 s (the start and two passes inward): every published
    tick within 3 sigma on each axis (main before angle21: 124 and 173 ticks beyond, the
    radial error 0.5-1.0 m at 0.15 m of published standard deviation)."""
    scenario = dataclasses.replace(
        load_scenario("sitl/scenarios/realistic-winch-heavy-figure8-5n.yaml"),
        seed=seed,
        duration_s=9.0,
    )
    record = fly(scenario, [kinds()["dynamic-angle"]])
    trace = record.traces["dynamic-angle"]
    published = trace.published & np.isfinite(trace.position_ned_m).all(axis=1)
    assert published.sum() > 100
    error = trace.position_ned_m[published] - record.position_ned_m[published]
    sd = np.sqrt(np.diagonal(trace.position_covariance_m2[published], axis1=1, axis2=2))
    assert np.all(np.abs(error) <= 3.0 * sd)
