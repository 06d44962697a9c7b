"""Messages describing the flight controller's state, built on demand (streams and requests).

Pure functions of a :class:`~tether_companion.emulator.autopilot.FlightController`'s state;
timestamps are the flight controller's boot time.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

from tether_companion.emulator.modes import GUIDED_FLAG_MODES, CopterMode
from tether_companion.mavlink import estimates, geo, units
from tether_companion.mavlink.framing import MAVLinkMessage, dialect

if TYPE_CHECKING:
    from tether_companion.emulator.autopilot import FlightController

FIRMWARE_VERSION = (4, 5, 0)
"""The ArduCopter version the emulator claims (behaviour modelled on 4.5)."""
_FLIGHT_SW_VERSION = (
    (FIRMWARE_VERSION[0] << 24)
    | (FIRMWARE_VERSION[1] << 16)
    | (FIRMWARE_VERSION[2] << 8)
    | dialect.FIRMWARE_VERSION_TYPE_OFFICIAL
)
_CAPABILITIES = (
    dialect.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | dialect.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | dialect.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | dialect.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | dialect.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
)
_SENSOR_BITS_ALWAYS = (
    dialect.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | dialect.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | dialect.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | dialect.MAV_SYS_STATUS_AHRS
)
UNKNOWN_U16 = 65535
INT16_MAX = 32767
"""BATTERY_STATUS.temperature when unknown [cdegC]."""
LANDING_MODES = frozenset({CopterMode.LAND})


def heartbeat(fc: FlightController) -> MAVLinkMessage:
    """HEARTBEAT: quadrotor, ArduPilot (or PX4 in that flavour), base_mode flags and the
    Copter mode number."""
    base = (
        dialect.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        | dialect.MAV_MODE_FLAG_STABILIZE_ENABLED
        | dialect.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
    )
    if fc.mode in GUIDED_FLAG_MODES:
        base |= dialect.MAV_MODE_FLAG_GUIDED_ENABLED
    if fc.armed:
        base |= dialect.MAV_MODE_FLAG_SAFETY_ARMED
    if fc.failsafe:
        state = dialect.MAV_STATE_CRITICAL
    else:
        state = dialect.MAV_STATE_ACTIVE if fc.armed else dialect.MAV_STATE_STANDBY
    return dialect.MAVLink_heartbeat_message(
        dialect.MAV_TYPE_QUADROTOR,
        dialect.MAV_AUTOPILOT_PX4
        if fc.config.autopilot == "px4"
        else dialect.MAV_AUTOPILOT_ARDUPILOTMEGA,
        base,
        int(fc.mode),
        state,
        3,
    )


def sys_status(fc: FlightController) -> MAVLinkMessage:
    """SYS_STATUS: sensors present/enabled/healthy; the battery's voltage (current and
    remaining unknown)."""
    position_bit = (
        dialect.MAV_SYS_STATUS_SENSOR_VISION_POSITION
        if fc.vision_navigation
        else dialect.MAV_SYS_STATUS_SENSOR_GPS
    )
    present = _SENSOR_BITS_ALWAYS | position_bit | dialect.MAV_SYS_STATUS_SENSOR_LASER_POSITION
    present |= dialect.MAV_SYS_STATUS_PREARM_CHECK
    health = _SENSOR_BITS_ALWAYS
    if fc.navigation_healthy:
        health |= position_bit
    if fc.rangefinder_in_range:
        health |= dialect.MAV_SYS_STATUS_SENSOR_LASER_POSITION
    if fc.prearm_failure() is None:
        health |= dialect.MAV_SYS_STATUS_PREARM_CHECK
    errors = min(fc.counters.rejected, UNKNOWN_U16 - 1)
    voltage_mv = min(round(fc.sim.battery_voltage_v * 1000.0), UNKNOWN_U16 - 1)
    return dialect.MAVLink_sys_status_message(
        present, present, health, 0, voltage_mv, -1, -1, 0, errors, 0, 0, 0, 0, 0, 0, 0
    )


def battery_status(fc: FlightController) -> MAVLinkMessage:
    """BATTERY_STATUS: the pack voltage in voltages[0], the other cells UINT16_MAX (the spec's
    form when cell voltages are not measured); current, charge and temperature unknown."""
    voltage_mv = min(round(fc.sim.battery_voltage_v * 1000.0), UNKNOWN_U16 - 1)
    return dialect.MAVLink_battery_status_message(
        0,
        dialect.MAV_BATTERY_FUNCTION_ALL,
        dialect.MAV_BATTERY_TYPE_LIPO,
        INT16_MAX,
        [voltage_mv] + [UNKNOWN_U16] * 9,
        -1,
        -1,
        -1,
        -1,
    )


def extended_sys_state(fc: FlightController) -> MAVLinkMessage:
    """EXTENDED_SYS_STATE: landed state (on ground, taking off, in air, landing), in
    ArduCopter's order (GCS_MAVLINK_Copter::landed_state): its land detector's verdict first."""
    if fc.land_detector.complete:
        landed = dialect.MAV_LANDED_STATE_ON_GROUND
    elif fc.taking_off:
        landed = dialect.MAV_LANDED_STATE_TAKEOFF
    elif fc.mode in LANDING_MODES:
        landed = dialect.MAV_LANDED_STATE_LANDING
    else:
        landed = dialect.MAV_LANDED_STATE_IN_AIR
    return dialect.MAVLink_extended_sys_state_message(dialect.MAV_VTOL_STATE_UNDEFINED, landed)


def system_time(fc: FlightController) -> MAVLinkMessage:
    """SYSTEM_TIME: Unix time (start time + emulator time) and boot time."""
    unix_s = fc.unix_time_at_start_s + fc.time_s
    return dialect.MAVLink_system_time_message(
        units.seconds_to_usec(unix_s), units.seconds_to_boot_ms(fc.boot_time_s)
    )


def raw_imu(fc: FlightController) -> MAVLinkMessage:
    """RAW_IMU in ArduPilot's units (milli-g, milli-rad/s), noisy as the scenario says."""
    sample = fc.sim.read_imu()
    return units.raw_imu_message(dataclasses.replace(sample, time_s=fc.boot_time_s))


