"""Telemetry streams: which messages the emulator sends periodically, at what rate, per link.

Each link has its own :class:`StreamSchedule`, as each ArduPilot telemetry port has its own
SRx_ rates: a ground station's REQUEST_DATA_STREAM on one link does not change what the
companion computer gets on another. Rates are changed by MAV_CMD_SET_MESSAGE_INTERVAL (per
message) and REQUEST_DATA_STREAM (per ArduPilot stream group, listed here as ``group``).

Times are simulation seconds: the schedule runs on the emulator's clock, so rates hold at
any ``--speed`` and in lock-step.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mav


@dataclass(frozen=True)
class StreamSpec:
    """A message the emulator can stream."""

    msg_id: int
    group: int | None
    """MAV_DATA_STREAM group of REQUEST_DATA_STREAM (ArduPilot's SRx_ parameter), or None."""
    default_hz: float
    """Default rate [Hz]; the four sensor streams default to the scenario's sensor rates."""


STREAMS: dict[str, StreamSpec] = {
    "HEARTBEAT": StreamSpec(mav.MAVLINK_MSG_ID_HEARTBEAT, None, 1.0),
    "SYS_STATUS": StreamSpec(
        mav.MAVLINK_MSG_ID_SYS_STATUS, mav.MAV_DATA_STREAM_EXTENDED_STATUS, 1.0
    ),
    "BATTERY_STATUS": StreamSpec(
        mav.MAVLINK_MSG_ID_BATTERY_STATUS, mav.MAV_DATA_STREAM_EXTENDED_STATUS, 1.0
    ),
    "EXTENDED_SYS_STATE": StreamSpec(
        mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, mav.MAV_DATA_STREAM_EXTENDED_STATUS, 1.0
    ),
    "SYSTEM_TIME": StreamSpec(mav.MAVLINK_MSG_ID_SYSTEM_TIME, mav.MAV_DATA_STREAM_EXTRA3, 1.0),
    "RAW_IMU": StreamSpec(mav.MAVLINK_MSG_ID_RAW_IMU, mav.MAV_DATA_STREAM_RAW_SENSORS, 200.0),
    "SCALED_IMU": StreamSpec(mav.MAVLINK_MSG_ID_SCALED_IMU, None, 0.0),
    "HIGHRES_IMU": StreamSpec(mav.MAVLINK_MSG_ID_HIGHRES_IMU, None, 0.0),
    "ATTITUDE": StreamSpec(mav.MAVLINK_MSG_ID_ATTITUDE, mav.MAV_DATA_STREAM_EXTRA1, 200.0),
    "SERVO_OUTPUT_RAW": StreamSpec(
        mav.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, mav.MAV_DATA_STREAM_RC_CHANNELS, 200.0
    ),
    "DISTANCE_SENSOR": StreamSpec(
        mav.MAVLINK_MSG_ID_DISTANCE_SENSOR, mav.MAV_DATA_STREAM_EXTRA3, 200.0
    ),
    "LOCAL_POSITION_NED": StreamSpec(
        mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED, mav.MAV_DATA_STREAM_POSITION, 10.0
    ),
    "GLOBAL_POSITION_INT": StreamSpec(
        mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, mav.MAV_DATA_STREAM_POSITION, 10.0
    ),
    "VFR_HUD": StreamSpec(mav.MAVLINK_MSG_ID_VFR_HUD, mav.MAV_DATA_STREAM_EXTRA2, 4.0),
    "SIM_STATE": StreamSpec(mav.MAVLINK_MSG_ID_SIM_STATE, mav.MAV_DATA_STREAM_EXTRA1, 50.0),
    "HOME_POSITION": StreamSpec(mav.MAVLINK_MSG_ID_HOME_POSITION, None, 0.0),
    "GPS_GLOBAL_ORIGIN": StreamSpec(mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, None, 0.0),
}
"""Every streamable message by name."""

STREAM_BY_ID: dict[int, str] = {spec.msg_id: name for name, spec in STREAMS.items()}

MIN_INTERVAL_S = 1e-3
"""Fastest stream: 1 kHz (ArduPilot caps by its loop rate; the emulator by its physics step)."""


def stream_names_in_group(group: int) -> list[str]:
    """Streams of a REQUEST_DATA_STREAM group (MAV_DATA_STREAM_ALL = every grouped stream)."""
    if group == mav.MAV_DATA_STREAM_ALL:
        return [name for name, spec in STREAMS.items() if spec.group is not None]
    return [name for name, spec in STREAMS.items() if spec.group == group]


class StreamSchedule:
    """Per-link stream intervals and due times (simulation seconds).

    Parameters
    ----------
    defaults_hz
        The default rate of every stream [Hz] (0 = off by default).
    now_s
        Current simulation time [s]; every enabled stream is due at once.
    """

    def __init__(self, defaults_hz: Mapping[str, float], now_s: float) -> None:
        self._defaults_hz = dict(defaults_hz)
        self._interval_s: dict[str, float] = {}
        self._next_s: dict[str, float] = {}
        for name in STREAMS:
            self.set_rate_hz(name, None, now_s)

    def set_rate_hz(self, name: str, rate_hz: float | None, now_s: float) -> None:
        """Set ``name`` to ``rate_hz`` (0 = off, None = its default), due from ``now_s``."""
        rate = self._defaults_hz.get(name, 0.0) if rate_hz is None else rate_hz
        if not (math.isfinite(rate) and rate > 0.0):
            self._interval_s.pop(name, None)
            self._next_s.pop(name, None)
            return
        self._interval_s[name] = max(1.0 / rate, MIN_INTERVAL_S)
        self._next_s[name] = now_s

    def rate_hz(self, name: str) -> float:
        """The current rate of ``name`` [Hz] (0 when off)."""
        interval = self._interval_s.get(name)
        return 0.0 if interval is None else 1.0 / interval

    def interval_s(self, name: str) -> float | None:
        """The current interval of ``name`` [s], None when off."""
        return self._interval_s.get(name)

    def next_due_s(self) -> float:
        """When the next stream is due [s] (inf when all are off)."""
        return min(self._next_s.values(), default=math.inf)

    def pop_due(self, now_s: float, tolerance_s: float) -> list[str]:
        """Streams due at ``now_s`` (within ``tolerance_s``), advancing each by its interval.

        A stream that fell more than one interval behind (after a pause) restarts from now
        rather than sending a burst.
        """
        due = []
        limit = now_s + tolerance_s
        for name, next_s in self._next_s.items():
            if next_s <= limit:
                due.append(name)
                interval = self._interval_s[name]
                next_s += interval
                self._next_s[name] = next_s if next_s > now_s else now_s + interval
        return due
