"""The winch's load cell as what it measures, the tension where the cable leaves the winch, and
the chord tension's walk while it is fused (sag13).

A constant-tension winch holds the anchor's tension; the chord tension the filter carries as
its state moves with the geometry at that held tension, slowly (the winch flights' true chord
tension changes by at most 0.07 N^2 per second of flight, tuning seeds 1-2). The filter walked
it at 2 N^2/s, 0.45 N between two of the winch's 10 Hz readings, so its tension's standard
deviation stayed near 0.3 N against a 0.1 N error and the sag rule withheld the 1 N flights.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from filter_states import resting_window, state_at

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.models import CATENARY, STRAIGHT
from tether_companion.estimation.dynamic.offline import run_dynamic
from tether_companion.physics.cable_winch import winch_catenary
from tether_companion.samples import AttitudeSample, ImuSample
from tether_companion.sim.scenario import load_scenario


@pytest.mark.parametrize(
    ("span_m", "height_m", "anchor_n", "density_kg_per_m"),
    [
        (5.0, 3.0, 1.0, 0.0167),  # the light 1 N hover: free, 8 degrees up at the anchor
        (7.0, 3.0, 1.0, 0.0167),  # beyond its touchdown span (5.8 m): resting on the ground
        (4.0, 3.0, 1.0, 0.1),  # the heavy 1 N circle: resting
        (3.0, 4.0, 5.0, 0.1),  # the heavy 5 N: free
    ],
)
def test_the_anchor_tension_is_the_winchs_on_its_cable(
    span_m: float, height_m: float, anchor_n: float, density_kg_per_m: float
) -> None:
    """The generated anchor tension at the state of a winch's cable (the simulator's
    :func:`winch_catenary`: chord tension ``pull |p| / a``) is the tension the winch holds,
    free or resting on the ground, and ``|F_c| - w b`` with the tension at the drone."""
    weight = density_kg_per_m * GRAVITY_MPS2
    cable = winch_catenary(span_m, height_m, anchor_n, weight)
    bearing = 0.7
    position = (span_m * math.cos(bearing), span_m * math.sin(bearing), -height_m)
    chord = math.dist(position, (0.0, 0.0, 0.0))
    x = state_at(position, cable.pull_n * chord / span_m)
    c = (1.5, 0.2, weight)
    (at_anchor,), jac = CATENARY.anchor_tension(x, (), c)
    assert at_anchor == pytest.approx(anchor_n, rel=1e-8)
    (at_drone,), _ = CATENARY.tension(x, (), c)
    assert at_drone == pytest.approx(cable.drone_tension_n, rel=1e-8)
    assert len(jac) == state.N_STATES


def test_a_weightless_cable_pulls_the_winchs_tension() -> None:
    """On the straight line the winch's tension is the chord tension, derivative 1."""
    (value,), jac = STRAIGHT.anchor_tension(state_at((3.0, -1.0, -2.0), 4.0), (), (1.5, 0.2, 0.0))
    assert value == pytest.approx(4.0)
    assert jac[state.TENSION] == pytest.approx(1.0)
    assert sum(abs(v) for v in jac) == pytest.approx(1.0)


def _filter_on_the_light_cable() -> tuple[object, float]:
    """A dynamic filter after 3 s of the paper circle, told of the light cable."""
    scenario = dataclasses.replace(load_scenario("paper-circle"), duration_s=3.0, seed=1)
    run = run_dynamic(scenario, EstimatorConfig(), DynamicFilterConfig(load_cell_noise_std_n=0.2))
    est = run.estimator
    est.constants.weight_n_per_m = 0.0167 * GRAVITY_MPS2
    return est, float(run.time_s[-1])


def _tick(est, t: float) -> None:
    est.on_attitude(AttitudeSample(t, 0.0, 0.0, 0.0))
    est.on_imu(ImuSample(t, np.array([0.0, 0.0, -9.8]), np.zeros(3)))


