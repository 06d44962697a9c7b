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


def _upper(j: np.ndarray) -> tuple[float, ...]:
    """``J`` as the terms of :meth:`PositionInformation.at` with no innovation excess."""
    return tuple(float(v) for v in j[np.triu_indices(3)]) + (0.0,) * 6


def test_without_information_the_added_term_is_left_exactly_as_it_is() -> None:
    rows = unmodelled_position_rows(3.0, 2.0, -2.5, 4.0, 0.2, 0.05)
    assert reduce_added_rows(rows, None) is rows
    assert reduce_added_rows(rows, (0.0,) * 12) == rows  # J = 0: (I + C 0)^-1 C = C
    assert PositionInformation(1.0).at(5.0) is None


def test_the_update_is_the_information_sum() -> None:
    rng = np.random.default_rng(3)
    for _ in range(50):
        a = rng.normal(size=(3, 3))
        c = a @ a.T + 0.01 * np.eye(3)
        h = rng.normal(size=(2, 3))
        j = h.T @ np.diag(1.0 / rng.uniform(0.01, 1.0, size=2)) @ h
        reduced = np.array(reduce_added_rows(c.tolist(), _upper(j)))
        np.testing.assert_allclose(reduced, np.linalg.inv(np.linalg.inv(c) + j), rtol=1e-9)
        assert np.linalg.eigvalsh(c - reduced).min() > -1e-12  # never wider than before


def test_an_angle_narrows_the_turn_of_the_cable_to_the_angle_s_accuracy() -> None:
    """The unmodelled force's turn of the cable (rank 2, across the cable) after ten readings
    of a 0.02 rad direction: about 0.02 |p| / sqrt(10) across, nothing along the cable."""
    p = np.array([4.0, 2.0, -2.5])
    distance = float(np.linalg.norm(p))
    rows = unmodelled_position_rows(*p, 4.0, 0.2, 0.05)
    h = _direction_rows(p)
    elevation = math.asin(-p[2] / distance)
    r_inv = np.diag([1.0 / 0.02**2, math.cos(elevation) ** 2 / 0.02**2])
    reduced = np.array(reduce_added_rows(rows, _upper(10.0 * h.T @ r_inv @ h)))
    u = p / distance
    across = np.cross(u, [0.0, 0.0, 1.0])
    across /= np.linalg.norm(across)
    before = math.sqrt(across @ np.array(rows) @ across)
    after = math.sqrt(across @ reduced @ across)
    assert before == pytest.approx(distance * 0.2 / 4.0)
    assert after < 0.02 * distance / math.sqrt(10.0) * 1.001
    assert after > 0.9 * 0.02 * distance / math.sqrt(10.0)
    # along the cable the winch's 0.05 m stays: a direction does not measure the range
    assert u @ reduced @ u == pytest.approx(0.05**2, rel=1e-9)


def test_the_information_is_forgotten_over_the_correlation_time() -> None:
    info = PositionInformation(2.0)
    info.add([(0.0, 1.0, 0.0)], [0.25], 10.0)
    assert info.at(10.0) == pytest.approx((0.0, 0.0, 0.0, 4.0, 0.0, 0.0) + (0.0,) * 6)
    assert info.at(12.0)[3] == pytest.approx(4.0 * math.exp(-1.0))
    info.add([(0.0, 1.0, 0.0)], [0.25], 12.0)  # the older reading decayed, the new one whole
    assert info.at(12.0)[3] == pytest.approx(4.0 * (1.0 + math.exp(-1.0)))
    info.add([(math.nan, 1.0, 0.0)], [0.25], 13.0)  # ignored
    info.add([(1.0, 1.0, 0.0)], [0.0], 13.0)  # ignored
    assert info.at(12.0)[3] == pytest.approx(4.0 * (1.0 + math.exp(-1.0)))
    info.clear()
    assert info.at(12.0) is None
    with pytest.raises(ValueError):
        PositionInformation(0.0)


def test_with_winch_and_angle_the_published_covariance_is_no_longer_far_too_wide() -> None:
    """The realistic 4 N circle flown with the winch length and the cable angle (the bench's
    ``dynamic-winch-angle`` kind, seed 1, 5-14 s): the NEES of the published position
    covariance averaged over the ticks lies in the one-run 95 % band of 3 dof (0.216-9.35).
    Until the angle narrowed the unmodelled term it was 0.04 (the turn of the cable by
    0.2 N at 4 N over 3.6 m, 0.18 m across, against errors of 0.02 m)."""
    from tether_companion.bench.estimators.flight import fly
    from tether_companion.bench.estimators.registry import kinds
    from tether_companion.bench.estimators.scores import nees, nees_band
    from tether_companion.sim.scenario import load_scenario

    scenario = dataclasses.replace(load_scenario("realistic-circle"), seed=1, duration_s=14.0)
    record = fly(scenario, [kinds()["dynamic-winch-angle"]])
    trace = record.traces["dynamic-winch-angle"]
    after = record.time_s >= 5.0
    values = nees(trace.position_ned_m - record.position_ned_m, trace.position_covariance_m2)
    mean = float(np.mean(values[after]))
    low, high = nees_band(1)
    assert trace.published[after].mean() > 0.9
    assert low < mean < high, mean
