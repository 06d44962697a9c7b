"""Messages other than commands that the emulated flight controller acts on.

:class:`MessageHandlers` is one part of the
:class:`~tether_companion.emulator.autopilot.FlightController`:
mode changes, data-stream requests, GUIDED position targets, the EKF origin, external
navigation (VISION_POSITION_ESTIMATE, ODOMETRY), the parameter protocol, TIMESYNC and the
mission protocol's empty answers. :data:`MESSAGE_HANDLERS` maps a message type to its handler.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from tether_companion.emulator import telemetry
from tether_companion.emulator.modes import (
    CopterMode,
)
from tether_companion.emulator.streams import (
    stream_names_in_group,
)
from tether_companion.mavlink import estimates, geo, units
from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.sim.controller import Setpoint

GUIDED_VELOCITY_TIMEOUT_S = 3.0
"""A velocity-only GUIDED target is dropped after this long without a new one (GUID_TIMEOUT)."""
MAX_DISTANCE_M = 10_000.0
"""Position targets farther than this from the origin are refused as invalid."""
_POS_IGNORE = 0b111
_VEL_IGNORE = 0b111 << 3
_YAW_IGNORE = 1 << 10


class MessageHandlers:
    """The flight controller's message handling (mixed into ``FlightController``)."""

    def _on_heartbeat(self, msg: MAVLinkMessage, link_id: int) -> None:
        """Ground stations and companions announce themselves; nothing to do."""

    def _on_command_long(self, msg: MAVLinkMessage, link_id: int) -> None:
        params = (
            msg.param1,
            msg.param2,
            msg.param3,
            msg.param4,
            msg.param5,
            msg.param6,
            msg.param7,
        )
        self._command(msg, msg.command, params, None, link_id)

    def _on_command_int(self, msg: MAVLinkMessage, link_id: int) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z)
        self._command(msg, msg.command, params, msg.frame, link_id)

    def _on_set_mode(self, msg: MAVLinkMessage, link_id: int) -> None:
        result, text = self._set_mode(float(msg.base_mode), float(msg.custom_mode))
        if text:
            self._text(dialect.MAV_SEVERITY_CRITICAL, text)
        self._ack(msg, dialect.MAVLINK_MSG_ID_SET_MODE, result, link_id)

    def _on_request_data_stream(self, msg: MAVLinkMessage, link_id: int) -> None:
        names = stream_names_in_group(msg.req_stream_id)
        if not names:
            self.counters.bad_values += 1
            return
        rate = float(msg.req_message_rate) if msg.start_stop else 0.0
        now = self.sim.time_s
        for name in names:
            self._schedules[link_id].set_rate_hz(name, rate, now)
        self._refresh_next_due()

    def _on_set_position_target_local_ned(self, msg: MAVLinkMessage, link_id: int) -> None:
        frame = msg.coordinate_frame
        if frame not in (
            dialect.MAV_FRAME_LOCAL_NED,
            dialect.MAV_FRAME_LOCAL_OFFSET_NED,
            dialect.MAV_FRAME_BODY_NED,
            dialect.MAV_FRAME_BODY_OFFSET_NED,
        ):
            self.counters.bad_values += 1
            return
        position = velocity = None
        mask = msg.type_mask
        if mask & _POS_IGNORE != _POS_IGNORE:
            position = (msg.x, msg.y, msg.z)
        if mask & _VEL_IGNORE != _VEL_IGNORE:
            velocity = (msg.vx, msg.vy, msg.vz)
        yaw = None if mask & _YAW_IGNORE else msg.yaw
        used = [v for v in (position, velocity) if v is not None]
        if not used or not all(
            math.isfinite(c) and abs(c) <= MAX_DISTANCE_M for v in used for c in v
        ):
            self.counters.bad_values += 1
            return
        if yaw is not None and not math.isfinite(yaw):
            self.counters.bad_values += 1
            return
        if not self._guided_target_allowed():
            return
        current = self._control_position()
        heading = self.sim.euler_rad[2]
        if frame in (dialect.MAV_FRAME_BODY_NED, dialect.MAV_FRAME_BODY_OFFSET_NED):
            c, s = math.cos(heading), math.sin(heading)
            if position is not None:
                position = (
                    c * position[0] - s * position[1],
                    s * position[0] + c * position[1],
                    position[2],
                )
            if velocity is not None:
                velocity = (
                    c * velocity[0] - s * velocity[1],
                    s * velocity[0] + c * velocity[1],
                    velocity[2],
                )
        if position is not None and frame != dialect.MAV_FRAME_LOCAL_NED:
            position = (
                current[0] + position[0],
                current[1] + position[1],
                current[2] + position[2],
            )
        self._guided_target(position, velocity, yaw)

    def _on_set_position_target_global_int(self, msg: MAVLinkMessage, link_id: int) -> None:
        position = velocity = None
        mask = msg.type_mask
        if mask & _POS_IGNORE != _POS_IGNORE:
            position = self._global_to_local(
                msg.coordinate_frame, float(msg.lat_int), float(msg.lon_int), msg.alt
            )
            if position is None:
                self.counters.bad_values += 1
                return
        if mask & _VEL_IGNORE != _VEL_IGNORE:
            velocity = (msg.vx, msg.vy, msg.vz)
            if not all(math.isfinite(v) and abs(v) <= MAX_DISTANCE_M for v in velocity):
                self.counters.bad_values += 1
                return
        yaw = None if mask & _YAW_IGNORE else msg.yaw
        if (position is None and velocity is None) or (yaw is not None and not math.isfinite(yaw)):
            self.counters.bad_values += 1
            return
        if self._guided_target_allowed():
            self._guided_target(position, velocity, yaw)

    def _guided_target_allowed(self) -> bool:
        if (
            self.mode != CopterMode.GUIDED
            or not self.armed
            or (self.sim.landed and not self.taking_off)
        ):
            self.counters.ignored += 1
            return False
        return True

    def _guided_target(self, position, velocity, yaw) -> None:  # noqa: ANN001 - tuples or None
        self._takeoff_target_d = None
        if position is None:
            self._velocity_deadline_s = self.sim.time_s + GUIDED_VELOCITY_TIMEOUT_S
        else:
            self._velocity_deadline_s = math.inf
        self._setpoint(Setpoint(position, velocity, None, yaw))

    def _global_to_local(
        self, frame: int, lat_e7: float, lon_e7: float, alt_m: float
    ) -> tuple[float, float, float] | None:
        """A global target in the EKF frame [m], None if invalid.

        Latitude and longitude are degE7 integers in every frame (COMMAND_INT's x/y and
        SET_POSITION_TARGET_GLOBAL_INT's lat_int/lon_int); the frame only says whether the
        altitude [m] is above mean sea level (GLOBAL*) or above home (RELATIVE_ALT, TERRAIN).
        """
        if not (math.isfinite(lat_e7) and math.isfinite(lon_e7) and math.isfinite(alt_m)):
            return None
        if frame == dialect.MAV_FRAME_GLOBAL_INT or frame == dialect.MAV_FRAME_GLOBAL:
            alt_amsl = alt_m
        elif frame in (
            dialect.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
            dialect.MAV_FRAME_GLOBAL_RELATIVE_ALT,
            dialect.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
            dialect.MAV_FRAME_GLOBAL_TERRAIN_ALT,
        ):
            alt_amsl = self.home.alt_m + alt_m
        else:
            return None
        try:
            point = geo.Geodetic(lat_e7 * 1e-7, lon_e7 * 1e-7, alt_amsl)
        except ValueError:
            return None
        local = geo.geodetic_to_ned(self.origin or self.home, point)
        if not np.all(np.abs(local) <= MAX_DISTANCE_M):
            return None
        return (float(local[0]), float(local[1]), float(local[2]))

    def _on_set_gps_global_origin(self, msg: MAVLinkMessage, link_id: int) -> None:
        try:
            origin = geo.Geodetic.from_e7(msg.latitude, msg.longitude, msg.altitude)
        except ValueError:
            self.counters.bad_values += 1
            return
        if self.origin is None:
            self.origin = origin
            self.nav.origin_set = True
            self._text(dialect.MAV_SEVERITY_INFO, "EKF3 origin set")
        else:
            self.counters.ignored += 1  # EKF3 takes the origin once per boot
        self._send(telemetry.gps_global_origin(self))

    def _on_vision_position_estimate(self, msg: MAVLinkMessage, link_id: int) -> None:
        self._external_pose(estimates.pose_from_vision_position_estimate(msg), msg.get_type())

    def _on_odometry(self, msg: MAVLinkMessage, link_id: int) -> None:
        try:
            pose = estimates.pose_from_odometry(msg)
        except ValueError:
            self.counters.bad_values += 1
            self.scorer.add(
                msg.get_type(), np.full(3, math.nan), math.nan, self.time_s, self.truth_history
            )
            return
        self._external_pose(pose, msg.get_type())
        try:
            velocity = estimates.velocity_from_odometry(msg)
        except ValueError:
            self.counters.bad_values += 1
            return
        if velocity is not None:
            self._external_velocity(velocity)

    def _on_vision_speed_estimate(self, msg: MAVLinkMessage, link_id: int) -> None:
        self._external_velocity(estimates.velocity_from_vision_speed_estimate(msg))

    def _external_pose(self, pose: estimates.PoseEstimate, kind: str) -> None:
        now = self.sim.time_s
        covariance = None if pose.covariance is None else pose.covariance[:3, :3]
        self.scorer.add(
            kind,
            pose.position_ned_m,
            pose.time_s + self._boot_sim_s,
            now,
            self.truth_history,
            covariance,
        )
        if self.vision_navigation:
            self.nav.on_estimate(pose, self.boot_time_s)

    def _external_velocity(self, velocity: estimates.VelocityEstimate) -> None:
        """Score a received velocity (scored only: the emulated EKF navigates on position)."""
        self.scorer.add_velocity(
            velocity.velocity_ned_m_s,
            velocity.time_s + self._boot_sim_s,
            self.sim.time_s,
            self.truth_history,
            velocity.covariance,
        )

    def _on_param_request_list(self, msg: MAVLinkMessage, link_id: int) -> None:
        for name in self.params.names:
            self._send(self.params.message(name), link_id)

    def _on_param_request_read(self, msg: MAVLinkMessage, link_id: int) -> None:
        name = (
            self.params.name_at(msg.param_index)
            if msg.param_index >= 0
            else _param_name(msg.param_id)
        )
        if name is None or name not in self.params:
            self.counters.ignored += 1
            return
        self._send(self.params.message(name), link_id)

    def _on_param_set(self, msg: MAVLinkMessage, link_id: int) -> None:
        name = _param_name(msg.param_id)
        if name not in self.params:
            self.counters.ignored += 1
            self._text(dialect.MAV_SEVERITY_WARNING, f"Unknown parameter {name}")
            return
        why = self.params.set(name, self.params.decode(float(msg.param_value), msg.param_type))
        if why is not None:
            self.counters.bad_values += 1
            self._text(dialect.MAV_SEVERITY_WARNING, f"{name}: {why}")
        self._send(self.params.message(name))

    def _on_timesync(self, msg: MAVLinkMessage, link_id: int) -> None:
        if msg.tc1 == 0:
            now_ns = units.saturate_int(self.boot_time_s * 1e9, 0, 2**63 - 1)
            self._send(dialect.MAVLink_timesync_message(now_ns, msg.ts1), link_id)

    def _on_mission_request_list(self, msg: MAVLinkMessage, link_id: int) -> None:
        self._send(
            dialect.MAVLink_mission_count_message(
                msg.get_srcSystem(), msg.get_srcComponent(), 0, msg.mission_type
            ),
            link_id,
        )

    def _on_mission_count(self, msg: MAVLinkMessage, link_id: int) -> None:
        self._send(
            dialect.MAVLink_mission_ack_message(
                msg.get_srcSystem(),
                msg.get_srcComponent(),
                dialect.MAV_MISSION_UNSUPPORTED,
                msg.mission_type,
            ),
            link_id,
        )

    def _on_mission_clear_all(self, msg: MAVLinkMessage, link_id: int) -> None:
        self._send(
            dialect.MAVLink_mission_ack_message(
                msg.get_srcSystem(),
                msg.get_srcComponent(),
                dialect.MAV_MISSION_ACCEPTED,
                msg.mission_type,
            ),
            link_id,
        )