def test_the_winchs_tension_is_fused_at_the_anchor_and_slows_the_tension_walk() -> None:
    """Fused winch readings count, move the chord tension toward the anchor tension's, and
    switch the chord tension's walk to ``noise.winch_tension_n2ps`` in every member; a winch
    silent for longer than ``staleness.tension_s`` gives the default walk back."""
    est, t = _filter_on_the_light_cable()
    noise = est.dynamic.noise
    assert noise.winch_tension_n2ps < noise.tension_n2ps
    for member in est.bank.filters:
        assert member.q_density[state.TENSION, state.TENSION] == noise.tension_n2ps
    x = est.bank.best.x_values()
    (at_anchor_before,), _ = CATENARY.anchor_tension(x, (), est.constants.values())
    reading = at_anchor_before + 1.0
    for k in range(5):
        est.set_winch_tension_n(reading, t + 0.001 * k)
    assert est.ground_station.winch_tension.status.fused >= 4
    assert est.health.load_cell_fused >= 4
    assert est.constants.tension_measured
    (at_anchor_after,), _ = CATENARY.anchor_tension(
        est.bank.best.x_values(), (), est.constants.values()
    )
    assert at_anchor_after > at_anchor_before + 0.3
    for member in est.bank.filters:
        assert member.q_density[state.TENSION, state.TENSION] == noise.winch_tension_n2ps
    # the walk the IMU batch steps with (inertial formulation) is the winch's too
    before = est.bank.best.P[state.TENSION, state.TENSION]
    _tick(est, t + 0.01)
    _tick(est, t + 0.02)
    grown = est.bank.best.P[state.TENSION, state.TENSION] - before
    assert grown < 2.0 * noise.winch_tension_n2ps * 0.02  # 2 N^2/s would add 0.02 N^2
    silent_until = t + 0.005 + est.config.staleness.tension_s + 0.05
    for k in range(int((silent_until - t) / 0.005)):
        _tick(est, t + 0.025 + 0.005 * k)
    for member in est.bank.filters:
        assert member.q_density[state.TENSION, state.TENSION] == noise.tension_n2ps


def test_a_bad_winch_tension_is_counted_and_dropped() -> None:
    est, t = _filter_on_the_light_cable()
    before = est.health.nonfinite_rejected
    for bad in (math.nan, -10.0 * est.dynamic.load_cell_noise_std_n, math.inf):
        est.set_winch_tension_n(bad, t)
    assert est.health.nonfinite_rejected == before + 3
    assert est.ground_station.winch_tension.status.fused == 0


def test_a_reading_just_below_zero_is_the_load_cells_noise_and_is_fused() -> None:
    """Near zero a load cell's noise scatters its readings below zero: dropping them fused
    only the upper half (a slack cable's 0.07 N anchor tension read with 0.2 N of noise
    averaged 0.19 N over the readings kept). One noise standard deviation below zero is a
    measurement (the aid's innovation test decides: this filter pulls 4 N, so it is gated);
    ten is a fault, counted and dropped."""
    est, t = _filter_on_the_light_cable()
    sigma = est.dynamic.load_cell_noise_std_n
    status = est.ground_station.winch_tension.status
    rejected = est.health.nonfinite_rejected
    est.set_winch_tension_n(-sigma, t)
    assert status.fused + status.gated == 1
    assert status.last_innovation[0] == pytest.approx(-sigma - 4.0, abs=0.5)
    assert est.health.nonfinite_rejected == rejected
    est.set_winch_tension_n(-10.0 * sigma, t + 0.001)
    assert status.fused + status.gated == 1
    assert est.health.nonfinite_rejected == rejected + 1


def test_the_winchs_tension_places_a_resting_cable_whose_pull_points_away() -> None:
    """The heavy 1 N circle's start (main: 8 s without a position): the cable rests on the
    ground (it leaves the anchor flat, so its elevation places nothing) and a wind blowing
    away from the anchor outweighs its pull, so the window's force points away from the anchor
    and its pull along the azimuth's bearing places nothing either. The winch's tension is the
    horizontal tension of a resting cable: with it, the azimuth, the winch length and the
    height the drone starts within 5 cm, the covariance covering it."""
    from tether_companion.estimation.dynamic.initialise import PLACEMENT_FAILED

    weight = 0.1 * GRAVITY_MPS2
    mass, drag_per_s, anchor_n, height, span = 1.5, 0.2, 1.0, 3.0, 4.5
    azimuth = 0.4
    outward = np.array((math.cos(azimuth), math.sin(azimuth), 0.0))
    config = dataclasses.replace(
        DynamicFilterConfig(), cable_weight_n_per_m=weight, load_cell_noise_std_n=0.2
    )
    truth = np.array((span * math.cos(azimuth), span * math.sin(azimuth), -height))
    wind = 4.0 * outward  # 1.2 N of drag outward against 1 N of pull
    for with_tension in (False, True):
        initialiser, length = resting_window(
            config,
            mass,
            drag_per_s,
            anchor_n,
            height,
            span,
            azimuth,
            wind,
            angles=True,
            winch_tension=with_tension,
        )
        start = initialiser.solve(1.2, length)
        if not with_tension:
            assert start.x is None and start.reason == PLACEMENT_FAILED
            continue
        assert start.x is not None and start.p is not None, start.reason
        assert np.allclose(start.x[state.POSITION], truth, atol=0.05)
        sd = np.sqrt(np.diag(start.p)[:3])
        assert np.all(np.abs(start.x[state.POSITION] - truth) < 3.0 * sd)
        chord = np.linalg.norm(truth)
        assert start.x[state.TENSION] == pytest.approx(anchor_n * chord / span, rel=0.02)
