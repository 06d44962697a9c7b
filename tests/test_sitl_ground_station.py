"""The ArduPilot SITL ground station's winch and cable-angle sensor (ardupilot_sitl/
ground_station.py) report what the offline simulator's sensors (sim/ground_sensors.py) report
of SITL's truth: one error model, configured by a ``ground_station`` section, seeded. No SITL
needed: the truth is handed in as the reader thread would."""

from __future__ import annotations

import dataclasses
import math
import os

import pytest
from pymavlink import mavutil

from tether_companion.ardupilot_sitl.ground_station import (
    ANGLE_COMPONENT,
    GCS_SYSTEM,
    WINCH_COMPONENT,
    GroundStation,
)
from tether_companion.ardupilot_sitl.telemetry import Telemetry
from tether_companion.sim.ground_sensors import GroundSensorConfig, GroundSensors

REALISTIC = GroundSensorConfig(enabled=True)
LINE_M = 6.0


@pytest.fixture(autouse=True)
def _mavlink2():
    """pymavlink's MAVLink 2 dialect, as on SITL's link (the connection switches to it at the
    first MAVLink 2 frame; WINCH_STATUS has no MAVLink 1 form); restored afterwards."""
    before_env, before_dialect = os.environ.get("MAVLINK20"), mavutil.current_dialect
    os.environ["MAVLINK20"] = "1"
    mavutil.set_dialect(before_dialect)
    yield
    if before_env is None:
        del os.environ["MAVLINK20"]
    else:
        os.environ["MAVLINK20"] = before_env
    mavutil.set_dialect(before_dialect)


def _station() -> GroundStation:
    """A GroundStation without a socket or threads (only what the sensors use)."""
    gcs = GroundStation.__new__(GroundStation)
    gcs.telemetry = Telemetry()
    gcs.line_length_m = LINE_M
    gcs.winch_sent = gcs.angle_sent = 0
    return gcs


def _truth(t: float) -> tuple[float, float, float]:
    """A slow circle 7 m out, 4 m up (taut: beyond the 6 m line)."""
    return (6.0 * math.cos(0.1 * t), 6.0 * math.sin(0.1 * t), -4.0 - 0.1 * t)


def _fly(config: GroundSensorConfig, seed: int, seconds: float = 3.0):
    """SIM_STATE at 25 Hz recorded at the autopilot's time; a report of each sensor at every
    fifth truth. Returns (sensors, [(winch message, angle message, offline length, offline
    angle, true distance)])."""
    gcs = _station()
    tel = gcs.telemetry
    sensors = GroundSensors(config, "constant_tension", seed)
    offline = GroundSensors(config, "constant_tension", seed)
    tel.ground_sensors = sensors
    winch = mavutil.mavlink.MAVLink(None, srcSystem=GCS_SYSTEM, srcComponent=WINCH_COMPONENT)
    angle = mavutil.mavlink.MAVLink(None, srcSystem=GCS_SYSTEM, srcComponent=ANGLE_COMPONENT)
    decoder = mavutil.mavlink.MAVLink(None)
    out = []
    for k in range(round(seconds * 25)):
        tel.fc_s = 0.04 * k
        p = _truth(tel.fc_s)
        gcs._record_truth(tel, p)
        distance = math.dist(p, (0.0, 0.0, 0.0))
        offline.record(tel.fc_s, max(LINE_M, distance), p, 0.0)
        if k % 5 == 4:
            w = decoder.decode(bytearray(gcs._winch_frame(winch, sensors)))
            a = decoder.decode(bytearray(gcs._angle_frame(angle, sensors)))
            want_angle = offline.cable_angle_rad(
                tel.fc_s, lambda q: tuple(v / math.dist(q, (0, 0, 0)) for v in q)
            )
            out.append((w, a, offline.winch_length_m(tel.fc_s), want_angle, distance))
    return sensors, out


def test_realistic_reports_are_the_offline_sensors_with_the_flights_calibration():
    sensors, reports = _fly(REALISTIC, seed=4)
    assert len(reports) == 15
    for winch, angle, want_length, want_angle, _ in reports:
        assert winch.line_length == pytest.approx(want_length, abs=1e-5)
        assert (angle.x, angle.y) == pytest.approx(want_angle, abs=1e-6)
        assert (winch.get_srcSystem(), winch.get_srcComponent()) == (GCS_SYSTEM, WINCH_COMPONENT)
    calibration = sensors.calibration  # seed 4: the encoder 1.8 % short, 1.6 deg of azimuth
    assert calibration == GroundSensors(REALISTIC, "constant_tension", 4).calibration
    for winch, _, _, _, distance in reports[1:]:
        assert winch.line_length - distance < -0.1  # 1.8 % of 7.2 m
    azimuth_errors = []
    for i, (_, angle, _, _, _) in enumerate(reports):
        north, east, _ = _truth(0.2 * i + 0.08)  # the last truth 0.05 s (latency) before
        azimuth_errors.append(math.remainder(angle.x - math.atan2(east, north), math.tau))
    mean = sum(azimuth_errors) / len(azimuth_errors)
    assert mean == pytest.approx(calibration.azimuth_bias_rad, abs=0.006)


def test_off_the_winch_reports_the_exact_stiff_tether_length():
    _, reports = _fly(dataclasses.replace(REALISTIC, enabled=False), seed=4)
    for winch, _, _, _, distance in reports:
        assert winch.line_length == pytest.approx(distance, abs=1e-5)


def test_a_short_tether_reports_the_line_length_not_the_distance():
    gcs = _station()
    gcs.line_length_m = 20.0
    sensors = GroundSensors(GroundSensorConfig(), "constant_tension", 1)
    gcs.telemetry.ground_sensors = sensors
    gcs._record_truth(gcs.telemetry, (3.0, 0.0, -4.0))
    assert sensors.winch_length_m(0.0) == 20.0
