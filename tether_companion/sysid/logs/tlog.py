"""MAVLink telemetry logs (.tlog): what a ground station records from the link.

Read with pymavlink's ``mavutil`` (each record is an 8-byte big-endian wall-clock stamp and one
MAVLink packet). Signals come from the flight controller's own time stamps:

- accelerometer: ``HIGHRES_IMU`` (PX4, m/s^2) or else ``RAW_IMU`` / ``SCALED_IMU``
  (ArduPilot, milli-g), instance 0;
- attitude: ``ATTITUDE`` (rad);
- motors: ``SERVO_OUTPUT_RAW`` port 0, ``servo1_raw`` .. ``servo4_raw`` (us);
- height: ``DISTANCE_SENSOR`` facing down (cm), optional;
- battery voltage, optional: ``SYS_STATUS`` ``voltage_battery`` or else ``BATTERY_STATUS``
  (:func:`tether_companion.mavlink.battery.battery_voltage_v`; unknown values skipped). These
  carry no flight-controller time: they are placed on it by the record's wall-clock stamp
  minus the median offset between the ``ATTITUDE`` stamps and their ``time_boot_ms``.

Only messages from the system that sends ``ATTITUDE`` most are used (other systems, such as
ArduPilot SITL's tether simulator, share the link).
"""

from __future__ import annotations

from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from pymavlink import mavutil

from tether_companion.errors import InputError
from tether_companion.mavlink import units
from tether_companion.mavlink.battery import BATTERY_MESSAGES, battery_voltage_v
from tether_companion.sysid.logs.flightlog import N_MOTORS, FlightLog, Series, make_series

WANTED = (
    "HIGHRES_IMU",
    "RAW_IMU",
    "SCALED_IMU",
    "ATTITUDE",
    "SERVO_OUTPUT_RAW",
    "DISTANCE_SENSOR",
    "LOCAL_POSITION_NED",
    *sorted(BATTERY_MESSAGES),
)
_UINT32_SPAN = 2**32
_STAMP_BYTES = 8
_MAGIC_V1, _MAGIC_V2 = 0xFE, 0xFD
IMU_DECODERS = {
    "HIGHRES_IMU": units.imu_from_highres_imu,
    "RAW_IMU": units.imu_from_raw_imu,
    "SCALED_IMU": units.imu_from_scaled_imu,
}
"""IMU messages in order of preference and their SI decoders."""


