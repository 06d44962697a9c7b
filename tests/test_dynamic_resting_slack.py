"""A cable with weight that may be slack on the ground (sag14): what its winch length and its
cable angle can and cannot say.

* A winch on the anchor's level with a cable longer than the drone's span plus height ``a + b``
  is slack whatever the filter's tension: the resting cable's length reaches ``a + b`` only at
  zero tension, so the length equality there is no measurement of the state (aid/winch.py
  ``surely_slack_by_length``).
* A resting cable's angle is modelled at the state's own chord tension, not at the slack
  threshold: there its model can be a free curve leaving the anchor lifted, just past the
  touchdown kink where the elevation rises ~1 rad per metre (aid/cable_angle.py).

Both were measured on the fixed-length sagging circle (tuning seed 1): one length fused on a
slack cable moved the drone 1.4 m, one flat angle linearised on the free side of the kink cut
the position's standard deviation from 0.46 to 0.03 m with the drone 1.6 m off (with the load
cell's negative readings taken)
(docs/estimation-history.md, sag14).

Once a load cell's tension has been fused (sag15), a cable with weight gives its length unless
its tension is surely below the slack threshold, with the length's second-order term in the
tension, and the azimuth holds its second-order term in the position near the anchor."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.aid.cable_angle import (
    UNIFORM_BEARING_VARIANCE_RAD2,
    bearing_curvature_variance,
)
from tether_companion.estimation.dynamic.aid.slack import SLACK
from tether_companion.estimation.dynamic.aid.winch import (
    surely_slack_by_length,
    tension_curvature_variance,
)
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.models import CATENARY, evaluate, rests_on_ground
from tether_companion.estimation.dynamic.offline import run_dynamic
from tether_companion.sim.scenario import load_scenario

LIGHT_N_PER_M = 0.0167 * GRAVITY_MPS2
"""The light sagging cable's weight per length [N/m]."""


def _on_a_light_cable(
    position: tuple[float, float, float], tension_n: float
) -> tuple[DynamicTetherEstimator, float]:
    """An estimator after 3 s of the paper circle, told of the light cable, every member at
    ``position`` [m] with chord tension ``tension_n`` [N] and 0.5 m of horizontal standard
    deviation (uncorrelated), the ground station's latencies 0; and the time [s]."""
    scenario = dataclasses.replace(load_scenario("paper-circle"), duration_s=3.0, seed=2)
    dynamic = dataclasses.replace(
        DynamicFilterConfig(), winch_latency_s=0.0, cable_angle_latency_s=0.0
    )
    run = run_dynamic(scenario, EstimatorConfig(), dynamic)
    est = run.estimator
    assert est.initialised
    est.constants.weight_n_per_m = LIGHT_N_PER_M
    for member in est.bank.filters:
        x, p = member.x.copy(), member.P.copy()
        x[state.POSITION] = position
        x[state.TENSION] = tension_n
        p[state.POSITION, :] = 0.0
        p[:, state.POSITION] = 0.0
        p[state.TENSION, :] = 0.0
        p[:, state.TENSION] = 0.0
        p[0, 0] = p[1, 1] = 0.25
        p[2, 2] = 0.01
        p[state.TENSION, state.TENSION] = 0.1**2
        member.x, member.P = x, p
    return est, float(run.time_s[-1])


def test_a_cable_longer_than_span_plus_height_is_slack_at_any_tension() -> None:
    """Chord tension 0.4 +- 0.1 N (above the 0.2 N slack threshold), drone 2 m out and 3 m up,
    7.5 m paid out: 2.5 m more than a resting cable can take taut. The length is skipped as
    slack (main tested it against the resting model: gated here, 3.8 m off at a 0.1 N spread;
    on the circle, where the tension's spread made that innovation look small, fused); a
    length 0.5 m short of ``a + b`` is fused."""
    position = (2.0, 0.0, -3.0)
    est, t = _on_a_light_cable(position, 0.4)
    status = est.ground_station.winch.status
    est.set_paid_out_length_m(7.5, t + 0.001)
    assert status.skipped_by_reason.get(SLACK) == 1
    assert status.fused == 0
    np.testing.assert_allclose(est.bank.best.x[state.POSITION], position, atol=1e-9)
    est.set_paid_out_length_m(4.5, t + 0.002)
    assert status.fused == 1


@pytest.mark.parametrize(
    ("span_m", "length_m", "weight", "slack"),
    [
        (2.0, 7.5, LIGHT_N_PER_M, True),  # 2.5 m beyond a + b = 5 m
        (2.0, 5.05, LIGHT_N_PER_M, False),  # within 3 sigma of a + b (0.05 m noise)
        (5.0, 7.5, LIGHT_N_PER_M, False),  # a + b = 8 m: may pull
        (2.0, 7.5, 0.0, False),  # a weightless cable: the tension's rule alone
        (0.0, 7.5, LIGHT_N_PER_M, False),  # right above the anchor: no span to judge by
    ],
)
def test_surely_slack_by_length(span_m: float, length_m: float, weight: float, slack: bool) -> None:
    """The drone ``span_m`` out and 3 m up, known to 1 mm, the encoder's offset and scale 0,
    its noise 0.05 m."""
    x = np.zeros(state.N_STATES)
    x[0:3] = (span_m * math.cos(0.4), span_m * math.sin(0.4), -3.0)
    p = np.eye(state.N_STATES) * 1e-6
    assert surely_slack_by_length(x, p, weight, length_m, 0.05**2) is slack


