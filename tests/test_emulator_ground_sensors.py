"""The emulator's ground station (WINCH_STATUS, DEBUG_VECT CABLE_ANG) reports what the offline
simulator's sensors (sim/ground_sensors.py) report of the same states: one error model,
configured by the scenario's ``ground_station`` section and seeded by its seed."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tether_companion.emulator.lockstep import build_controller
from tether_companion.mavlink.framing import dialect
from tether_companion.physics.cable_anchor import anchor_direction_ned
from tether_companion.sim.ground_sensors import GroundSensors

BOTH = {"winch": {"enabled": True}, "cable_angle": {"enabled": True}}


def _scenario(tmp_path: Path, seed: int, ground_station: str = "{}") -> Path:
    """A 3 s realistic circle (every ground-station error on) with ``ground_station``
    overrides (YAML flow mapping)."""
    path = tmp_path / f"circle-{seed}.yaml"
    path.write_text(
        f"base: realistic-circle\nduration_s: 3.0\nseed: {seed}\n"
        f"ground_station: {ground_station}\n",
        encoding="utf-8",
    )
    return path


def _fly(path: Path, seconds: float = 3.0):
    """Step the emulator one physics step at a time, feeding an offline GroundSensors the same
    states; returns (controller, [(time, frame message, offline report, true paid-out length
    then)])."""
    controller = build_controller(str(path), emulator=BOTH)
    scenario = controller.scenario
    offline = GroundSensors(scenario.ground_station, scenario.cable.model, scenario.seed)
    decoder = dialect.MAVLink(None)
    sim = controller.sim
    out = []
    for step in range(1, round(seconds / sim.physics_dt_s) + 1):
        controller.advance_to(step * sim.physics_dt_s)
        offline.record(sim.time_s, sim.cable.paid_out_m, sim.position_ned_m, sim.cable.tension_n)
        for _, frame in controller.drain():
            if not isinstance(frame, bytes):
                continue
            msg = decoder.decode(bytearray(frame))
            if msg.get_type() == "WINCH_STATUS":
                expected = offline.winch_length_m(sim.time_s)
            else:
                cable = sim.cable
                expected = offline.cable_angle_rad(
                    sim.time_s, lambda p, cable=cable: anchor_direction_ned(cable, p)
                )
            out.append((sim.time_s, msg, expected, sim.cable.paid_out_m))
    return controller, out


def test_the_emulators_reports_are_the_offline_sensors_with_the_flights_calibration(tmp_path):
    controller, reports = _fly(_scenario(tmp_path, seed=4))
    lengths = [
        (m.line_length, want, true)
        for _, m, want, true in reports
        if m.get_type() == "WINCH_STATUS"
    ]
    angles = [((m.x, m.y), want) for _, m, want, _ in reports if m.get_type() == "DEBUG_VECT"]
    assert 29 <= len(lengths) <= 31 and 29 <= len(angles) <= 31  # 10 Hz for 3 s
    for sent, want, _ in lengths:
        assert sent == pytest.approx(want, abs=1e-5)  # float32 on the wire
    for sent, want in angles:
        assert sent == pytest.approx(want, abs=1e-6)
    # the flight's calibration is in them: seed 4's encoder is 1.8 % short (6 cm at 3.4 m)
    calibration = controller.ground_sensors.calibration
    assert calibration.winch_scale < -0.015 and abs(calibration.azimuth_bias_rad) > 0.02
    for sent, _, true in lengths[2:]:  # the climbing circle: < 2 cm in the latency
        assert sent - true < -0.04
        expected = calibration.winch_offset_m + (1.0 + calibration.winch_scale) * true
        assert sent == pytest.approx(expected, abs=0.025)


def test_the_same_seed_draws_the_same_calibration_offline_and_in_the_emulator(tmp_path):
    controller = build_controller(str(_scenario(tmp_path, seed=7)), emulator=BOTH)
    scenario = controller.scenario
    offline = GroundSensors(scenario.ground_station, scenario.cable.model, 7)
    assert controller.ground_sensors.calibration == offline.calibration
    other = build_controller(str(_scenario(tmp_path, seed=8)), emulator=BOTH)
    assert other.ground_sensors.calibration != offline.calibration


def test_off_the_winch_reports_the_exact_length_at_the_sections_rates(tmp_path):
    path = _scenario(tmp_path, 2, "{enabled: false, winch_rate_hz: 5.0, angle_rate_hz: 4.0}")
    controller, reports = _fly(path, seconds=2.0)
    lengths = [(m.line_length, true) for _, m, _, true in reports if m.get_type() == "WINCH_STATUS"]
    assert 9 <= len(lengths) <= 11  # 5 Hz
    assert 7 <= sum(m.get_type() == "DEBUG_VECT" for _, m, _, _ in reports) <= 9  # 4 Hz
    for sent, true in lengths:
        assert sent == pytest.approx(true, abs=1e-5)  # exact (float32 on the wire)
    sent = np.array([s for s, _ in lengths])
    assert np.any(np.abs(sent / 0.01 - np.round(sent / 0.01)) > 0.05)  # not in 1 cm steps
    assert controller.ground_sensors.calibration.winch_scale == 0.0


def test_without_a_sensor_nothing_is_recorded(tmp_path):
    controller = build_controller(str(_scenario(tmp_path, seed=1)))
    assert controller.ground_sensors is None and math.isfinite(controller.time_s)
