"""SI samples <-> MAVLink message fields, in both directions.

The emulator encodes with the ``*_message`` functions, the service and replay decode with the
``*_from_*`` functions; nothing else in the project sees MAVLink's units. Field units follow
the MAVLink definitions (``common.xml``) and ArduPilot's encoders:

==================== ============================== ==========================================
message              wire units                     here
==================== ============================== ==========================================
RAW_IMU (ArduPilot)  acc mG, gyro mrad/s, int16     m/s^2 (x 9.80665/1000), rad/s (/1000)
SCALED_IMU           as RAW_IMU, time_boot_ms       as RAW_IMU
HIGHRES_IMU (PX4)    m/s^2, rad/s (float)           unchanged
ATTITUDE             rad, rad/s, time_boot_ms       unchanged
SERVO_OUTPUT_RAW     us (uint16), time_usec uint32  us (float array); time wraps at 2^32 us
DISTANCE_SENSOR      cm (uint16), covariance cm^2   m; readings outside [min, max] dropped
VISION_POSITION_EST. m, rad, 21-float URT cov.      NED m, rad, (6, 6) covariance
ODOMETRY             m, quaternion (w,x,y,z), cov.  NED m, rad, (6, 6) covariance; velocity
                     body FRD m/s, cov.             NED m/s, (3, 3) covariance
VISION_SPEED_EST.    m/s NED, 9-float row-major     NED m/s, (3, 3) covariance
LOCAL_POSITION_NED   m, m/s, time_boot_ms           unchanged
GLOBAL_POSITION_INT  degE7, mm, cm/s, cdeg          see :mod:`tether_companion.mavlink.geo`
==================== ============================== ==========================================

Integer fields are rounded to nearest and saturated to their wire type (RAW_IMU's int16
covers +/-32.7 g and +/-32.7 rad/s). A non-finite value for an integer field raises
``ValueError``: a NaN must never reach a flight controller.

The 21-element covariance of VISION_POSITION_ESTIMATE and ODOMETRY is the row-major upper
right triangle of the 6x6 pose covariance (x, y, z, roll, pitch, yaw): entries 0-5 are row 0,
6-10 row 1 from the diagonal on, ..., entry 20 is (5, 5). NaN in entry 0 means "unknown".
"""

from __future__ import annotations

import math
import operator
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample

FloatArray = NDArray[np.float64]
Vector3 = tuple[float, float, float]

MILLI_G_TO_MPS2: float = GRAVITY_MPS2 / 1000.0
"""One milli-g in m/s^2 (ArduPilot scales RAW_IMU by 1000 / GRAVITY_MSS)."""
MILLI_RAD_TO_RAD: float = 1e-3
INT16_MIN, INT16_MAX = -32768, 32767
UINT16_MAX = 65535
UINT32_MASK = 0xFFFFFFFF
N_COVARIANCE_URT = 21
"""Length of the upper-right-triangle covariance array of a 6x6 matrix."""
POSE_DIM = 6
SERVO_CHANNELS = 16
MAV_FRAME_LOCAL_NED = dialect.MAV_FRAME_LOCAL_NED
MAV_FRAME_LOCAL_FRD = dialect.MAV_FRAME_LOCAL_FRD
MAV_FRAME_BODY_FRD = dialect.MAV_FRAME_BODY_FRD
DOWNWARD_ORIENTATION = dialect.MAV_SENSOR_ROTATION_PITCH_270
"""DISTANCE_SENSOR ``orientation`` of a downward-facing rangefinder."""
DISTANCE_COVARIANCE_UNKNOWN = 255
_HIGHRES_IMU_ACC_GYRO_FIELDS = 0b111111
"""HIGHRES_IMU ``fields_updated`` bits for x/y/z acc and x/y/z gyro."""

_URT_ROWS, _URT_COLS = np.triu_indices(POSE_DIM)


# --- scalar helpers -------------------------------------------------------------------------


def saturate_int(value: float, lo: int, hi: int) -> int:
    """Round ``value`` to the nearest integer and clip it to [lo, hi].

    Raises
    ------
    ValueError
        When ``value`` is NaN or infinite.
    """
    if not math.isfinite(value):
        raise ValueError(f"cannot encode non-finite value {value!r} into an integer field")
    return int(min(hi, max(lo, round(value))))


