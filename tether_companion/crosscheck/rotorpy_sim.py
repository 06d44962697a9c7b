"""Our scenarios flown by rotorpy's multirotor (PyPI ``rotorpy``) instead of our rigid body.

rotorpy (University of Pennsylvania, MIT licence) integrates its own quadrotor dynamics
(``Multirotor._s_dot_fn``: rotor thrust ``k_eta w^2`` with first-order rotor-speed lag, rotor
drag "H force" ``-w k_d v_local`` at each hub, induced inflow ``-w k_z v_z``, translational
lift ``k_h v_xy^2``, blade-flapping moment, parasitic drag ``-|v| c_D v``; scipy's RK45 via
``Multirotor.step``). We keep *our* controller, cable, winch events, wind and sensors, and
swap the physics of the airframe: the tether's force enters rotorpy's equations of motion as
an external force evaluated inside its integrator, and rotorpy's states become our samples.

Frames: rotorpy's world is x north, y west, z up and its body is FLU; ours are NED and FRD.
Both maps are ``S = diag(1, -1, -1)``: ``p_ned = S x``, ``R_ned_frd = S R S``,
``omega_frd = S omega_flu``. rotorpy's gravity is 9.81 m/s^2 (ours 9.80665).

Vehicle mapping (:func:`rotorpy_params`): mass, inertia, rotor positions and spin from our
profile (a ``ccw`` rotor's reaction torque is ``-k f`` about z-up); ``k_eta`` from a nominal
top rotor speed; the rotor drag ``k_d`` (and ``k_z``) chosen so that the four hubs at the
hover rotor speed give our vehicle's linear drag coefficient: ``n w_hover k_d = c_d``. The
rest is rotorpy's own aerodynamics, scaled from its AscTec Hummingbird parameters by the
ratio of hover thrust per rotor (translational lift) and of mass (parasitic drag): see
docs/simulator.md, "rotorpy cross-check", for what this makes differ and by how much.

Implements the part of :class:`~tether_companion.sim.simulator.Simulator` that the
scorecard's flight loop uses (``advance_to``, ``read_*``, ``truth``, ``cable``,
``physics_dt_s``, ``gravity_mps2``), so ``bench estimators --simulator rotorpy`` runs on it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tether_companion.errors import InputError
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample
from tether_companion.sim.scenario import Scenario
from tether_companion.sim.simulator import Simulator, TruthState

FloatArray = NDArray[np.float64]

FLIP = np.diag((1.0, -1.0, -1.0))
"""NED <-> rotorpy world (x north, y west, z up), FRD <-> FLU: the same diagonal map."""
ROTORPY_GRAVITY_MPS2 = 9.81
NOMINAL_TOP_ROTOR_SPEED_RAD_S = 1000.0
"""Rotor speed at full thrust (sets k_eta; only the product k_eta w^2 matters)."""
HUMMINGBIRD = {
    "mass_kg": 0.5,
    "hover_thrust_per_rotor_n": 0.5 * 9.81 / 4.0,
    "k_h": 3.39e-3,
    "c_dx": 0.5e-2,
    "c_dz": 1e-2,
}
"""rotorpy's ``vehicles/hummingbird_params.py`` values our profile's aerodynamics scale from."""
INSTALL_HINT = "pip install 'tether-companion[crosscheck]' (or: pip install rotorpy)"


def require_rotorpy() -> Any:
    """rotorpy's ``Multirotor`` class, or an :class:`InputError` saying what to install."""
    try:
        from rotorpy.vehicles.multirotor import Multirotor
    except ImportError:
        raise InputError(f"the rotorpy cross-check needs rotorpy: {INSTALL_HINT}") from None
    return Multirotor


def hover_thrust_per_rotor_n(vehicle: VehicleProfile, gravity_mps2: float) -> float:
    """Thrust per rotor holding the vehicle's weight [N]."""
    return vehicle.mass_kg * gravity_mps2 / vehicle.n_motors


