"""The whole loop without hardware: identification flight in the simulator -> log file ->
processing -> identified models -> thrust-model file -> ThrustInput; and the physics of the
thrust signal with a tether."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tether_companion.cli import main
from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.pipeline import TetherEstimator
from tether_companion.frames import rotation_ned_to_body
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sysid.flight import FlightPlan, record_identification_flight
from tether_companion.sysid.identify import DYNAMIC_STRUCTURES, identify
from tether_companion.sysid.logs import load_flight_log
from tether_companion.sysid.processing import ProcessingOptions, lowpass, prepare
from tether_companion.sysid.thrust_model import LinearThrust, load_thrust_model
from tether_companion.sysid.thrust_signal import total_thrust_n

SHORT_PLAN = FlightPlan(cycle_amplitudes=(1.0, 0.6, 1.3))
"""Three excitation cycles instead of four: a 66 s flight keeps the tests quick."""


@pytest.fixture(scope="module")
def slack_flight(tmp_path_factory):
    path = tmp_path_factory.mktemp("flight") / "identification.tlog"
    simulator = record_identification_flight(path, SHORT_PLAN, seed=3)
    return path, simulator.vehicle


def test_identified_dynamic_models_reach_95_percent_on_emulated_flight(slack_flight):
    path, vehicle = slack_flight
    curve = vehicle.thrust_curve
    data = prepare(load_flight_log(path), vehicle.mass_kg, (curve.pwm_min_us, curve.pwm_max_us))
    results = identify([data.estimation], [data.validation], (curve.pwm_min_us, curve.pwm_max_us))
    by_name = {r.structure: r for r in results}
    for name in DYNAMIC_STRUCTURES:
        assert by_name[name].ok, by_name[name].error
        assert by_name[name].metrics.fit_prediction_pct >= 95.0, name
    process = by_name["process"].model
    time_constant_s = -0.01 / np.log(-process.model.f[1])
    assert time_constant_s == pytest.approx(vehicle.motor_time_constant_s, rel=0.15)


def test_tethered_flight_thrust_corrected_with_known_tension(tmp_path, slack_flight):
    """The same flight on a 3 N constant-tension tether from the anchor below. The motors
    work ~3 N harder, but the accelerometer reads (T - c_z)/m, the same as in the slack
    flight; with the tension given the thrust signal shows the extra ~3 N."""
    path = tmp_path / "tethered.bin"
    tension_n = 3.0
    plan = dataclasses.replace(SHORT_PLAN, cable_tension_n=tension_n)
    simulator = record_identification_flight(path, plan, seed=4)
    vehicle = simulator.vehicle
    curve = vehicle.thrust_curve
    pwm_range = (curve.pwm_min_us, curve.pwm_max_us)
    log = load_flight_log(path)
    corrected = prepare(
        log, vehicle.mass_kg, pwm_range, ProcessingOptions(cable_tension_n=tension_n)
    )
    raw = prepare(log, vehicle.mass_kg, pwm_range)
    slack = prepare(load_flight_log(slack_flight[0]), vehicle.mass_kg, pwm_range)

    def mean_thrust(data):
        return np.mean(np.concatenate([data.estimation.thrust_n, data.validation.thrust_n]))

    assert mean_thrust(raw) == pytest.approx(mean_thrust(slack), abs=0.3)
    # the cable tilts up to ~20 deg in the lateral steps: its vertical pull is 2.8-3 N
    assert 2.6 < mean_thrust(corrected) - mean_thrust(slack) < 3.1


def test_cli_flies_identifies_and_writes_a_model_the_estimator_loads(tmp_path, capsys):
    """fly (--fly-emulated, CSV) -> identify -> --out -> EstimatorConfig.thrust_model."""
    flight, out = tmp_path / "flight.csv", tmp_path / "thrust.yaml"
    args = ["sysid", "--fly-emulated", str(flight), "--out", str(out)]
    assert main([*args, "--structure", "arx", "--structure", "static"]) == 0
    printed = capsys.readouterr().out
    assert "recorded" in printed and "static" in printed and "wrote arx" in printed
    assert flight.read_text().splitlines()[0].startswith("time_s,pwm1_us")
    vehicle = load_vehicle("default-quad")
    thrust = load_thrust_model(out)
    assert isinstance(thrust, LinearThrust)
    hover_pwm = float(vehicle.thrust_curve.pwm_for_thrust(vehicle.mass_kg * GRAVITY_MPS2 / 4))
    value = 0.0
    for k in range(100):
        value = thrust.total_thrust_n(np.full(4, hover_pwm), 0.005 * k)
    assert value == pytest.approx(vehicle.mass_kg * GRAVITY_MPS2, rel=0.05)
    config = EstimatorConfig(thrust_model=str(out))
    assert isinstance(TetherEstimator(config, vehicle).thrust_input, LinearThrust)


def test_thrust_signal_recovers_thrust_under_a_tilted_cable():
    """a = (F_thrust + F_cable) / m in FRD body; with the tension known T is exact."""
    rng = np.random.default_rng(12)
    mass_kg, tension_n = 1.5, 4.0
    rows, thrusts = [], []
    for _ in range(50):
        roll, pitch, yaw = rng.uniform(-0.3, 0.3, 3)
        thrust = rng.uniform(10.0, 25.0)
        to_anchor = -np.array([*rng.uniform(-1.0, 1.0, 2), -3.0])  # drone above the anchor
        cable_ned = tension_n * to_anchor / np.linalg.norm(to_anchor)
        force = np.array([0.0, 0.0, -thrust]) + rotation_ned_to_body(roll, pitch, yaw) @ cable_ned
        rows.append(force / mass_kg)
        thrusts.append(thrust)
    accel = np.array(rows)
    np.testing.assert_allclose(total_thrust_n(accel, mass_kg, tension_n), thrusts, atol=1e-9)
    assert np.all(total_thrust_n(accel, mass_kg) < np.array(thrusts))


def test_zero_phase_lowpass_adds_no_lag():
    t = np.arange(0, 10, 0.01)
    slow = np.sin(2 * np.pi * 0.5 * t)
    filtered = lowpass(slow + 0.2 * np.sin(2 * np.pi * 30 * t), 100.0, 10.0, 5)
    np.testing.assert_allclose(filtered[100:-100], slow[100:-100], atol=0.01)