def _param_name(param_id: str | bytes) -> str:
    if isinstance(param_id, bytes):
        param_id = param_id.decode("ascii", "replace")
    return param_id.rstrip("\x00")


MESSAGE_HANDLERS: dict[str, Callable[..., None]] = {
    "HEARTBEAT": MessageHandlers._on_heartbeat,
    "COMMAND_LONG": MessageHandlers._on_command_long,
    "COMMAND_INT": MessageHandlers._on_command_int,
    "SET_MODE": MessageHandlers._on_set_mode,
    "REQUEST_DATA_STREAM": MessageHandlers._on_request_data_stream,
    "SET_POSITION_TARGET_LOCAL_NED": MessageHandlers._on_set_position_target_local_ned,
    "SET_POSITION_TARGET_GLOBAL_INT": MessageHandlers._on_set_position_target_global_int,
    "SET_GPS_GLOBAL_ORIGIN": MessageHandlers._on_set_gps_global_origin,
    "VISION_POSITION_ESTIMATE": MessageHandlers._on_vision_position_estimate,
    "ODOMETRY": MessageHandlers._on_odometry,
    "VISION_SPEED_ESTIMATE": MessageHandlers._on_vision_speed_estimate,
    "PARAM_REQUEST_LIST": MessageHandlers._on_param_request_list,
    "PARAM_REQUEST_READ": MessageHandlers._on_param_request_read,
    "PARAM_SET": MessageHandlers._on_param_set,
    "TIMESYNC": MessageHandlers._on_timesync,
    "MISSION_REQUEST_LIST": MessageHandlers._on_mission_request_list,
    "MISSION_COUNT": MessageHandlers._on_mission_count,
    "MISSION_CLEAR_ALL": MessageHandlers._on_mission_clear_all,
}
