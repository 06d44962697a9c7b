"""Rotor drag identified from a log with velocity: a simulated identification flight of a
vehicle with known drag, recorded as a .tlog with LOCAL_POSITION_NED, gives the coefficient
back; without velocity there is no fit."""

from __future__ import annotations

import contextlib
import dataclasses

import numpy as np
import pytest

from tether_companion.mavlink.framing import dialect
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.simulator import Simulator
from tether_companion.sysid.drag import identify_drag
from tether_companion.sysid.flight import FlightPlan, fly, identification_scenario
from tether_companion.sysid.logs import load_flight_log
from tether_companion.sysid.recorders import TlogRecorder

MU_PER_S = 0.4


@pytest.fixture(scope="module")
def flight_with_velocity(tmp_path_factory):
    plan = FlightPlan(cycle_amplitudes=(1.0, 1.3))
    vehicle = dataclasses.replace(load_vehicle("default-quad"), rotor_drag_per_s=MU_PER_S)
    simulator = Simulator(identification_scenario(plan), vehicle, rng=np.random.default_rng(7))
    path = tmp_path_factory.mktemp("drag") / "flight.tlog"
    sensors = simulator.scenario.sensors
    recorder = TlogRecorder(path, (sensors.range_min_m, sensors.range_max_m))
    with contextlib.closing(recorder):
        for k, tick in enumerate(fly(plan, simulator)):
            recorder.write(*tick)
            if k % 4 == 0:  # LOCAL_POSITION_NED at a quarter of the IMU rate, as streamed
                truth = simulator.truth
                p, v = truth.position_ned_m, truth.velocity_ned_m_s
                msg = dialect.MAVLink_local_position_ned_message(int(truth.time_s * 1e3), *p, *v)
                recorder._put(truth.time_s, msg)  # noqa: SLF001 - a test adds one stream
    return path, vehicle


def test_drag_coefficient_is_recovered(flight_with_velocity) -> None:
    path, vehicle = flight_with_velocity
    log = load_flight_log(path)
    assert log.velocity_ned_mps is not None and len(log.velocity_ned_mps) > 100
    fit = identify_drag(log, vehicle.mass_kg)
    assert fit is not None and fit.samples >= 50
    assert fit.mu_per_s == pytest.approx(MU_PER_S, rel=0.15)
    assert fit.coefficient_n_s_per_m == pytest.approx(MU_PER_S * vehicle.mass_kg, rel=0.15)


def test_no_velocity_no_drag(flight_with_velocity) -> None:
    path, vehicle = flight_with_velocity
    log = dataclasses.replace(load_flight_log(path), velocity_ned_mps=None)
    assert identify_drag(log, vehicle.mass_kg) is None


def test_cli_writes_the_profile_with_the_identified_drag(flight_with_velocity, tmp_path) -> None:
    from tether_companion.cli import main

    path, _ = flight_with_velocity
    out = tmp_path / "with-drag.yaml"
    args = ["sysid", str(path), "--structure", "static", "--profile-out", str(out)]
    assert main(args) == 0
    assert load_vehicle(out).rotor_drag_per_s == pytest.approx(MU_PER_S, rel=0.15)
