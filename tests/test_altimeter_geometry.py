"""The altimeter model with the ground station's geometry: the rangefinder sees the ground
under the drone from its mounting point, the anchor sits anchor_height_m above that ground."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tether_companion.config import ConfigError, from_mapping
from tether_companion.estimation.altimeter_geometry import height_above_anchor_m
from tether_companion.estimation.config import EstimatorConfig, load_estimator_config
from tether_companion.estimation.runner import run_scenario
from tether_companion.frames import rotation_ned_to_body
from tether_companion.sim.scenario import load_scenario
from tether_companion.sim.simulator import Simulator


def test_height_matches_the_ray_cast_geometry() -> None:
    """Cast the sensor's beam (body down) from its mounting point to the ground and back."""
    rng = np.random.default_rng(4)
    for _ in range(50):
        roll, pitch, yaw = rng.uniform(-0.5, 0.5, 3) * (1, 1, 6)
        r_vb = rotation_ned_to_body(roll, pitch, yaw)
        offset = tuple(rng.uniform(-0.3, 0.3, 3))
        anchor_height = rng.uniform(-1.0, 3.0)
        cg_height_above_ground = rng.uniform(2.0, 20.0)
        sensor_down = -cg_height_above_ground + (r_vb.T @ np.array(offset))[2]  # NED, ground z=0
        beam_down = (r_vb.T @ np.array([0.0, 0.0, 1.0]))[2]
        distance = -sensor_down / beam_down
        got = height_above_anchor_m(distance, r_vb, offset, anchor_height)
        assert got == pytest.approx(cg_height_above_ground - anchor_height, abs=1e-9)


def test_keys_are_validated() -> None:
    with pytest.raises(ConfigError, match="ground_station.anchor_height_m"):
        from_mapping(EstimatorConfig, {"ground_station": {"anchor_height_m": 500}})
    with pytest.raises(ConfigError, match=r"rangefinder.offset_frd_m"):
        from_mapping(EstimatorConfig, {"rangefinder": {"offset_frd_m": [0, 0]}})


def _down_rmse(monkeypatch, ground_below_anchor_m: float, anchor_key_m: float) -> float:
    """Paper circle (20 s) with the ground ``ground_below_anchor_m`` below the anchor (the
    simulated rangefinder sees that ground), the estimator told ``anchor_key_m``."""

    def read_rangefinder(self):
        x = self.body.x
        return self.sensors.rangefinder(self.time_s, -x[2] + ground_below_anchor_m, x[6], x[7])

    monkeypatch.setattr(Simulator, "read_rangefinder", read_rangefinder)
    scenario = dataclasses.replace(load_scenario("paper-circle"), duration_s=20.0)
    config = load_estimator_config(None)
    config = dataclasses.replace(
        config,
        ground_station=dataclasses.replace(config.ground_station, anchor_height_m=anchor_key_m),
    )
    result = run_scenario(scenario, config)
    late = result.time_s > 5.0
    error = result.position_4s_ned_m[late, 2] - result.truth_position_ned_m[late, 2]
    return float(np.sqrt(np.mean(error**2)))


def test_anchor_one_metre_up_gives_the_same_down_rmse(monkeypatch) -> None:
    on_ground = _down_rmse(monkeypatch, 0.0, 0.0)
    raised = _down_rmse(monkeypatch, 1.0, 1.0)
    ignored = _down_rmse(monkeypatch, 1.0, 0.0)
    assert raised == pytest.approx(on_ground, rel=0.02)
    assert ignored > on_ground + 0.5  # without the key the metre shows up in the estimate


def test_noise_as_standard_deviations_and_the_old_variance_keys() -> None:
    """One convention (standard deviations with units, as datasheets and the tension filter's
    keys give them); the variance keys still read."""
    by_std = from_mapping(
        EstimatorConfig, {"accel_noise": {"std_mps2": 0.2}, "altimeter_noise_std_m": 0.05}
    )
    assert by_std.accel_noise.variance_mps2_sq == pytest.approx(0.04)
    assert by_std.altimeter_noise_variance_m2 == pytest.approx(0.0025)
    old = from_mapping(
        EstimatorConfig,
        {"accel_noise": {"variance": 0.04}, "altimeter_noise_variance_m2": 0.0025},
    )
    assert old.accel_noise.variance_mps2_sq == pytest.approx(by_std.accel_noise.variance_mps2_sq)
    assert old.altimeter_noise_variance_m2 == pytest.approx(by_std.altimeter_noise_variance_m2)
    with pytest.raises(ConfigError, match="give either std_mps2 or variance"):
        from_mapping(EstimatorConfig, {"accel_noise": {"std_mps2": 0.2, "variance": 0.5}})
    with pytest.raises(ConfigError, match="altimeter_noise_std_m"):
        from_mapping(
            EstimatorConfig, {"altimeter_noise_std_m": 0.2, "altimeter_noise_variance_m2": 0.5}
        )
