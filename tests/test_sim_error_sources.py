"""The simulator's real-world error sources, each measured back from what it outputs."""

from __future__ import annotations

import math
import re
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from scipy.signal import welch

from tether_companion.cli import main
from tether_companion.config import ConfigError
from tether_companion.frames import rotation_ned_to_body
from tether_companion.physics.cable_drag import cable_drag_force_ned_n
from tether_companion.physics.rigid_body import RigidBody
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.ground import Ground, GroundConfig
from tether_companion.sim.propulsion import BatteryConfig, PropulsionConfig
from tether_companion.sim.scenario import REALISTIC_SCENARIOS, WINCH_SAG_SCENARIOS, load_scenario
from tether_companion.sim.sensors import SensorConfig, SensorSuite
from tether_companion.sim.simulator import Simulator
from tether_companion.sim.truth import FlightImpossibleError
from tether_companion.sim.wind import DrydenParameters, DrydenTurbulence, dryden_psd

G = 9.80665


def test_rotor_and_body_drag_in_the_specific_force() -> None:
    """Level flight at 2 m/s along body x in still air: the accelerometer's x reads the drag."""
    vehicle = load_vehicle("realistic-quad")
    body = RigidBody(vehicle)
    n = vehicle.n_motors
    hover = vehicle.mass_kg * G / n
    body.set_state([0, 0, -5, 2.0, -1.0, 0, 0, 0, 0, 0, 0, 0] + [hover] * n)
    ax, ay, az = body.specific_force_body_mps2()
    k = 0.5 * 1.225 / vehicle.ballistic_coefficient_kg_per_m2
    assert ax == pytest.approx(-0.2 * 2.0 - k * 4.0, rel=1e-9)
    assert ay == pytest.approx(-0.2 * -1.0 + k * 1.0, rel=1e-9)
    assert az == pytest.approx(-G, rel=1e-9)


def test_drag_measured_back_from_a_realistic_flight() -> None:
    """On realistic-circle, m f - thrust - R F_cable is the drag: regress mu from the truth."""
    scenario = replace(load_scenario("realistic-circle"), duration_s=20.0)
    sim = Simulator(scenario)
    vehicle = sim.vehicle
    k = 0.5 * 1.225 / vehicle.ballistic_coefficient_kg_per_m2
    air, residual = [], []
    for step in range(1, 400):
        sim.advance_to(step * 0.05)
        t = sim.truth
        r = rotation_ned_to_body(*t.euler_rad)
        drag_body = vehicle.mass_kg * t.specific_force_body_mps2 - r @ t.cable_force_ned_n
        air_body = r @ (t.velocity_ned_m_s - t.wind_ned_m_s)
        for i in (0, 1):
            air.append(air_body[i])
            quadratic = k * air_body[i] * abs(air_body[i]) * vehicle.mass_kg
            residual.append(drag_body[i] + quadratic)
    air_a, res_a = np.array(air), np.array(residual)
    mu = -float(air_a @ res_a / (air_a @ air_a)) / vehicle.mass_kg
    assert mu == pytest.approx(vehicle.rotor_drag_per_s, rel=0.02)
    assert np.max(np.abs(air_a)) > 1.0  # the flight really moved through the air


def test_wind_drag_on_the_cable_at_the_drone() -> None:
    """Cross wind on a 4 mm cable along the chord (5, 0, -3): half of q L reaches the drone;
    wind along the chord drags nothing (skin friction neglected)."""
    p = (5.0, 0.0, -3.0)
    length = math.sqrt(34.0)
    force = cable_drag_force_ned_n(p, (0.0, 6.0, 0.0), 0.004)
    q = 0.5 * 1.225 * 1.2 * 0.004 * 36.0
    assert force == pytest.approx((0.0, 0.5 * q * length, 0.0), abs=1e-12)
    along = cable_drag_force_ned_n(p, tuple(2.0 * c / length for c in p), 0.004)
    assert along == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    # in flight: the simulator's cable force is the winch's pull plus that drag
    scenario = replace(load_scenario("realistic-gusty-hover"), duration_s=2.0)
    sim = Simulator(scenario)
    sim.advance_to(1.0)
    t = sim.truth
    pull = sim.cable.force_components(*t.position_ned_m, *t.velocity_ned_m_s)
    drag = cable_drag_force_ned_n(tuple(t.position_ned_m), tuple(t.wind_ned_m_s), 0.004)
    assert t.cable_force_ned_n == pytest.approx(np.add(pull, drag), abs=1e-12)
    assert np.linalg.norm(drag) > 1e-3


