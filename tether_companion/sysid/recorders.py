"""Write flight samples as a log file: MAVLink .tlog, ArduPilot dataflash .bin or CSV.

The three formats the loaders read (:mod:`tether_companion.sysid.logs`), written from typed
SI samples, so a simulated identification flight can be identified like a real one.

- .tlog: each record is the wall-clock stamp [us] as 8 big-endian bytes and one MAVLink 2
  packet (what ground stations record); RAW_IMU in milli-g (ArduPilot), ATTITUDE,
  SERVO_OUTPUT_RAW, DISTANCE_SENSOR in cm (encoded by :mod:`tether_companion.mavlink.units`),
  a 1 Hz HEARTBEAT and SYS_STATUS with the battery voltage at 2 Hz (ArduPilot's default
  extended-status rate).
- .bin: IMU, ATT (degrees), RCOU, RFND records and BAT at 10 Hz
  (:mod:`...logs.dataflash_writer`).
- .csv: the columns of :mod:`tether_companion.sysid.logs.csvlog`, battery voltage included.
"""

from __future__ import annotations

import csv
import math
import struct
from pathlib import Path
from typing import BinaryIO, Protocol, TextIO

import numpy as np
from numpy.typing import NDArray

from tether_companion.errors import InputError
from tether_companion.mavlink import units
from tether_companion.mavlink.battery import UNKNOWN_MV
from tether_companion.mavlink.framing import FrameEncoder, MAVLinkMessage, dialect
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample
from tether_companion.sysid.logs import csvlog
from tether_companion.sysid.logs.dataflash_writer import (
    DataflashWriter,
    declare_identification_messages,
)

FloatArray = NDArray[np.float64]

TLOG_EPOCH_US = 1_700_000_000_000_000
"""Wall-clock stamp [us since 1970] given to flight-controller time 0 in written .tlogs."""
_RAD_TO_DEG = 180.0 / math.pi
SYS_STATUS_PERIOD_S = 0.5
"""SYS_STATUS interval in written .tlogs [s]."""
BAT_PERIOD_S = 0.1
"""BAT record interval in written .bin logs [s] (ArduPilot logs BAT at 10 Hz)."""


class Recorder(Protocol):
    """Something that stores one tick of samples."""

    def write(
        self,
        imu: ImuSample,
        attitude: AttitudeSample,
        body_rates_rad_s: FloatArray,
        pwm: PwmSample,
        rangefinder: RangeSample | None,
        battery_voltage_v: float = math.nan,
    ) -> None:
        """Store the samples of one tick (and the battery voltage [V], NaN: unknown)."""
        ...

    def close(self) -> None:
        """Flush and close the file."""
        ...


class _FileRecorder:
    """A recorder writing one open file ``_file``; :meth:`close` closes it."""

    _file: BinaryIO | TextIO

    def close(self) -> None:
        """Close the file."""
        self._file.close()


class TlogRecorder(_FileRecorder):
    """MAVLink 2 telemetry log as a ground station records it (see module docstring)."""

    def __init__(self, path: Path, range_limits_m: tuple[float, float], system_id: int = 1) -> None:
        self._file: BinaryIO = path.open("wb")
        self._encoder = FrameEncoder(system_id, 1)
        self._range_limits_m = range_limits_m
        self._next_heartbeat_s = 0.0
        self._next_status_s = 0.0

    def _put(self, time_s: float, msg: MAVLinkMessage) -> None:
        stamp = TLOG_EPOCH_US + int(round(time_s * 1e6))
        self._file.write(struct.pack(">Q", stamp) + self._encoder.encode(msg))

    def write(
        self,
        imu: ImuSample,
        attitude: AttitudeSample,
        body_rates_rad_s: FloatArray,
        pwm: PwmSample,
        rangefinder: RangeSample | None,
        battery_voltage_v: float = math.nan,
    ) -> None:
        """Store RAW_IMU, ATTITUDE, SERVO_OUTPUT_RAW, DISTANCE_SENSOR (and a HEARTBEAT at 1 Hz,
        SYS_STATUS at 2 Hz when the voltage is known)."""
        if math.isfinite(battery_voltage_v) and imu.time_s >= self._next_status_s:
            self._put(imu.time_s, _sys_status_message(battery_voltage_v))
            self._next_status_s = imu.time_s + SYS_STATUS_PERIOD_S
        if imu.time_s >= self._next_heartbeat_s:
            heartbeat = dialect.MAVLink_heartbeat_message(
                dialect.MAV_TYPE_QUADROTOR, dialect.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0, 3
            )
            self._put(imu.time_s, heartbeat)
            self._next_heartbeat_s = imu.time_s + 1.0
        self._put(imu.time_s, units.raw_imu_message(imu))
        self._put(attitude.time_s, units.attitude_message(attitude, body_rates_rad_s))
        self._put(pwm.time_s, units.servo_output_raw_message(pwm))
        if rangefinder is not None:
            lo, hi = self._range_limits_m
            msg = units.distance_sensor_message(
                rangefinder.time_s, rangefinder.distance_m, min_distance_m=lo, max_distance_m=hi
            )
            self._put(rangefinder.time_s, msg)


