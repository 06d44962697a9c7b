"""The unmodelled term of the published covariance narrowed by what the cable angle measures
(estimation/dynamic/position_information.py): the Kalman update of the added covariance, its
exact identity without an angle, the forgetting, and the estimator's hook."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.estimation.dynamic.observability import unmodelled_position_rows
from tether_companion.estimation.dynamic.position_information import (
    PositionInformation,
    reduce_added_rows,
)


def _direction_rows(p: np.ndarray) -> np.ndarray:
    """The Jacobian of (elevation, azimuth) of a straight cable from the anchor to ``p``
    (NED [m]) with respect to ``p`` [rad/m]."""
    n, e, d = p
    rho = math.hypot(n, e)
    r2 = rho * rho + d * d
    elevation = np.array([n * d / (rho * r2), e * d / (rho * r2), -rho / r2])
    azimuth = np.array([-e / (rho * rho), n / (rho * rho), 0.0])
    return np.vstack([elevation, azimuth])


def _rows_of(r2: np.ndarray) -> list[np.ndarray]:
    return [r2[0], r2[1]]


def test_without_a_reading_the_added_term_is_left_exactly_as_it_is() -> None:
    rows = unmodelled_position_rows(3.0, 2.0, -2.5, 4.0, 0.2, 0.05)
    assert reduce_added_rows(rows, None) is rows
    info = PositionInformation(1.0)
    assert info.at(5.0) is None
    info.add_angle_innovation((0.01, 0.02), (1e-4, 1e-4), (3.0, 2.0, -2.5), 5.0)  # no reading
    assert info.at(5.0) is None


def test_a_reading_is_the_kalman_update_of_the_added_covariance() -> None:
    rng = np.random.default_rng(3)
    for _ in range(50):
        a = rng.normal(size=(3, 3))
        c = a @ a.T + 0.01 * np.eye(3)
        h = rng.normal(size=(2, 3))
        r = rng.uniform(0.01, 1.0, size=2)
        info = PositionInformation(1.0)
        info.add(_rows_of(h), r.tolist(), 2.0, c.tolist())
        reduced = np.array(reduce_added_rows(c.tolist(), info.at(2.0)))
        expected = np.linalg.inv(np.linalg.inv(c) + h.T @ np.diag(1.0 / r) @ h)
        np.testing.assert_allclose(reduced, expected, rtol=1e-9, atol=1e-12)
        assert np.linalg.eigvalsh(c - reduced).min() > -1e-12  # never wider than before


def test_a_steady_angle_narrows_the_turn_of_the_cable_and_the_term_comes_back_after() -> None:
    """The unmodelled force's turn of the cable (across it) under a 10 Hz angle of 0.02 rad
    with tau = 1 s: a smooth offset measured ten times per correlation time, well below the
    term and below one reading's accuracy; along the cable the winch's 0.05 m stays (a
    direction does not measure the range); without readings it is back to ``C``."""
    p = np.array([4.0, 2.0, -2.5])
    distance = float(np.linalg.norm(p))
    rows = unmodelled_position_rows(*p, 4.0, 0.2, 0.05)
    h = _direction_rows(p)
    elevation = math.asin(-p[2] / distance)
    variances = [0.02**2, (0.02 / math.cos(elevation)) ** 2]
    info = PositionInformation(1.0)
    for k in range(100):
        info.add(_rows_of(h), variances, 0.1 * k, rows)
    reduced = np.array(reduce_added_rows(rows, info.at(9.9)))
    u = p / distance
    across = np.cross(u, [0.0, 0.0, 1.0])
    across /= np.linalg.norm(across)
    before = math.sqrt(across @ np.array(rows) @ across)
    after = math.sqrt(across @ reduced @ across)
    assert before == pytest.approx(distance * 0.2 / 4.0)
    assert 0.02 * distance / math.sqrt(10.0) < after < 0.02 * distance  # one reading
    assert u @ reduced @ u == pytest.approx(0.05**2, rel=1e-9)
    later = np.array(reduce_added_rows(rows, info.at(9.9 + 8.0)))  # 8 tau without a reading
    np.testing.assert_allclose(later, np.array(rows), rtol=1e-4, atol=1e-9)
    info.clear()
    assert info.at(10.0) is None


def test_the_offset_is_smooth_between_readings() -> None:
    """The offset is a displacement of the estimated position, which moves only through the
    velocity: its knowledge fades as ``1 - rho^2``, ``rho = (1 + dt / tau) exp(-dt / tau)``
    (second-order Gauss-Markov), so 0.1 s after an exact reading the term is 0.9 % of ``C``
    (the first-order ``1 - exp(-2 dt / tau)`` gave 18 %: a 0.8 m/s velocity error on the
    4 N circle), 46 % after one ``tau``, 96 % after three."""
    p = np.array([4.0, 2.0, -2.5])
    rows = unmodelled_position_rows(*p, 4.0, 0.2, 0.05)
    c = np.array(rows)
    info = PositionInformation(1.0)
    exact = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]  # every axis, 1e-12 m noise
    info.add(exact, [1e-24] * 3, 2.0, rows)
    assert np.abs(np.array(reduce_added_rows(rows, info.at(2.0)))).max() < 1e-20
    for dt, share in ((0.1, 0.0093), (1.0, 0.4587), (3.0, 0.9603)):
        rho = (1.0 + dt) * math.exp(-dt)
        term = np.array(reduce_added_rows(rows, info.at(2.0 + dt)))
        np.testing.assert_allclose(term, (1.0 - rho * rho) * c, rtol=1e-9, atol=1e-15)
        assert 1.0 - rho * rho == pytest.approx(share, abs=1e-4)


def test_innovations_beyond_the_predicted_widen_the_term_across_the_cable() -> None:
    """A filter whose bearing is off (azimuth innovations of 0.2 rad, 4 m out, predicted
    0.02 rad) publishes about that offset across the cable."""
    p = (4.0, 0.0, -2.5)
    rows = unmodelled_position_rows(*p, 4.0, 0.2, 0.05)
    info = PositionInformation(1.0)
    info.add(_rows_of(_direction_rows(np.array(p))), [1e-4, 1e-4], 0.0, rows)
    for k in range(40):
        info.add_angle_innovation((0.0, 0.2), (4e-4, 4e-4), p, 0.1 * k)
    widened = np.array(reduce_added_rows(rows, info.at(7.9)))  # the reading's knowledge gone
    east = math.sqrt(widened[1, 1])
    assert 0.5 < east < 1.0  # the excess (2 s average, 4 s in) of the 0.8 m across, and C
    assert widened[2, 2] == pytest.approx(rows[2][2], rel=1e-3)  # the elevation agrees
    with pytest.raises(ValueError):
        PositionInformation(0.0)


def test_with_the_ground_stations_errors_the_published_covariance_covers_them() -> None:
    """The realistic 4 N circle flown with the winch length and the cable angle (the bench's
    ``dynamic-winch-angle`` kind, seed 1, 5-14 s) with the ground station's real errors
    (sim/ground_sensors.py: seed 1 draws the encoder 0.15 m short and 1.7 % small, the
    angle's level 0.4 degrees off): the filter learns them as states (``state.py``) and its
    covariance carries what it has not learnt: NEES mean 1.74 (1.54 with the first-order
    offset of before nees15), in the one-run band, no published tick beyond 3 sigma. Before
    the calibration states the filter followed them and the published covariance added them
    as fixed terms (NEES 3.47); without either, 53.3 and 928 ticks beyond."""
    from tether_companion.bench.estimators.flight import fly
    from tether_companion.bench.estimators.registry import kinds
    from tether_companion.bench.estimators.scores import nees, nees_band
    from tether_companion.sim.scenario import load_scenario

    scenario = dataclasses.replace(load_scenario("realistic-circle"), seed=1, duration_s=14.0)
    record = fly(scenario, [kinds()["dynamic-winch-angle"]])
    trace = record.traces["dynamic-winch-angle"]
    after = record.time_s >= 5.0
    error = trace.position_ned_m - record.position_ned_m
    values = nees(error, trace.position_covariance_m2)
    mean = float(np.mean(values[after]))
    published = after & trace.published
    sd = np.sqrt(np.diagonal(trace.position_covariance_m2, axis1=1, axis2=2))
    assert trace.published[after].mean() > 0.9
    low, high = nees_band(1)
    assert low < mean < high, mean
    assert not np.any(np.abs(error[published]) > 3.0 * sd[published])


@pytest.mark.parametrize(
    ("rows", "variances", "time_s", "added"),
    [
        ([[math.nan, 0.0, 0.0]], [1e-4], 1.0, None),  # a non-finite Jacobian
        ([[0.1, 0.2, 0.0]], [0.0], 1.0, None),  # no noise: not a measurement
        ([[0.1, 0.2, 0.0]], [math.inf], 1.0, None),
        ([[0.1, 0.2, 0.0]], [1e-4], math.nan, None),  # no time
        ([[0.1, 0.2, 0.0]], [1e-4], 1.0, math.nan),  # a non-finite term
    ],
)
def test_a_bad_reading_is_ignored_and_leaves_the_term_as_it_was(rows, variances, time_s, added):
    """What reaches the term from the filter is already checked at the service's boundary;
    a non-finite or noiseless value that gets here anyway changes nothing (no NaN can reach
    the published covariance through it)."""
    term = unmodelled_position_rows(3.0, 2.0, -2.5, 4.0, 0.2, 0.05)
    if added is not None:
        term = [[added, *row[1:]] for row in term]
    info = PositionInformation(1.0)
    info.add(rows, variances, time_s, term)
    assert info.at(1.0) is None