def test_dryden_turbulence_has_the_dryden_spectrum_and_intensity() -> None:
    parameters = DrydenParameters.low_altitude(7.7, 5.0)
    gusts = DrydenTurbulence(parameters, (3.0, 0.0, 0.0), 0.01, np.random.default_rng(7))
    samples = np.array([gusts.step() for _ in range(120_000)])
    for axis in range(3):
        f, psd = welch(samples[:, axis], fs=100.0, nperseg=4096)
        band = (f > 0.05) & (f < 5.0)
        model = dryden_psd(
            f[band], parameters.sigma_mps[axis], parameters.length_m[axis], 3.0, axis
        )
        ratio = psd[band] / model
        assert 0.8 < float(np.median(ratio)) < 1.25, axis
    assert np.std(samples[:, 2]) == pytest.approx(parameters.sigma_mps[2], rel=0.15)


def test_the_simulators_wind_is_the_mean_wind_plus_dryden_gusts() -> None:
    """Measured back from a flight: the simulator's wind over 120 s of realistic-gusty-hover
    (seed 3; W20 7.7 m/s at 4 m: sigma_w 0.77 m/s, L_w 4 m, L_u 30 m at 3 m/s mean wind).
    Vertical: tau = L_w / V = 1.3 s, so 120 s hold ~45 independent stretches: its sd within 20 %
    of sigma_w, its mean within 0.35 m/s of 0 (3 sd), its spectrum within 0.75-1.33 of the
    Dryden PSD (median over 0.1-5 Hz). Horizontal: tau_u = 10 s, the 120 s mean has an sd of
    about 0.6 m/s: within 2 m/s of the configured mean wind. About 2.5 s of CPU."""
    scenario = replace(load_scenario("realistic-gusty-hover"), duration_s=120.0, seed=3)
    sim = Simulator(scenario)
    wind = []
    for k in range(1, 2400):
        sim.advance_to(k * 0.05)
        wind.append(sim.truth.wind_ned_m_s.copy())
    w = np.array(wind)
    parameters = DrydenParameters.low_altitude(
        scenario.wind.turbulence_w20_mps, scenario.wind.turbulence_height_m
    )
    mean = np.array(scenario.wind.velocity_ned_m_s)
    assert np.std(w[:, 2]) == pytest.approx(parameters.sigma_mps[2], rel=0.2)
    assert abs(float(np.mean(w[:, 2]))) < 0.35
    assert np.all(np.abs(w[:, :2].mean(axis=0) - mean[:2]) < 2.0)
    f, psd = welch(w[:, 2], fs=20.0, nperseg=256)
    band = (f > 0.1) & (f < 5.0)
    airspeed = math.hypot(mean[0], mean[1])
    model = dryden_psd(f[band], parameters.sigma_mps[2], parameters.length_m[2], airspeed, 2)
    assert 0.75 < float(np.median(psd[band] / model)) < 1.33


def test_dryden_low_altitude_parameters() -> None:
    """MIL-HDBK-1797 at 20 ft with W20 = 10 m/s: sigma_w = 1, sigma_u = 1/(0.177+0.01646)^0.4."""
    p = DrydenParameters.low_altitude(10.0, 20 * 0.3048)
    base = 0.177 + 0.000823 * 20
    assert p.sigma_mps[2] == pytest.approx(1.0)
    assert p.sigma_mps[0] == pytest.approx(1.0 / base**0.4)
    assert p.length_m[2] == pytest.approx(20 * 0.3048)
    assert p.length_m[0] == pytest.approx(20 / base**1.2 * 0.3048)