def seconds_to_usec(time_s: float) -> int:
    """Flight-controller time [s] to integer microseconds (``time_usec``)."""
    return saturate_int(time_s * 1e6, 0, (1 << 64) - 1)


def seconds_to_boot_ms(time_s: float) -> int:
    """Flight-controller time [s] to ``time_boot_ms`` (uint32, wraps after 49.7 days)."""
    return saturate_int(time_s * 1e3, 0, (1 << 63)) & UINT32_MASK


# --- covariance layout ----------------------------------------------------------------------


def covariance_to_urt(covariance: ArrayLike | None) -> list[float]:
    """A symmetric (6, 6) pose covariance to MAVLink's 21-element upper right triangle.

    ``None`` gives the "unknown" encoding: NaN in entry 0, zeros elsewhere.

    Raises
    ------
    ValueError
        When the matrix is not (6, 6) or holds non-finite values.
    """
    if covariance is None:
        return [math.nan] + [0.0] * (N_COVARIANCE_URT - 1)
    matrix = np.asarray(covariance, dtype=float)
    if matrix.shape != (POSE_DIM, POSE_DIM):
        raise ValueError(f"pose covariance must be (6, 6), got {matrix.shape}")
    if not np.all(np.isfinite(matrix)):
        raise ValueError("pose covariance holds non-finite values")
    return [float(v) for v in matrix[_URT_ROWS, _URT_COLS]]


def urt_to_covariance(urt: Sequence[float]) -> FloatArray | None:
    """MAVLink's 21-element upper right triangle to a symmetric (6, 6) matrix.

    Returns ``None`` when entry 0 is NaN (the spec's "unknown").

    Raises
    ------
    ValueError
        When the array does not have 21 entries.
    """
    values = np.asarray(urt, dtype=float)
    if values.shape != (N_COVARIANCE_URT,):
        raise ValueError(f"covariance array must have 21 entries, got {values.shape}")
    if math.isnan(values[0]):
        return None
    matrix = np.zeros((POSE_DIM, POSE_DIM))
    matrix[_URT_ROWS, _URT_COLS] = values
    matrix[_URT_COLS, _URT_ROWS] = values
    return matrix


# --- quaternions ----------------------------------------------------------------------------


def quaternion_from_euler(roll_rad: float, pitch_rad: float, yaw_rad: float) -> list[float]:
    """Body-to-NED attitude quaternion (w, x, y, z) of 3-2-1 Euler angles [rad]."""
    cr, sr = math.cos(roll_rad / 2), math.sin(roll_rad / 2)
    cp, sp = math.cos(pitch_rad / 2), math.sin(pitch_rad / 2)
    cy, sy = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    return [
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ]


def euler_from_quaternion(q: Sequence[float]) -> tuple[float, float, float]:
    """Roll, pitch, yaw [rad] of a body-to-NED quaternion (w, x, y, z); normalises first.

    Raises
    ------
    ValueError
        When the quaternion has zero or non-finite norm.
    """
    w, x, y, z = (float(v) for v in q)
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    if not (math.isfinite(norm) and norm > 0.0):
        raise ValueError(f"quaternion {tuple(q)} has no valid norm")
    w, x, y, z = w / norm, x / norm, y / norm, z / norm
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


# --- IMU ------------------------------------------------------------------------------------


def raw_imu_message(sample: ImuSample, *, imu_id: int = 0) -> MAVLinkMessage:
    """ArduPilot-style RAW_IMU: acc in milli-g, gyro in milli-rad/s, ``time_usec`` from boot."""
    acc = sample.specific_force_body_mps2
    gyro = sample.angular_rate_body_rad_s
    return dialect.MAVLink_raw_imu_message(
        seconds_to_usec(sample.time_s),
        *(saturate_int(float(a) / MILLI_G_TO_MPS2, INT16_MIN, INT16_MAX) for a in acc),
        *(saturate_int(float(g) / MILLI_RAD_TO_RAD, INT16_MIN, INT16_MAX) for g in gyro),
        0,
        0,
        0,
        imu_id,
        0,
    )