def scaled_imu(fc: FlightController) -> MAVLinkMessage:
    """SCALED_IMU: the same numbers as RAW_IMU (ArduPilot), stamped in boot milliseconds."""
    msg = raw_imu(fc)
    return dialect.MAVLink_scaled_imu_message(
        units.seconds_to_boot_ms(fc.boot_time_s),
        msg.xacc,
        msg.yacc,
        msg.zacc,
        msg.xgyro,
        msg.ygyro,
        msg.zgyro,
        0,
        0,
        0,
        0,
    )


def highres_imu(fc: FlightController) -> MAVLinkMessage:
    """HIGHRES_IMU in m/s^2 and rad/s (as PX4 sends it)."""
    sample = fc.sim.read_imu()
    return units.highres_imu_message(dataclasses.replace(sample, time_s=fc.boot_time_s))


def attitude(fc: FlightController) -> MAVLinkMessage:
    """ATTITUDE: the attitude estimate (truth plus the scenario's attitude noise) and rates."""
    sample = fc.sim.read_attitude()
    return units.attitude_message(
        dataclasses.replace(sample, time_s=fc.boot_time_s), fc.sim.body_rates_rad_s
    )


def servo_output_raw(fc: FlightController) -> MAVLinkMessage:
    """SERVO_OUTPUT_RAW: motor outputs in the vehicle profile's order [us]."""
    sample = fc.sim.read_pwm()
    return units.servo_output_raw_message(dataclasses.replace(sample, time_s=fc.boot_time_s))


def distance_sensor(fc: FlightController) -> MAVLinkMessage:
    """DISTANCE_SENSOR, downward; out of range (or forced so) reads just beyond a limit."""
    sensors = fc.sim.sensor_config
    reading = None if fc.rangefinder_forced_out_of_range else fc.sim.read_rangefinder()
    if reading is None:
        high = -fc.sim.position_ned_m[2] > 0.5 * (sensors.range_min_m + sensors.range_max_m)
        distance = sensors.range_max_m + 0.01 if high or fc.rangefinder_forced_out_of_range else 0.0
        fc.rangefinder_in_range = False
    else:
        distance = reading.distance_m
        fc.rangefinder_in_range = True
    return units.distance_sensor_message(
        fc.boot_time_s,
        distance,
        min_distance_m=sensors.range_min_m,
        max_distance_m=sensors.range_max_m,
        stddev_m=sensors.range_noise_std_m,
    )


def local_position_ned(fc: FlightController) -> MAVLinkMessage | None:
    """LOCAL_POSITION_NED: what the flight controller believes, relative to its EKF origin."""
    position = fc.navigation_position_ned_m()
    if position is None:
        return None
    return estimates.local_position_ned_message(fc.boot_time_s, position, fc.sim.velocity_ned_m_s)


def global_position_int(fc: FlightController) -> MAVLinkMessage | None:
    """GLOBAL_POSITION_INT: the believed position placed at the EKF origin."""
    position = fc.navigation_position_ned_m()
    if position is None or fc.origin is None:
        return None
    return geo.global_position_int_message(
        fc.boot_time_s, fc.origin, position, fc.sim.velocity_ned_m_s, fc.sim.euler_rad[2]
    )


