"""The ground a moving drone averages (:class:`GroundFootprint`): a hover keeps the ground's
whole variance, a drone moving over more ground than its correlation length within the
height's memory keeps ``sigma^2 / sqrt(1 + (D / l)^2)``; and that form is the simulator's
terrain averaged the filter's way (undulations in random directions, ``l`` = the wavelength
over 2 pi)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.estimation.dynamic.terrain import GroundFootprint
from tether_companion.sim.ground import Ground, GroundConfig

STD_M = 0.05
CORRELATION_M = 4.0 / (2.0 * math.pi)
"""The realistic scenarios' 4 m undulations."""
GAIN = 0.03
"""The height's gain per reading with the cable angle alone on the realistic circle (1.7 s
of memory at 20 Hz)."""
READING_S = 0.05


def _flown(footprint: GroundFootprint, speed_mps: float, readings: int = 2000) -> float:
    """The footprint's variance after ``readings`` readings along a straight line at
    ``speed_mps`` [m/s]."""
    for i in range(readings):
        footprint.add(GAIN, 1.0 + speed_mps * READING_S * i, 2.0)
    return footprint.variance_m2


def test_a_hover_keeps_the_whole_variance_and_a_restart_forgets() -> None:
    footprint = GroundFootprint(STD_M, CORRELATION_M)
    assert footprint.variance_m2 == STD_M**2  # before a reading
    assert _flown(footprint, 0.0) == STD_M**2
    assert _flown(footprint, 1.0) < 0.5 * STD_M**2
    footprint.clear()
    assert footprint.variance_m2 == STD_M**2
    assert GroundFootprint(0.0, CORRELATION_M).variance_m2 == 0.0


@pytest.mark.parametrize("speed_mps", [0.1, 0.3, 1.0, 3.0])
def test_a_straight_path_averages_the_ground_over_speed_times_memory(speed_mps: float) -> None:
    """``D`` is the readings' weighted spread, ``v dt sqrt(1 - K) / K`` on a straight line."""
    memory_m = speed_mps * READING_S * math.sqrt(1.0 - GAIN) / GAIN
    expected = STD_M**2 / math.sqrt(1.0 + (memory_m / CORRELATION_M) ** 2)
    assert _flown(GroundFootprint(STD_M, CORRELATION_M), speed_mps) == pytest.approx(
        expected, rel=1e-6
    )


@pytest.mark.parametrize("gain", [0.0, -0.1, 1.5, math.nan])
def test_gains_out_of_range_and_nonfinite_positions_are_ignored(gain: float) -> None:
    footprint = GroundFootprint(STD_M, CORRELATION_M)
    footprint.add(GAIN, 0.0, 0.0)
    footprint.add(gain, 10.0, 0.0)
    footprint.add(GAIN, math.nan, 0.0)
    footprint.add(GAIN, 0.0, math.inf)
    assert footprint.variance_m2 == STD_M**2


@pytest.mark.parametrize(("speed_mps", "kept"), [(0.3, 0.9), (1.0, 0.5)])
def test_the_form_is_the_simulators_terrain_averaged_the_filters_way(
    speed_mps: float, kept: float
) -> None:
    """The simulator's ground (six plane waves of random direction, wavelengths 0.5-1.5
    times 4 m) averaged with the filter's exponential weights along a straight line: the
    average's variance over 400 drawn grounds within its sampling error (the variance of a
    variance estimate of n draws: 2 / n relative, four times that) of the footprint's."""
    rng = np.random.default_rng(7)
    config = GroundConfig(terrain_std_m=STD_M, terrain_wavelength_m=4.0)
    steps = 250  # (1 - K)^250 = 5e-4 of the weight left
    weights = GAIN * (1.0 - GAIN) ** np.arange(steps)
    averages = []
    for _ in range(400):
        ground = Ground(config, rng)
        heading = rng.uniform(0.0, 2.0 * math.pi)
        along = speed_mps * READING_S * np.arange(steps)
        elevations = [
            ground.elevation_m(s * math.cos(heading), s * math.sin(heading)) for s in along
        ]
        averages.append(float(np.dot(weights, elevations)) / weights.sum())
    measured = float(np.mean(np.square(averages)))
    predicted = _flown(GroundFootprint(STD_M, CORRELATION_M), speed_mps)
    assert measured == pytest.approx(predicted, rel=4.0 * math.sqrt(2.0 / 400))
    assert measured < kept * STD_M**2  # and the motion does average the ground down