def test_a_resting_cables_flat_reading_is_modelled_at_the_states_own_tension() -> None:
    """Drone 0.9 m out and 3.5 m up at 0.15 +- 0.1 N of chord tension: the cable rests on the
    ground (touchdown 0.1 m out) and leaves the anchor flat, as the reading says; the position
    stays where it was and keeps its variance. Main evaluated the angle at the slack threshold
    (0.2 N), a free curve leaving 0.26 rad up, and the flat reading moved the drone."""
    position = (0.9, 0.0, -3.5)
    est, t = _on_a_light_cable(position, 0.15)
    x = est.bank.best.x.copy()
    assert rests_on_ground(x.tolist(), est.constants.values())
    before = est.bank.best.P.copy()
    est.on_cable_angle(0.0, 0.0, t + 0.001, 0.01)
    assert est.ground_station.cable_angle.status.fused == 1
    np.testing.assert_allclose(est.bank.best.x[state.POSITION], position, atol=0.002)
    assert est.bank.best.P[0, 0] == pytest.approx(before[0, 0], rel=1e-3)


@pytest.mark.parametrize("load_cell", [True, False])
def test_a_heavy_cable_below_the_slack_threshold_gives_its_length_after_a_load_cell(
    load_cell: bool,
) -> None:
    """The sagging hover's cable: 7 m paid out, drone 5 m out and 3 m up, taut at 0.12 N of
    chord tension (below the 0.2 N ``slack_tension_n``) +- 0.1 N. After a load cell's tension
    (``tension_measured``) the length is fused, the one reading of the range (sag15); without
    one it is skipped as before. Surely below the threshold (0.05 +- 0.02 N) it is skipped
    either way."""
    est, t = _on_a_light_cable((5.0, 0.0, -3.0), 0.12)
    est.constants.tension_measured = load_cell
    status = est.ground_station.winch.status
    est.set_paid_out_length_m(7.0, t + 0.001)
    assert status.fused == (1 if load_cell else 0)
    assert status.skipped_by_reason.get(SLACK, 0) == (0 if load_cell else 1)
    est, t = _on_a_light_cable((5.0, 0.0, -3.0), 0.05)
    est.constants.tension_measured = load_cell
    for member in est.bank.filters:
        p = member.P.copy()
        p[state.TENSION, state.TENSION] = 0.02**2
        member.P = p
    est.set_paid_out_length_m(7.0, t + 0.001)
    assert est.ground_station.winch.status.skipped_by_reason.get(SLACK) == 1


def test_the_lengths_curvature_in_the_tension_near_zero_and_at_a_pull() -> None:
    """The light cable 5 m out and 3 m up: at 0.1 +- 0.15 N of chord tension the length's
    second-order term is metres^2 (the encoder's noise is 0.0025 m^2): it is no longer a
    measurement of the tension there; at 1 +- 0.1 N under 5 % of the noise."""
    c = (1.5, 0.2, LIGHT_N_PER_M)

    def length(xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return evaluate(CATENARY.winch_length, xs, (), c, 1)

    def variance(tension_n: float, sd_n: float) -> float:
        x = np.zeros(state.N_STATES)
        x[0:3] = (5.0, 0.0, -3.0)
        x[state.TENSION], x[state.SCALE] = tension_n, 1.0
        p = np.eye(state.N_STATES) * 1e-6
        p[state.TENSION, state.TENSION] = sd_n**2
        return tension_curvature_variance(length, x, p)

    assert variance(0.1, 0.15) > 0.1
    assert variance(1.0, 0.1) < 0.05 * 0.05**2


@pytest.mark.parametrize(("span_m", "sd_m"), [(5.0, 0.1), (2.0, 0.5), (0.5, 0.5)])
def test_the_bearings_curvature_is_the_spread_over_the_span_to_the_fourth(
    span_m: float, sd_m: float
) -> None:
    """A round horizontal spread ``sd`` at the span ``a``: ``(sd / a)^4`` [rad^2], at most a
    uniform bearing's ``pi^2 / 3`` (also right above the anchor)."""
    x = np.zeros(state.N_STATES)
    x[0:2] = (span_m * math.cos(1.1), span_m * math.sin(1.1))
    p = np.eye(state.N_STATES) * sd_m**2
    expected = min((sd_m / span_m) ** 4, UNIFORM_BEARING_VARIANCE_RAD2)
    assert bearing_curvature_variance(x, p) == pytest.approx(expected, rel=1e-9)
    x[0:2] = 0.0
    assert bearing_curvature_variance(x, p) == UNIFORM_BEARING_VARIANCE_RAD2


@pytest.mark.parametrize("load_cell", [True, False])
def test_an_angle_next_to_the_anchor_moves_a_load_cells_filter_by_its_curvature(
    load_cell: bool,
) -> None:
    """A drone put 0.4 m from the anchor with 0.5 m of horizontal spread (a slack cable's
    filter, tuning seed 6 of the sagging circle) reads a bearing 0.2 rad from its own: the
    linearised azimuth (Jacobian 1/a) collapses the spread across the bearing to 0.03 m;
    after a load cell's tension the curvature term (``(0.5/0.4)^4`` = 2.4 rad^2) keeps it at
    0.39 m (sag15). Without a load cell the plain linearisation is kept (its filter regressed
    with the term, sag14)."""
    est, t = _on_a_light_cable((0.4, 0.0, -3.0), 1.0)
    est.constants.tension_measured = load_cell
    before = math.sqrt(est.bank.best.P[1, 1])
    est.on_cable_angle(math.atan2(3.0, 0.4), 0.2, t + 0.001, 0.01)
    after = math.sqrt(est.bank.best.P[1, 1])
    assert est.ground_station.cable_angle.status.fused == 1
    if load_cell:
        assert after > 0.7 * before
    else:
        assert after < 0.1 * before