def vfr_hud(fc: FlightController) -> MAVLinkMessage:
    """VFR_HUD: speeds, heading, throttle and altitude (truth; there is no air data)."""
    _, _, down_m = fc.sim.position_ned_m
    vn, ve, vd = fc.sim.velocity_ned_m_s
    curve = fc.sim.vehicle.thrust_curve
    pwm = fc.sim.read_pwm().pwm_us
    throttle = (
        100.0 * (float(pwm.mean()) - curve.pwm_min_us) / (curve.pwm_max_us - curve.pwm_min_us)
    )
    ground_speed = math.hypot(vn, ve)
    return dialect.MAVLink_vfr_hud_message(
        ground_speed,
        ground_speed,
        units.saturate_int(math.degrees(fc.sim.euler_rad[2]) % 360.0, 0, 359),
        units.saturate_int(throttle, 0, 100),
        float(fc.home.alt_m - down_m),
        float(-vd),
    )


def sim_state(fc: FlightController) -> MAVLinkMessage:
    """SIM_STATE: the ground truth (position at the anchor's location), as ArduPilot SITL."""
    sim = fc.sim
    return geo.sim_state_message(
        fc.home,
        sim.position_ned_m,
        sim.velocity_ned_m_s,
        sim.euler_rad,
        sim.specific_force_body_mps2,
        sim.body_rates_rad_s,
    )


def home_position(fc: FlightController) -> MAVLinkMessage:
    """HOME_POSITION: the tether anchor's location; x, y, z relative to the EKF origin."""
    offset = geo.geodetic_to_ned(fc.origin, fc.home) if fc.origin is not None else (0.0, 0.0, 0.0)
    return dialect.MAVLink_home_position_message(
        fc.home.lat_e7,
        fc.home.lon_e7,
        fc.home.alt_mm,
        float(offset[0]),
        float(offset[1]),
        float(offset[2]),
        [1.0, 0.0, 0.0, 0.0],
        0.0,
        0.0,
        0.0,
        units.seconds_to_usec(fc.boot_time_s),
    )


def gps_global_origin(fc: FlightController) -> MAVLinkMessage | None:
    """GPS_GLOBAL_ORIGIN, or None before an origin exists."""
    if fc.origin is None:
        return None
    return dialect.MAVLink_gps_global_origin_message(
        fc.origin.lat_e7, fc.origin.lon_e7, fc.origin.alt_mm, units.seconds_to_usec(fc.boot_time_s)
    )


def autopilot_version(fc: FlightController) -> MAVLinkMessage:
    """AUTOPILOT_VERSION: ArduCopter 4.5.0 (official) with MAVLink 2 capabilities (parameters
    encoded bytewise in the PX4 flavour)."""
    capabilities = _CAPABILITIES
    if fc.config.autopilot == "px4":
        capabilities = (
            capabilities & ~dialect.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
        ) | dialect.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    return dialect.MAVLink_autopilot_version_message(
        capabilities,
        _FLIGHT_SW_VERSION,
        0,
        0,
        0,
        list(b"emulatr\x00"),
        [0] * 8,
        [0] * 8,
        0,
        0,
        fc.config.system_id,
        [0] * 18,
    )


BUILDERS = {
    "HEARTBEAT": heartbeat,
    "SYS_STATUS": sys_status,
    "BATTERY_STATUS": battery_status,
    "EXTENDED_SYS_STATE": extended_sys_state,
    "SYSTEM_TIME": system_time,
    "RAW_IMU": raw_imu,
    "SCALED_IMU": scaled_imu,
    "HIGHRES_IMU": highres_imu,
    "ATTITUDE": attitude,
    "SERVO_OUTPUT_RAW": servo_output_raw,
    "DISTANCE_SENSOR": distance_sensor,
    "LOCAL_POSITION_NED": local_position_ned,
    "GLOBAL_POSITION_INT": global_position_int,
    "VFR_HUD": vfr_hud,
    "SIM_STATE": sim_state,
    "HOME_POSITION": home_position,
    "GPS_GLOBAL_ORIGIN": gps_global_origin,
}
"""Message name -> builder; a builder returns None when the message cannot be sent now."""


def statustext(severity: int, text: str) -> MAVLinkMessage:
    """STATUSTEXT (text cut to the field's 50 characters)."""
    return dialect.MAVLink_statustext_message(severity, text.encode("ascii", "replace")[:50], 0, 0)