def rotorpy_params(vehicle: VehicleProfile, drag_n_s_per_m: float, max_thrust_n: float) -> dict:
    """rotorpy ``quad_params`` for our ``vehicle`` (see the module docstring).

    Parameters
    ----------
    vehicle
        Our profile.
    drag_n_s_per_m
        Linear drag coefficient to reproduce at the hover rotor speed [N s/m].
    max_thrust_n
        Thrust of one rotor at full command [N].
    """
    n = vehicle.n_motors
    k_eta = max_thrust_n / NOMINAL_TOP_ROTOR_SPEED_RAD_S**2
    hover_n = hover_thrust_per_rotor_n(vehicle, ROTORPY_GRAVITY_MPS2)
    hover_speed = math.sqrt(hover_n / k_eta)
    k_d = drag_n_s_per_m / (n * hover_speed)
    lift_scale = hover_n / HUMMINGBIRD["hover_thrust_per_rotor_n"]
    mass_scale = vehicle.mass_kg / HUMMINGBIRD["mass_kg"]
    positions = {}
    for i, motor in enumerate(vehicle.motors):
        angle = math.radians(motor.angle_deg)
        arm = vehicle.arm_length_m
        positions[f"r{i + 1}"] = np.array((arm * math.cos(angle), -arm * math.sin(angle), 0.0))
    ixx, iyy, izz = vehicle.inertia_kg_m2
    return {
        "mass": vehicle.mass_kg,
        "Ixx": ixx,
        "Iyy": iyy,
        "Izz": izz,
        "Ixy": 0.0,
        "Ixz": 0.0,
        "Iyz": 0.0,
        "num_rotors": n,
        "rotor_pos": positions,
        "rotor_directions": np.array([-1 if m.spin == "ccw" else 1 for m in vehicle.motors]),
        "c_Dx": HUMMINGBIRD["c_dx"] * mass_scale,
        "c_Dy": HUMMINGBIRD["c_dx"] * mass_scale,
        "c_Dz": HUMMINGBIRD["c_dz"] * mass_scale,
        "k_eta": k_eta,
        "k_m": vehicle.yaw_moment_per_thrust_m * k_eta,
        "k_d": k_d,
        "k_z": k_d,
        "k_h": HUMMINGBIRD["k_h"] * lift_scale,
        "k_flap": 0.0,
        "tau_m": vehicle.motor_time_constant_s,
        "rotor_speed_min": 0.0,
        "rotor_speed_max": NOMINAL_TOP_ROTOR_SPEED_RAD_S * 1.2,
        "motor_noise_std": 0.0,
    }


def euler_from_rotation(rotation_body_to_ned: FloatArray) -> tuple[float, float, float]:
    """ZYX (roll, pitch, yaw) [rad] of a body (FRD) to NED rotation matrix."""
    r = rotation_body_to_ned
    return (
        math.atan2(r[2, 1], r[2, 2]),
        -math.asin(max(-1.0, min(1.0, r[2, 0]))),
        math.atan2(r[1, 0], r[0, 0]),
    )


