"""The simulated ground station's sensors (sim/ground_sensors.py): each error of the winch's
drum encoder and of the cable-angle sensor is in what they report, with its configured size
(each test fails with that error removed from the model)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.config import ConfigError
from tether_companion.physics.cable import ConstantTensionCable
from tether_companion.sim.ground_sensors import GroundSensorConfig, GroundSensors, noisy_angles
from tether_companion.sim.scenario import load_scenario, scenario_from_mapping

NONE = GroundSensorConfig(
    enabled=True,
    winch_scale_error_std=0.0,
    winch_zero_offset_std_m=0.0,
    winch_resolution_m=0.0,
    winch_latency_s=0.0,
    angle_noise_std_rad=0.0,
    angle_azimuth_bias_std_rad=0.0,
    angle_elevation_bias_std_rad=0.0,
    angle_resolution_rad=0.0,
    angle_latency_s=0.0,
)
"""On, every error 0: the reports are the truth at the sensors' rates."""
TICK_S = 0.005


def _fly(config: GroundSensorConfig, seed: int, seconds: float = 2.0, tension_n: float = 4.0):
    """The reports along a drone flying a 3 m circle at 1 m/s, 2 m up, on a constant-tension
    cable: (times, true positions, true paid-out lengths, lengths, angles) per tick."""
    sensors = GroundSensors(config, "constant_tension", seed)
    cable = ConstantTensionCable(tension_n)
    out = []
    for i in range(int(seconds / TICK_S)):
        t = i * TICK_S
        position = (3.0 * math.cos(t / 3.0), 3.0 * math.sin(t / 3.0), -2.0 - 0.2 * t)
        cable.force_components(*position, 0.0, 0.0, 0.0)  # sets paid_out_m
        out.append((t, position, cable.paid_out_m, sensors.read(t, cable, position, tension_n)))
    return out


def _angles(position):
    n, e, d = position
    return math.atan2(e, n), math.atan2(-d, math.hypot(n, e))


def test_off_reports_the_exact_length_every_tick_and_the_angle_with_white_noise():
    flight = _fly(GroundSensorConfig(), seed=3)
    assert all(r.paid_out_m == length for _, _, length, r in flight)
    angles = [(p, r.cable_angle_rad) for _, p, _, r in flight if r.cable_angle_rad is not None]
    assert len(angles) == 20  # 10 Hz for 2 s
    rng = np.random.default_rng([3, 250])
    for position, reported in angles:
        distance = math.dist(position, (0.0, 0.0, 0.0))
        direction = tuple(v / distance for v in position)
        assert reported == pytest.approx(noisy_angles(direction, 0.01, rng), abs=1e-12)


def test_without_errors_the_reports_are_the_truth_at_their_rates():
    flight = _fly(NONE, seed=1)
    lengths = [(length, r.paid_out_m) for _, _, length, r in flight if r.paid_out_m is not None]
    assert len(lengths) == 20
    assert all(reported == pytest.approx(true, abs=1e-12) for true, reported in lengths)
    for _, position, _, r in flight:
        if r.cable_angle_rad is not None:
            assert r.cable_angle_rad == pytest.approx(_angles(position), abs=1e-12)


def _length_errors(config: GroundSensorConfig, seeds: range) -> np.ndarray:
    """Per seed: (reported / true - 1) at the first report and reported - true at it."""
    rows = []
    for seed in seeds:
        (_, _, true, reading) = _fly(config, seed, seconds=TICK_S)[0]
        rows.append((reading.paid_out_m / true - 1.0, reading.paid_out_m - true))
    return np.array(rows)


def test_winch_scale_error_is_drawn_per_flight_with_its_std():
    errors = _length_errors(dataclasses.replace(NONE, winch_scale_error_std=0.01), range(400))
    assert np.std(errors[:, 0]) == pytest.approx(0.01, rel=0.15)
    flight = _fly(dataclasses.replace(NONE, winch_scale_error_std=0.01), seed=5)
    ratios = [r.paid_out_m / true for _, _, true, r in flight if r.paid_out_m is not None]
    assert max(ratios) - min(ratios) < 1e-12  # one scale for the flight
    assert abs(ratios[0] - 1.0) > 1e-4


def test_winch_zero_offset_is_drawn_per_flight_with_its_std():
    errors = _length_errors(dataclasses.replace(NONE, winch_zero_offset_std_m=0.1), range(400))
    assert np.std(errors[:, 1]) == pytest.approx(0.1, rel=0.15)
    assert abs(np.mean(errors[:, 1])) < 0.02