class DataflashRecorder(_FileRecorder):
    """ArduPilot dataflash log with IMU, ATT, RCOU and RFND records."""

    def __init__(self, path: Path) -> None:
        self._file: BinaryIO = path.open("wb")
        self._writer = DataflashWriter(self._file)
        declare_identification_messages(self._writer)
        self._next_battery_s = 0.0

    def write(
        self,
        imu: ImuSample,
        attitude: AttitudeSample,
        body_rates_rad_s: FloatArray,
        pwm: PwmSample,
        rangefinder: RangeSample | None,
        battery_voltage_v: float = math.nan,
    ) -> None:
        """Store one IMU, ATT, RCOU, (when in range) RFND and (at 10 Hz, when known) BAT record."""
        gyro, acc = imu.angular_rate_body_rad_s, imu.specific_force_body_mps2
        self._writer.write("IMU", _us(imu.time_s), 0, *gyro.tolist(), *acc.tolist())
        angles = (attitude.roll_rad, attitude.pitch_rad, attitude.yaw_rad)
        self._writer.write("ATT", _us(attitude.time_s), *(a * _RAD_TO_DEG for a in angles))
        self._writer.write("RCOU", _us(pwm.time_s), *(int(round(p)) for p in pwm.pwm_us[:4]))
        if rangefinder is not None:
            self._writer.write("RFND", _us(rangefinder.time_s), 0, rangefinder.distance_m)
        if math.isfinite(battery_voltage_v) and imu.time_s >= self._next_battery_s:
            self._writer.write("BAT", _us(imu.time_s), 0, battery_voltage_v)
            self._next_battery_s = imu.time_s + BAT_PERIOD_S


class CsvRecorder(_FileRecorder):
    """CSV with the documented columns; ``height_m`` empty when the rangefinder is out of range,
    ``battery_voltage_v`` when the voltage is unknown."""

    def __init__(self, path: Path) -> None:
        self._file: TextIO = path.open("w", newline="", encoding="utf-8")
        self._csv = csv.writer(self._file)
        self._csv.writerow([*csvlog.REQUIRED_COLUMNS, csvlog.HEIGHT_COLUMN, csvlog.BATTERY_COLUMN])

    def write(
        self,
        imu: ImuSample,
        attitude: AttitudeSample,
        body_rates_rad_s: FloatArray,
        pwm: PwmSample,
        rangefinder: RangeSample | None,
        battery_voltage_v: float = math.nan,
    ) -> None:
        """Store one row, all signals stamped with the IMU time."""
        height = "" if rangefinder is None else f"{rangefinder.distance_m:.4f}"
        voltage = f"{battery_voltage_v:.3f}" if math.isfinite(battery_voltage_v) else ""
        self._csv.writerow(
            [
                f"{imu.time_s:.6f}",
                *(f"{p:.0f}" for p in pwm.pwm_us[:4]),
                *(f"{a:.5f}" for a in imu.specific_force_body_mps2),
                *(f"{a:.6f}" for a in (attitude.roll_rad, attitude.pitch_rad, attitude.yaw_rad)),
                height,
                voltage,
            ]
        )


def _sys_status_message(voltage_v: float) -> MAVLinkMessage:
    """SYS_STATUS carrying only the battery voltage (current, charge, sensors unknown)."""
    millivolts = min(round(voltage_v * 1000.0), UNKNOWN_MV - 1)
    return dialect.MAVLink_sys_status_message(
        0, 0, 0, 0, millivolts, -1, -1, 0, 0, 0, 0, 0, 0, 0, 0, 0
    )


def _us(time_s: float) -> int:
    return int(round(time_s * 1e6))


def open_recorder(path: str | Path, range_limits_m: tuple[float, float]) -> Recorder:
    """A recorder for ``path``'s extension (.tlog, .bin or .csv); close it when done
    (``contextlib.closing``).

    Raises
    ------
    InputError
        For another extension or a path that cannot be created.
    """
    path = Path(path)
    kinds = {
        ".tlog": lambda: TlogRecorder(path, range_limits_m),
        ".bin": lambda: DataflashRecorder(path),
        ".csv": lambda: CsvRecorder(path),
    }
    make = kinds.get(path.suffix.lower())
    if make is None:
        raise InputError(f"{path}: cannot record a {path.suffix!r} file; use .tlog, .bin or .csv")
    try:
        return make()
    except OSError as exc:
        raise InputError(f"{path}: cannot create ({exc.strerror})") from None
