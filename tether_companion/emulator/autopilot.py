"""The flight controller: the simulator dressed as an ArduPilot Copter, synchronous and pure.

:class:`FlightController` owns a :class:`~tether_companion.sim.simulator.Simulator` and does
what the autopilot's MAVLink side does: it answers commands (with COMMAND_ACK), runs the
parameter protocol, flies the modes, uses external position like EKF3, schedules telemetry
streams per link and scores received estimates. It does no I/O: :meth:`handle` takes a
decoded message from a link, :meth:`advance_to` moves time on, and :meth:`drain` returns the
messages to send as ``(link_id, message)`` pairs (``link_id`` None = every link). The async
server (:mod:`tether_companion.emulator.server`) moves bytes; tests drive this class directly
in lock-step.

Command results follow the MAVLink definitions: DENIED for invalid parameters (NaN, out of
range, unknown mode), FAILED when valid but impossible now (pre-arm checks, not in GUIDED),
UNSUPPORTED for commands the emulator does not implement.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from tether_companion.emulator import telemetry
from tether_companion.emulator.config import EmulatorConfig
from tether_companion.emulator.faults import LinkFaultSettings
from tether_companion.emulator.modes import (
    ARMABLE_MODES,
    POSITION_MODES,
    CopterMode,
    mode_from_number,
)
from tether_companion.emulator.navigation import ExternalNav
from tether_companion.emulator.params import (
    NAV_SOURCE_EXTERNAL,
    NAV_SOURCE_GPS,
    ParameterStore,
    parameter_definitions,
)
from tether_companion.emulator.scoring import Scorer, ScoreReport, TruthHistory
from tether_companion.emulator.streams import (
    STREAM_BY_ID,
    STREAMS,
    StreamSchedule,
    stream_names_in_group,
)
from tether_companion.frames import wrap_pi
from tether_companion.mavlink import geo, units
from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.physics.cable import CABLE_MODELS
from tether_companion.sim.controller import Setpoint
from tether_companion.sim.scenario import Scenario
from tether_companion.sim.simulator import Simulator

Outgoing = tuple[int | None, MAVLinkMessage]

FORCE_MAGIC = 21196.0
"""param2 of MAV_CMD_COMPONENT_ARM_DISARM that skips the checks (ArduPilot, MAVSDK)."""
MODE_TICK_S = 0.02
"""Mode logic (landing detection, take-off completion, failsafes) runs at 50 Hz."""
LAND_DISARM_DELAY_S = 1.0
GUIDED_VELOCITY_TIMEOUT_S = 3.0
"""A velocity-only GUIDED target is dropped after this long without a new one (GUID_TIMEOUT)."""
MAX_ATTITUDE_MISMATCH_RAD = math.radians(10.0)
MAX_TAKEOFF_ALT_M = 1000.0
RTL_ARRIVAL_M = 0.5
MAX_DISTANCE_M = 10_000.0
"""Position targets farther than this from the origin are refused as invalid."""
TUG_COMMAND = dialect.MAV_CMD_USER_1
"""MAV_CMD_USER_1: tug; param1-3 force NED [N], param4 duration [s]."""
RELEASE_COMMAND = dialect.MAV_CMD_USER_2
"""MAV_CMD_USER_2: release the tether; param1 must be 1."""
TENSION_COMMAND = dialect.MAV_CMD_USER_3
"""MAV_CMD_USER_3: winch tension; param1 [N] (constant_tension cable)."""
_ACCEPTED = dialect.MAV_RESULT_ACCEPTED
_DENIED = dialect.MAV_RESULT_DENIED
_FAILED = dialect.MAV_RESULT_FAILED
_UNSUPPORTED = dialect.MAV_RESULT_UNSUPPORTED
_POS_IGNORE = 0b111
_VEL_IGNORE = 0b111 << 3
_YAW_IGNORE = 1 << 10


@dataclass
class FlightControllerCounters:
    """What the flight controller did with its input."""

    messages_in: int = 0
    other_target: int = 0
    """Messages addressed to another system or component: ignored."""
    bad_values: int = 0
    """Messages with NaN or out-of-range fields: ignored or refused."""
    ignored: int = 0
    """Valid messages that do not apply now (e.g. position targets outside GUIDED)."""
    handler_errors: int = 0
    """Internal errors while handling a message (should stay 0; the message is dropped)."""
    unhandled: Counter = field(default_factory=Counter)
    """Message types the emulator does not act on, by name."""
    command_results: Counter = field(default_factory=Counter)
    """COMMAND_ACK results sent, by MAV_RESULT value."""
    reboots: int = 0

    @property
    def rejected(self) -> int:
        """Input refused or dropped for a reason (for SYS_STATUS.errors_comm)."""
        return self.other_target + self.bad_values + self.handler_errors


class FlightController:
    """An ArduPilot-Copter-like flight controller around a simulator (see module docstring).

    Parameters
    ----------
    scenario
        The simulated world.
    config
        Identity, navigation source, stream rates, faults.
    rng
        The simulator's Generator (default: ``default_rng(scenario.seed)``).
    unix_time_at_start_s
        Unix time of simulation time 0 (SYSTEM_TIME); the server passes the wall clock.
    """

    def __init__(
        self,
        scenario: Scenario,
        config: EmulatorConfig,
        *,
        rng: np.random.Generator | None = None,
        unix_time_at_start_s: float = 0.0,
    ) -> None:
        self.scenario = scenario
        self.config = config
        self.sim = Simulator(scenario, rng=rng)
        self.unix_time_at_start_s = unix_time_at_start_s
        home = scenario.home
        self.home = geo.Geodetic(home.latitude_deg, home.longitude_deg, home.altitude_m)
        self.counters = FlightControllerCounters()
        self.nav = ExternalNav()
        self.link_faults = LinkFaultSettings(
            config.faults.drop_probability,
            config.faults.duplicate_probability,
            config.faults.corrupt_probability,
            config.faults.delay_ms * 1e-3,
            config.faults.delay_jitter_ms * 1e-3,
        )
        self.params = ParameterStore(parameter_definitions(scenario, config), self._apply_param)
        self.truth_history = TruthHistory(self.sim.physics_dt_s)
        self.scorer = Scorer(config.score_start_s)
        self._stream_defaults = self._default_rates(scenario, config)
        self._schedules: dict[int, StreamSchedule] = {}
        self._next_link_id = 0
        self._next_due_s = math.inf
        self._outbox: list[Outgoing] = []
        self._cache_step = -1
        self._cache: dict[str, MAVLinkMessage | None] = {}
        self._reboot_times = sorted(config.faults.reboots_s)
        self._next_mode_tick_s = 0.0
        self._boot_sim_s = 0.0
        self.rangefinder_in_range = True
        self._rangefinder_param_forced = False
        self._after_ack: list[Callable[[], None]] = []
        self._descent = [0.0, 0.0, 0.0]
        self._boot()
        if scenario.initial.airborne:
            self.mode = CopterMode.AUTO if self.sim.follow_trajectory else CopterMode.GUIDED
        elif self.sim.follow_trajectory and self.sim.armed:
            self.mode = CopterMode.AUTO  # a landed, armed start that flies its waypoints
        else:
            self._hold_here()

    # ------------------------------------------------------------------ time and identity
    @property
    def time_s(self) -> float:
        """Simulation time since the start [s]."""
        return self.sim.time_s

    @property
    def boot_time_s(self) -> float:
        """Flight-controller time since its last boot [s] (restarts at a reboot)."""
        return self.sim.time_s - self._boot_sim_s

    @property
    def armed(self) -> bool:
        """Motors armed."""
        return self.sim.armed

    @property
    def vision_navigation(self) -> bool:
        """True when EK3_SRC1_POSXY selects ExternalNav."""
        return self.params.value("EK3_SRC1_POSXY") == NAV_SOURCE_EXTERNAL

    @property
    def navigation_healthy(self) -> bool:
        """A position estimate is available (always on truth; a fresh estimate on vision)."""
        return not self.vision_navigation or self.nav.healthy(self.boot_time_s)

    @property
    def rangefinder_forced_out_of_range(self) -> bool:
        """EMU_RNG_OOR is 1 or a rangefinder fault window is open now."""
        now = self.sim.time_s
        return self._rangefinder_param_forced or any(
            w.contains(now) for w in self.config.faults.rangefinder_out_of_range
        )

    @property
    def taking_off(self) -> bool:
        """A NAV_TAKEOFF climb is in progress."""
        return self._takeoff_target_d is not None

    def _boot(self) -> None:
        """Start (or restart) the flight controller's software state."""
        self._boot_sim_s = self.sim.time_s
        self._cache_step = -1  # messages built before the boot carry the old clock
        self.mode = CopterMode.STABILIZE
        self.failsafe = False
        self.nav.reset()
        self.nav.enabled = self.params.value("VISO_TYPE") == 1
        self.origin: geo.Geodetic | None = None if self.vision_navigation else self.home
        self.nav.origin_set = self.origin is not None
        self._vision_in_use = False
        self._dead_reckoning: list[float] | None = None
        self._takeoff_target_d: float | None = None
        self._velocity_deadline_s = math.inf
        self._landed_since_s: float | None = None
        self._rtl_landing = False
        now = self.sim.time_s
        for link_id in self._schedules:
            self._schedules[link_id] = StreamSchedule(self._stream_defaults, now)
        self._refresh_next_due()
        self._text(
            dialect.MAV_SEVERITY_INFO,
            "ArduCopter V{}.{}.{} (tether emulator)".format(*telemetry.FIRMWARE_VERSION),
        )
        self._text(
            dialect.MAV_SEVERITY_INFO,
            f"Frame: QUAD/X, position source {'ExternalNav' if self.vision_navigation else 'GPS'}",
        )

    @staticmethod
    def _default_rates(scenario: Scenario, config: EmulatorConfig) -> dict[str, float]:
        rates = {name: spec.default_hz for name, spec in STREAMS.items()}
        sensors = scenario.sensors
        rates["RAW_IMU"] = sensors.imu_rate_hz
        rates["ATTITUDE"] = sensors.attitude_rate_hz
        rates["SERVO_OUTPUT_RAW"] = sensors.pwm_rate_hz
        rates["DISTANCE_SENSOR"] = sensors.range_rate_hz
        rates.update(config.stream_rates_hz)
        return rates

    # ------------------------------------------------------------------ links and output
    def add_link(self) -> int:
        """Register a link; returns its id. Its streams start at the default rates."""
        link_id = self._next_link_id
        self._next_link_id += 1
        self._schedules[link_id] = StreamSchedule(self._stream_defaults, self.sim.time_s)
        self._refresh_next_due()
        return link_id

    def remove_link(self, link_id: int) -> None:
        """Forget a link."""
        self._schedules.pop(link_id, None)
        self._refresh_next_due()

    def stream_rate_hz(self, link_id: int, name: str) -> float:
        """Current rate of stream ``name`` on a link [Hz]."""
        return self._schedules[link_id].rate_hz(name)

    def drain(self) -> list[Outgoing]:
        """Messages produced since the last call, in order."""
        out, self._outbox = self._outbox, []
        return out

    def _send(self, msg: MAVLinkMessage | None, link_id: int | None = None) -> None:
        if msg is not None:
            self._outbox.append((link_id, msg))

    def _text(self, severity: int, text: str) -> None:
        self._send(telemetry.statustext(severity, text))

    def _refresh_next_due(self) -> None:
        self._next_due_s = min((s.next_due_s() for s in self._schedules.values()), default=math.inf)

    def next_event_s(self) -> float:
        """Simulation time of the next stream message [s] (inf without links)."""
        return self._next_due_s

    # ------------------------------------------------------------------ time advance
    def advance_to(self, time_s: float) -> None:
        """Run the simulation to ``time_s`` [s], emitting streams as they fall due."""
        sim = self.sim
        dt = sim.physics_dt_s
        target = round(time_s / dt)
        steps_done = round(sim.time_s / dt)
        tolerance = 0.5 * dt
        if sim.time_s >= self._next_due_s - tolerance:
            self._emit_due(sim.time_s, tolerance)
        while steps_done < target:
            self._before_step()
            sim.step()
            steps_done += 1
            now = sim.time_s
            self.truth_history.record(now, sim.position_ned_m)
            if now >= self._next_mode_tick_s - tolerance:
                self._mode_tick(now)
                self._next_mode_tick_s = now + MODE_TICK_S
            if now >= self._next_due_s - tolerance:
                self._emit_due(now, tolerance)

    def _emit_due(self, now: float, tolerance: float) -> None:
        for link_id, schedule in self._schedules.items():
            for name in schedule.pop_due(now, tolerance):
                if self._in_outage(name, now):
                    continue
                self._send(self._stream_message(name), link_id)
        self._refresh_next_due()

    def _stream_message(self, name: str) -> MAVLinkMessage | None:
        """Build ``name`` once per physics step, shared by every link due at that step."""
        step = round(self.sim.time_s / self.sim.physics_dt_s)
        if step != self._cache_step:
            self._cache_step = step
            self._cache.clear()
        if name not in self._cache:
            self._cache[name] = telemetry.BUILDERS[name](self)
        return self._cache[name]

    def _in_outage(self, name: str, now: float) -> bool:
        return any(o.stream == name and o.contains(now) for o in self.config.faults.outages)

    def _before_step(self) -> None:
        """Feed the controller the navigation position (vision mode) before a physics step."""
        if not (
            self.vision_navigation and (self._vision_in_use or not self.scenario.initial.airborne)
        ):
            self.sim.navigation_position_override = None
            return
        velocity = self.sim.velocity_ned_m_s
        position = self.nav.position_ned_m(self.boot_time_s, np.asarray(velocity))
        if position is not None:
            self._dead_reckoning = [float(v) for v in position]
        elif self._dead_reckoning is not None:
            dt = self.sim.physics_dt_s
            self._dead_reckoning = [
                p + v * dt for p, v in zip(self._dead_reckoning, velocity, strict=True)
            ]
        self.sim.navigation_position_override = (
            tuple(self._dead_reckoning) if self._dead_reckoning is not None else None  # type: ignore[assignment]
        )

    def _control_position(self) -> tuple[float, float, float]:
        """The position the controller flies on: the navigation override, else the truth."""
        override = self.sim.navigation_position_override
        if override is not None:
            return override
        return self.sim.position_ned_m

    def navigation_position_ned_m(self) -> tuple[float, float, float] | None:
        """Where the flight controller believes it is, in its EKF frame [m], or None."""
        if self.vision_navigation:
            if not self.nav.healthy(self.boot_time_s):
                return None
            override = self.sim.navigation_position_override
            if override is not None:
                return override
            velocity = np.asarray(self.sim.velocity_ned_m_s)
            position = self.nav.position_ned_m(self.boot_time_s, velocity)
            return (
                None
                if position is None
                else (float(position[0]), float(position[1]), float(position[2]))
            )
        return self.sim.position_ned_m

    # ------------------------------------------------------------------ mode logic (50 Hz)
    def _mode_tick(self, now: float) -> None:
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

    def reboot(self) -> None:
        """Flight-controller reboot: motors stop, clocks restart, origin and streams reset."""
        self.counters.reboots += 1
        self.sim.disarm()
        self._boot()
        self._hold_here()

    # ------------------------------------------------------------------ input
    def handle(self, msg: MAVLinkMessage, link_id: int) -> None:
        """Act on one received message (any error is counted, never raised)."""
        self.counters.messages_in += 1
        target_system = getattr(msg, "target_system", 0)
        target_component = getattr(msg, "target_component", 0)
        if target_system not in (0, self.config.system_id) or target_component not in (
            0,
            self.config.component_id,
        ):
            self.counters.other_target += 1
            return
        handler = self._handlers.get(msg.get_type())
        if handler is None:
            self.counters.unhandled[msg.get_type()] += 1
            return
        try:
            handler(self, msg, link_id)
        except (ValueError, TypeError, OverflowError, ArithmeticError, KeyError, IndexError):
            self.counters.handler_errors += 1

    def _ack(self, msg: MAVLinkMessage, command: int, result: int, link_id: int) -> None:
        self.counters.command_results[result] += 1
        self._send(
            dialect.MAVLink_command_ack_message(
                command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
            ),
            link_id,
        )

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

    # -- other messages
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
        self._external_pose(units.pose_from_vision_position_estimate(msg), msg.get_type())

    def _on_odometry(self, msg: MAVLinkMessage, link_id: int) -> None:
        try:
            pose = units.pose_from_odometry(msg)
        except ValueError:
            self.counters.bad_values += 1
            self.scorer.add(
                msg.get_type(), np.full(3, math.nan), math.nan, self.time_s, self.truth_history
            )
            return
        self._external_pose(pose, msg.get_type())

    def _external_pose(self, pose: units.PoseEstimate, kind: str) -> None:
        now = self.sim.time_s
        self.scorer.add(
            kind, pose.position_ned_m, pose.time_s + self._boot_sim_s, now, self.truth_history
        )
        if self.vision_navigation:
            self.nav.on_estimate(pose, self.boot_time_s)

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
        why = self.params.set(name, float(msg.param_value))
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

    # ------------------------------------------------------------------ parameters
    def _apply_param(self, name: str, value: float) -> None:
        """Make a parameter change real in the simulation (raises ValueError to refuse)."""
        sim = self.sim
        if name == "EK3_SRC1_POSXY":
            if value not in (NAV_SOURCE_GPS, NAV_SOURCE_EXTERNAL):
                raise ValueError(
                    f"only {NAV_SOURCE_GPS} (GPS) or {NAV_SOURCE_EXTERNAL} (ExternalNav)"
                )
            if self.armed:
                raise ValueError("disarm first")
            self._switch_navigation(value == NAV_SOURCE_EXTERNAL)
        elif name == "VISO_TYPE":
            self.nav.enabled = value == 1
        elif name == "TETH_MODEL":
            self._rebuild_cable(model=CABLE_MODELS[int(value)])
        elif name == "TETH_TENSION":
            if CABLE_MODELS.index("constant_tension") != self.params.value("TETH_MODEL"):
                raise ValueError("TETH_MODEL is not constant_tension")
            sim.set_tension_n(value)
        elif name == "TETH_LENGTH":
            sim.set_paid_out_m(value)
        elif name == "TETH_WINCH_RATE":
            sim.set_winch_rate_mps(value)
        elif name in ("TETH_STIFFNESS", "TETH_DAMPING", "TETH_DENSITY"):
            self._rebuild_cable(**{_CABLE_FIELDS[name]: value})
        elif name == "TETH_RELEASE":
            if value == 1:
                sim.release_tether()
            elif sim.cable.released:
                raise ValueError("set TETH_MODEL to re-attach the tether")
        elif name in _SENSOR_FIELDS:
            sim.set_sensor_config(replace(sim.sensor_config, **{_SENSOR_FIELDS[name]: value}))
        elif name in ("SIM_WIND_N", "SIM_WIND_E", "SIM_WIND_D"):
            wind = list(sim.wind_ned_m_s)
            wind["NED".index(name[-1])] = value
            sim.set_wind_ned_m_s(wind)
        elif name == "EMU_DROP_PCT":
            self.link_faults.drop_probability = value / 100.0
        elif name == "EMU_DUP_PCT":
            self.link_faults.duplicate_probability = value / 100.0
        elif name == "EMU_CORRUPT_PCT":
            self.link_faults.corrupt_probability = value / 100.0
        elif name == "EMU_DELAY_MS":
            self.link_faults.delay_s = value / 1000.0
        elif name == "EMU_JITTER_MS":
            self.link_faults.delay_jitter_s = value / 1000.0
        elif name == "EMU_RNG_OOR":
            self._rangefinder_param_forced = value == 1

    def _rebuild_cable(self, **changes: object) -> None:
        """Replace the simulator's cable with a fresh one built from the current parameters."""
        values = {
            "model": CABLE_MODELS[int(self.params.value("TETH_MODEL"))],
            "tension_n": self.params.value("TETH_TENSION"),
            "length_m": self.sim.cable.paid_out_m
            if self.sim.cable.paid_out_m > 0
            else self.params.value("TETH_LENGTH"),
            "winch_rate_mps": self.params.value("TETH_WINCH_RATE"),
            "stiffness_n_per_m": self.params.value("TETH_STIFFNESS"),
            "damping_n_s_per_m": self.params.value("TETH_DAMPING"),
            "linear_density_kg_per_m": self.params.value("TETH_DENSITY"),
        }
        values.update(changes)
        cable_config = self.scenario.cable
        values["length_m"] = min(
            max(float(values["length_m"]), cable_config.min_length_m), cable_config.spool_length_m
        )
        self.sim.replace_cable(replace(cable_config, **values))
        self.params.force("TETH_RELEASE", 0.0)

    def _switch_navigation(self, vision: bool) -> None:
        self._text(
            dialect.MAV_SEVERITY_INFO, f"Position source {'ExternalNav' if vision else 'GPS'}"
        )
        if vision:
            self._vision_in_use = False
            self._dead_reckoning = None
        else:
            self.origin = self.origin or self.home
            self.nav.origin_set = True

    # ------------------------------------------------------------------ scoring
    def score(self) -> ScoreReport:
        """Accuracy of the received estimates so far."""
        return self.scorer.report()

    _handlers: dict[str, Callable[[FlightController, MAVLinkMessage, int], None]] = {}