def test_winch_length_is_quantised():
    flight = _fly(dataclasses.replace(NONE, winch_resolution_m=0.01), seed=2)
    reports = [(true, r.paid_out_m) for _, _, true, r in flight if r.paid_out_m is not None]
    for true, reported in reports:
        assert reported / 0.01 == pytest.approx(round(reported / 0.01), abs=1e-9)
        assert abs(reported - true) <= 0.005 + 1e-12
    assert any(abs(reported - true) > 1e-3 for true, reported in reports)


def test_the_encoder_does_not_see_the_cable_stretch():
    config = dataclasses.replace(NONE, cable_axial_stiffness_n=2000.0)
    for _, _, true, r in _fly(config, seed=2, tension_n=10.0):
        if r.paid_out_m is not None:  # 10 N on EA = 2 kN: 0.5 % short
            assert r.paid_out_m == pytest.approx(true / 1.005, abs=1e-12)


def test_winch_reports_the_length_its_latency_ago():
    flight = _fly(dataclasses.replace(NONE, winch_latency_s=0.1), seed=2)
    true_at = {round(t / TICK_S): true for t, _, true, _ in flight}
    reports = [(t, r.paid_out_m) for t, _, _, r in flight if r.paid_out_m is not None]
    for t, reported in reports[3:]:
        assert reported == pytest.approx(true_at[round((t - 0.1) / TICK_S)], abs=1e-12)
        assert reported != pytest.approx(true_at[round(t / TICK_S)], abs=1e-6)


def _angle_errors(config: GroundSensorConfig, seed: int, seconds: float = 2.0) -> np.ndarray:
    rows = []
    for _, position, _, r in _fly(config, seed, seconds):
        if r.cable_angle_rad is not None:
            azimuth, elevation = _angles(position)
            rows.append((r.cable_angle_rad[0] - azimuth, r.cable_angle_rad[1] - elevation))
    return np.array(rows)


def test_angle_biases_are_drawn_per_flight_with_their_std():
    config = dataclasses.replace(
        NONE, angle_azimuth_bias_std_rad=0.026, angle_elevation_bias_std_rad=0.007
    )
    biases = np.array([_angle_errors(config, seed, 0.2).mean(axis=0) for seed in range(300)])
    assert np.std(biases[:, 0]) == pytest.approx(0.026, rel=0.15)
    assert np.std(biases[:, 1]) == pytest.approx(0.007, rel=0.15)
    one = _angle_errors(config, 4)
    assert np.ptp(one, axis=0).max() < 1e-12  # the same bias all flight


def test_angle_white_noise_has_its_std():
    errors = np.concatenate(
        [_angle_errors(dataclasses.replace(NONE, angle_noise_std_rad=0.01), s) for s in range(30)]
    )
    assert np.std(errors[:, 1]) == pytest.approx(0.01, rel=0.1)  # elevation: sigma
    cos_el = math.cos(math.atan2(2.2, 3.0))  # the azimuth's: sigma / cos(el)
    assert np.std(errors[:, 0]) == pytest.approx(0.01 / cos_el, rel=0.15)


def test_angles_are_quantised():
    step = 0.0015
    for _, _, _, r in _fly(dataclasses.replace(NONE, angle_resolution_rad=step), seed=1):
        if r.cable_angle_rad is not None:
            azimuth, elevation = r.cable_angle_rad
            assert elevation / step == pytest.approx(round(elevation / step), abs=1e-9)
            assert azimuth / step == pytest.approx(round(azimuth / step), abs=1e-9)


def test_angle_reports_the_direction_its_latency_ago():
    flight = _fly(dataclasses.replace(NONE, angle_latency_s=0.05), seed=1)
    position_at = {round(t / TICK_S): p for t, p, _, _ in flight}
    reports = [(t, r.cable_angle_rad) for t, _, _, r in flight if r.cable_angle_rad is not None]
    for t, reported in reports[1:]:
        assert reported == pytest.approx(_angles(position_at[round((t - 0.05) / TICK_S)]))
        assert reported[0] != pytest.approx(_angles(position_at[round(t / TICK_S)])[0], abs=1e-4)


def test_the_realistic_scenarios_have_the_errors_on():
    for name in ("realistic-circle", "realistic-gusty-hover", "realistic-takeoff-figure8"):
        assert load_scenario(name).ground_station.enabled
    assert not load_scenario("paper-circle").ground_station.enabled


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("winch_scale_error_std", math.nan),
        ("winch_zero_offset_std_m", -0.1),
        ("winch_rate_hz", 0.0),
        ("angle_latency_s", math.inf),
        ("angle_azimuth_bias_std_rad", 3.0),
        ("cable_axial_stiffness_n", -1.0),
    ],
)
def test_absurd_sensor_errors_are_rejected(tmp_path, key, value):
    with pytest.raises(ConfigError, match=key):
        scenario_from_mapping({"ground_station": {key: value}}, tmp_path / "s.yaml")
