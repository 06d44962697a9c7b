"""Commands (COMMAND_LONG and COMMAND_INT) of the emulated flight controller.

:class:`CommandHandlers` is one part of the
:class:`~tether_companion.emulator.autopilot.FlightController`:
each ``_cmd_*`` method takes the seven parameters and the frame and returns
``(MAV_RESULT, STATUSTEXT or "")``; :meth:`CommandHandlers._command` acknowledges with COMMAND_ACK.
DENIED for invalid parameters, FAILED when valid but impossible now, UNSUPPORTED otherwise.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from tether_companion.emulator import telemetry
from tether_companion.emulator.modes import (
    CopterMode,
    mode_from_number,
)
from tether_companion.emulator.streams import (
    STREAM_BY_ID,
)
from tether_companion.mavlink import units
from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.sim.controller import Setpoint

FORCE_MAGIC = 21196.0
"""param2 of MAV_CMD_COMPONENT_ARM_DISARM that skips the checks (ArduPilot, MAVSDK)."""
MAX_TAKEOFF_ALT_M = 1000.0
TUG_COMMAND = dialect.MAV_CMD_USER_1
"""MAV_CMD_USER_1: tug; param1-3 force NED [N], param4 duration [s]."""
RELEASE_COMMAND = dialect.MAV_CMD_USER_2
"""MAV_CMD_USER_2: release the tether; param1 must be 1."""
TENSION_COMMAND = dialect.MAV_CMD_USER_3
"""MAV_CMD_USER_3: winch tension; param1 [N] (constant_tension or winch_catenary cable)."""
_ACCEPTED = dialect.MAV_RESULT_ACCEPTED
_DENIED = dialect.MAV_RESULT_DENIED
_FAILED = dialect.MAV_RESULT_FAILED
_UNSUPPORTED = dialect.MAV_RESULT_UNSUPPORTED


class CommandHandlers:
    """The flight controller's command handling (mixed into ``FlightController``)."""

    def _command(
        self,
        msg: MAVLinkMessage,
        command: int,
        params: tuple[float, ...],
        frame: int | None,
        link_id: int,
    ) -> None:
        self._after_ack.clear()
        handler = _COMMANDS.get(command)
        if handler is None:
            self._ack(msg, command, _UNSUPPORTED, link_id)
            return
        result, text = handler(self, params, frame, link_id)
        if text:
            severity = (
                dialect.MAV_SEVERITY_CRITICAL if result != _ACCEPTED else dialect.MAV_SEVERITY_INFO
            )
            self._text(severity, text)
        if result == _DENIED:
            self.counters.bad_values += 1
        self._ack(msg, command, result, link_id)
        for deferred in self._after_ack:
            deferred()
        self._after_ack.clear()

    # -- commands: each returns (MAV_RESULT, STATUSTEXT or "")
    def _cmd_arm_disarm(
        self, p: tuple[float, ...], frame: int | None, link_id: int
    ) -> tuple[int, str]:
        force = p[1] == FORCE_MAGIC
        if p[0] == 1.0:
            if self.armed:
                return _ACCEPTED, ""
            why = None if force else self.prearm_failure()
            if why is not None:
                return _FAILED, why
            self.failsafe = False
            if self.sim.landed:
                self._hold_here()
            self.sim.arm()
            self._landed_since_s = None
            return _ACCEPTED, ""
        if p[0] == 0.0:
            if not self.armed:
                return _ACCEPTED, ""
            if not (self.sim.landed or force):
                return _FAILED, "Disarm: vehicle is flying"
            self.sim.disarm()
            return _ACCEPTED, ""
        return _DENIED, ""

    def _cmd_takeoff(
        self, p: tuple[float, ...], frame: int | None, link_id: int
    ) -> tuple[int, str]:
        altitude = p[6]
        if not (math.isfinite(altitude) and 0.0 < altitude <= MAX_TAKEOFF_ALT_M):
            return _DENIED, ""
        if self.mode != CopterMode.GUIDED:
            return _FAILED, "Takeoff: not in GUIDED"
        if not self.armed:
            return _FAILED, "Takeoff: arm first"
        if not self.sim.landed:
            return _FAILED, "Takeoff: already flying"
        position = self._control_position()
        home_d = self._home_local()[2]
        self._takeoff_target_d = home_d - altitude
        self._setpoint(
            Setpoint(
                (float(position[0]), float(position[1]), self._takeoff_target_d), None, None, None
            )
        )
        return _ACCEPTED, ""

    def _cmd_land(self, p: tuple[float, ...], frame: int | None, link_id: int) -> tuple[int, str]:
        why = self._enter_mode(CopterMode.LAND)
        return (_FAILED, why) if why else (_ACCEPTED, "")

    def _cmd_rtl(self, p: tuple[float, ...], frame: int | None, link_id: int) -> tuple[int, str]:
        why = self._enter_mode(CopterMode.RTL)
        return (_FAILED, why) if why else (_ACCEPTED, "")

    def _cmd_set_mode(
        self, p: tuple[float, ...], frame: int | None, link_id: int
    ) -> tuple[int, str]:
        return self._set_mode(p[0], p[1])

    def _set_mode(self, base_mode: float, custom_mode: float) -> tuple[int, str]:
        if not (
            math.isfinite(base_mode) and int(base_mode) & dialect.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        ):
            return _DENIED, ""
        mode = mode_from_number(custom_mode)
        if mode is None:
            return _DENIED, ""
        if mode == self.mode:
            return _ACCEPTED, ""
        why = self._enter_mode(mode)
        return (_FAILED, why) if why else (_ACCEPTED, "")

    def _cmd_reposition(
        self, p: tuple[float, ...], frame: int | None, link_id: int
    ) -> tuple[int, str]:
        if frame is None:
            return _UNSUPPORTED, ""  # global positions need COMMAND_INT
        target = self._global_to_local(frame, p[4], p[5], p[6])
        if target is None:
            return _DENIED, ""
        change_mode = (
            math.isfinite(p[1]) and int(p[1]) & dialect.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE
        )
        if change_mode and self.mode != CopterMode.GUIDED:
            why = self._enter_mode(CopterMode.GUIDED)
            if why:
                return _FAILED, why
        if self.mode != CopterMode.GUIDED:
            return _FAILED, "Reposition: not in GUIDED"
        if not self.armed or self.sim.landed:
            return _FAILED, "Reposition: not flying"
        yaw = p[3] if math.isfinite(p[3]) else None
        self._setpoint(Setpoint(target, None, None, yaw))
        return _ACCEPTED, ""

    def _cmd_set_message_interval(
        self, p: tuple[float, ...], frame: int | None, link_id: int
    ) -> tuple[int, str]:
        name = STREAM_BY_ID.get(int(p[0])) if math.isfinite(p[0]) and p[0] == int(p[0]) else None
        interval_us = p[1]
        if (
            name is None
            or not math.isfinite(interval_us)
            or (interval_us < 0 and interval_us != -1)
        ):
            return _DENIED, ""
        now = self.sim.time_s
        schedule = self._schedules[link_id]
        if interval_us == -1:
            schedule.set_rate_hz(name, 0.0, now)
        elif interval_us == 0:
            schedule.set_rate_hz(name, None, now)
        else:
            schedule.set_rate_hz(name, 1e6 / interval_us, now)
        self._refresh_next_due()
        return _ACCEPTED, ""

    def _cmd_get_message_interval(
        self, p: tuple[float, ...], frame: int | None, link_id: int
    ) -> tuple[int, str]:
        name = STREAM_BY_ID.get(int(p[0])) if math.isfinite(p[0]) and p[0] == int(p[0]) else None
        if name is None:
            return _DENIED, ""
        interval = self._schedules[link_id].interval_s(name)
        interval_us = -1 if interval is None else units.saturate_int(interval * 1e6, 0, 2**31 - 1)
        self._after_ack.append(
            lambda: self._send(
                dialect.MAVLink_message_interval_message(int(p[0]), interval_us), link_id
            )
        )
        return _ACCEPTED, ""

    def _cmd_request_message(
        self, p: tuple[float, ...], frame: int | None, link_id: int
    ) -> tuple[int, str]:
        if not (math.isfinite(p[0]) and p[0] == int(p[0])):
            return _DENIED, ""
        msg_id = int(p[0])
        if msg_id == dialect.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            reply = telemetry.autopilot_version(self)
        elif msg_id in STREAM_BY_ID:
            reply = telemetry.BUILDERS[STREAM_BY_ID[msg_id]](self)
            if reply is None:
                return _FAILED, ""
        else:
            return _DENIED, ""
        self._after_ack.append(lambda: self._send(reply, link_id))
        return _ACCEPTED, ""

    def _cmd_autopilot_capabilities(
        self, p: tuple[float, ...], frame: int | None, link_id: int
    ) -> tuple[int, str]:
        self._after_ack.append(lambda: self._send(telemetry.autopilot_version(self), link_id))
        return _ACCEPTED, ""

    def _cmd_reboot(self, p: tuple[float, ...], frame: int | None, link_id: int) -> tuple[int, str]:
        if p[0] == 0.0:
            return _ACCEPTED, ""
        if p[0] != 1.0:
            return _DENIED, ""
        if self.armed:
            return _FAILED, "Reboot: disarm first"
        self._after_ack.append(self.reboot)
        return _ACCEPTED, ""

    def _cmd_tug(self, p: tuple[float, ...], frame: int | None, link_id: int) -> tuple[int, str]:
        force, duration = p[:3], p[3]
        if not (
            all(math.isfinite(f) and abs(f) <= 100.0 for f in force)
            and math.isfinite(duration)
            and 0.0 < duration <= 60.0
        ):
            return _DENIED, ""
        self.sim.apply_tug(force, duration)
        return (
            _ACCEPTED,
            f"Tether tug {math.sqrt(sum(f * f for f in force)):.1f} N for {duration:g} s",
        )

    def _cmd_release(
        self, p: tuple[float, ...], frame: int | None, link_id: int
    ) -> tuple[int, str]:
        if p[0] != 1.0:
            return _DENIED, ""
        self.sim.release_tether()
        self.params.force("TETH_RELEASE", 1.0)
        return _ACCEPTED, "Tether released"

    def _cmd_tension(
        self, p: tuple[float, ...], frame: int | None, link_id: int
    ) -> tuple[int, str]:
        return self._set_param_by_command("TETH_TENSION", p[0])

    def _cmd_winch(self, p: tuple[float, ...], frame: int | None, link_id: int) -> tuple[int, str]:
        action = p[1]
        if action == dialect.WINCH_RATE_CONTROL:
            name, value = "TETH_WINCH_RATE", p[3]
        elif action == dialect.WINCH_RELATIVE_LENGTH_CONTROL:
            name, value = (
                "TETH_LENGTH",
                self.sim.cable.paid_out_m + p[2] if math.isfinite(p[2]) else math.nan,
            )
        else:
            return _DENIED, ""
        return self._set_param_by_command(name, value)

    def _set_param_by_command(self, name: str, value: float) -> tuple[int, str]:
        """DENIED for an invalid value, FAILED when the simulation cannot take it now."""
        why = self.params.definitions[name].check(value)
        if why is not None:
            return _DENIED, f"{name}: {why}"
        why = self.params.set(name, value)
        if why is not None:
            return _FAILED, f"{name}: {why}"
        self._send(self.params.message(name))
        return _ACCEPTED, ""