def _unwrap_uint32_us(stamps_us: list[int]) -> np.ndarray:
    """Undo the wrap of a uint32 microsecond clock (every ~71.6 min) [us]."""
    raw = np.asarray(stamps_us, dtype=np.int64)
    wraps = np.cumsum(np.concatenate(([0], np.diff(raw) < -_UINT32_SPAN // 2)))
    return (raw + wraps * _UINT32_SPAN).astype(float)


def ends_mid_record(data: bytes) -> bool:
    """True when the last tlog record (8-byte stamp + MAVLink packet) is cut short.

    Walks the records by their packet lengths (MAVLink 2: payload + 12 bytes, + 13 signature
    bytes when signed; MAVLink 1: payload + 8); stops without a verdict at bytes that are not
    a packet start.
    """
    position = 0
    while position < len(data):
        if position + _STAMP_BYTES + 2 > len(data):
            return True
        magic, payload = data[position + _STAMP_BYTES], data[position + _STAMP_BYTES + 1]
        if magic == _MAGIC_V2:
            incompat = (
                data[position + _STAMP_BYTES + 2] if position + _STAMP_BYTES + 2 < len(data) else 0
            )
            size = payload + 12 + (13 if incompat & 1 else 0)
        elif magic == _MAGIC_V1:
            size = payload + 8
        else:
            return False
        position += _STAMP_BYTES + size
    return position > len(data)


def _read_messages(path: Path) -> tuple[dict[str, list[Any]], bool]:
    """All wanted messages of the main system, by type, and whether the file ends mid-record."""
    source = str(path)
    try:
        # the streaming reader (mavlink_connection picks an mmap reader for .tlog files
        # that fails on a file cut mid-record)
        link = mavutil.mavlogfile(source, robust_parsing=True)
    except OSError as exc:
        raise InputError(f"{source}: cannot open ({exc.strerror})") from None
    by_system: dict[tuple[int, int], dict[str, list[Any]]] = defaultdict(lambda: defaultdict(list))
    try:
        while True:
            try:
                msg = link.recv_match(type=list(WANTED))
            except Exception as exc:  # noqa: BLE001 - pymavlink raises many kinds on bad bytes
                raise InputError(
                    f"{source}: unreadable MAVLink data ({type(exc).__name__}: {exc})"
                ) from None
            if msg is None:
                break
            by_system[(msg.get_srcSystem(), msg.get_srcComponent())][msg.get_type()].append(msg)
    finally:
        link.close()
    truncated = ends_mid_record(path.read_bytes())
    if not by_system:
        raise InputError(
            f"{source}: no IMU, ATTITUDE or SERVO_OUTPUT_RAW message found (not a MAVLink .tlog?)"
        )
    attitude_counts = Counter({key: len(msgs["ATTITUDE"]) for key, msgs in by_system.items()})
    main, _ = attitude_counts.most_common(1)[0]
    return by_system[main], truncated


def _battery_voltage(
    source: str, messages: dict[str, list[Any]], attitude: list[Any]
) -> Series | None:
    """Battery voltage [V] on flight-controller time, or None when fewer than two are known."""
    offset_s = float(np.median([m.time_boot_ms * 1e-3 - m._timestamp for m in attitude]))
    for name in ("SYS_STATUS", "BATTERY_STATUS"):
        stamped = [(m._timestamp + offset_s, battery_voltage_v(m)) for m in messages.get(name, [])]
        known = [(t, v) for t, v in stamped if np.isfinite(v)]
        if len(known) >= 2:
            times, volts = zip(*known, strict=True)
            return make_series(source, name, times, volts, 1)
    return None


def load_tlog(path: Path) -> FlightLog:
    """Read a MAVLink .tlog into a :class:`FlightLog` (see module docstring).

    Raises
    ------
    InputError
        When the file cannot be read or lacks IMU, ATTITUDE or SERVO_OUTPUT_RAW messages.
    """
    source = str(path)
    messages, truncated = _read_messages(path)
    notes = (
        ("file ends in a partial record (truncated); the partial record was dropped",)
        if truncated
        else ()
    )
    suffix = " (the file is truncated)" if truncated else ""

    def need(*names: str) -> tuple[str, list[Any]]:
        for name in names:
            if messages.get(name):
                return name, messages[name]
        raise InputError(f"{source}: no {' or '.join(names)} message in the log{suffix}")

    imu_name, imu_msgs = need(*IMU_DECODERS)
    imu = [IMU_DECODERS[imu_name](m) for m in imu_msgs if getattr(m, "id", 0) == 0]
    _, att_msgs = need("ATTITUDE")
    _, servo_msgs = need("SERVO_OUTPUT_RAW")
    servo_msgs = [m for m in servo_msgs if m.port == 0]
    pwm = [[getattr(m, f"servo{i + 1}_raw") for i in range(N_MOTORS)] for m in servo_msgs]
    ranges = [
        sample
        for m in messages.get("DISTANCE_SENSOR", [])
        if m.orientation == units.DOWNWARD_ORIENTATION
        and (sample := units.range_from_distance_sensor(m)) is not None
    ]
    height = None
    if len(ranges) >= 2:
        height = make_series(
            source, "DISTANCE_SENSOR", [r.time_s for r in ranges], [r.distance_m for r in ranges], 1
        )
    attitude = [units.attitude_from_attitude(m) for m in att_msgs]
    local = messages.get("LOCAL_POSITION_NED", [])
    velocity = None
    if len(local) >= 2:
        velocity = make_series(
            source,
            "LOCAL_POSITION_NED",
            [m.time_boot_ms * 1e-3 for m in local],
            [[m.vx, m.vy, m.vz] for m in local],
            3,
        )
    return FlightLog(
        source=source,
        pwm_us=make_series(
            source,
            "SERVO_OUTPUT_RAW",
            _unwrap_uint32_us([m.time_usec for m in servo_msgs]) * 1e-6,
            pwm,
            N_MOTORS,
        ),
        specific_force_body_mps2=make_series(
            source, imu_name, [x.time_s for x in imu], [x.specific_force_body_mps2 for x in imu], 3
        ),
        euler_rad=make_series(
            source,
            "ATTITUDE",
            [a.time_s for a in attitude],
            [[a.roll_rad, a.pitch_rad, a.yaw_rad] for a in attitude],
            3,
        ),
        height_m=height,
        velocity_ned_mps=velocity,
        battery_voltage_v=_battery_voltage(source, messages, att_msgs),
        notes=notes,
    )
