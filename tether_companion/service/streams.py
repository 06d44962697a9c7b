"""The input streams the service asks the flight controller for, and when to ask again.

Pure bookkeeping (no I/O): :class:`StreamRequests` keeps one :class:`StreamRequest` per input,
decides which requests are due at a local time and builds them; the service sends them and
hands back the COMMAND_ACKs of MAV_CMD_SET_MESSAGE_INTERVAL.

Every input's rate is set once per flight-controller boot and again while it stays silent
(``INPUT_SILENT_S``): MAV_CMD_SET_MESSAGE_INTERVAL first; after
``INTERVAL_ATTEMPTS_BEFORE_FALLBACK`` silent retries, or at once when the autopilot refused the
interval, also REQUEST_DATA_STREAM for its group (old firmware, or a ground station that keeps
resetting the rates).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.service.ingest import (
    ATTITUDE,
    FC_POSITION,
    IMU,
    LANDED,
    PWM,
    RANGE,
    SYSTEM_TIME,
)
from tether_companion.service.link_config import LinkConfig, StreamsConfig

INPUT_SILENT_S = 0.5
"""An input not heard for this long [s] (local time) while the link is up is re-requested."""
FC_POSITION_RATE_HZ = 20.0
"""LOCAL_POSITION_NED rate asked for (the tension modes' frame) [Hz]."""
SYSTEM_TIME_RATE_HZ = 5.0
"""SYSTEM_TIME rate asked for: the evidence of a flight-controller reboot [Hz]."""
LANDED_STATE_RATE_HZ = 5.0
"""EXTENDED_SYS_STATE rate asked for: the autopilot's landed state, an on-ground sign [Hz]
(above 1 / ``INPUT_SILENT_S``, so a stream at this rate is never taken for silent)."""
INTERVAL_ATTEMPTS_BEFORE_FALLBACK = 2
MAX_AWAITING_ACK = 16
"""Requests remembered while waiting for their COMMAND_ACK (bounded if never acked)."""

_STREAM_GROUPS = {
    IMU: dialect.MAV_DATA_STREAM_RAW_SENSORS,
    ATTITUDE: dialect.MAV_DATA_STREAM_EXTRA1,
    PWM: dialect.MAV_DATA_STREAM_RC_CHANNELS,
    RANGE: dialect.MAV_DATA_STREAM_EXTRA3,
    FC_POSITION: dialect.MAV_DATA_STREAM_POSITION,
    SYSTEM_TIME: dialect.MAV_DATA_STREAM_EXTRA3,
    LANDED: dialect.MAV_DATA_STREAM_EXTENDED_STATUS,
}
"""ArduPilot's REQUEST_DATA_STREAM groups (SRx_RAW_SENS, _EXTRA1, _RC_CHAN, _EXTRA3, _POSITION,
_EXT_STAT)."""


@dataclass
class StreamRequest:
    """Bookkeeping of one input stream we ask the flight controller for."""

    message_id: int
    rate_hz: float
    attempts: int = 0
    last_request_s: float = -math.inf
    last_count: int = 0
    last_heard_s: float = -math.inf
    acked: bool | None = None
    """Result of the last SET_MESSAGE_INTERVAL (None: no COMMAND_ACK yet)."""


class StreamRequests:
    """Which streams to ask for, and the requests due at a given local time.

    Parameters
    ----------
    link
        The link section (flight controller ids, re-request interval).
    streams
        The configured rates.
    """

    def __init__(self, link: LinkConfig, streams: StreamsConfig) -> None:
        self._link = link
        self._streams = streams
        self.table: dict[str, StreamRequest] = {}
        self._awaiting_ack: list[StreamRequest] = []
        self.reset()

    def reset(self) -> None:
        """Forget every request (a new link, or a flight-controller reboot)."""
        streams = self._streams
        imu_id = (
            dialect.MAVLINK_MSG_ID_RAW_IMU
            if self._link.autopilot == "ardupilot"
            else dialect.MAVLINK_MSG_ID_HIGHRES_IMU
        )
        table = {
            IMU: StreamRequest(imu_id, streams.imu_hz),
            ATTITUDE: StreamRequest(dialect.MAVLINK_MSG_ID_ATTITUDE, streams.attitude_hz),
            PWM: StreamRequest(dialect.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, streams.servo_hz),
        }
        if streams.rangefinder_hz > 0:
            table[RANGE] = StreamRequest(
                dialect.MAVLINK_MSG_ID_DISTANCE_SENSOR, streams.rangefinder_hz
            )
        # the tension modes' targets are in the FC's frame (asked for always: they may be
        # enabled at run time)
        table[FC_POSITION] = StreamRequest(
            dialect.MAVLINK_MSG_ID_LOCAL_POSITION_NED, FC_POSITION_RATE_HZ
        )
        # a reboot is believed only on SYSTEM_TIME's word (service/fc_time.py)
        table[SYSTEM_TIME] = StreamRequest(dialect.MAVLINK_MSG_ID_SYSTEM_TIME, SYSTEM_TIME_RATE_HZ)
        # the autopilot's land detector: the dynamic filter's on-ground sign
        table[LANDED] = StreamRequest(
            dialect.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, LANDED_STATE_RATE_HZ
        )
        self.table = table
        self._awaiting_ack = []

    def on_interval_ack(self, result: int) -> None:
        """A COMMAND_ACK of MAV_CMD_SET_MESSAGE_INTERVAL (the autopilot answers in order)."""
        if self._awaiting_ack:
            self._awaiting_ack.pop(0).acked = result == dialect.MAV_RESULT_ACCEPTED

    def silent_s(self, kind: str, now_s: float) -> float:
        """Local seconds since ``kind`` was last accepted (inf: never)."""
        return now_s - self.table[kind].last_heard_s

    def due(self, now_s: float, accepted: dict[str, int]) -> list[MAVLinkMessage]:
        """The requests to send at local time ``now_s`` [s], given the counts of accepted
        samples per input so far (a count that moved means the input was heard)."""
        cfg = self._link
        out: list[MAVLinkMessage] = []
        for kind, stream in self.table.items():
            count = accepted[kind]
            if count != stream.last_count:
                stream.last_count = count
                stream.last_heard_s = now_s
            silent = now_s - stream.last_heard_s > INPUT_SILENT_S
            first = stream.attempts == 0  # always set the configured rate once per FC boot
            if (
                not (first or silent)
                or now_s - stream.last_request_s < cfg.stream_request_interval_s
            ):
                continue
            refused = stream.acked is False  # DENIED/UNSUPPORTED/FAILED: no point waiting
            stream.attempts += 1
            stream.last_request_s = now_s
            stream.acked = None
            self._awaiting_ack = [*self._awaiting_ack[-(MAX_AWAITING_ACK - 1) :], stream]
            out.append(
                dialect.MAVLink_command_long_message(
                    cfg.fc_system_id,
                    cfg.fc_component_id,
                    dialect.MAV_CMD_SET_MESSAGE_INTERVAL,
                    0,
                    float(stream.message_id),
                    1e6 / stream.rate_hz,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                )
            )
            fallback = refused or stream.attempts > INTERVAL_ATTEMPTS_BEFORE_FALLBACK
            if fallback and kind in _STREAM_GROUPS:
                group = _STREAM_GROUPS[kind]
                out.append(
                    dialect.MAVLink_request_data_stream_message(
                        cfg.fc_system_id,
                        cfg.fc_component_id,
                        group,
                        max(1, round(self.group_rate_hz(group))),
                        1,
                    )
                )
        return out

    def group_rate_hz(self, group: int) -> float:
        """The rate to ask for a REQUEST_DATA_STREAM group [Hz]: the fastest of the inputs in
        it (the group's rate applies to all its messages: the rangefinder's 20 Hz and
        SYSTEM_TIME's 5 Hz share ArduPilot's EXTRA3, and asking at 5 Hz would slow both)."""
        return max(
            stream.rate_hz
            for kind, stream in self.table.items()
            if _STREAM_GROUPS.get(kind) == group
        )