_COMMANDS: dict[int, Callable[..., tuple[int, str]]] = {
    dialect.MAV_CMD_COMPONENT_ARM_DISARM: CommandHandlers._cmd_arm_disarm,
    dialect.MAV_CMD_NAV_TAKEOFF: CommandHandlers._cmd_takeoff,
    dialect.MAV_CMD_NAV_LAND: CommandHandlers._cmd_land,
    dialect.MAV_CMD_NAV_RETURN_TO_LAUNCH: CommandHandlers._cmd_rtl,
    dialect.MAV_CMD_DO_SET_MODE: CommandHandlers._cmd_set_mode,
    dialect.MAV_CMD_DO_REPOSITION: CommandHandlers._cmd_reposition,
    dialect.MAV_CMD_SET_MESSAGE_INTERVAL: CommandHandlers._cmd_set_message_interval,
    dialect.MAV_CMD_GET_MESSAGE_INTERVAL: CommandHandlers._cmd_get_message_interval,
    dialect.MAV_CMD_REQUEST_MESSAGE: CommandHandlers._cmd_request_message,
    dialect.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: CommandHandlers._cmd_autopilot_capabilities,
    dialect.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: CommandHandlers._cmd_reboot,
    dialect.MAV_CMD_DO_WINCH: CommandHandlers._cmd_winch,
    TUG_COMMAND: CommandHandlers._cmd_tug,
    RELEASE_COMMAND: CommandHandlers._cmd_release,
    TENSION_COMMAND: CommandHandlers._cmd_tension,
}
"""Implemented commands (COMMAND_LONG and COMMAND_INT); anything else gets UNSUPPORTED."""