def test_accelerometer_and_gyro_turn_on_bias_and_random_walk_statistics() -> None:
    """300 seeds, sensors at rest, no white noise: the first sample is the turn-on bias, the
    change over 100 s the random walk (sd of an sd estimate from 900 values: 2.4 %)."""
    config = SensorConfig(
        accel_noise_std_mps2=0.0,
        accel_turn_on_bias_std_mps2=0.1,
        accel_bias_random_walk_mps2_per_sqrt_s=0.01,
        gyro_noise_std_rad_s=0.0,
        gyro_turn_on_bias_std_rad_s=0.002,
        gyro_bias_random_walk_rad_s_per_sqrt_s=0.0003,
    )
    start, end, gyro_start, gyro_end = [], [], [], []
    for seed in range(300):
        suite = SensorSuite(config, np.random.default_rng(seed))
        first = suite.imu(0.0, (0.0, 0.0, -G), (0.0, 0.0, 0.0))
        accel0 = first.specific_force_body_mps2.copy()
        gyro0 = first.angular_rate_body_rad_s.copy()
        for k in range(1, 101):
            last = suite.imu(k * 1.0, (0.0, 0.0, -G), (0.0, 0.0, 0.0))
        start.append(accel0)
        end.append(last.specific_force_body_mps2 - accel0)
        gyro_start.append(gyro0)
        gyro_end.append(last.angular_rate_body_rad_s - gyro0)
    start_a, walk = np.array(start), np.array(end)
    assert np.std(start_a[:, 0]) == pytest.approx(0.1, rel=0.15)
    # 100 s of random walk at 0.01 m/s^2/sqrt(s): sigma 0.1 m/s^2
    assert np.std(walk) == pytest.approx(0.01 * math.sqrt(100.0), rel=0.15)
    assert np.std(np.array(gyro_start)) == pytest.approx(0.002, rel=0.15)
    assert np.std(np.array(gyro_end)) == pytest.approx(0.0003 * math.sqrt(100.0), rel=0.15)


def test_flight_controller_attitude_error_is_a_slow_gauss_markov_process() -> None:
    config = SensorConfig(
        attitude_noise_std_rad=0.0,
        attitude_error_std_rad=0.005,
        attitude_error_time_constant_s=10.0,
    )
    suite = SensorSuite(config, np.random.default_rng(3))
    rolls = np.array([suite.attitude(k * 0.1, 0.0, 0.0, 0.0).roll_rad for k in range(60_000)])
    assert np.std(rolls) == pytest.approx(0.005, rel=0.25)
    lag = 100  # one time constant
    rho = np.corrcoef(rolls[:-lag], rolls[lag:])[0, 1]
    assert rho == pytest.approx(math.exp(-1.0), abs=0.12)


def test_the_heading_error_has_its_own_sigma_and_time_constant() -> None:
    """A compass-aided heading is worse than roll and pitch: its own Gauss-Markov process."""
    config = SensorConfig(
        attitude_noise_std_rad=0.0,
        attitude_error_std_rad=0.005,
        attitude_error_time_constant_s=10.0,
        heading_error_std_rad=0.02,
        heading_error_time_constant_s=40.0,
    )
    suite = SensorSuite(config, np.random.default_rng(4))
    readings = [suite.attitude(k * 0.1, 0.0, 0.0, 0.0) for k in range(120_000)]
    rolls = np.array([a.roll_rad for a in readings])
    yaws = np.array([a.yaw_rad for a in readings])
    assert np.std(rolls) == pytest.approx(0.005, rel=0.25)
    assert np.std(yaws) == pytest.approx(0.02, rel=0.25)
    lag = 400  # the heading's time constant
    rho = np.corrcoef(yaws[:-lag], yaws[lag:])[0, 1]
    assert rho == pytest.approx(math.exp(-1.0), abs=0.15)
    assert np.corrcoef(rolls[:-lag], rolls[lag:])[0, 1] < 0.1  # the tilt's own 10 s


def test_an_unset_heading_error_is_the_attitude_error() -> None:
    """Without the heading keys every axis draws the same numbers as before they existed."""
    tilt = SensorConfig(attitude_error_std_rad=0.005, attitude_error_time_constant_s=10.0)
    same = replace(tilt, heading_error_std_rad=0.005, heading_error_time_constant_s=10.0)
    a = SensorSuite(tilt, np.random.default_rng(5))
    b = SensorSuite(same, np.random.default_rng(5))
    for k in range(200):
        assert a.attitude(k * 0.1, 0.0, 0.0, 0.0) == b.attitude(k * 0.1, 0.0, 0.0, 0.0)


def test_a_heading_error_alone_moves_only_the_heading() -> None:
    config = SensorConfig(attitude_noise_std_rad=0.0, heading_error_std_rad=0.02)
    suite = SensorSuite(config, np.random.default_rng(6))
    readings = [suite.attitude(k * 0.1, 0.1, -0.1, 1.0) for k in range(100)]
    assert all(a.roll_rad == 0.1 and a.pitch_rad == -0.1 for a in readings)
    assert max(abs(a.yaw_rad - 1.0) for a in readings) > 0.001


