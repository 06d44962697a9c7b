"""The gusts' walk (estimation/dynamic/consistency.py, GustWalk): the wind's random walk read
from the force balance's horizontal innovations, which the bearing window then takes."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.estimation.dynamic.consistency import BearingWindow, GustWalk
from tether_companion.sim.scenario import load_scenario

MU = 0.2  # rotor drag per unit mass of the realistic quad [1/s]
STEP_S = 0.02  # one fused force balance per 4 IMU ticks at 200 Hz [s]


def _measure(walk_m2ps3: float, noise_mps2: float, speed_mps: float, seed: int) -> float:
    """The walk read from 60 s of innovations: the drag of a wind walking by ``walk_m2ps3``
    plus white noise of ``noise_mps2`` per axis."""
    rng = np.random.default_rng(seed)
    gusts = GustWalk(MU)
    wind = np.zeros(2)
    for k in range(int(60.0 / STEP_S)):
        wind += rng.normal(0.0, math.sqrt(walk_m2ps3 * STEP_S), 2)
        north, east = MU * wind + rng.normal(0.0, noise_mps2, 2)
        gusts.add(k * STEP_S, (float(north), float(east)), speed_mps)
    return gusts.walk_m2ps3


def test_the_walk_of_a_gusty_wind_is_read_from_the_innovations() -> None:
    """A wind walking by 0.5 m^2/s^3 (the gusty hover's) under the realistic innovations'
    0.3 m/s^2 of noise reads within 40 % of it; white innovations alone read well below the
    bearing window's configured 0.3."""
    for seed in (1, 2, 3):
        assert 0.3 < _measure(0.5, 0.3, 0.0, seed) < 0.7
        assert _measure(0.0, 0.3, 0.0, seed) < 0.05


def test_a_body_innovation_is_turned_to_north_east() -> None:
    """Facing east (yaw 90 degrees, ``R_v^b`` rows (0, 1, 0), (-1, 0, 0), (0, 0, 1)), the
    body's forward innovation is the east one: the same walk read either way."""
    rows = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    rng = np.random.default_rng(4)
    body, ned = GustWalk(MU), GustWalk(MU)
    wind = np.zeros(2)
    for k in range(int(30.0 / STEP_S)):
        wind += rng.normal(0.0, math.sqrt(0.5 * STEP_S), 2)
        north, east = MU * wind + rng.normal(0.0, 0.3, 2)
        ned.add(k * STEP_S, (float(north), float(east)), 0.0)
        body.add_body(k * STEP_S, [float(east), float(-north), 0.5], rows, 0.0)
    assert body.walk_m2ps3 == pytest.approx(ned.walk_m2ps3, rel=1e-12)
    assert ned.walk_m2ps3 > 0.0


def test_nothing_is_read_while_the_drone_moves() -> None:
    """In flight the residuals change with the drone's own air speed: not counted."""
    assert _measure(0.5, 0.3, 1.0, 1) == 0.0


def test_the_window_takes_the_larger_walk() -> None:
    """A hover 4 m out at 4 N: the window's across-cable term grows with a measured walk
    above the configured one, and a smaller one leaves it as configured."""
    stds = {}
    for measured in (0.0, 0.1, 1.0):
        window = BearingWindow(0.3, 2.0, 0.2, 1.0, 0.1, 0.3)
        window.set_wind_walk(measured)
        t = 0.0
        while t <= 30.0:
            window.add(t, [4.0, 0.0, -2.5], 4.0, (0.04, 0.0, 0.04))
            t += 0.02
        stds[measured] = window.force_std_n
    assert stds[0.1] == stds[0.0]
    assert stds[1.0] > 1.1 * stds[0.0]


def _flown_walk(scenario_name: str, seed: int) -> float:
    """The gusts' walk the winch kind's filter reads after 20 s of ``scenario_name``."""
    pytest.importorskip("distributed", reason="bench estimators needs dask.distributed")
    from tether_companion.bench.estimators.flight import fly
    from tether_companion.bench.estimators.registry import kinds

    kind = kinds()["dynamic-winch"]
    built = []

    def build(context):  # type: ignore[no-untyped-def]
        estimator = kind.build(context)
        built.append(estimator)
        return estimator

    scenario = dataclasses.replace(load_scenario(scenario_name), duration_s=20.0, seed=seed)
    fly(scenario, [dataclasses.replace(kind, build=build)])
    return built[0]._estimator.gusts.walk_m2ps3


@pytest.mark.slow
def test_the_gusty_hover_reads_its_gusts_and_the_circle_does_not() -> None:
    """Tuning seed 1: the gusty hover (true wind walk 0.42) reads above the window's
    configured 0.3, which it then takes; the 4 N circle (true 0.04) moves and reads
    nothing."""
    assert 0.3 < _flown_walk("realistic-gusty-hover", 1) < 1.5
    assert _flown_walk("realistic-circle", 1) < 0.3
