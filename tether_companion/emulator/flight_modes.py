"""The flight modes of the emulated flight controller, run at 50 Hz: take-off completion,
LAND and RTL descents, landing detection and auto-disarm, the external-navigation failsafe,
mode changes and ArduPilot's pre-arm checks.

:class:`FlightModes` is one part of the
:class:`~tether_companion.emulator.autopilot.FlightController` (like
:class:`~tether_companion.emulator.parameter_actions.ParameterActions`).
"""

from __future__ import annotations

import math

from tether_companion.emulator.modes import ARMABLE_MODES, POSITION_MODES, CopterMode
from tether_companion.frames import wrap_pi
from tether_companion.mavlink import geo
from tether_companion.mavlink.framing import dialect
from tether_companion.sim.controller import Setpoint

MODE_TICK_S = 0.02
"""Mode logic (landing detection, take-off completion, failsafes) runs at 50 Hz."""
LAND_DISARM_DELAY_S = 1.0
"""Seconds on the ground in LAND or RTL before the motors are disarmed [s]."""
MAX_ATTITUDE_MISMATCH_RAD = math.radians(10.0)
"""External navigation's attitude may differ from the FC's by this much to arm [rad]."""
RTL_ARRIVAL_M = 0.5
"""RTL starts its descent within this horizontal distance of home [m]."""


class FlightModes:
    """The flight controller's mode logic (mixed into ``FlightController``)."""

    def _mode_tick(self, now: float) -> None:
        self.land_detector.update(now, self.armed, self.sim.landed)
        while self._reboot_times and self._reboot_times[0] <= now + 1e-9:
            self._reboot_times.pop(0)
            self.reboot()
        boot_now = self.boot_time_s
        if self.vision_navigation:
            healthy = self.nav.healthy(boot_now)
            if healthy and not self._vision_in_use:
                self._vision_in_use = True
                self._text(dialect.MAV_SEVERITY_INFO, "EKF3 IMU0 is using external nav data")
            elif not healthy and self._vision_in_use and self.armed and not self.sim.landed:
                if not self.failsafe:
                    self.failsafe = True
                    self._text(
                        dialect.MAV_SEVERITY_CRITICAL, "EKF Failsafe: lost external nav, LAND"
                    )
                    self._enter_mode(CopterMode.LAND, forced=True)
            elif healthy and self.failsafe:
                self.failsafe = False
                self._text(dialect.MAV_SEVERITY_INFO, "EKF Failsafe cleared")
        if not self.armed:
            self._landed_since_s = None
            return
        position = self.navigation_position_ned_m()
        if self._takeoff_target_d is not None and position is not None:
            if abs(position[2] - self._takeoff_target_d) < max(
                0.1, 0.05 * abs(self._takeoff_target_d)
            ):
                self._takeoff_target_d = None
        if self._velocity_deadline_s <= now:
            self._velocity_deadline_s = math.inf
            self._hold_here()
        if self.mode == CopterMode.RTL and not self._rtl_landing and position is not None:
            home = self._home_local()
            if math.hypot(position[0] - home[0], position[1] - home[1]) < RTL_ARRIVAL_M:
                self._rtl_landing = True
                self._start_descent()
        if self.mode == CopterMode.LAND or self._rtl_landing:
            self._update_descent()
        self._auto_disarm(now)

    def _auto_disarm(self, now: float) -> None:
        landed = self.sim.landed and self._takeoff_target_d is None
        if not landed:
            self._landed_since_s = None
            return
        if self._landed_since_s is None:
            self._landed_since_s = now
        delay = (
            LAND_DISARM_DELAY_S
            if self.mode == CopterMode.LAND or self._rtl_landing
            else self.params.value("DISARM_DELAY")
        )
        if delay > 0 and now - self._landed_since_s >= delay:
            self.sim.disarm()
            self._landed_since_s = None
            self._text(dialect.MAV_SEVERITY_INFO, "Disarming motors (landed)")

    # ------------------------------------------------------------------ set-points
    def _setpoint(self, setpoint: Setpoint) -> None:
        self.sim.set_setpoint(setpoint)

    def _hold_here(self) -> None:
        """Hold the current (believed) position and heading."""
        self._setpoint(Setpoint(self._control_position(), (0.0, 0.0, 0.0), None, None))

    def _start_descent(self) -> None:
        position = self._control_position()
        self._descent = [float(position[0]), float(position[1]), float(position[2])]
        self._takeoff_target_d = None
        self._update_descent()

    def _update_descent(self) -> None:
        """Move the LAND target down at LAND_SPEED, ending below the ground (motors idle)."""
        speed = self.params.value("LAND_SPEED") * 0.01
        self._descent[2] = min(self._descent[2] + speed * MODE_TICK_S, 1.0)
        self._setpoint(Setpoint(tuple(self._descent), (0.0, 0.0, speed), None, None))  # type: ignore[arg-type]

    def _home_local(self) -> tuple[float, float, float]:
        if self.origin is None:
            return (0.0, 0.0, 0.0)
        offset = geo.geodetic_to_ned(self.origin, self.home)
        return (float(offset[0]), float(offset[1]), float(offset[2]))

    # ------------------------------------------------------------------ modes
    def _enter_mode(self, mode: CopterMode, *, forced: bool = False) -> str | None:
        """Switch mode; returns why it is refused (None when done)."""
        if not forced:
            if mode in POSITION_MODES and not self.navigation_healthy:
                return f"Mode change to {mode.name} failed: requires position"
            if mode == CopterMode.AUTO and self.scenario.trajectory.kind == "none":
                return "Mode change to AUTO failed: mission empty"
        self.mode = mode
        self._takeoff_target_d = None
        self._velocity_deadline_s = math.inf
        self._rtl_landing = False
        if mode == CopterMode.AUTO:
            self.sim.resume_trajectory()
        elif mode == CopterMode.LAND:
            self._start_descent()
        elif mode == CopterMode.RTL:
            position = self._control_position()
            home = self._home_local()
            self._setpoint(Setpoint((home[0], home[1], float(position[2])), None, None, None))
        else:
            self._hold_here()
        return None

    def prearm_failure(self) -> str | None:
        """The first pre-arm check that fails, as ArduPilot words it, or None."""
        if self.mode not in ARMABLE_MODES:
            return "Arm: Mode not armable"
        if self.vision_navigation:
            if self.origin is None:
                return "PreArm: EKF3 waiting for origin"
            if not self.nav.healthy(self.boot_time_s):
                return "PreArm: VisOdom: not healthy"
            euler = self.nav.last_euler_rad
            if euler is not None:
                worst = max(
                    abs(wrap_pi(a - b)) for a, b in zip(euler, self.sim.euler_rad, strict=True)
                )
                if worst > MAX_ATTITUDE_MISMATCH_RAD:
                    return f"PreArm: VisOdom: attitude differs by {math.degrees(worst):.0f} deg"
        if self.mode in POSITION_MODES and not self.navigation_healthy:
            return "PreArm: Need Position Estimate"
        return None
