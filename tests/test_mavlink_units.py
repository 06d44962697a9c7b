"""SI <-> MAVLink field conversions: units, layouts, rounding, saturation, round trips."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.frames import rotation_body_to_ned, rotation_ned_to_body, wrap_pi
from tether_companion.mavlink import estimates, geo, units
from tether_companion.mavlink.framing import FrameEncoder, FrameParser
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample

ACC = st.floats(-300.0, 300.0)
GYRO = st.floats(-30.0, 30.0)
ANGLE = st.floats(-math.pi, math.pi)


def over_the_wire(msg):
    """Encode and decode through real frames, as every message is in the system."""
    (decoded,) = FrameParser().feed(FrameEncoder(1, 1).encode(msg))
    return decoded


def test_raw_imu_is_in_milli_g_and_milli_rad_per_s() -> None:
    sample = ImuSample(1.5, np.array([0.0, 0.0, -GRAVITY_MPS2]), np.array([0.1, -0.2, 0.3]))
    msg = over_the_wire(units.raw_imu_message(sample))
    assert (msg.xacc, msg.yacc, msg.zacc) == (0, 0, -1000)
    assert (msg.xgyro, msg.ygyro, msg.zgyro) == (100, -200, 300)
    assert msg.time_usec == 1_500_000


@settings(max_examples=200, deadline=None)
@given(st.tuples(ACC, ACC, ACC), st.tuples(GYRO, GYRO, GYRO), st.floats(0.0, 1e5))
def test_raw_imu_round_trip_within_quantisation(acc, gyro, time_s) -> None:
    sample = ImuSample(time_s, np.array(acc), np.array(gyro))
    back = units.imu_from_raw_imu(over_the_wire(units.raw_imu_message(sample)))
    assert abs(back.time_s - time_s) <= 0.5e-6 + 1e-9 * time_s
    np.testing.assert_allclose(
        back.specific_force_body_mps2, acc, atol=0.5e-3 * GRAVITY_MPS2 + 1e-12
    )
    np.testing.assert_allclose(back.angular_rate_body_rad_s, gyro, atol=0.5e-3 + 1e-12)


def test_raw_imu_saturates_and_refuses_nan() -> None:
    big = ImuSample(0.0, np.array([1e4, -1e4, 0.0]), np.array([100.0, 0.0, 0.0]))
    msg = units.raw_imu_message(big)
    assert (msg.xacc, msg.yacc, msg.xgyro) == (32767, -32768, 32767)
    with pytest.raises(ValueError, match="non-finite"):
        units.raw_imu_message(ImuSample(0.0, np.array([math.nan, 0, 0]), np.zeros(3)))


@settings(max_examples=100, deadline=None)
@given(st.tuples(ACC, ACC, ACC), st.tuples(GYRO, GYRO, GYRO))
def test_highres_imu_round_trip_in_float32(acc, gyro) -> None:
    sample = ImuSample(12.25, np.array(acc), np.array(gyro))
    back = units.imu_from_highres_imu(over_the_wire(units.highres_imu_message(sample)))
    np.testing.assert_allclose(back.specific_force_body_mps2, acc, rtol=1e-6, atol=1e-30)
    np.testing.assert_allclose(back.angular_rate_body_rad_s, gyro, rtol=1e-6, atol=1e-30)
    assert back.time_s == 12.25


def test_scaled_imu_uses_boot_milliseconds() -> None:
    msg = units.dialect.MAVLink_scaled_imu_message(2500, 0, 0, -1000, 10, 0, 0, 0, 0, 0, 0)
    sample = units.imu_from_scaled_imu(msg)
    assert sample.time_s == 2.5
    np.testing.assert_allclose(sample.specific_force_body_mps2, [0, 0, -GRAVITY_MPS2])
    np.testing.assert_allclose(sample.angular_rate_body_rad_s, [0.01, 0, 0])


@settings(max_examples=100, deadline=None)
@given(ANGLE, st.floats(-1.5, 1.5), ANGLE, st.floats(0.0, 4e6))
def test_attitude_round_trip(roll, pitch, yaw, time_s) -> None:
    msg = units.attitude_message(AttitudeSample(time_s, roll, pitch, yaw), [0.1, 0.2, 0.3])
    back = units.attitude_from_attitude(over_the_wire(msg))
    assert abs(back.time_s - time_s) <= 0.5e-3 + 1e-9
    assert back.roll_rad == pytest.approx(roll, abs=1e-6)
    assert back.pitch_rad == pytest.approx(pitch, abs=1e-6)
    assert back.yaw_rad == pytest.approx(yaw, abs=1e-6)


def test_servo_output_raw_channels_rounding_and_time_wrap() -> None:
    sample = PwmSample(4295.0, np.array([1500.4, 1500.6, 999.0, 2000.0]))
    msg = over_the_wire(units.servo_output_raw_message(sample))
    assert [msg.servo1_raw, msg.servo2_raw, msg.servo3_raw, msg.servo4_raw] == [
        1500,
        1501,
        999,
        2000,
    ]
    assert msg.servo5_raw == 0 and msg.servo16_raw == 0
    assert msg.time_usec == 4_295_000_000 & 0xFFFFFFFF  # uint32 on the wire
    back = units.pwm_from_servo_output_raw(msg, 4, time_s=4295.0)
    np.testing.assert_array_equal(back.pwm_us, [1500, 1501, 999, 2000])
    assert back.time_s == 4295.0
    with pytest.raises(ValueError):
        units.servo_output_raw_message(PwmSample(0.0, np.full(17, 1500.0)))
    with pytest.raises(ValueError):
        units.pwm_from_servo_output_raw(msg, 0)


def test_distance_sensor_centimetres_and_range_gate() -> None:
    msg = over_the_wire(
        units.distance_sensor_message(
            3.2, 1.234, min_distance_m=0.2, max_distance_m=8.0, stddev_m=0.05
        )
    )
    assert (msg.current_distance, msg.min_distance, msg.max_distance) == (123, 20, 800)
    assert msg.covariance == 25 and msg.orientation == units.DOWNWARD_ORIENTATION
    sample = units.range_from_distance_sensor(msg)
    assert sample is not None and sample.distance_m == pytest.approx(1.23) and sample.time_s == 3.2
    for distance_m in (0.1, 8.05, -1.0, 1e9):
        out = units.distance_sensor_message(0.0, distance_m, min_distance_m=0.2, max_distance_m=8.0)
        assert units.range_from_distance_sensor(out) is None
    unknown = units.distance_sensor_message(0.0, 1.0, min_distance_m=0.2, max_distance_m=8.0)
    assert unknown.covariance == 255


def test_covariance_layout_is_row_major_upper_triangle() -> None:
    matrix = np.zeros((6, 6))
    for i in range(6):
        for j in range(6):
            matrix[i, j] = matrix[j, i] = 10 * min(i, j) + max(i, j)
    urt = units.covariance_to_urt(matrix)
    assert urt[:6] == [0, 1, 2, 3, 4, 5]  # row 0
    assert urt[6:11] == [11, 12, 13, 14, 15]  # row 1 from the diagonal
    assert urt[11] == 22 and urt[15] == 33 and urt[18] == 44 and urt[20] == 55


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(-1e3, 1e3), min_size=36, max_size=36))
def test_covariance_round_trip(values) -> None:
    a = np.array(values).reshape(6, 6)
    sym = a + a.T
    back = units.urt_to_covariance(units.covariance_to_urt(sym))
    np.testing.assert_array_equal(back, sym)


def test_unknown_covariance_is_nan_first() -> None:
    urt = units.covariance_to_urt(None)
    assert math.isnan(urt[0]) and urt[1:] == [0.0] * 20
    assert units.urt_to_covariance(urt) is None
    with pytest.raises(ValueError):
        units.covariance_to_urt(np.eye(3))
    with pytest.raises(ValueError):
        units.covariance_to_urt(np.full((6, 6), math.inf))
    with pytest.raises(ValueError):
        units.urt_to_covariance([0.0] * 20)


@settings(max_examples=200, deadline=None)
@given(ANGLE, st.floats(-1.55, 1.55), ANGLE)
def test_quaternion_matches_rotation_matrix(roll, pitch, yaw) -> None:
    w, x, y, z = units.quaternion_from_euler(roll, pitch, yaw)
    rot = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    np.testing.assert_allclose(rot, rotation_body_to_ned(roll, pitch, yaw), atol=1e-12)
    back = units.euler_from_quaternion([w, x, y, z])
    differences = [wrap_pi(a - b) for a, b in zip(back, (roll, pitch, yaw), strict=True)]
    np.testing.assert_allclose(differences, 0.0, atol=1e-6)  # -pi and pi are one angle


def test_vision_position_estimate_round_trip() -> None:
    cov = np.diag([0.01, 0.02, 0.03, 1.0, 1.0, 1.0])
    cov[0, 1] = cov[1, 0] = 0.005
    est = estimates.PoseEstimate(
        12.345678, np.array([1.5, -2.5, -3.0]), (0.1, -0.05, 1.2), cov, 300
    )
    msg = over_the_wire(estimates.vision_position_estimate_message(est))
    back = estimates.pose_from_vision_position_estimate(msg)
    assert msg.usec == 12_345_678 and back.reset_counter == 300 & 0xFF
    np.testing.assert_allclose(back.position_ned_m, est.position_ned_m, rtol=1e-6)
    np.testing.assert_allclose(back.euler_rad, est.euler_rad, rtol=1e-6)
    np.testing.assert_allclose(back.covariance, cov, rtol=1e-6)


def test_odometry_round_trip_and_frame_check() -> None:
    est = estimates.PoseEstimate(2.0, np.array([1.0, 2.0, -3.0]), (0.2, -0.1, 2.5), None, 4)
    velocity = estimates.VelocityEstimate(2.0, np.array([0.5, 0.0, -0.1]), None, 4)
    msg = over_the_wire(estimates.odometry_message(est, velocity))
    back = estimates.pose_from_odometry(msg)
    np.testing.assert_allclose(back.position_ned_m, [1, 2, -3], rtol=1e-6)
    np.testing.assert_allclose(back.euler_rad, est.euler_rad, atol=1e-6)
    assert back.covariance is None and back.reset_counter == 4
    msg.frame_id = units.MAV_FRAME_BODY_FRD
    with pytest.raises(ValueError, match="frame_id"):
        estimates.pose_from_odometry(msg)
    with pytest.raises(ValueError):
        units.euler_from_quaternion([0, 0, 0, 0])


def test_odometry_velocity_in_the_body_frame_as_ardupilot_and_px4_read_it() -> None:
    """ArduPilot drops ODOMETRY unless frame_id is LOCAL_FRD and child_frame_id BODY_FRD, then
    rotates the body velocity to NED with the message's quaternion; PX4 reads the velocity frame
    from child_frame_id. The NED velocity and its covariance survive the round trip."""
    euler = (0.1, -0.2, 2.0)
    est = estimates.PoseEstimate(3.0, np.array([1.0, 2.0, -3.0]), euler, None, 7)
    a = np.array([[0.02, 0.005, 0.0], [0.005, 0.03, 0.001], [0.0, 0.001, 0.01]])
    velocity = estimates.VelocityEstimate(3.0, np.array([0.8, -0.3, 0.2]), a, 7)
    msg = over_the_wire(
        estimates.odometry_message(est, velocity, frame_id=units.MAV_FRAME_LOCAL_FRD)
    )
    assert msg.frame_id == units.MAV_FRAME_LOCAL_FRD
    assert msg.child_frame_id == units.MAV_FRAME_BODY_FRD
    body = rotation_ned_to_body(*euler) @ velocity.velocity_ned_m_s
    np.testing.assert_allclose([msg.vx, msg.vy, msg.vz], body, rtol=1e-6, atol=1e-7)
    back = estimates.velocity_from_odometry(msg)
    assert back is not None and back.reset_counter == 7
    np.testing.assert_allclose(back.velocity_ned_m_s, velocity.velocity_ned_m_s, atol=1e-6)
    np.testing.assert_allclose(back.covariance, a, atol=1e-6)
    assert all(math.isfinite(v) for v in msg.velocity_covariance)  # never NaN beside a value
    without = over_the_wire(estimates.odometry_message(est))
    assert estimates.velocity_from_odometry(without) is None
    assert math.isnan(without.velocity_covariance[0])


def test_vision_speed_estimate_round_trip_and_unknown_covariance() -> None:
    cov = np.diag([0.01, 0.02, 0.04])
    velocity = estimates.VelocityEstimate(4.5, np.array([1.0, -0.5, 0.25]), cov, 258)
    msg = over_the_wire(estimates.vision_speed_estimate_message(velocity))
    assert msg.usec == 4_500_000 and msg.reset_counter == 2
    back = estimates.velocity_from_vision_speed_estimate(msg)
    np.testing.assert_allclose(back.velocity_ned_m_s, velocity.velocity_ned_m_s, rtol=1e-6)
    np.testing.assert_allclose(back.covariance, cov, rtol=1e-6)
    unknown = estimates.VelocityEstimate(4.5, np.zeros(3), None, 0)
    msg = over_the_wire(estimates.vision_speed_estimate_message(unknown))
    assert math.isnan(msg.covariance[0])
    assert estimates.velocity_from_vision_speed_estimate(msg).covariance is None
    with pytest.raises(ValueError, match="covariance"):
        estimates.vision_speed_estimate_message(
            estimates.VelocityEstimate(1.0, np.zeros(3), np.full((3, 3), math.nan), 0)
        )


def test_local_position_ned() -> None:
    msg = over_the_wire(estimates.local_position_ned_message(1.25, [1, 2, -3], [0.1, 0.2, 0.3]))
    assert msg.time_boot_ms == 1250
    assert (msg.x, msg.y, msg.z) == (1.0, 2.0, -3.0)


@settings(max_examples=100, deadline=None)
@given(
    st.floats(-80, 80),
    st.floats(-179.9, 179.9),
    st.floats(-100, 3000),
    st.tuples(st.floats(-500, 500), st.floats(-500, 500), st.floats(-300, 300)),
)
def test_geodetic_round_trip(lat, lon, alt, ned) -> None:
    home = geo.Geodetic(lat, lon, alt)
    back = geo.geodetic_to_ned(home, geo.ned_to_geodetic(home, ned))
    np.testing.assert_allclose(back, ned, atol=1e-6)


def test_geodetic_scale_and_global_position_int() -> None:
    home = geo.Geodetic(47.0, 8.0, 400.0)
    north = geo.ned_to_geodetic(home, [111.319, 0.0, 0.0])
    assert north.lat_deg - 47.0 == pytest.approx(1e-3, rel=1e-4)  # 1 mdeg of latitude
    east = geo.ned_to_geodetic(home, [0.0, 111.319 * math.cos(math.radians(47.0)), -10.0])
    assert east.lon_deg - 8.0 == pytest.approx(1e-3, rel=1e-4) and east.alt_m == 410.0
    msg = over_the_wire(
        geo.global_position_int_message(3.0, home, [0, 0, -10.0], [1.0, -2.0, 0.5], -0.5)
    )
    assert msg.relative_alt == 10_000 and msg.alt == 410_000
    assert (msg.vx, msg.vy, msg.vz) == (100, -200, 50)
    assert msg.hdg == round((math.degrees(-0.5) % 360) * 100)
    assert geo.Geodetic.from_e7(msg.lat, msg.lon, msg.alt).lat_deg == pytest.approx(47.0)
    with pytest.raises(ValueError):
        geo.Geodetic(91.0, 0.0, 0.0)


def test_sim_state_carries_truth() -> None:
    home = geo.Geodetic(47.0, 8.0, 400.0)
    msg = over_the_wire(
        geo.sim_state_message(
            home, [1.0, 2.0, -3.0], [0.1, 0.2, 0.3], (0.1, 0.2, 0.3), [0, 0, -9.8], [0.01, 0, 0]
        )
    )
    assert (msg.roll, msg.zacc, msg.vd) == pytest.approx((0.1, -9.8, 0.3))
    assert msg.alt == pytest.approx(403.0)
    point = geo.Geodetic.from_e7(msg.lat_int, msg.lon_int, 403_000)
    np.testing.assert_allclose(geo.geodetic_to_ned(home, point), [1, 2, -3], atol=0.02)
