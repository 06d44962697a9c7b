"""The simulator end to end: hover under each cable, circle tracking, events, determinism."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.frames import rotation_ned_to_body
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.controller import Setpoint
from tether_companion.sim.events import Event
from tether_companion.sim.scenario import Scenario, load_scenario
from tether_companion.sim.sensors import SensorConfig
from tether_companion.sim.simulator import Simulator

G = GRAVITY_MPS2


def _hover(cable_model: str, **cable: float) -> Scenario:
    base = load_scenario("hover")
    return replace(
        base,
        cable=replace(base.cable, model=cable_model, **cable),
        trajectory=replace(base.trajectory, position_ned_m=(4.0, 0.0, -3.0)),
    )


@pytest.mark.parametrize(
    ("scenario", "event", "duration_s"),
    [
        # the winch doubles its tension: an unknown extra 4 N the integrators must take up
        (_hover("constant_tension", tension_n=4.0), Event(1.0, "set_tension", tension_n=8.0), 12.0),
        # the winch reels a slack elastic line in until it is 0.1 m stretched (10 N)
        (_hover("elastic", length_m=5.2), Event(1.0, "winch_rate", winch_rate_mps=-0.3), 25.0),
        # the winch reels a sagging catenary in until it is nearly straight
        (
            _hover("catenary", length_m=5.25, linear_density_kg_per_m=0.05),
            Event(0.5, "winch_rate", winch_rate_mps=-0.3),
            6.0,
        ),
        # a winch on a heavy cable resting on the ground goes from 2 to 5 N: the cable lifts off
        (
            _hover("winch_catenary", tension_n=2.0, linear_density_kg_per_m=0.1),
            Event(1.0, "set_tension", tension_n=5.0),
            6.0,
        ),
    ],
    ids=["constant_tension", "elastic", "catenary", "winch_catenary"],
)
def test_controller_holds_hover_against_each_cable(
    scenario: Scenario, event: Event, duration_s: float
) -> None:
    stop = Event(event.time_s + 1.0, "winch_rate", winch_rate_mps=0.0)
    events = (event,) if event.kind == "set_tension" else (event, stop)
    sim = Simulator(replace(scenario, events=events, duration_s=duration_s))
    tension_before = sim.truth.tension_n
    sim.advance_to(duration_s - 1.0)
    errors = []
    while sim.time_s < duration_s:
        sim.advance_to(sim.time_s + 0.1)
        errors.append(np.linalg.norm(sim.truth.position_ned_m - [4.0, 0.0, -3.0]))
    assert sim.truth.tension_n > tension_before + 2.0  # the cable pulls clearly harder now
    assert max(errors) < 0.04


def test_paper_circle_is_tracked_with_bounded_error() -> None:
    sim = Simulator(load_scenario("paper-circle"))
    errors, radii = [], []
    for k in range(1, 601):
        sim.advance_to(k * 0.1)
        truth = sim.truth
        setpoint = sim.trajectory.setpoint_at(truth.time_s)
        errors.append(np.linalg.norm(truth.position_ned_m - setpoint.position_ned_m))
        radii.append(math.hypot(*truth.position_ned_m[:2]))
        assert truth.tension_n == 4.0
    assert max(errors) < 0.15
    assert np.mean(radii) == pytest.approx(2.5, abs=0.05)
    assert not sim.landed


def _sensor_trace(seed_scenario: Scenario, rng: np.random.Generator | None = None) -> np.ndarray:
    sim = Simulator(seed_scenario, rng=rng)
    rows = []
    for k in range(1, 401):
        sim.advance_to(k / 200.0)
        imu, att, pwm = sim.read_imu(), sim.read_attitude(), sim.read_pwm()
        rng_sample = sim.read_rangefinder()
        rows.append(
            [
                *imu.specific_force_body_mps2,
                *imu.angular_rate_body_rad_s,
                att.roll_rad,
                att.pitch_rad,
                att.yaw_rad,
                *pwm.pwm_us,
                rng_sample.distance_m if rng_sample else -1.0,
                *sim.truth.position_ned_m,
            ]
        )
    return np.array(rows)


def test_same_seed_gives_identical_runs_and_other_seeds_differ() -> None:
    scenario = replace(load_scenario("paper-circle"), duration_s=2.0)
    a = _sensor_trace(scenario)
    b = _sensor_trace(scenario)
    assert np.array_equal(a, b)
    c = _sensor_trace(replace(scenario, seed=scenario.seed + 1))
    assert not np.array_equal(a[:, :6], c[:, :6])
    assert np.array_equal(a[:, -3:], c[:, -3:])  # noise does not touch the flight (truth)
    d = _sensor_trace(scenario, rng=np.random.default_rng(scenario.seed))
    assert np.array_equal(a, d)


def test_truth_and_reads_are_consistent() -> None:
    sim = Simulator(load_scenario("hover"))
    sim.advance_to(3.0)
    truth = sim.truth
    assert truth.time_s == pytest.approx(3.0)
    expected_cable = -4.0 * truth.position_ned_m / np.linalg.norm(truth.position_ned_m)
    assert truth.cable_force_ned_n == pytest.approx(expected_cable)
    assert truth.tension_n == 4.0
    # steady hover: specific force = -g in the body frame (thrust + cable = -gravity)
    r = rotation_ned_to_body(*truth.euler_rad)
    assert truth.specific_force_body_mps2 == pytest.approx(r @ [0.0, 0.0, -G], abs=0.02)
    # ... and eq. 20: (thrust + cable) / m
    mass = sim.vehicle.mass_kg
    eq20 = (np.array([0.0, 0.0, -truth.motor_thrust_n.sum()]) + r @ truth.cable_force_ned_n) / mass
    assert truth.specific_force_body_mps2 == pytest.approx(eq20, abs=1e-9)
    pwm = sim.read_pwm()
    assert pwm.time_s == truth.time_s and np.array_equal(pwm.pwm_us, truth.pwm_us)
    assert np.all(pwm.pwm_us == np.round(pwm.pwm_us))
    rangefinder = sim.read_rangefinder()
    assert rangefinder is not None
    assert rangefinder.distance_m == pytest.approx(3.0, abs=5 * math.sqrt(0.1))


def test_takeoff_waypoints_and_landing_from_the_anchor() -> None:
    scenario = load_scenario("waypoints")
    sim = Simulator(scenario)
    assert sim.landed and sim.read_rangefinder() is None  # on the ground: below min range
    visited = set()
    corners = {(3.0, 0.0), (3.0, 3.0), (0.0, 3.0)}
    while sim.time_s < scenario.duration_s:
        sim.advance_to(sim.time_s + 0.1)
        position = sim.truth.position_ned_m
        for corner in corners:
            if math.dist(position[:2], corner) < 0.1 and abs(position[2] + 3.0) < 0.1:
                visited.add(corner)
    assert visited == corners
    assert sim.landed
    assert sim.truth.position_ned_m == pytest.approx([0.0, 0.0, 0.0], abs=0.05)
    assert np.all(sim.read_pwm().pwm_us == sim.vehicle.thrust_curve.pwm_min_us)


def test_tug_pushes_the_drone_and_it_comes_back() -> None:
    sim = Simulator(load_scenario("hover"))
    sim.advance_to(1.0)
    sim.apply_tug((0.0, 6.0, 0.0), 0.5)
    peak = 0.0
    while sim.time_s < 2.0:
        sim.advance_to(sim.time_s + 0.01)
        peak = max(peak, sim.truth.position_ned_m[1])
    assert peak > 0.02
    sim.advance_to(10.0)
    assert sim.truth.position_ned_m == pytest.approx([2.0, 0.0, -3.0], abs=0.03)
    with pytest.raises(ValueError, match="duration"):
        sim.apply_tug((1.0, 0.0, 0.0), 0.0)


def test_release_event_drops_the_cable_and_the_drone_keeps_flying() -> None:
    base = load_scenario("hover")
    sim = Simulator(replace(base, events=(Event(2.0, "release"),)))
    sim.advance_to(1.0)
    assert sim.truth.tension_n == 4.0
    sim.advance_to(10.0)
    truth = sim.truth
    assert truth.tension_n == 0.0 and np.all(truth.cable_force_ned_n == 0.0)
    assert truth.position_ned_m == pytest.approx([2.0, 0.0, -3.0], abs=0.03)
    r = rotation_ned_to_body(*truth.euler_rad)
    assert truth.specific_force_body_mps2 == pytest.approx(r @ [0.0, 0.0, -G], abs=0.02)
    assert abs(truth.euler_rad[1]) < 0.01  # level again: nothing pulls


def test_disarmed_drone_falls_and_lands() -> None:
    sim = Simulator(load_scenario("hover"))
    sim.advance_to(1.0)
    sim.disarm()
    sim.advance_to(3.0)
    assert sim.landed and sim.truth.position_ned_m[2] == 0.0
    sim.arm()
    sim.advance_to(8.0)  # armed again: it takes off back to the hover set-point
    assert sim.truth.position_ned_m == pytest.approx([2.0, 0.0, -3.0], abs=0.1)


def test_navigation_override_is_what_the_controller_flies_on() -> None:
    sim = Simulator(load_scenario("hover"))
    sim.set_setpoint(Setpoint(position_ned_m=(2.0, 0.0, -3.0)))
    offset = np.array([0.5, -0.3, 0.2])
    for k in range(1, 801):
        sim.navigation_position_override = tuple((sim.body.x[:3] + offset).tolist())
        sim.advance_to(k * 0.01)
    # it believes it is at the set-point, so truly it sits at set-point - offset
    assert sim.truth.position_ned_m == pytest.approx(np.array([2.0, 0.0, -3.0]) - offset, abs=0.03)


def test_velocity_setpoint_and_yaw_are_flown() -> None:
    sim = Simulator(load_scenario("hover"))
    sim.set_setpoint(Setpoint(velocity_ned_m_s=(0.0, 0.5, 0.0), yaw_rad=0.5))
    sim.advance_to(6.0)
    truth = sim.truth
    assert truth.velocity_ned_m_s == pytest.approx([0.0, 0.5, 0.0], abs=0.05)
    assert truth.euler_rad[2] == pytest.approx(0.5, abs=0.01)
    assert not sim.follow_trajectory


def test_scenario_events_run_at_their_time() -> None:
    base = load_scenario("hover")
    events = (
        Event(0.5, "set_tension", tension_n=6.0),
        Event(1.0, "tug", force_ned_n=(0, 0, 3.0), duration_s=0.2),
    )
    sim = Simulator(replace(base, events=events))
    sim.advance_to(0.49)
    assert sim.truth.tension_n == 4.0
    sim.advance_to(0.6)
    assert sim.truth.tension_n == 6.0
    sim.advance_to(1.1)
    assert sim.body.tug_force_ned_n == (0.0, 0.0, 3.0)
    sim.advance_to(1.3)
    assert sim.body.tug_force_ned_n == (0.0, 0.0, 0.0)


def test_emulator_style_start_landed_without_trajectory_then_fly_setpoints() -> None:
    base = load_scenario("hover")
    scenario = replace(
        base,
        trajectory=replace(base.trajectory, kind="none"),
        initial=replace(base.initial, airborne=False, armed=False, position_ned_m=(1.0, 0.0, 0.0)),
    )
    sim = Simulator(scenario)
    assert sim.landed and not sim.armed and not sim.follow_trajectory
    sim.advance_to(1.0)
    assert sim.truth.position_ned_m == pytest.approx([1.0, 0.0, 0.0])
    sim.arm()
    sim.set_setpoint(Setpoint(position_ned_m=(1.0, 0.0, -2.0)))
    sim.advance_to(8.0)
    assert not sim.landed
    assert sim.truth.position_ned_m == pytest.approx([1.0, 0.0, -2.0], abs=0.03)
    sim.set_setpoint(Setpoint(position_ned_m=(1.0, 0.0, 0.0)))  # land
    sim.advance_to(16.0)
    assert sim.landed


# --------------------------------------------------------------------------- run-time changes


def test_state_accessors_agree_with_truth() -> None:
    sim = Simulator(load_scenario("paper-circle"))
    sim.advance_to(2.0)
    truth = sim.truth
    assert sim.position_ned_m == tuple(truth.position_ned_m)
    assert sim.velocity_ned_m_s == tuple(truth.velocity_ned_m_s)
    assert sim.euler_rad == tuple(truth.euler_rad)
    assert sim.body_rates_rad_s == tuple(truth.body_rates_rad_s)
    assert sim.specific_force_body_mps2 == tuple(truth.specific_force_body_mps2)


def test_resume_trajectory_flies_the_scenario_again() -> None:
    sim = Simulator(load_scenario("hover"))
    assert sim.follow_trajectory
    sim.set_setpoint(Setpoint(position_ned_m=(0.0, 1.0, -2.0)))
    sim.advance_to(6.0)
    assert sim.position_ned_m == pytest.approx((0.0, 1.0, -2.0), abs=0.05)
    sim.resume_trajectory()
    assert sim.follow_trajectory
    sim.advance_to(14.0)
    assert sim.position_ned_m == pytest.approx((2.0, 0.0, -3.0), abs=0.05)


def test_wind_set_at_run_time_is_flown_against() -> None:
    scenario = load_scenario("hover")
    draggy = replace(load_vehicle(scenario.vehicle), drag_coefficient_n_s_per_m=0.3)
    sim = Simulator(scenario, vehicle=draggy)
    sim.advance_to(3.0)
    calm_roll_rad = sim.euler_rad[0]
    sim.set_wind_ned_m_s([0.0, 5.0, 0.0])
    assert sim.wind_ned_m_s == (0.0, 5.0, 0.0)
    sim.advance_to(15.0)
    # drag pushes east; the controller holds position by banking west (roll left, negative)
    assert sim.position_ned_m == pytest.approx((2.0, 0.0, -3.0), abs=0.05)
    assert sim.euler_rad[0] < calm_roll_rad - 0.01
    with pytest.raises(ValueError):
        sim.set_wind_ned_m_s([1.0, 2.0])


def test_sensor_config_set_at_run_time_is_read_with_its_vibration_frequency() -> None:
    base = load_scenario("hover")
    scenario = replace(
        base,
        trajectory=replace(base.trajectory, kind="none"),
        initial=replace(base.initial, airborne=False, armed=False),
    )
    sim = Simulator(scenario)  # resting on the ground: the true specific force is constant
    quiet = SensorConfig(
        accel_noise_std_mps2=0.0,
        gyro_noise_std_rad_s=0.0,
        accel_vibration_amplitude_mps2=1.0,
        accel_vibration_frequency_hz=50.0,
    )
    sim.set_sensor_config(quiet)
    assert sim.sensor_config is quiet
    sim.advance_to(1.0)

    def vibration() -> np.ndarray:
        return sim.read_imu().specific_force_body_mps2 - sim.truth.specific_force_body_mps2

    start = vibration()
    assert np.abs(start).max() > 0.1
    sim.advance_to(1.01)  # half a period of 50 Hz
    assert vibration() == pytest.approx(-start, abs=1e-9)
    sim.advance_to(1.02)
    assert vibration() == pytest.approx(start, abs=1e-9)


def test_replace_cable_pulls_with_the_new_cable_at_once() -> None:
    sim = Simulator(load_scenario("hover"))
    sim.advance_to(2.0)
    before = np.array(sim.specific_force_body_mps2)
    old_force = sim.truth.cable_force_ned_n
    sim.replace_cable(replace(sim.scenario.cable, tension_n=10.0))
    new_force = sim.truth.cable_force_ned_n
    assert np.linalg.norm(new_force) == pytest.approx(10.0)
    roll, pitch, yaw = sim.euler_rad
    expected = (
        rotation_ned_to_body(roll, pitch, yaw) @ (new_force - old_force) / sim.vehicle.mass_kg
    )
    assert np.array(sim.specific_force_body_mps2) - before == pytest.approx(expected, abs=1e-9)
    sim.replace_cable(replace(sim.scenario.cable, model="elastic", length_m=4.0))
    sim.set_paid_out_m(4.5)
    assert sim.cable.paid_out_m == 4.5 and not sim.cable.released


def _streams(sim: Simulator, seconds: float) -> list[tuple]:
    """Every IMU sample, true tension and position at 200 Hz, and a tension set-point
    changed mid-flight (between an IMU read and the next step; the tension read again)."""
    rows = []
    for k in range(1, int(seconds * 200) + 1):
        sim.advance_to(k * 0.005)
        imu = sim.read_imu()
        rows.append((*imu.specific_force_body_mps2.tolist(), sim.tension_n, *sim.position_ned_m))
        if k == 100 and sim.scenario.cable.model == "constant_tension":
            sim.set_tension_n(5.0)
            rows.append((sim.tension_n,))  # the new set-point's, at the same state
    return rows


@pytest.mark.parametrize("name", ["paper-circle", "elastic-hover", "realistic-gusty-hover"])
def test_reused_evaluations_give_the_same_flight_bit_for_bit(name: str) -> None:
    """The IMU read's forces reused for the true tension and the next RK4 step's first stage
    (a history-free cable) change nothing: the same streams as a simulator told its cable has
    a history (every evaluation made afresh, in the usual order)."""
    scenario = replace(load_scenario(name), duration_s=1.5)
    reusing, fresh = Simulator(scenario), Simulator(scenario)
    assert reusing.cable.history_free
    fresh.cable.history_free = False
    fresh.body.force_history_free = False
    assert _streams(reusing, 1.5) == _streams(fresh, 1.5)


def test_a_catenary_cable_is_not_history_free() -> None:
    """The stretched catenary's root search starts from its last answer: its forces are
    evaluated every time (reusing one would move the flight in the last digits)."""
    sim = Simulator(replace(load_scenario("catenary-hover"), duration_s=0.1))
    assert not sim.cable.history_free and not sim.body.force_history_free
