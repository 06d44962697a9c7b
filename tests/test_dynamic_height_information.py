"""The rangefinder's readings narrow the unmodelled offset's down part with a winch length
(``GroundStationInputs.add_height_reading``): the height is measured with an error that has
nothing to do with the unmodelled force, as the cable angle is. The readings since the last
fused angle go in with it as one row on the height, each weighed by what it still tells of
the offset (``rho(dt)^2 / (R + (1 - rho(dt)^2) C_dd)``); without a winch length they are
forgotten (the term's vertical part then stands for the range's error, nees10)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from status_settings import NO_DRAG_RULE as SETTINGS

from tether_companion.bench.estimators.flight import fly
from tether_companion.bench.estimators.registry import kinds
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.consistency import BearingWindow
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.ground_station import GroundStationInputs
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.estimation.dynamic.output import DynamicHealth
from tether_companion.estimation.dynamic.position_information import (
    PositionInformation,
    kept_fraction,
)
from tether_companion.sim.scenario import load_scenario

R_M2 = 0.1
"""The paper's rangefinder noise (the realistic scenarios' and the config's)."""
X = [2.5, 0.0, -1.0]
"""The realistic circle's position from the anchor [m] (1 m above it)."""


def _inputs(winch: bool) -> GroundStationInputs:
    dynamic = DynamicFilterConfig()
    bearing = BearingWindow(0.5, 1.0, 0.2, 1.0, 0.0, 0.0)
    health = DynamicHealth()
    health.winch_fused = 1 if winch else 0
    return GroundStationInputs(dynamic, bearing, health, SETTINGS, 0.0)


def _state(tension_n: float) -> list[float]:
    x = np.zeros(state.N_STATES)
    x[:3] = X
    x[state.TENSION] = tension_n
    x[state.SCALE] = 1.0
    return x.tolist()


def _angle_at(inputs: GroundStationInputs, time_s: float, tension_n: float) -> None:
    inputs._add_angle_information(
        ModelConstants(1.5, 0.2, 0.0), _state(tension_n), -math.atan2(1.0, 2.5), 0.01, time_s
    )


def _term_dd(inputs: GroundStationInputs) -> float:
    terms = inputs.position_information.at(1.0)
    assert terms is not None
    return terms[5]


def test_the_readings_weights_and_none_is_no_row() -> None:
    inputs = _inputs(winch=True)
    assert inputs._height_row_variance(1.0, 0.5) == math.inf
    inputs.add_height_reading(R_M2, 1.0)
    inputs.add_height_reading(R_M2, 1.0)
    assert math.isclose(inputs._height_row_variance(1.0, 0.5), R_M2 / 2.0)
    assert inputs._height_row_variance(1.0, 0.5) == math.inf  # used once
    inputs.add_height_reading(R_M2, 0.95)
    inputs.add_height_reading(R_M2, 0.5)
    kept = [kept_fraction(0.05, 1.0), kept_fraction(0.5, 1.0)]
    expected = 1.0 / sum(k / (R_M2 + (1.0 - k) * 0.5) for k in kept)
    assert math.isclose(inputs._height_row_variance(1.0, 0.5), expected)
    for bad in (0.0, -1.0, math.nan, math.inf):
        inputs.add_height_reading(bad, 1.0)
    inputs.add_height_reading(R_M2, math.nan)
    assert inputs._height_row_variance(1.0, 0.5) == math.inf


def test_with_a_winch_length_the_rangefinder_narrows_the_down_part(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The realistic circle's geometry at 0.5 and 4 N: the angle's rows with two readings of
    the height since the last angle against the angle's alone; the row handed over is
    (0, 0, -1) with variance R / 2 for two fresh readings."""
    for tension_n in (0.5, 4.0):
        plain, ranged = _inputs(winch=True), _inputs(winch=True)
        for step in range(20):
            t = 0.1 * step
            ranged.add_height_reading(R_M2, t - 0.05)
            ranged.add_height_reading(R_M2, t)
            _angle_at(plain, t, tension_n)
            _angle_at(ranged, t, tension_n)
        assert _term_dd(ranged) < 0.97 * _term_dd(plain)
        assert _term_dd(ranged) > 0.0
    inputs, handed = _inputs(winch=True), []
    monkeypatch.setattr(
        PositionInformation,
        "add",
        lambda self, rows, variances, *_: handed.append((rows, variances)),
    )
    inputs.add_height_reading(R_M2, 0.1)
    inputs.add_height_reading(R_M2, 0.1)
    _angle_at(inputs, 0.1, 0.5)
    ((rows, variances),) = handed
    assert len(rows) == 3 and rows[2] == [0.0, 0.0, -1.0]
    assert math.isclose(variances[2], R_M2 / 2.0)


def test_without_a_winch_length_the_readings_are_forgotten() -> None:
    plain, ranged = _inputs(winch=False), _inputs(winch=False)
    for step in range(20):
        t = 0.1 * step
        ranged.add_height_reading(R_M2, t)
        _angle_at(plain, t, 0.5)
        _angle_at(ranged, t, 0.5)
    assert _term_dd(ranged) == _term_dd(plain)
    assert ranged._height_row_variance(2.0, 0.5) == math.inf


def test_the_estimator_hands_every_fused_reading_over(monkeypatch: pytest.MonkeyPatch) -> None:
    """A short realistic 0.5 N flight with winch + angle: each fused rangefinder reading (the
    filter's ``range_fused`` count) reaches the ground station with the reading's noise."""
    handed: list[float] = []
    estimators: list[DynamicTetherEstimator] = []
    original = GroundStationInputs.add_height_reading
    original_init = DynamicTetherEstimator.__init__

    def record(self: GroundStationInputs, noise_variance_m2: float, time_s: float) -> None:
        handed.append(noise_variance_m2)
        original(self, noise_variance_m2, time_s)

    def keep(self: DynamicTetherEstimator, *args: object, **kwargs: object) -> None:
        original_init(self, *args, **kwargs)  # type: ignore[arg-type]
        estimators.append(self)

    monkeypatch.setattr(GroundStationInputs, "add_height_reading", record)
    monkeypatch.setattr(DynamicTetherEstimator, "__init__", keep)
    scenario = dataclasses.replace(load_scenario("realistic-low-tension"), seed=1, duration_s=6.0)
    fly(scenario, [kinds()["dynamic-winch-angle"]])
    (estimator,) = estimators
    assert estimator.health.range_fused > 20
    assert len(handed) == estimator.health.range_fused
    assert set(handed) == {R_M2}
