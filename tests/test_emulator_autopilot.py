"""The flight controller in lock-step: commands, modes, parameters, streams, navigation, scoring.

Everything passes through real MAVLink frames (LockstepPeer) but time only moves when the test
says, so nothing here depends on the machine's speed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.emulator.lockstep import LockstepPeer, build_controller
from tether_companion.emulator.modes import CopterMode
from tether_companion.mavlink import estimates, units
from tether_companion.mavlink.framing import dialect
from tether_companion.physics.cable import CABLE_MODELS

ACCEPTED = dialect.MAV_RESULT_ACCEPTED
DENIED = dialect.MAV_RESULT_DENIED
FAILED = dialect.MAV_RESULT_FAILED
UNSUPPORTED = dialect.MAV_RESULT_UNSUPPORTED
ARM = dialect.MAV_CMD_COMPONENT_ARM_DISARM
CUSTOM = dialect.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
POSITION_ONLY = 0b110111111000  # use x, y, z; ignore velocity, acceleration, yaw, yaw rate
HOME = (32.2828, -106.7478, 1200.0)


def truth(fc):
    return fc.sim.truth.position_ned_m


def set_mode(gcs: LockstepPeer, mode: CopterMode) -> int:
    return gcs.command(dialect.MAV_CMD_DO_SET_MODE, CUSTOM, int(mode))


def param_set(gcs: LockstepPeer, name: str, value: float):
    gcs.received.clear()
    gcs.send(
        dialect.MAVLink_param_set_message(1, 1, name.encode(), value, dialect.MAV_PARAM_TYPE_REAL32)
    )
    values = [m for m in gcs.received if m.get_type() == "PARAM_VALUE" and m.param_id == name]
    return values[-1] if values else None


def vision(fc, position, reset_counter=0, stamp_s=None):
    est = estimates.PoseEstimate(
        fc.boot_time_s if stamp_s is None else stamp_s,
        np.asarray(position, dtype=float),
        tuple(float(a) for a in fc.sim.truth.euler_rad),
        np.eye(6) * 0.01,
        reset_counter,
    )
    return estimates.vision_position_estimate_message(est)


def set_origin(gcs: LockstepPeer):
    lat, lon, alt = HOME
    gcs.send(
        dialect.MAVLink_set_gps_global_origin_message(
            1, int(lat * 1e7), int(lon * 1e7), int(alt * 1e3), 0
        )
    )


# --------------------------------------------------------------------------- flying


def test_guided_flight_arm_takeoff_goto_land_disarm() -> None:
    fc = build_controller("hover", landed=True)
    gcs = LockstepPeer(fc)
    assert fc.mode == CopterMode.STABILIZE and not fc.armed and fc.sim.landed
    assert set_mode(gcs, CopterMode.GUIDED) == ACCEPTED
    assert gcs.command(dialect.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5.0) == FAILED  # not armed
    assert "Takeoff: arm first" in gcs.texts()
    assert gcs.command(ARM, 1) == ACCEPTED
    assert gcs.command(dialect.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5.0) == ACCEPTED
    gcs.advance(12.0)
    assert truth(fc)[2] == pytest.approx(-5.0, abs=0.2) and not fc.taking_off
    gcs.send(
        dialect.MAVLink_set_position_target_local_ned_message(
            0,
            1,
            1,
            dialect.MAV_FRAME_LOCAL_NED,
            POSITION_ONLY,
            3.0,
            2.0,
            -5.0,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
        )
    )
    gcs.advance(10.0)
    np.testing.assert_allclose(truth(fc), [3.0, 2.0, -5.0], atol=0.2)
    assert gcs.command(ARM, 0) == FAILED and "Disarm: vehicle is flying" in gcs.texts()
    assert gcs.command(dialect.MAV_CMD_NAV_LAND) == ACCEPTED and fc.mode == CopterMode.LAND
    gcs.advance(20.0)
    assert fc.sim.landed and not fc.armed
    np.testing.assert_allclose(truth(fc)[:2], [3.0, 2.0], atol=0.3)
    states = [m.landed_state for m in gcs.received if m.get_type() == "EXTENDED_SYS_STATE"]
    for state in (
        dialect.MAV_LANDED_STATE_ON_GROUND,
        dialect.MAV_LANDED_STATE_TAKEOFF,
        dialect.MAV_LANDED_STATE_IN_AIR,
        dialect.MAV_LANDED_STATE_LANDING,
    ):
        assert state in states


def test_heartbeat_reflects_mode_and_arming() -> None:
    fc = build_controller("hover", landed=True)
    gcs = LockstepPeer(fc)
    gcs.advance(0.01)
    hb = gcs.last("HEARTBEAT")
    assert (hb.type, hb.autopilot) == (
        dialect.MAV_TYPE_QUADROTOR,
        dialect.MAV_AUTOPILOT_ARDUPILOTMEGA,
    )
    assert (
        hb.custom_mode == CopterMode.STABILIZE
        and not hb.base_mode & dialect.MAV_MODE_FLAG_SAFETY_ARMED
    )
    assert hb.system_status == dialect.MAV_STATE_STANDBY
    set_mode(gcs, CopterMode.GUIDED)
    gcs.command(ARM, 1)
    gcs.advance(1.0)
    hb = gcs.last("HEARTBEAT")
    assert hb.custom_mode == CopterMode.GUIDED
    assert (
        hb.base_mode & dialect.MAV_MODE_FLAG_SAFETY_ARMED
        and hb.base_mode & dialect.MAV_MODE_FLAG_GUIDED_ENABLED
    )
    assert hb.system_status == dialect.MAV_STATE_ACTIVE


def test_airborne_scenario_flies_its_trajectory_in_auto() -> None:
    fc = build_controller("paper-circle")
    gcs = LockstepPeer(fc)
    assert fc.mode == CopterMode.AUTO and fc.armed
    gcs.advance(5.0)
    p = truth(fc)
    assert math.hypot(p[0], p[1]) == pytest.approx(2.5, abs=0.3)
    assert gcs.last("HEARTBEAT").custom_mode == CopterMode.AUTO


def test_rtl_returns_over_the_anchor_and_lands() -> None:
    fc = build_controller("hover")  # hovering 2 m north, 3 m up
    gcs = LockstepPeer(fc)
    assert gcs.command(dialect.MAV_CMD_NAV_RETURN_TO_LAUNCH) == ACCEPTED
    gcs.advance(25.0)
    assert fc.sim.landed and not fc.armed
    assert np.linalg.norm(truth(fc)[:2]) < 0.6


def test_auto_disarm_after_sitting_landed() -> None:
    fc = build_controller("hover", landed=True)
    gcs = LockstepPeer(fc)
    set_mode(gcs, CopterMode.GUIDED)
    gcs.command(ARM, 1)
    gcs.advance(9.0)
    assert fc.armed
    gcs.advance(2.0)
    assert not fc.armed and "Disarming motors (landed)" in gcs.texts()


# --------------------------------------------------------------------------- refusals


def test_prearm_refusals_are_explained() -> None:
    fc = build_controller("hover", landed=True, emulator={"navigation": "vision"})
    gcs = LockstepPeer(fc)
    assert gcs.command(ARM, 1) == FAILED
    assert "PreArm: EKF3 waiting for origin" in gcs.texts()
    set_origin(gcs)
    assert gcs.command(ARM, 1) == FAILED and "PreArm: VisOdom: not healthy" in gcs.texts()
    assert gcs.command(ARM, 1, 21196) == ACCEPTED  # forced
    assert gcs.command(ARM, 0) == ACCEPTED
    fc2 = build_controller("hover", landed=True)
    gcs2 = LockstepPeer(fc2)
    assert set_mode(gcs2, CopterMode.LAND) == ACCEPTED
    assert gcs2.command(ARM, 1) == FAILED and "Arm: Mode not armable" in gcs2.texts()


def test_bad_parameters_get_denied_unknown_commands_unsupported() -> None:
    fc = build_controller("hover", landed=True)
    gcs = LockstepPeer(fc)
    nan = math.nan
    assert gcs.command(ARM, nan) == DENIED
    assert gcs.command(ARM, 0.5) == DENIED
    assert gcs.command(ARM, math.inf) == DENIED
    assert set_mode(gcs, CopterMode.GUIDED) == ACCEPTED
    gcs.command(ARM, 1)
    for altitude in (nan, -5.0, 0.0, 1e9, math.inf):
        assert gcs.command(dialect.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, altitude) == DENIED
    assert gcs.command(dialect.MAV_CMD_DO_SET_MODE, CUSTOM, 99) == DENIED
    assert gcs.command(dialect.MAV_CMD_DO_SET_MODE, CUSTOM, nan) == DENIED
    assert gcs.command(dialect.MAV_CMD_DO_SET_MODE, 0, 4) == DENIED  # no custom-mode flag
    assert gcs.command(dialect.MAV_CMD_SET_MESSAGE_INTERVAL, 27, nan) == DENIED
    assert gcs.command(dialect.MAV_CMD_SET_MESSAGE_INTERVAL, 27, -7) == DENIED
    assert gcs.command(dialect.MAV_CMD_SET_MESSAGE_INTERVAL, 99999, 1000) == DENIED
    assert gcs.command(dialect.MAV_CMD_REQUEST_MESSAGE, nan) == DENIED
    assert gcs.command(dialect.MAV_CMD_REQUEST_MESSAGE, 12345) == DENIED
    assert gcs.command(dialect.MAV_CMD_USER_1, nan, 0, 0, 1.0) == DENIED  # tug
    assert gcs.command(dialect.MAV_CMD_USER_1, 5, 0, 0, -1.0) == DENIED
    assert gcs.command(dialect.MAV_CMD_USER_2, 0.0) == DENIED  # release needs param1 = 1
    assert gcs.command(dialect.MAV_CMD_USER_3, -1.0) == DENIED  # negative tension
    assert gcs.command(dialect.MAV_CMD_DO_WINCH, 1, 2, 0, nan) == DENIED
    assert gcs.command(dialect.MAV_CMD_DO_FLIGHTTERMINATION, 1) == UNSUPPORTED
    assert gcs.command(dialect.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1) == FAILED  # armed
    assert fc.armed and fc.mode == CopterMode.GUIDED and fc.counters.handler_errors == 0


def test_position_mode_needs_a_position_estimate() -> None:
    fc = build_controller("hover", landed=True, emulator={"navigation": "vision"})
    gcs = LockstepPeer(fc)
    assert set_mode(gcs, CopterMode.GUIDED) == FAILED
    assert "Mode change to GUIDED failed: requires position" in gcs.texts()
    assert set_mode(gcs, CopterMode.ALT_HOLD) == ACCEPTED


def test_messages_for_other_systems_are_ignored_and_counted() -> None:
    fc = build_controller("hover", landed=True)
    gcs = LockstepPeer(fc)
    gcs.send(dialect.MAVLink_command_long_message(7, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0))
    gcs.send(dialect.MAVLink_command_long_message(1, 100, ARM, 0, 1, 0, 0, 0, 0, 0, 0))  # a camera
    gcs.send(dialect.MAVLink_param_set_message(9, 1, b"TETH_TENSION", 1.0, 9))
    assert fc.counters.other_target == 3
    assert not fc.armed and fc.params.value("TETH_TENSION") == 4.0
    assert not [m for m in gcs.received if m.get_type() == "COMMAND_ACK"]


def test_set_mode_message_gets_an_ack() -> None:
    fc = build_controller("hover", landed=True)
    gcs = LockstepPeer(fc)
    gcs.send(dialect.MAVLink_set_mode_message(1, CUSTOM, int(CopterMode.LOITER)))
    ack = gcs.last("COMMAND_ACK")
    assert ack.command == dialect.MAVLINK_MSG_ID_SET_MODE and ack.result == ACCEPTED
    assert fc.mode == CopterMode.LOITER


def test_targets_outside_guided_or_with_nan_are_ignored() -> None:
    fc = build_controller("hover")
    gcs = LockstepPeer(fc)
    set_mode(gcs, CopterMode.LOITER)
    before = truth(fc).copy()
    target = dialect.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, dialect.MAV_FRAME_LOCAL_NED, POSITION_ONLY, 10.0, 0.0, -3.0, 0, 0, 0, 0, 0, 0, 0, 0
    )
    gcs.send(target)
    assert fc.counters.ignored == 1
    set_mode(gcs, CopterMode.GUIDED)
    target.x = math.nan
    gcs.send(target)
    assert fc.counters.bad_values == 1
    gcs.advance(3.0)
    np.testing.assert_allclose(truth(fc), before, atol=0.2)


# --------------------------------------------------------------------------- parameters


def test_parameter_protocol_lists_reads_and_sets() -> None:
    fc = build_controller("hover")
    gcs = LockstepPeer(fc)
    gcs.send(dialect.MAVLink_param_request_list_message(1, 1))
    values = [m for m in gcs.received if m.get_type() == "PARAM_VALUE"]
    assert len(values) == len(fc.params) and sorted(v.param_index for v in values) == list(
        range(len(values))
    )
    assert {v.param_count for v in values} == {len(fc.params)}
    gcs.received.clear()
    gcs.send(dialect.MAVLink_param_request_read_message(1, 1, b"SIM_WIND_N", -1))
    assert gcs.last("PARAM_VALUE").param_id == "SIM_WIND_N"
    gcs.send(dialect.MAVLink_param_request_read_message(1, 1, b"", 0))
    assert gcs.last("PARAM_VALUE").param_index == 0
    gcs.received.clear()
    gcs.send(dialect.MAVLink_param_request_read_message(1, 1, b"NO_SUCH_PARAM", -1))
    assert gcs.last("PARAM_VALUE") is None


def test_tension_parameter_changes_the_simulated_cable() -> None:
    fc = build_controller("hover")
    gcs = LockstepPeer(fc)
    gcs.advance(1.0)
    assert fc.sim.truth.tension_n == pytest.approx(4.0)
    assert param_set(gcs, "TETH_TENSION", 9.0).param_value == 9.0
    gcs.advance(0.5)
    truth_state = fc.sim.truth
    assert truth_state.tension_n == pytest.approx(9.0)
    assert np.linalg.norm(truth_state.cable_force_ned_n) == pytest.approx(9.0)
    gcs.advance(5.0)
    np.testing.assert_allclose(truth(fc), [2.0, 0.0, -3.0], atol=0.3)  # the integrator holds it


@pytest.mark.parametrize("value", [math.nan, math.inf, -1.0, 1e6])
def test_bad_parameter_values_are_refused_with_the_old_value(value: float) -> None:
    fc = build_controller("hover")
    gcs = LockstepPeer(fc)
    reply = param_set(gcs, "TETH_TENSION", value)
    assert reply.param_value == 4.0 and fc.sim.truth.tension_n == 4.0
    assert any(t.startswith("TETH_TENSION:") for t in gcs.texts())


def test_read_only_integer_and_model_dependent_parameters() -> None:
    fc = build_controller("hover")
    gcs = LockstepPeer(fc)
    assert param_set(gcs, "SYSID_THISMAV", 5).param_value == 1
    elastic = CABLE_MODELS.index("elastic")
    assert param_set(gcs, "TETH_MODEL", elastic + 0.5).param_value == 0  # whole numbers only
    assert param_set(gcs, "TETH_MODEL", elastic).param_value == elastic
    assert type(fc.sim.cable).__name__ == "ElasticCable"
    assert param_set(gcs, "TETH_TENSION", 3.0).param_value == 4.0  # not a constant-tension winch
    assert param_set(gcs, "TETH_RELEASE", 1).param_value == 1
    gcs.advance(0.1)
    assert fc.sim.truth.tension_n == 0.0
    assert param_set(gcs, "EK3_SRC1_POSXY", 4).param_value == 3  # neither GPS nor ExternalNav


def test_noise_and_wind_parameters_reach_the_simulation() -> None:
    fc = build_controller("hover")
    gcs = LockstepPeer(fc)
    param_set(gcs, "SIM_ACC_NOISE", 0.0)
    param_set(gcs, "SIM_GYR_NOISE", 0.0)
    gcs.received.clear()
    gcs.advance(0.2)
    imu = [m for m in gcs.received if m.get_type() == "RAW_IMU"]
    accs = np.array([[m.xacc, m.yacc, m.zacc] for m in imu])
    assert np.ptp(accs, axis=0).max() <= 2  # only quantisation and slow motion left
    param_set(gcs, "SIM_WIND_E", 5.0)
    assert fc.sim.wind_ned_m_s == (0.0, 5.0, 0.0)


# --------------------------------------------------------------------------- streams


def test_default_streams_hold_their_rates_in_emulator_time() -> None:
    fc = build_controller("paper-circle")
    gcs = LockstepPeer(fc)
    gcs.advance(10.0)
    counts = gcs.counts()
    expected = {
        "RAW_IMU": 200,
        "ATTITUDE": 200,
        "SERVO_OUTPUT_RAW": 200,
        "DISTANCE_SENSOR": 200,
        "HEARTBEAT": 1,
        "SYS_STATUS": 1,
        "LOCAL_POSITION_NED": 10,
        "GLOBAL_POSITION_INT": 10,
        "SIM_STATE": 50,
        "SYSTEM_TIME": 1,
        "VFR_HUD": 4,
    }
    for name, rate in expected.items():
        assert counts[name] == 10 * rate + 1, name  # both ends included
    stamps = [m.time_usec for m in gcs.received if m.get_type() == "RAW_IMU"]
    assert set(np.diff(stamps)) == {5000}


def test_message_interval_and_data_stream_requests_are_per_link() -> None:
    fc = build_controller("hover")
    gcs = LockstepPeer(fc)
    companion = LockstepPeer(fc, system_id=1, component_id=197)
    assert gcs.command(dialect.MAV_CMD_SET_MESSAGE_INTERVAL, 27, 10_000) == ACCEPTED  # 100 Hz
    assert gcs.command(dialect.MAV_CMD_SET_MESSAGE_INTERVAL, 30, -1) == ACCEPTED  # ATTITUDE off
    gcs.send(
        dialect.MAVLink_request_data_stream_message(1, 1, dialect.MAV_DATA_STREAM_POSITION, 2, 1)
    )
    gcs.received.clear()
    companion.received.clear()
    gcs.advance(2.0)
    mine, theirs = gcs.counts(), companion.counts()
    assert (mine["RAW_IMU"], mine["ATTITUDE"], mine["LOCAL_POSITION_NED"]) == (201, 0, 5)
    assert (theirs["RAW_IMU"], theirs["ATTITUDE"], theirs["LOCAL_POSITION_NED"]) == (401, 401, 21)
    gcs.received.clear()
    assert gcs.command(dialect.MAV_CMD_GET_MESSAGE_INTERVAL, 27) == ACCEPTED
    assert gcs.last("MESSAGE_INTERVAL").interval_us == 10_000
    assert gcs.command(dialect.MAV_CMD_SET_MESSAGE_INTERVAL, 27, 0) == ACCEPTED  # default again
    assert fc.stream_rate_hz(gcs.link_id, "RAW_IMU") == 200


def test_request_message_autopilot_version_home_and_origin() -> None:
    fc = build_controller("hover", emulator={"navigation": "vision"})
    gcs = LockstepPeer(fc)
    assert (
        gcs.command(dialect.MAV_CMD_REQUEST_MESSAGE, dialect.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
        == ACCEPTED
    )
    version = gcs.last("AUTOPILOT_VERSION")
    assert version.capabilities & dialect.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert version.flight_sw_version >> 24 == 4
    assert (
        gcs.command(dialect.MAV_CMD_REQUEST_MESSAGE, dialect.MAVLINK_MSG_ID_HOME_POSITION)
        == ACCEPTED
    )
    home = gcs.last("HOME_POSITION")
    assert home.latitude == int(HOME[0] * 1e7)
    assert (
        gcs.command(dialect.MAV_CMD_REQUEST_MESSAGE, dialect.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)
        == FAILED
    )
    set_origin(gcs)
    origin = gcs.last("GPS_GLOBAL_ORIGIN")
    assert origin.latitude == int(HOME[0] * 1e7) and origin.altitude == int(HOME[2] * 1e3)
    assert "EKF3 origin set" in gcs.texts()


def test_timesync_is_answered_in_boot_time() -> None:
    fc = build_controller("hover")
    gcs = LockstepPeer(fc)
    gcs.advance(2.0)
    gcs.send(dialect.MAVLink_timesync_message(0, 123456789))
    reply = gcs.last("TIMESYNC")
    assert reply.ts1 == 123456789 and reply.tc1 == pytest.approx(2e9, abs=1e6)


# --------------------------------------------------------------------------- vision navigation


def test_vision_navigation_flies_on_the_estimates_and_drifts_with_a_bias() -> None:
    fc = build_controller("hover", emulator={"navigation": "vision"})
    gcs = LockstepPeer(fc)
    gcs.send(vision(fc, truth(fc)))
    assert fc.nav.counters.ignored_no_origin == 1
    set_origin(gcs)
    bias = np.array([1.0, -0.5, 0.0])
    for _ in range(300):  # 10 s of estimates at 30 Hz, each 1 m north / 0.5 m west of the truth
        gcs.send(vision(fc, truth(fc) + bias))
        gcs.advance(1 / 30)
    assert "EKF3 IMU0 is using external nav data" in gcs.texts()
    # the controller holds the *estimate* at the hover point, so the truth sits off by -bias
    np.testing.assert_allclose(truth(fc), np.array([2.0, 0.0, -3.0]) - bias, atol=0.15)
    local = gcs.last("LOCAL_POSITION_NED")
    np.testing.assert_allclose([local.x, local.y, local.z], [2.0, 0.0, -3.0], atol=0.15)


def test_vision_reset_counter_and_timeout_lead_to_failsafe_land() -> None:
    fc = build_controller("hover", emulator={"navigation": "vision"})
    gcs = LockstepPeer(fc)
    set_origin(gcs)
    for _ in range(30):
        gcs.send(vision(fc, truth(fc)))
        gcs.advance(1 / 30)
    used = fc.nav.counters.used
    gcs.send(vision(fc, truth(fc), reset_counter=1))
    gcs.advance(0.5)
    gcs.send(vision(fc, truth(fc), reset_counter=1))
    assert fc.nav.counters.resets == 1 and fc.nav.counters.ignored_after_reset == 2
    assert fc.nav.counters.used == used
    gcs.advance(0.5)  # > 300 ms since the last used estimate: lost
    assert fc.failsafe and fc.mode == CopterMode.LAND
    assert "EKF Failsafe: lost external nav, LAND" in gcs.texts()
    assert gcs.last("HEARTBEAT") is not None
    gcs.advance(15.0)
    assert fc.sim.landed


def test_attitude_mismatch_blocks_arming_in_vision_mode() -> None:
    fc = build_controller("hover", landed=True, emulator={"navigation": "vision"})
    gcs = LockstepPeer(fc)
    set_origin(gcs)
    est = estimates.PoseEstimate(fc.boot_time_s, truth(fc), (0.0, 0.0, math.radians(30)), None, 0)
    gcs.send(estimates.vision_position_estimate_message(est))
    assert gcs.command(ARM, 1) == FAILED
    assert any(t.startswith("PreArm: VisOdom: attitude differs by 30 deg") for t in gcs.texts())


# --------------------------------------------------------------------------- scoring


def test_score_of_exact_and_biased_estimates() -> None:
    fc = build_controller("paper-circle")
    gcs = LockstepPeer(fc)
    gcs.advance(1.0)
    for _ in range(90):
        stamp = fc.boot_time_s - 0.02  # 20 ms old: matched at its own time, not at arrival
        position = fc.truth_history.at(fc.time_s - 0.02) + np.array([0.3, 0.0, -0.4])
        gcs.send(vision(fc, position, stamp_s=stamp))
        gcs.advance(1 / 30)
    gcs.send(vision(fc, [math.nan, 0, 0]))
    gcs.send(vision(fc, [0, 0, 0], stamp_s=fc.boot_time_s + 5.0))  # from the future
    report = fc.score()
    assert report.scored == 90 and report.invalid == 1 and report.unmatched == 1
    assert report.rmse_m["north"] == pytest.approx(0.3, abs=1e-4)
    assert report.rmse_m["east"] == pytest.approx(0.0, abs=1e-4)
    assert report.rmse_m["down"] == pytest.approx(0.4, abs=1e-4)
    assert report.rmse_m["3d"] == pytest.approx(0.5, abs=1e-4)
    assert report.rate_hz == pytest.approx(30.0, rel=0.02)
    assert report.age_ms["p50"] == pytest.approx(20.0, abs=0.5)


# --------------------------------------------------------------------------- faults and events


def test_stream_outage_reboot_and_rangefinder_windows() -> None:
    fc = build_controller(
        "hover",
        emulator={
            "faults": {
                "outages": [{"stream": "ATTITUDE", "start_s": 1.0, "duration_s": 0.5}],
                "reboots_s": [3.0],
                "rangefinder_out_of_range": [{"start_s": 2.0, "duration_s": 0.5}],
            }
        },
    )
    gcs = LockstepPeer(fc)
    gcs.advance(4.0)
    attitude_times = np.array([m.time_boot_ms for m in gcs.received if m.get_type() == "ATTITUDE"])
    assert not np.any((attitude_times > 1000) & (attitude_times < 1500))
    imu = [m.time_usec for m in gcs.received if m.get_type() == "RAW_IMU"]
    assert np.any(np.diff(imu) < 0)  # time_boot went back at the reboot
    assert imu[-1] == pytest.approx(1_000_000, abs=10_000)
    ranges = [m for m in gcs.received if m.get_type() == "DISTANCE_SENSOR"]
    before_reboot = ranges[: int(np.argmax(np.diff([m.time_boot_ms for m in ranges]) < 0)) + 1]
    out = [m.time_boot_ms for m in before_reboot if units.range_from_distance_sensor(m) is None]
    assert len(out) == 100 and min(out) == 2000 and max(out) == 2495  # 0.5 s at 200 Hz
    assert fc.counters.reboots == 1 and not fc.armed and fc.mode == CopterMode.STABILIZE


def test_ground_station_events_tug_release_and_winch() -> None:
    fc = build_controller("hover")
    gcs = LockstepPeer(fc)
    assert gcs.command(dialect.MAV_CMD_USER_1, 0.0, 20.0, 0.0, 0.5) == ACCEPTED
    gcs.advance(0.5)
    assert truth(fc)[1] > 0.1  # pushed east
    assert gcs.command(dialect.MAV_CMD_USER_3, 6.0) == ACCEPTED and fc.sim.cable.set_point_n == 6.0
    assert gcs.command(dialect.MAV_CMD_USER_2, 1.0) == ACCEPTED
    gcs.advance(0.1)
    assert fc.sim.truth.tension_n == 0.0 and fc.params.value("TETH_RELEASE") == 1
    elastic = build_controller("elastic-hover")
    peer = LockstepPeer(elastic)
    assert (
        peer.command(dialect.MAV_CMD_DO_WINCH, 1, dialect.WINCH_RATE_CONTROL, 0, -0.2) == ACCEPTED
    )
    peer.advance(1.0)
    assert elastic.sim.cable.paid_out_m == pytest.approx(5.0, abs=0.01)