def raw_imu_si(msg: MAVLinkMessage) -> tuple[float, Vector3, Vector3]:
    """RAW_IMU (ArduPilot units: milli-g, milli-rad/s, ``time_usec`` since boot) in SI
    scalars: time [s], specific force (FRD) [m/s^2], body rates [rad/s]."""
    g, rad = MILLI_G_TO_MPS2, MILLI_RAD_TO_RAD
    return (
        msg.time_usec * 1e-6,
        (msg.xacc * g, msg.yacc * g, msg.zacc * g),
        (msg.xgyro * rad, msg.ygyro * rad, msg.zgyro * rad),
    )


def imu_from_raw_imu(msg: MAVLinkMessage) -> ImuSample:
    """RAW_IMU (ArduPilot units: milli-g, milli-rad/s, ``time_usec`` since boot) to SI."""
    # scaled in scalars, one array each: the same doubles as scaling arrays, at every IMU
    # message without four array allocations
    time_s, force, rate = raw_imu_si(msg)
    return ImuSample(time_s, np.array(force), np.array(rate))


def imu_from_scaled_imu(msg: MAVLinkMessage) -> ImuSample:
    """SCALED_IMU/2/3 (milli-g, milli-rad/s, ``time_boot_ms``) to SI."""
    return ImuSample(
        time_s=msg.time_boot_ms * 1e-3,
        specific_force_body_mps2=np.array([msg.xacc, msg.yacc, msg.zacc], dtype=float)
        * MILLI_G_TO_MPS2,
        angular_rate_body_rad_s=np.array([msg.xgyro, msg.ygyro, msg.zgyro], dtype=float)
        * MILLI_RAD_TO_RAD,
    )


def highres_imu_message(sample: ImuSample, *, imu_id: int = 0) -> MAVLinkMessage:
    """PX4-style HIGHRES_IMU in m/s^2 and rad/s (only acc and gyro marked updated)."""
    acc = sample.specific_force_body_mps2
    gyro = sample.angular_rate_body_rad_s
    return dialect.MAVLink_highres_imu_message(
        seconds_to_usec(sample.time_s),
        float(acc[0]),
        float(acc[1]),
        float(acc[2]),
        float(gyro[0]),
        float(gyro[1]),
        float(gyro[2]),
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        _HIGHRES_IMU_ACC_GYRO_FIELDS,
        imu_id,
    )


def highres_imu_si(msg: MAVLinkMessage) -> tuple[float, Vector3, Vector3]:
    """HIGHRES_IMU (m/s^2, rad/s, ``time_usec``) in scalars: time [s], specific force (FRD)
    [m/s^2], body rates [rad/s]."""
    return (
        msg.time_usec * 1e-6,
        (float(msg.xacc), float(msg.yacc), float(msg.zacc)),
        (float(msg.xgyro), float(msg.ygyro), float(msg.zgyro)),
    )


def imu_from_highres_imu(msg: MAVLinkMessage) -> ImuSample:
    """HIGHRES_IMU (m/s^2, rad/s, ``time_usec``) to an :class:`ImuSample`."""
    time_s, force, rate = highres_imu_si(msg)
    return ImuSample(time_s, np.array(force), np.array(rate))


# --- attitude, motors, rangefinder ----------------------------------------------------------


def attitude_message(sample: AttitudeSample, body_rates_rad_s: ArrayLike) -> MAVLinkMessage:
    """ATTITUDE: Euler angles [rad], body rates (p, q, r) [rad/s], ``time_boot_ms``."""
    rates = np.asarray(body_rates_rad_s, dtype=float)
    return dialect.MAVLink_attitude_message(
        seconds_to_boot_ms(sample.time_s),
        float(sample.roll_rad),
        float(sample.pitch_rad),
        float(sample.yaw_rad),
        float(rates[0]),
        float(rates[1]),
        float(rates[2]),
    )


def attitude_from_attitude(msg: MAVLinkMessage) -> AttitudeSample:
    """ATTITUDE to an :class:`AttitudeSample` (time from ``time_boot_ms``)."""
    return AttitudeSample(
        time_s=msg.time_boot_ms * 1e-3,
        roll_rad=float(msg.roll),
        pitch_rad=float(msg.pitch),
        yaw_rad=float(msg.yaw),
    )