class RotorpySimulator:
    """A scenario flown by rotorpy's airframe with our controller, cable, wind and sensors.

    Parameters
    ----------
    scenario
        The set-up; airborne starts only (rotorpy's ground model is not ours).
    rng
        Generator of the sensor noise (default ``default_rng(scenario.seed)``).

    Raises
    ------
    InputError
        rotorpy is not installed, or the scenario starts on the ground.
    """

    def __init__(self, scenario: Scenario, rng: np.random.Generator | None = None) -> None:
        multirotor_cls = require_rotorpy()
        if not scenario.initial.airborne:
            raise InputError(
                "the rotorpy cross-check flies airborne starts only "
                "(scenario starts on the ground: initial.airborne false)"
            )
        from scipy.spatial.transform import Rotation

        self._rotation_cls = Rotation
        # Our simulator, never stepped: it builds the trimmed start, the controller (its
        # integrators preloaded against the cable), the cable, the trajectory and the sensors.
        self._ours = Simulator(scenario, rng=rng)
        self.scenario = scenario
        self.vehicle = self._ours.vehicle
        self.cable = self._ours.cable
        self.sensors = self._ours.sensors
        self.controller = self._ours.controller
        self.gravity_mps2 = ROTORPY_GRAVITY_MPS2
        self.physics_dt_s = 1.0 / scenario.physics_rate_hz
        self.control_dt_s = 1.0 / scenario.controller.rate_hz
        self.params = rotorpy_params(
            self.vehicle,
            self.vehicle.drag_coefficient_n_s_per_m,
            self.vehicle.thrust_curve.max_thrust_n,
        )
        self._k_eta = self.params["k_eta"]
        truth = self._ours.truth
        rotation = FLIP @ _rotation_body_to_ned(truth.euler_rad) @ FLIP
        state = {
            "x": FLIP @ truth.position_ned_m,
            "v": FLIP @ truth.velocity_ned_m_s,
            "q": Rotation.from_matrix(rotation).as_quat(),
            "w": FLIP @ truth.body_rates_rad_s,
            "wind": FLIP @ np.asarray(scenario.wind.velocity_ned_m_s, dtype=float),
            "rotor_speeds": np.sqrt(np.maximum(truth.motor_thrust_n, 0.0) / self._k_eta),
        }
        self._external = _TetheredForce(self)
        self.multirotor = _tethered_class(multirotor_cls)(
            self.params,
            initial_state=state,
            control_abstraction="cmd_motor_speeds",
            aero=True,
            enable_ground=False,
            external_force=self._external,
        )
        self.state = state
        self._pwm_us = list(self._ours.truth.pwm_us)
        self._steps = 0
        self._command = state["rotor_speeds"].copy()

    # ------------------------------------------------------------------ time
    @property
    def time_s(self) -> float:
        """Simulation time [s]."""
        return self._steps * self.control_dt_s

    def advance_to(self, time_s: float) -> None:
        """Step rotorpy at the controller rate until ``time_s`` [s] (nearest control step)."""
        target = round(time_s / self.control_dt_s)
        while self._steps < target:
            self._step()

    def _step(self) -> None:
        t = self.time_s
        self._ours._apply_due_events(t + 0.5 * self.control_dt_s)  # winch, tension, release
        position, velocity, euler, rates = self._kinematics()
        if self._ours.follow_trajectory:
            self.controller.set_setpoint(self._ours.trajectory.setpoint_at(t))
        pwm = self.controller.update(
            self.control_dt_s, tuple(position), tuple(velocity), euler, tuple(rates), landed=False
        )
        self._pwm_us = list(pwm)
        thrusts = np.asarray(self.controller.mixer.thrusts_for_pwm_us(pwm))
        self._command = np.sqrt(np.maximum(thrusts, 0.0) / self._k_eta)
        self.state = self.multirotor.step(
            self.state, {"cmd_motor_speeds": self._command}, self.control_dt_s
        )
        self.cable.advance(self.control_dt_s)
        self._steps += 1

    # ------------------------------------------------------------------ truth
    def _kinematics(self) -> tuple[FloatArray, FloatArray, tuple[float, float, float], FloatArray]:
        s = self.state
        rotation = self._rotation_cls.from_quat(s["q"]).as_matrix()
        euler = euler_from_rotation(FLIP @ rotation @ FLIP)
        return FLIP @ s["x"], FLIP @ s["v"], euler, FLIP @ s["w"]

    def specific_force_body_mps2(self) -> FloatArray:
        """Non-gravitational force per unit mass on the airframe now, FRD [m/s^2], from
        rotorpy's own state derivative (thrust, drag, lift, the tether)."""
        packed = self.multirotor._pack_state(self.state)
        s_dot = self.multirotor._s_dot_fn(0.0, packed, self._command)
        rotation = self._rotation_cls.from_quat(self.state["q"]).as_matrix()
        world = s_dot[3:6] - np.array((0.0, 0.0, -ROTORPY_GRAVITY_MPS2))
        return FLIP @ (rotation.T @ world)

    @property
    def truth(self) -> TruthState:
        """The noise-free state now, as our simulator reports it."""
        position, velocity, euler, rates = self._kinematics()
        cable = np.array(self.cable.force_components(*position.tolist(), *velocity.tolist()))
        return TruthState(
            time_s=self.time_s,
            position_ned_m=position,
            velocity_ned_m_s=velocity,
            euler_rad=np.array(euler),
            body_rates_rad_s=rates,
            motor_thrust_n=self._k_eta * self.state["rotor_speeds"] ** 2,
            pwm_us=np.array(self._pwm_us),
            cable_force_ned_n=cable,
            tension_n=self.cable.tension_n,
            specific_force_body_mps2=self.specific_force_body_mps2(),
            landed=False,
        )

    # ------------------------------------------------------------------ sensors
    def read_imu(self) -> ImuSample:
        """Accelerometer and gyro through our sensor models."""
        _, _, _, rates = self._kinematics()
        force = tuple(self.specific_force_body_mps2().tolist())
        return self.sensors.imu(self.time_s, force, tuple(rates.tolist()))

    def read_attitude(self) -> AttitudeSample:
        """Roll, pitch, yaw with our attitude noise."""
        _, _, (roll, pitch, yaw), _ = self._kinematics()
        return self.sensors.attitude(self.time_s, roll, pitch, yaw)

    def read_pwm(self) -> PwmSample:
        """The PWM our controller commanded."""
        return self.sensors.pwm(self.time_s, np.array(self._pwm_us))

    def read_rangefinder(self) -> RangeSample | None:
        """Our downward rangefinder model over flat ground at the anchor's level."""
        position, _, (roll, pitch, _), _ = self._kinematics()
        return self.sensors.rangefinder(self.time_s, -float(position[2]), roll, pitch)


def _rotation_body_to_ned(euler_rad: FloatArray) -> FloatArray:
    from tether_companion.frames import rotation_ned_to_body

    return rotation_ned_to_body(*(float(a) for a in euler_rad)).T


class _TetheredForce:
    """The cable's (and a ground-station tug's) force in rotorpy's world frame [N]."""

    def __init__(self, simulator: RotorpySimulator) -> None:
        self._sim = simulator

    def __call__(self, s: FloatArray) -> FloatArray:
        pn, pe, pd = s[0], -s[1], -s[2]
        vn, ve, vd = s[3], -s[4], -s[5]
        fn, fe, fd = self._sim.cable.force_components(pn, pe, pd, vn, ve, vd)
        tn, te, td = self._sim._ours.body.tug_force_ned_n
        return np.array((fn + tn, -(fe + te), -(fd + td)))


def _tethered_class(multirotor_cls: type) -> type:
    """rotorpy's ``Multirotor`` with an external world-frame force in its equations of motion."""

    class TetheredMultirotor(multirotor_cls):  # type: ignore[misc, valid-type]
        def __init__(self, *args: Any, external_force: _TetheredForce, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            self._external_force = external_force

        def _s_dot_fn(self, t: float, s: FloatArray, cmd_rotor_speeds: FloatArray) -> FloatArray:
            s_dot = super()._s_dot_fn(t, s, cmd_rotor_speeds)
            s_dot[3:6] += self._external_force(s) / self.mass
            return s_dot

    return TetheredMultirotor