def _param_name(param_id: str | bytes) -> str:
    if isinstance(param_id, bytes):
        param_id = param_id.decode("ascii", "replace")
    return param_id.rstrip("\x00")


_CABLE_FIELDS = {
    "TETH_STIFFNESS": "stiffness_n_per_m",
    "TETH_DAMPING": "damping_n_s_per_m",
    "TETH_DENSITY": "linear_density_kg_per_m",
}
_SENSOR_FIELDS = {
    "SIM_ACC_NOISE": "accel_noise_std_mps2",
    "SIM_GYR_NOISE": "gyro_noise_std_rad_s",
    "SIM_ATT_NOISE": "attitude_noise_std_rad",
    "SIM_RNG_NOISE": "range_noise_std_m",
    "SIM_VIB_AMP": "accel_vibration_amplitude_mps2",
}

FlightController._handlers = {
    "HEARTBEAT": FlightController._on_heartbeat,
    "COMMAND_LONG": FlightController._on_command_long,
    "COMMAND_INT": FlightController._on_command_int,
    "SET_MODE": FlightController._on_set_mode,
    "REQUEST_DATA_STREAM": FlightController._on_request_data_stream,
    "SET_POSITION_TARGET_LOCAL_NED": FlightController._on_set_position_target_local_ned,
    "SET_POSITION_TARGET_GLOBAL_INT": FlightController._on_set_position_target_global_int,
    "SET_GPS_GLOBAL_ORIGIN": FlightController._on_set_gps_global_origin,
    "VISION_POSITION_ESTIMATE": FlightController._on_vision_position_estimate,
    "ODOMETRY": FlightController._on_odometry,
    "PARAM_REQUEST_LIST": FlightController._on_param_request_list,
    "PARAM_REQUEST_READ": FlightController._on_param_request_read,
    "PARAM_SET": FlightController._on_param_set,
    "TIMESYNC": FlightController._on_timesync,
    "MISSION_REQUEST_LIST": FlightController._on_mission_request_list,
    "MISSION_COUNT": FlightController._on_mission_count,
    "MISSION_CLEAR_ALL": FlightController._on_mission_clear_all,
}

