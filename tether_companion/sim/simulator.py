"""The offline simulator: rigid body + motors + cable + controller + sensors, stepped in time.

Typical offline loop (sensors at 200 Hz on a 1 kHz physics clock)::

    sim = Simulator(load_scenario("paper-circle"))
    period = 1.0 / sim.scenario.sensors.imu_rate_hz
    for k in range(1, int(sim.scenario.duration_s / period) + 1):
        sim.advance_to(k * period)
        imu, att = sim.read_imu(), sim.read_attitude()
        pwm, rng = sim.read_pwm(), sim.read_rangefinder()

The simulator follows the scenario's trajectory until :meth:`Simulator.set_setpoint` is
called; from then on it flies the set-points it is sent (the emulator's mode).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.frames import rotation_ned_to_body
from tether_companion.physics.cable import CableConfig, CableModel, make_cable
from tether_companion.physics.cable_drag import cable_drag_force_ned_n
from tether_companion.physics.rigid_body import (
    BODY_RATES,
    EULER,
    N_RIGID_STATES,
    POSITION,
    RigidBody,
)
from tether_companion.physics.vehicle import VehicleProfile, load_vehicle
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample
from tether_companion.sim.controller import CascadedController, Setpoint
from tether_companion.sim.ground import Ground
from tether_companion.sim.ground_station import GroundStationEvents
from tether_companion.sim.propulsion import PropulsionConfig
from tether_companion.sim.scenario import Scenario
from tether_companion.sim.sensors import SensorConfig, SensorSuite
from tether_companion.sim.trajectory import Trajectory
from tether_companion.sim.truth import FlightImpossibleError, TruthState
from tether_companion.sim.wind import DrydenParameters, DrydenTurbulence

FloatArray = NDArray[np.float64]

CRASH_SPEED_MPS = 3.0
"""Touching the ground faster than this is a crash, not a landing."""
SATURATION_LIMIT_S = 2.0
"""Every motor at full command for this long: the vehicle cannot fly the scenario."""


class Simulator(GroundStationEvents):
    """A tethered quadcopter flying a scenario.

    Parameters
    ----------
    scenario
        The set-up (see :mod:`tether_companion.sim.scenario`).
    vehicle
        Overrides the scenario's vehicle profile when given.
    rng
        The one Generator every noise draw comes from; default ``default_rng(scenario.seed)``.
    stop_on_failure
        Raise :class:`FlightImpossibleError` (naming the time and the cause) when the flight
        fails: a crash while armed, every motor saturated for 2 s, a non-finite state. The
        emulator passes False: a crash is then recorded in ``failure`` and flying goes on.

    Notes
    -----
    ``cable`` (a :class:`~tether_companion.physics.cable.CableModel`) may be read
    (``paid_out_m``, ``released``, ``tension_n``); the cable, the wind and the sensor settings
    are changed only through the methods here (``replace_cable``, ``set_wind_ned_m_s``,
    ``set_sensor_config``, the ground-station events), so the rigid body always pulls on the
    cable it is given.
    """

    def __init__(
        self,
        scenario: Scenario,
        vehicle: VehicleProfile | None = None,
        rng: np.random.Generator | None = None,
        *,
        stop_on_failure: bool = True,
    ) -> None:
        self.scenario = scenario
        self.propulsion = scenario.propulsion
        """How the true thrust differs from the profile's curve (change with set_propulsion)."""
        self.stop_on_failure = stop_on_failure
        self.failure: str | None = None
        """Why the flight failed first (a crash while armed, saturation, a non-finite state)."""
        self.vehicle = vehicle if vehicle is not None else load_vehicle(scenario.vehicle)
        self.rng = rng if rng is not None else np.random.default_rng(scenario.seed)
        self.gravity_mps2 = GRAVITY_MPS2
        self.physics_dt_s = 1.0 / scenario.physics_rate_hz
        self.body = RigidBody(self.vehicle, gravity_mps2=self.gravity_mps2)
        self._attach_cable(scenario.cable)
        self.body.wind_ned_m_s = scenario.wind.velocity_ned_m_s
        self.controller = CascadedController(scenario.controller, self.vehicle, self.gravity_mps2)
        self.trajectory = Trajectory(scenario.trajectory)
        self.sensors = SensorSuite(scenario.sensors, self.rng)
        self.ground = Ground(scenario.ground, self.rng)
        self.body.ground_down_m = self.ground.down_m
        self._mean_wind_ned_m_s = scenario.wind.velocity_ned_m_s
        self._gusts = self._make_gusts()
        self._saturated_since_s = math.inf
        self._follow_trajectory = scenario.trajectory.kind != "none"
        self.navigation_position_override: tuple[float, float, float] | None = None
        self.armed = False
        self._controller_steps = scenario.controller_steps
        self._controller_dt_s = self._controller_steps * self.physics_dt_s
        self._steps = 0
        self._events = sorted(scenario.events, key=lambda e: e.time_s)
        self._next_event = 0
        self._next_event_s = self._events[0].time_s if self._events else math.inf
        self._tug_end_s = math.inf
        self._pwm_us = self.controller.idle()
        self._steady_thrust_n = self._thrusts_for(self._pwm_us)
        self._cache_step = -1
        self._specific_force: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._tension_step = -1
        """The step at which the cable last evaluated its force at the state now (``tension_n``
        holds; -1 after any change to the cable)."""
        self._thrust_varies = scenario.propulsion.battery.sag_v_per_cell_per_min > 0.0
        self._initialise()

    # ------------------------------------------------------------------ set-up
    def _cable_force(
        self, pn: float, pe: float, pd: float, vn: float, ve: float, vd: float
    ) -> tuple[float, float, float]:
        """The tether's force on the drone, NED [N]: its tension plus the wind's drag on it."""
        fn, fe, fd = self.cable.force_components(pn, pe, pd, vn, ve, vd)
        if self.cable.released:
            return (fn, fe, fd)
        wind = self.body.wind_ned_m_s
        dn, de, dd = cable_drag_force_ned_n((pn, pe, pd), wind, self._cable_diameter_m)
        return (fn + dn, fe + de, fd + dd)

    def _attach_cable(self, config: CableConfig) -> None:
        """Make the cable of ``config`` the one the rigid body pulls on."""
        self.cable: CableModel = make_cable(config, self.gravity_mps2)
        self._cable_diameter_m = config.diameter_m
        force = self._cable_force if config.diameter_m > 0.0 else self.cable.force_components
        self.body.external_force = force
        self.body.force_history_free = self.cable.history_free
        self._cable_changed()

    def _make_gusts(self, w20_mps: float | None = None) -> DrydenTurbulence | None:
        wind = self.scenario.wind
        w20 = wind.turbulence_w20_mps if w20_mps is None else w20_mps
        if w20 <= 0.0:
            return None
        parameters = DrydenParameters.low_altitude(w20, wind.turbulence_height_m)
        return DrydenTurbulence(
            parameters,
            self._mean_wind_ned_m_s,
            self.scenario.controller_steps / self.scenario.physics_rate_hz,
            self.rng,
            wind.min_airspeed_mps,
        )

    def _thrusts_for(self, pwm_us: list[float]) -> list[float]:
        """True steady-state motor thrusts [N]: the profile's curve times the scale and sag."""
        propulsion = self.propulsion
        if propulsion.exact:
            return self.controller.mixer.thrusts_for_pwm_us(pwm_us)
        ratio = propulsion.voltage_ratio(self.time_s)
        thrusts = self.vehicle.thrust_curve.thrust_n(np.asarray(pwm_us), ratio)
        return (propulsion.thrust_scale * thrusts).tolist()

    def _initialise(self) -> None:
        init = self.scenario.initial
        n = self.vehicle.n_motors
        idle_thrust = self._steady_thrust_n
        if not init.airborne:
            state = [0.0] * N_RIGID_STATES + idle_thrust
            state[0], state[1] = init.position_ned_m[0], init.position_ned_m[1]
            state[2] = self.ground.down_m(state[0], state[1])
            state[8] = math.radians(init.yaw_deg)
            self.body.set_state(state, landed=True)
            self.armed = init.armed
            return
        sp = self.trajectory.setpoint_at(0.0)
        position = sp.position_ned_m if sp.position_ned_m is not None else init.position_ned_m
        velocity = sp.velocity_ned_m_s or (0.0, 0.0, 0.0)
        accel = sp.acceleration_ned_mps2 or (0.0, 0.0, 0.0)
        yaw = sp.yaw_rad if sp.yaw_rad is not None else math.radians(init.yaw_deg)
        m, g = self.vehicle.mass_kg, self.gravity_mps2
        cable = self.body.external_force(*position, *velocity)
        thrust_ned = [m * accel[i] - cable[i] for i in range(3)]
        thrust_ned[2] -= m * g
        collective = math.sqrt(sum(f * f for f in thrust_ned))
        cy, sy = math.cos(yaw), math.sin(yaw)
        fx = cy * thrust_ned[0] + sy * thrust_ned[1]
        fy = -sy * thrust_ned[0] + cy * thrust_ned[1]
        roll = math.asin(fy / collective)
        pitch = math.atan2(-fx, -thrust_ned[2])
        body_velocity = rotation_ned_to_body(roll, pitch, yaw) @ np.asarray(velocity)
        state = [*position, *body_velocity.tolist(), roll, pitch, yaw, 0.0, 0.0, 0.0]
        per_motor = collective / n
        self.body.set_state(state + [per_motor] * n)
        self.controller.preload_integral((-cable[0] / m, -cable[1] / m, -cable[2] / m))
        self._pwm_us = self.controller.mixer.pwm_us([per_motor] * n)
        self._steady_thrust_n = self._thrusts_for(self._pwm_us)
        self.armed = True

    # ------------------------------------------------------------------ time
    @property
    def time_s(self) -> float:
        """Simulation time since the start [s] (the flight controller's clock)."""
        return self._steps * self.physics_dt_s

    def step(self) -> None:
        """One physics step: events, controller (at its rate), RK4 with motor lag, cable, ground."""
        dt = self.physics_dt_s
        t = self._steps * dt  # self.time_s
        if self._next_event_s <= t + 0.5 * dt:
            self._apply_due_events(t + 0.5 * dt)
        if t >= self._tug_end_s - 0.5 * dt:
            self.body.tug_force_ned_n = (0.0, 0.0, 0.0)
            self._tug_end_s = math.inf
        if self._steps % self._controller_steps == 0:
            if self._gusts is not None:
                gust = self._gusts.step()
                mean = self._mean_wind_ned_m_s
                self.body.wind_ned_m_s = [m + g for m, g in zip(mean, gust, strict=True)]
            self._update_controller(t)
            self._check_flyable(t)
        body = self.body
        was_landed = body.landed
        before = body.x  # the step makes a new list: this one keeps the state before it
        body.step(dt, self._steady_thrust_n)
        self.cable.advance(dt)
        self._steps += 1
        if not body.landed or was_landed:
            return
        descent_mps = body.velocity_ned_m_s(before)[2]  # touched down in this step: how fast
        if descent_mps > CRASH_SPEED_MPS and self.armed:
            self._fail(
                f"t = {t:.2f} s: the drone hit the ground at {descent_mps:.1f} m/s "
                f"(a landing is slower than {CRASH_SPEED_MPS} m/s)"
            )

    def _check_flyable(self, t: float) -> None:
        """Fail on a non-finite state or a lasting saturation of every motor."""
        if not all(map(math.isfinite, self.body.x)):
            self._fail(f"t = {t:.2f} s: the vehicle's state is not finite")
        top = self.vehicle.thrust_curve.pwm_max_us
        if self.armed and min(self._pwm_us) >= top - 0.5:  # every motor at the top
            self._saturated_since_s = min(self._saturated_since_s, t)
            if t - self._saturated_since_s >= SATURATION_LIMIT_S:
                self._saturated_since_s = math.inf
                self._fail(
                    f"t = {t:.2f} s: every motor at full command for {SATURATION_LIMIT_S:.0f} s "
                    "(the controller saturates: the scenario asks more thrust than the vehicle has)"
                )
        else:
            self._saturated_since_s = math.inf

    def _fail(self, why: str) -> None:
        """Record the first reason the flight failed; raise it when ``stop_on_failure``."""
        if self.failure is None:
            self.failure = why
        if self.stop_on_failure:
            raise FlightImpossibleError(why)

    def advance_to(self, time_s: float) -> None:
        """Step until the simulation time reaches ``time_s`` [s] (to the nearest physics step)."""
        target = round(time_s / self.physics_dt_s)
        while self._steps < target:
            self.step()

    def _update_controller(self, t: float) -> None:
        if not self.armed:
            pwm = self.controller.idle()
        else:
            if self._follow_trajectory:
                self.controller.set_setpoint(self.trajectory.setpoint_at(t))
            x = self.body.x
            position = self.navigation_position_override or (x[0], x[1], x[2])
            pwm = self.controller.update(
                self._controller_dt_s,
                position,
                self.body.velocity_ned_m_s(),
                (x[6], x[7], x[8]),
                (x[9], x[10], x[11]),
                landed=self.body.landed,
            )
        if pwm != self._pwm_us or self._thrust_varies:
            self._pwm_us = pwm
            self._steady_thrust_n = self._thrusts_for(pwm)

    # ------------------------------------------------------------------ truth
    @property
    def landed(self) -> bool:
        """True while the drone rests on the ground plane."""
        return self.body.landed

    @property
    def position_ned_m(self) -> tuple[float, float, float]:
        """True position relative to the anchor, NED [m] (a tuple: cheap at every step)."""
        x = self.body.x
        return (x[0], x[1], x[2])

    @property
    def velocity_ned_m_s(self) -> tuple[float, float, float]:
        """True velocity, NED [m/s]."""
        return self.body.velocity_ned_m_s()

    @property
    def euler_rad(self) -> tuple[float, float, float]:
        """True (roll, pitch, yaw) [rad]."""
        x = self.body.x
        return (x[6], x[7], x[8])

    @property
    def body_rates_rad_s(self) -> tuple[float, float, float]:
        """True body rates (p, q, r), FRD [rad/s]."""
        x = self.body.x
        return (x[9], x[10], x[11])

    @property
    def specific_force_body_mps2(self) -> tuple[float, float, float]:
        """Noise-free accelerometer specific force, FRD [m/s^2], evaluated on the forces now."""
        return self.body.specific_force_body_mps2()

    def _specific_force_now(self) -> tuple[float, float, float]:
        if self._cache_step != self._steps:
            body = self.body
            self._specific_force = body.specific_force_body_mps2()
            self._cache_step = self._steps
            if not body.landed and self.cable.history_free:  # the cable asked at this state
                self._tension_step = self._steps
        return self._specific_force

    @property
    def truth(self) -> TruthState:
        """The noise-free state now (arrays are fresh copies)."""
        state = self.body.state
        specific_force = self._specific_force_now()
        velocity = self.body.velocity_ned_m_s()
        cable = self._cable_force_now(velocity)
        return TruthState(
            time_s=self.time_s,
            position_ned_m=state[POSITION].copy(),
            velocity_ned_m_s=np.array(velocity),
            euler_rad=state[EULER].copy(),
            body_rates_rad_s=state[BODY_RATES].copy(),
            motor_thrust_n=state[N_RIGID_STATES:].copy(),
            pwm_us=np.array(self._pwm_us),
            cable_force_ned_n=np.array(cable),
            tension_n=self.cable.tension_n,
            specific_force_body_mps2=np.array(specific_force),
            landed=self.body.landed,
            wind_ned_m_s=np.array(self.body.wind_ned_m_s),
            battery_voltage_v=self.battery_voltage_v,
        )

    @property
    def tension_n(self) -> float:
        """True cable tension at the drone now [N] (``truth.tension_n`` without the arrays;
        the cable's own when it was evaluated at this state already, by the IMU's specific
        force: the same call with the same arguments)."""
        if self._tension_step != self._steps:
            self._cable_force_now(self.body.velocity_ned_m_s())
            if self.cable.history_free:
                self._tension_step = self._steps
        return self.cable.tension_n

    def _cable_force_now(self, velocity_ned_m_s: tuple[float, float, float]) -> tuple:
        """The tether's force on the drone [N] at the state now moving at ``velocity_ned_m_s``
        (NED [m/s]); sets the cable's ``tension_n`` to the tension at this state."""
        x = self.body.x
        return self.body.external_force(x[0], x[1], x[2], *velocity_ned_m_s)

    @property
    def battery_voltage_v(self) -> float:
        """Battery pack voltage now [V]."""
        return self.propulsion.battery.voltage_v(self.time_s)

    # ------------------------------------------------------------------ sensors
    def read_imu(self) -> ImuSample:
        """Accelerometer and gyro now, with noise, bias and vibration from the scenario."""
        x = self.body.x
        return self.sensors.imu(self.time_s, self._specific_force_now(), (x[9], x[10], x[11]))

    def read_attitude(self) -> AttitudeSample:
        """Roll, pitch, yaw now, with noise."""
        x = self.body.x
        return self.sensors.attitude(self.time_s, x[6], x[7], x[8])

    def read_pwm(self) -> PwmSample:
        """The PWM outputs now [us], whole microseconds, in the vehicle's motor order."""
        return self.sensors.pwm(self.time_s, np.array(self._pwm_us))

    def read_rangefinder(self) -> RangeSample | None:
        """Downward rangefinder now (tilted beam from its mounting point to the ground under
        it), or None when out of range."""
        x = self.body.x
        offset = self.sensors.config.range_offset_frd_m
        if offset == (0.0, 0.0, 0.0):
            sensor_ned = (x[0], x[1], x[2])
        else:
            lever = rotation_ned_to_body(x[6], x[7], x[8]).T @ np.asarray(offset)
            sensor_ned = (x[0] + lever[0], x[1] + lever[1], x[2] + lever[2])
        height = self.ground.down_m(sensor_ned[0], sensor_ned[1]) - sensor_ned[2]
        return self.sensors.rangefinder(self.time_s, height, x[6], x[7])

    # ------------------------------------------------------------------ flight control
    def arm(self) -> None:
        """Arm the motors (the controller starts flying the current set-point)."""
        self.armed = True

    def disarm(self) -> None:
        """Disarm: motors to pwm_min at the next controller update (the drone falls if airborne)."""
        self.armed = False

    @property
    def follow_trajectory(self) -> bool:
        """True while the controller flies the scenario's trajectory (from the start when it
        has one, again after :meth:`resume_trajectory`); False after :meth:`set_setpoint`."""
        return self._follow_trajectory

    def resume_trajectory(self) -> None:
        """Fly the scenario's trajectory from the next controller update (at the current time)."""
        self._follow_trajectory = True

    def set_setpoint(self, setpoint: Setpoint) -> None:
        """Fly this set-point from now on (stops following the scenario's trajectory)."""
        self._follow_trajectory = False
        self.controller.set_setpoint(setpoint)

    # ------------------------------------------------------------------ environment
    @property
    def wind_ned_m_s(self) -> tuple[float, float, float]:
        """The mean wind, NED [m/s] (the gusts come on top)."""
        return self._mean_wind_ned_m_s

    def set_wind_ned_m_s(self, wind_ned_m_s: ArrayLike) -> None:
        """Blow this mean wind, NED [m/s], shape (3,), from the next step on."""
        mean = np.asarray(wind_ned_m_s, dtype=float).reshape(3).tolist()
        self._mean_wind_ned_m_s = tuple(mean)  # type: ignore[assignment]
        self.body.wind_ned_m_s = mean

    def set_turbulence_w20_mps(self, w20_mps: float) -> None:
        """Dryden turbulence of this intensity (wind at 6.1 m [m/s]; 0 = none) from now on."""
        self._gusts = self._make_gusts(w20_mps)
        if self._gusts is None:
            self.body.wind_ned_m_s = self._mean_wind_ned_m_s

    def set_propulsion(self, config: PropulsionConfig) -> None:
        """Take the thrust scale and battery of ``config`` from the next controller update."""
        self.propulsion = config
        self._thrust_varies = True

    @property
    def sensor_config(self) -> SensorConfig:
        """The sensors' rates, noise, biases and rangefinder limits now."""
        return self.sensors.config

    def set_sensor_config(self, config: SensorConfig) -> None:
        """Read the sensors with these settings from now on (the noise stream carries on)."""
        self.sensors.config = config

    def replace_cable(self, config: CableConfig) -> None:
        """Swap the tether for a fresh one built from ``config`` (attached, its own winch state)."""
        self._attach_cable(config)
