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
from dataclasses import dataclass, field

import numpy as np

from tether_companion.config import ConfigError
from tether_companion.emulator import telemetry
from tether_companion.emulator.cable_angle import EmulatedCableAngle
from tether_companion.emulator.command_handlers import CommandHandlers
from tether_companion.emulator.config import EmulatorConfig
from tether_companion.emulator.faults import LinkFaultSettings
from tether_companion.emulator.flight_modes import MODE_TICK_S, FlightModes
from tether_companion.emulator.land_detector import LandDetector
from tether_companion.emulator.message_handlers import MESSAGE_HANDLERS, MessageHandlers
from tether_companion.emulator.modes import (
    CopterMode,
)
from tether_companion.emulator.navigation import ExternalNav
from tether_companion.emulator.parameter_actions import ParameterActions
from tether_companion.emulator.params import (
    NAV_SOURCE_EXTERNAL,
    ParameterStore,
    parameter_definitions,
    vehicle_parameter_definitions,
)
from tether_companion.emulator.routing import MavlinkRoutes
from tether_companion.emulator.scoring import Scorer, ScoreReport, TruthHistory
from tether_companion.emulator.streams import (
    STREAMS,
    StreamSchedule,
)
from tether_companion.emulator.winch import EmulatedWinch
from tether_companion.mavlink import geo
from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.sim.ground_sensors import GroundSensors
from tether_companion.sim.scenario import Scenario
from tether_companion.sim.simulator import Simulator

Outgoing = tuple[int | None, MAVLinkMessage | bytes]
"""(link id or None for every link, message): a message is framed as the flight controller;
bytes are a frame of another system routed unchanged (the ground station's winch)."""


@dataclass
class FlightControllerCounters:
    """What the flight controller did with its input."""

    messages_in: int = 0
    other_target: int = 0
    """Messages addressed to another system or component that no link leads to: ignored."""
    routed: int = 0
    """Messages forwarded to other links, one per link
    (:mod:`~tether_companion.emulator.routing`)."""
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


class FlightController(MessageHandlers, CommandHandlers, ParameterActions, FlightModes):
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
        self.sim = Simulator(scenario, rng=rng, stop_on_failure=False)
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
        vehicle_params = vehicle_parameter_definitions(self.sim.vehicle, config.autopilot)
        self.params = ParameterStore(
            [*parameter_definitions(scenario, config), *vehicle_params],
            self._apply_param,
            read_only=frozenset({"SYSID_THISMAV", *(d.name for d in vehicle_params)}),
            bytewise=config.autopilot == "px4",
        )
        self.truth_history = TruthHistory(self.sim.physics_dt_s)
        self.scorer = Scorer(config.score_start_s)
        self._stream_defaults = self._default_rates(scenario, config)
        self._schedules: dict[int, StreamSchedule] = {}
        self._next_link_id = 0
        self.routes = MavlinkRoutes(config.system_id, config.component_id)
        """What ArduPilot's routing has learnt: who is reachable on which link."""
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
        self.ground_sensors = (
            GroundSensors(scenario.ground_station, scenario.cable.model, scenario.seed)
            if config.winch.enabled or config.cable_angle.enabled
            else None
        )
        """The ground station's sensors' errors (the scenario's ``ground_station``: the offline
        simulator's model), recorded at every physics step while a sensor sends, or None."""
        self.winch = (
            EmulatedWinch(config.winch, scenario, self.ground_sensors, unix_time_at_start_s)
            if self.ground_sensors is not None and config.winch.enabled
            else None
        )
        """The ground station's winch (``emulator.winch``), or None."""
        self.cable_angle = (
            EmulatedCableAngle(
                config.cable_angle, scenario, self.ground_sensors, unix_time_at_start_s
            )
            if self.ground_sensors is not None and config.cable_angle.enabled
            else None
        )
        """The ground station's cable-angle sensor (``emulator.cable_angle``), or None."""
        self._ground_sensors = tuple(s for s in (self.winch, self.cable_angle) if s is not None)
        """The ground station's sensors: their frames are routed unchanged to every link."""
        self._boot()
        if scenario.initial.airborne:
            self.mode = CopterMode.AUTO if self.sim.follow_trajectory else CopterMode.GUIDED
        elif self.sim.follow_trajectory and self.sim.armed:
            self.mode = CopterMode.AUTO  # a landed, armed start that flies its waypoints
        else:
            self._hold_here()
        for name, value in config.parameters.items():
            why = self.params.override(name, value)
            if why is not None:
                raise ConfigError("", f"emulator.parameters.{name}", value, why)

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
        self.land_detector = LandDetector()
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
        imu = "HIGHRES_IMU" if config.autopilot == "px4" else "RAW_IMU"  # each one's own
        rates["RAW_IMU"] = 0.0
        rates[imu] = sensors.imu_rate_hz
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
        self.routes.forget_link(link_id)
        self._refresh_next_due()

    def stream_rate_hz(self, link_id: int, name: str) -> float:
        """Current rate of stream ``name`` on a link [Hz]."""
        return self._schedules[link_id].rate_hz(name)

    def drain(self) -> list[Outgoing]:
        """Messages produced since the last call, in order."""
        out, self._outbox = self._outbox, []
        return out

    def _send(self, msg: MAVLinkMessage | bytes | None, link_id: int | None = None) -> None:
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
            if self.ground_sensors is not None:
                self.ground_sensors.record(
                    now, sim.cable.paid_out_m, sim.position_ned_m, sim.cable.tension_n
                )
            for sensor in self._ground_sensors:
                if now >= sensor.next_s - tolerance:
                    frame = sensor.frame(sim)
                    if frame is not None:
                        self._outbox.append((None, frame))

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
        routes = self.routes
        routes.learn(msg.get_srcSystem(), msg.get_srcComponent(), link_id)
        routing = routes.route(target_system, target_component, link_id)
        if routing.forward_to:
            frame = bytes(msg.get_msgbuf())
            for other in routing.forward_to:
                self._send(frame, other)
            self.counters.routed += len(routing.forward_to)
        if not routing.process_locally:
            if not routing.forward_to:  # for a system no link leads to
                self.counters.other_target += 1
            return
        if target_system not in (0, self.config.system_id) or target_component not in (
            0,
            self.config.component_id,
        ):
            self.counters.other_target += 1
            return
        handler = MESSAGE_HANDLERS.get(msg.get_type())
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

    # ------------------------------------------------------------------ scoring
    def score(self) -> ScoreReport:
        """Accuracy of the received estimates so far."""
        return self.scorer.report()