def test_battery_sag_lowers_the_thrust_for_the_same_command() -> None:
    battery = BatteryConfig(
        cells=4, full_cell_voltage_v=4.2, reference_cell_voltage_v=4.0, sag_v_per_cell_per_min=0.1
    )
    propulsion = PropulsionConfig(thrust_scale=0.95, battery=battery)
    scenario = replace(load_scenario("hover"), propulsion=propulsion, duration_s=70.0)
    sim = Simulator(scenario)
    for t_s in (5.0, 35.0, 65.0):
        sim.advance_to(t_s)
        truth = sim.truth
        expected_v = 4 * (4.2 - 0.1 * t_s / 60.0)
        assert truth.battery_voltage_v == pytest.approx(expected_v, abs=0.005)
        steady = 0.95 * sim.vehicle.thrust_curve.thrust_n(truth.pwm_us, expected_v / 16.0)
        # in a steady hover the motors sit at their steady-state thrust (lag settled)
        assert truth.motor_thrust_n == pytest.approx(steady, rel=0.01)
    assert battery.voltage_v(1e6) == pytest.approx(4 * 3.3)


def test_rangefinder_measures_to_the_terrain_from_its_mounting_point() -> None:
    base = load_scenario("realistic-gusty-hover")
    sensors = replace(base.sensors, range_noise_std_m=0.0, range_rate_hz=200.0)
    sim = Simulator(replace(base, sensors=sensors, duration_s=5.0))
    for k in range(1, 40):
        sim.advance_to(0.1 * k)
        x = sim.body.x
        reading = sim.read_rangefinder()
        r = rotation_ned_to_body(x[6], x[7], x[8])
        sensor = np.array(x[:3]) + r.T @ np.array(sensors.range_offset_frd_m)
        height = sim.ground.down_m(sensor[0], sensor[1]) - sensor[2]
        assert reading.distance_m * math.cos(x[6]) * math.cos(x[7]) == pytest.approx(
            height, abs=1e-9
        )
    # the terrain is really uneven and the anchor really stands 1 m above the mean ground
    ground = Ground(GroundConfig(anchor_height_m=1.0, terrain_std_m=0.05), np.random.default_rng(1))
    heights = [
        ground.elevation_m(n, e) for n in np.linspace(-20, 20, 60) for e in np.linspace(-20, 20, 60)
    ]
    assert np.std(heights) == pytest.approx(0.05, rel=0.3)
    assert np.mean([ground.down_m(n, 0.0) for n in np.linspace(-20, 20, 200)]) == pytest.approx(
        1.0, abs=0.03
    )


def test_a_landed_start_sits_on_the_ground_below_the_anchor() -> None:
    sim = Simulator(replace(load_scenario("realistic-takeoff-figure8"), duration_s=1.0))
    x = sim.body.x
    assert sim.landed and x[2] == pytest.approx(sim.ground.down_m(x[0], x[1]))
    assert x[2] > 0.8  # the anchor stands on a 1 m tripod


def test_every_realistic_scenario_loads_with_every_error_source_on() -> None:
    for name in REALISTIC_SCENARIOS + WINCH_SAG_SCENARIOS:
        s = load_scenario(name)
        assert s.vehicle == "realistic-quad" and s.sensors.accel_turn_on_bias_std_mps2 > 0, name
        assert s.wind.turbulence_w20_mps > 0 and s.propulsion.thrust_scale != 1.0, name
        assert s.ground.anchor_height_m > 0 and s.ground.terrain_std_m > 0, name
        assert s.propulsion.battery.sag_v_per_cell_per_min > 0, name
        assert s.cable.diameter_m > 0, name


def test_the_winch_sag_scenarios_cover_issue_10s_sagging_cables() -> None:
    """0.0167 and 0.1 kg/m, 5 and 1 N at the anchor, hover, circle and figure-8: each cable
    at both tensions and each flight on both cables and at both tensions."""
    cases = set()
    for name in WINCH_SAG_SCENARIOS:
        s = load_scenario(name)
        assert s.cable.model == "winch_catenary" and s.ground_station.enabled, name
        cases.add((s.cable.linear_density_kg_per_m, s.cable.tension_n, s.trajectory.kind))
    assert {(d, t) for d, t, _ in cases} == {(d, t) for d in (0.0167, 0.1) for t in (1.0, 5.0)}
    for kind in ("hover", "circle", "figure8"):
        assert {d for d, _, k in cases if k == kind} == {0.0167, 0.1}, kind
        assert {t for _, t, k in cases if k == kind} == {1.0, 5.0}, kind