_COMMANDS: dict[int, Callable[..., tuple[int, str]]] = {
    dialect.MAV_CMD_COMPONENT_ARM_DISARM: FlightController._cmd_arm_disarm,
    dialect.MAV_CMD_NAV_TAKEOFF: FlightController._cmd_takeoff,
    dialect.MAV_CMD_NAV_LAND: FlightController._cmd_land,
    dialect.MAV_CMD_NAV_RETURN_TO_LAUNCH: FlightController._cmd_rtl,
    dialect.MAV_CMD_DO_SET_MODE: FlightController._cmd_set_mode,
    dialect.MAV_CMD_DO_REPOSITION: FlightController._cmd_reposition,
    dialect.MAV_CMD_SET_MESSAGE_INTERVAL: FlightController._cmd_set_message_interval,
    dialect.MAV_CMD_GET_MESSAGE_INTERVAL: FlightController._cmd_get_message_interval,
    dialect.MAV_CMD_REQUEST_MESSAGE: FlightController._cmd_request_message,
    dialect.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: FlightController._cmd_autopilot_capabilities,
    dialect.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: FlightController._cmd_reboot,
    dialect.MAV_CMD_DO_WINCH: FlightController._cmd_winch,
    TUG_COMMAND: FlightController._cmd_tug,
    RELEASE_COMMAND: FlightController._cmd_release,
    TENSION_COMMAND: FlightController._cmd_tension,
}
"""Implemented commands (COMMAND_LONG and COMMAND_INT); anything else gets UNSUPPORTED."""
