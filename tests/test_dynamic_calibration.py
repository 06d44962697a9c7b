"""The ground station's calibration errors in the published covariance
(estimation/dynamic/position_information.py: ``angle_calibration``, ``winch_calibration``):
their geometry, and that the published term carries them from the first fused reading until
a restart."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.config import ConfigError
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.observability import unmodelled_position_rows
from tether_companion.estimation.dynamic.position_information import (
    PositionInformation,
    angle_calibration,
    reduce_added_rows,
    winch_calibration,
)
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.service.config import load_service_config

P = (3.0, 4.0, -2.0)
"""A drone 5 m out horizontally, 2 m above the anchor."""


def _matrix(six) -> np.ndarray:
    nn, ne, nd, ee, ed, dd = six
    return np.array([[nn, ne, nd], [ne, ee, ed], [nd, ed, dd]])


def _variance(six, direction) -> float:
    v = np.asarray(direction, dtype=float)
    v = v / np.linalg.norm(v)
    return float(v @ _matrix(six) @ v)


def test_an_azimuth_zero_error_turns_the_drone_across_the_cable() -> None:
    term = angle_calibration(P, 0.026, 0.0, with_length=True)
    assert _variance(term, (-4.0, 3.0, 0.0)) == pytest.approx((5.0 * 0.026) ** 2)
    assert _variance(term, P) == pytest.approx(0.0, abs=1e-15)
    assert _variance(term, (0.0, 0.0, 1.0)) == pytest.approx(0.0, abs=1e-15)


def test_an_elevation_zero_error_moves_the_drone_in_the_cables_vertical_plane() -> None:
    distance = math.sqrt(29.0)
    with_length = angle_calibration(P, 0.0, 0.007, with_length=True)
    # perpendicular to the cable in its vertical plane: (n d, e d, -rho^2) / (rho |p|)
    across = (3.0 * -2.0, 4.0 * -2.0, -25.0)
    assert _variance(with_length, across) == pytest.approx((distance * 0.007) ** 2)
    assert _variance(with_length, P) == pytest.approx(0.0, abs=1e-15)
    # without a length the range is h / tan(el): |p|^2 / h per radian along the range
    without = angle_calibration(P, 0.0, 0.007, with_length=False)
    assert _variance(without, (3.0, 4.0, 0.0)) == pytest.approx((29.0 / 2.0 * 0.007) ** 2)
    assert _variance(without, (0.0, 0.0, 1.0)) == pytest.approx(0.0, abs=1e-15)


def test_the_winchs_zero_and_scale_errors_move_the_drone_along_its_horizontal_range() -> None:
    """Without an angle the rangefinder holds the height: a length off by ``dL`` moves the
    drone horizontally by ``dL |p| / rho``, ``dL`` along the cable."""
    term = winch_calibration(P, 5.5, 0.1, 0.01, with_angle=False)
    length_var = 0.1**2 + (0.01 * 5.5) ** 2
    assert _variance(term, (3.0, 4.0, 0.0)) == pytest.approx(length_var * 29.0 / 25.0)
    assert _variance(term, P) == pytest.approx(length_var)
    assert _variance(term, (-4.0, 3.0, 0.0)) == pytest.approx(0.0, abs=1e-15)
    assert _variance(term, (0.0, 0.0, 1.0)) == pytest.approx(0.0, abs=1e-15)
    steep = winch_calibration((0.1, 0.0, -5.0), 5.0, 0.1, 0.0, with_angle=False)
    assert _variance(steep, (1.0, 0.0, 0.0)) == pytest.approx(0.1**2 * 9.0)  # at most 3x
    assert winch_calibration((0.0, 0.0, -3.0), 5.5, 0.1, 0.01, False) == (0.0,) * 6
    assert angle_calibration((0.0, 0.0, -3.0), 0.026, 0.007, True) == (0.0,) * 6


def test_with_an_angle_the_winchs_errors_lie_along_the_cable() -> None:
    """The angle holds the direction: a length off by ``dL`` moves the drone along it."""
    term = winch_calibration(P, 5.5, 0.1, 0.01, with_angle=True)
    assert _variance(term, P) == pytest.approx(0.1**2 + (0.01 * 5.5) ** 2)
    assert _variance(term, (-4.0, 3.0, 0.0)) == pytest.approx(0.0, abs=1e-15)
    assert _variance(term, (3.0 * -2.0, 4.0 * -2.0, -25.0)) == pytest.approx(0.0, abs=1e-15)


def test_the_published_term_carries_them_from_the_first_reading_until_a_restart() -> None:
    rows = unmodelled_position_rows(*P, 4.0, 0.2, 0.02)
    info = PositionInformation(1.0)
    assert info.at(1.0) is None
    winch = winch_calibration(P, 5.5, 0.1, 0.01, with_angle=False)
    info.set_winch_calibration(winch)
    # no angle yet: the unmodelled term as it is, and the winch's calibration
    added = np.array(reduce_added_rows(rows, info.at(1.0)))
    assert added == pytest.approx(np.array(rows) + _matrix(winch))
    angle = angle_calibration(P, 0.026, 0.007, True)
    info.set_angle_calibration(angle)
    added = np.array(reduce_added_rows(rows, info.at(2.0)))
    assert added == pytest.approx(np.array(rows) + _matrix(winch) + _matrix(angle))
    info.set_angle_calibration((math.nan,) * 6)  # ignored
    assert np.array(reduce_added_rows(rows, info.at(2.0))) == pytest.approx(added)
    info.clear()
    assert info.at(3.0) is None


@pytest.mark.parametrize(
    "calibration", [(math.nan, 0.026), (0.007, math.inf), (-0.007, 0.026), (0.007, -1.0)]
)
def test_a_reading_with_absurd_calibration_errors_is_counted_and_dropped(calibration) -> None:
    estimator = DynamicTetherEstimator(EstimatorConfig(), load_vehicle("default-quad"))
    estimator.on_cable_angle(0.5, 0.3, 1.0, 0.01, calibration)
    assert estimator.health.nonfinite_rejected == 1
    estimator.on_cable_angle(0.5, 0.3, 1.0, 0.01, (0.007, 0.026))
    assert estimator.health.nonfinite_rejected == 1


@pytest.mark.parametrize(
    ("section", "key", "value"),
    [
        ("cable_angle", "azimuth_calibration_std_rad", math.nan),
        ("cable_angle", "elevation_calibration_std_rad", -0.01),
        ("cable_angle", "azimuth_calibration_std_rad", 2.0),
        ("dynamic_filter", "winch_length_offset_std_m", math.inf),
        ("dynamic_filter", "winch_length_scale_std", -0.01),
        ("dynamic_filter", "winch_length_noise_std_m", 0.0),
    ],
)
def test_absurd_calibration_settings_are_rejected(section, key, value) -> None:
    with pytest.raises(ConfigError, match=key):
        load_service_config(None, {section: {key: value}})