def servo_output_raw_message(sample: PwmSample, *, port: int = 0) -> MAVLinkMessage:
    """SERVO_OUTPUT_RAW: motor ``i`` on ``servo{i+1}_raw`` [us]; unused channels 0.

    ``time_usec`` is uint32 on the wire and wraps every 71.6 minutes.

    Raises
    ------
    ValueError
        With more than 16 motors, or a non-finite pulse width.
    """
    pwm = [saturate_int(float(v), 0, UINT16_MAX) for v in sample.pwm_us]
    if len(pwm) > SERVO_CHANNELS:
        raise ValueError(f"SERVO_OUTPUT_RAW carries 16 channels, got {len(pwm)}")
    pwm += [0] * (SERVO_CHANNELS - len(pwm))
    time_usec = seconds_to_usec(sample.time_s) & UINT32_MASK
    return dialect.MAVLink_servo_output_raw_message(time_usec, port, *pwm)


_SERVO_FIELDS = tuple(f"servo{i + 1}_raw" for i in range(SERVO_CHANNELS))
"""SERVO_OUTPUT_RAW's channel fields in channel order."""
_SERVO_GETTERS = {
    n: operator.attrgetter(*_SERVO_FIELDS[:n], _SERVO_FIELDS[0])
    for n in range(1, SERVO_CHANNELS + 1)
}
"""``_SERVO_GETTERS[n](msg)``: channels 1..n then channel 1 again (so that n = 1 also gives a
tuple; the extra item is dropped)."""


def servo_outputs(msg: MAVLinkMessage, n_motors: int) -> tuple[int, ...]:
    """SERVO_OUTPUT_RAW's channels 1..``n_motors`` as sent [us] (n_motors in 1..16)."""
    return _SERVO_GETTERS[n_motors](msg)[:-1]


def pwm_from_servo_output_raw(
    msg: MAVLinkMessage, n_motors: int, *, time_s: float | None = None
) -> PwmSample:
    """SERVO_OUTPUT_RAW to a :class:`PwmSample` of channels 1..``n_motors``.

    Parameters
    ----------
    msg
        The message.
    n_motors
        How many leading channels are motors (1..16).
    time_s
        Flight-controller time to stamp the sample with; by default ``time_usec`` [s], which
        is only unambiguous for the first 71.6 minutes after boot (uint32 wrap).
    """
    if not 1 <= n_motors <= SERVO_CHANNELS:
        raise ValueError(f"n_motors must be 1..16, got {n_motors}")
    pwm = np.array(servo_outputs(msg, n_motors), dtype=float)
    return PwmSample(time_s=msg.time_usec * 1e-6 if time_s is None else time_s, pwm_us=pwm)


def distance_sensor_message(
    time_s: float,
    distance_m: float,
    *,
    min_distance_m: float,
    max_distance_m: float,
    sensor_id: int = 0,
    orientation: int = DOWNWARD_ORIENTATION,
    sensor_type: int = dialect.MAV_DISTANCE_SENSOR_LASER,
    stddev_m: float | None = None,
) -> MAVLinkMessage:
    """DISTANCE_SENSOR in whole centimetres.

    A reading outside [min, max] is sent as it is (clipped to uint16), as ArduPilot does;
    receivers drop it. ``stddev_m`` fills ``covariance`` in cm^2 (255 = unknown; the field
    tops out at 254 cm^2, a 16 cm standard deviation).
    """
    if stddev_m is None:
        covariance = DISTANCE_COVARIANCE_UNKNOWN
    else:
        covariance = saturate_int((stddev_m * 100.0) ** 2, 0, DISTANCE_COVARIANCE_UNKNOWN - 1)
    return dialect.MAVLink_distance_sensor_message(
        seconds_to_boot_ms(time_s),
        saturate_int(min_distance_m * 100.0, 0, UINT16_MAX),
        saturate_int(max_distance_m * 100.0, 0, UINT16_MAX),
        saturate_int(distance_m * 100.0, 0, UINT16_MAX),
        sensor_type,
        sensor_id,
        orientation,
        covariance,
    )


def range_from_distance_sensor(msg: MAVLinkMessage) -> RangeSample | None:
    """DISTANCE_SENSOR to a :class:`RangeSample` [m], or None when outside [min, max]."""
    if not msg.min_distance <= msg.current_distance <= msg.max_distance:
        return None
    return RangeSample(time_s=msg.time_boot_ms * 1e-3, distance_m=msg.current_distance * 0.01)
