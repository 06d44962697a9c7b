"""PX4 ULog files (.ulg) read with pyulog (optional extra: ``pip install tether-companion[ulog]``).

Topics used (instance 0): ``sensor_combined`` (``accelerometer_m_s2[0..2]``, FRD body
[m/s^2]), ``vehicle_attitude`` (``q[0..3]``, Hamilton w-x-y-z, body FRD to NED),
``actuator_outputs`` (``output[0..3]`` [us]), optionally ``distance_sensor``
(``current_distance`` [m]) and ``battery_status`` (``voltage_v`` [V], ``voltage_filtered_v``
in logs older than PX4 1.10; samples with ``connected`` false are unknown and skipped, a
connected one that is not a positive finite voltage is an error naming its time). Time stamps
are PX4's ``timestamp`` [us since boot].
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tether_companion.errors import InputError
from tether_companion.sysid.logs.flightlog import N_MOTORS, FlightLog, Series, make_series

TOPICS = (
    "sensor_combined",
    "vehicle_attitude",
    "actuator_outputs",
    "distance_sensor",
    "battery_status",
)
BATTERY_FIELDS = ("voltage_v", "voltage_filtered_v")
"""battery_status's voltage field, newest name first."""


def euler_from_quaternion_rad(q_wxyz: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw [rad], shape (n, 3), of body-to-NED unit quaternions, shape (n, 4)."""
    w, x, y, z = (q_wxyz[:, i] for i in range(4))
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return np.column_stack([roll, pitch, yaw])


def _columns(
    source: str, topic: dict[str, Any], name: str, fields: list[str]
) -> tuple[np.ndarray, np.ndarray]:
    missing = [f for f in fields if f not in topic]
    if missing:
        raise InputError(f"{source}: topic {name} lacks field(s) {', '.join(missing)}")
    return np.asarray(topic["timestamp"], dtype=float) * 1e-6, np.column_stack(
        [topic[f] for f in fields]
    )


def _battery_voltage(source: str, topic: dict[str, Any] | None) -> Series | None:
    """battery_status's voltage [V] while connected, or None (no topic, under two samples).

    Raises
    ------
    InputError
        When the topic has no voltage field, or a connected sample's voltage is not a positive
        finite number (named with its time).
    """
    if topic is None:
        return None
    field = next((f for f in BATTERY_FIELDS if f in topic), None)
    if field is None:
        raise InputError(f"{source}: topic battery_status lacks field {BATTERY_FIELDS[0]}")
    time_s = np.asarray(topic["timestamp"], dtype=float) * 1e-6
    volts = np.asarray(topic[field], dtype=float)
    if "connected" in topic:
        connected = np.asarray(topic["connected"]) != 0
        time_s, volts = time_s[connected], volts[connected]
    bad = ~(np.isfinite(volts) & (volts > 0.0))
    if np.any(bad):
        k = int(np.argmax(bad))
        raise InputError(
            f"{source}: battery_status at {time_s[k]:.3f} s: {field} = {volts[k]:g} is not a "
            "positive voltage [V]"
        )
    if volts.size < 2:
        return None
    return make_series(source, "battery_status", time_s, volts, 1)


def load_ulog(path: Path) -> FlightLog:
    """Read a PX4 .ulg into a :class:`FlightLog` (see module docstring).

    Raises
    ------
    InputError
        When pyulog is not installed, the file is unreadable, or a needed topic is missing.
    """
    source = str(path)
    try:
        from pyulog import ULog
    except ImportError:
        raise InputError(
            f"{source}: reading PX4 .ulg logs needs pyulog: pip install 'tether-companion[ulog]'"
        ) from None
    if not path.is_file():
        raise InputError(f"{source}: no such file")
    try:
        log = ULog(source, message_name_filter_list=list(TOPICS))
    except Exception as exc:  # pyulog raises bare Exception subclasses of many kinds on bad files
        raise InputError(f"{source}: not a readable ULog file ({exc})") from None
    topics = {d.name: d.data for d in log.data_list if d.multi_id == 0}
    for name in TOPICS[:3]:
        if name not in topics:
            raise InputError(f"{source}: no {name} topic in the log")
    imu_t, accel = _columns(
        source,
        topics["sensor_combined"],
        "sensor_combined",
        [f"accelerometer_m_s2[{i}]" for i in range(3)],
    )
    att_t, quat = _columns(
        source, topics["vehicle_attitude"], "vehicle_attitude", [f"q[{i}]" for i in range(4)]
    )
    pwm_t, pwm = _columns(
        source,
        topics["actuator_outputs"],
        "actuator_outputs",
        [f"output[{i}]" for i in range(N_MOTORS)],
    )
    height = None
    if "distance_sensor" in topics:
        h_t, h = _columns(
            source, topics["distance_sensor"], "distance_sensor", ["current_distance"]
        )
        height = make_series(source, "distance_sensor", h_t, h, 1)
    return FlightLog(
        source=source,
        pwm_us=make_series(source, "actuator_outputs", pwm_t, pwm, N_MOTORS),
        specific_force_body_mps2=make_series(source, "sensor_combined", imu_t, accel, 3),
        euler_rad=make_series(
            source, "vehicle_attitude", att_t, euler_from_quaternion_rad(quat), 3
        ),
        height_m=height,
        battery_voltage_v=_battery_voltage(source, topics.get("battery_status")),
    )
