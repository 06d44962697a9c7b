"""Estimator config: paper defaults, unit interpretations, and refusal of bad input."""

from __future__ import annotations

import numpy as np
import pytest

from tether_companion.config import ConfigError, from_mapping
from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.config import EstimatorConfig, load_estimator_config


def test_shipped_file_is_the_paper_defaults() -> None:
    config = load_estimator_config()
    assert config == EstimatorConfig()
    # paper: Q = 5e-3 I per 200 Hz step -> 1 m^2/s; P0 = I; x0 = (1.5, 2.5, 1.5) up -> p_d < 0
    np.testing.assert_allclose(config.q_density(), np.eye(4))
    np.testing.assert_allclose(config.p0(), np.eye(4))
    np.testing.assert_allclose(config.x0()[:3], [1.5, 2.5, -1.5])
    assert config.accel_noise.variance_mps2_sq == pytest.approx(0.01)


def test_unit_interpretations() -> None:
    in_g = from_mapping(EstimatorConfig, {"accel_noise": {"variance": 0.01, "unit": "g_squared"}})
    assert in_g.accel_noise.variance_mps2_sq == pytest.approx(0.01 * GRAVITY_MPS2**2)
    density = from_mapping(
        EstimatorConfig,
        {
            "kind": "three_state",
            "process_noise": {"form": "spectral_density", "position_m2": [1, 2, 3]},
        },
    )
    np.testing.assert_allclose(density.q_density(), np.diag([1.0, 2.0, 3.0]))
    assert density.x0().shape == (3,) and density.p0().shape == (3, 3)


@pytest.mark.parametrize(
    ("data", "key", "fragment"),
    [
        ({"kindd": "four_state"}, "kindd", "unknown key"),
        ({"kind": "five_state"}, "kind", "one of"),
        ({"altimeter_noise_variance_m2": -0.1}, "altimeter_noise_variance_m2", "> 0"),
        ({"accel_noise": {"variance": 0}}, "accel_noise.variance", "> 0"),
        ({"accel_noise": {"unit": "m/s^2"}}, "accel_noise.unit", "one of"),
        ({"process_noise": {"position_m2": [1, -1, 1]}}, "process_noise.position_m2[1]", ">= 0"),
        ({"process_noise": {"step_s": 0}}, "process_noise.step_s", "> 0"),
        ({"initial_position_ned_m": [1, 2]}, "initial_position_ned_m", "3 items"),
        ({"initial_tension_variance_n2": "big"}, "initial_tension_variance_n2", "number"),
        ({"gate": {"probability": 1.5}}, "gate.probability", "<= 1"),
        ({"staleness": {"pwm_s": 0}}, "staleness.pwm_s", "> 0"),
        (
            {"rangefinder": {"min_m": 5, "max_m": 2}},
            "rangefinder.max_m",
            "must be > rangefinder.min_m",
        ),
    ],
)
def test_bad_values_are_refused_with_key_and_range(data: dict, key: str, fragment: str) -> None:
    with pytest.raises(ConfigError) as info:
        from_mapping(EstimatorConfig, data, source="est.yaml")
    assert str(info.value).startswith(f"est.yaml: {key} = ")
    assert fragment in str(info.value)


def test_missing_file_is_a_config_error(tmp_path) -> None:
    with pytest.raises(ConfigError, match="file not found"):
        load_estimator_config(tmp_path / "none.yaml")