def test_the_paper_scenario_stays_clean() -> None:
    s = load_scenario("paper-circle")
    assert s.propulsion == PropulsionConfig() and s.ground == GroundConfig()
    assert s.wind.turbulence_w20_mps == 0.0 and load_vehicle(s.vehicle).rotor_drag_per_s == 0.0


@pytest.mark.parametrize(
    ("text", "key", "words"),
    [
        ("propulsion: {thrust_scale: 3}\n", "propulsion.thrust_scale", "<= 1.5"),
        ("propulsion: {battery: {cells: 0}}\n", "propulsion.battery.cells", ">= 1"),
        (
            "propulsion: {battery: {full_cell_voltage_v: 3.2, empty_cell_voltage_v: 3.5}}\n",
            "propulsion.battery.full_cell_voltage_v",
            "> empty_cell_voltage_v",
        ),
        ("ground: {anchor_height_m: -1}\n", "ground.anchor_height_m", ">= 0"),
        ("ground: {terrain_std_m: .nan}\n", "ground.terrain_std_m", "finite"),
        ("wind: {turbulence_w20_mps: -2}\n", "wind.turbulence_w20_mps", ">= 0"),
        ("sensors: {attitude_error_std_rad: 1}\n", "sensors.attitude_error_std_rad", "<= 0.2"),
        ("sensors: {heading_error_std_rad: -0.1}\n", "sensors.heading_error_std_rad", ">= 0"),
        (
            "sensors: {heading_error_time_constant_s: 0}\n",
            "sensors.heading_error_time_constant_s",
            "> 0",
        ),
        ("sensors: {range_offset_frd_m: [0, 0]}\n", "sensors.range_offset_frd_m", "3 items"),
        ("trajectory: {kind: figure8}\n", "trajectory.waypoints_ned_m", "at least one"),
        ("trajectory: {kind: hover, yaw_rate_deg_s: 500}\n", "trajectory.yaw_rate_deg_s", "<= 90"),
        ("base: no-such-scenario\n", "", "no-such-scenario"),
        ("base: 5\n", "base", "scenario name"),
        (
            "ground: {anchor_height_m: 1}\ntrajectory: {kind: hover, position_ned_m: [0, 0, 2]}\n",
            "trajectory.position_ned_m",
            "<= 1.0",
        ),
    ],
)
def test_bad_error_source_keys_name_the_key(
    tmp_path, capsys, text: str, key: str, words: str
) -> None:
    """The loader names file, key, value and what is allowed; ``simulate`` and ``bench
    estimators`` exit 2 with that one line."""
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_scenario(path)
    message = str(info.value)
    if key:
        shown = repr(info.value.value)
        assert f"{path}: {key} = {shown}: " in message and words in message
    else:
        assert words in message
    for argv in (["simulate", str(path)], ["bench", "estimators", "--scenario", str(path)]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], (argv, err)


IMPOSSIBLE = (
    "base: realistic-gusty-hover\npropulsion: {thrust_scale: 0.5}\ncable: {tension_n: 10}\n"
)
"""A thrust map 50 % weak cannot hold a 1.5 kg quad against 10 N of pull."""
IMPOSSIBLE_MESSAGE = r"t = \d+\.\d\d s: .*(full command|hit the ground)"


def test_an_impossible_flight_names_the_time_and_the_cause(tmp_path) -> None:
    """The simulator and ``simulate`` say when and why (one line, exit 2)."""
    path = tmp_path / "weak.yaml"
    path.write_text(IMPOSSIBLE)
    with pytest.raises(FlightImpossibleError, match=IMPOSSIBLE_MESSAGE):
        sim = Simulator(load_scenario(path))
        sim.advance_to(20.0)
    result = subprocess.run(
        [sys.executable, "-m", "tether_companion.cli", "simulate", str(path)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and re.search(IMPOSSIBLE_MESSAGE, lines[0])
    assert "Traceback" not in result.stderr


@pytest.mark.slow  # starts a local Dask cluster: about 7 s of CPU
def test_an_impossible_flight_on_a_dask_worker_ends_bench_estimators_with_one_line(
    tmp_path, capsys
) -> None:
    path = tmp_path / "weak.yaml"
    path.write_text(IMPOSSIBLE)
    bench = ["bench", "estimators", "--scenario", str(path), "--seeds", "1", "--workers", "1"]
    assert main([*bench, "--estimator", "ekf-4s", "--json"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("tether-companion bench: error: t = ")
    assert re.search(IMPOSSIBLE_MESSAGE, err[0]) and "Traceback" not in err[0]
