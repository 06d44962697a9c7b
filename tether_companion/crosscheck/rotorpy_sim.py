"""Our scenarios flown with rotorpy's airframe physics (PyPI ``rotorpy``) in place of ours.

rotorpy (University of Pennsylvania, MIT licence) integrates its own quadrotor dynamics
(``Multirotor._s_dot_fn``: rotor thrust ``k_eta w^2`` with first-order rotor-speed lag, rotor
drag "H force" ``-w k_d v_local`` at each hub, induced inflow ``-w k_z v_z``, translational
lift ``k_h v_xy^2``, blade-flapping moment, parasitic drag ``-|v| c_D v``; scipy's RK45 via
``Multirotor.step``). :class:`RotorpySimulator` is our
:class:`~tether_companion.sim.simulator.Simulator` with its :class:`RigidBody` swapped for
:class:`RotorpyBody`: everything else is ours (controller, cable and its wind drag, winch
events, wind and Dryden gusts, thrust-map error and battery sag, terrain, sensors, failure
checks). The tether's force enters rotorpy's equations of motion as an external force
evaluated inside its integrator.

Frames: rotorpy's world is x north, y west, z up and its body is FLU; ours are NED and FRD.
Both maps are ``S = diag(1, -1, -1)``: ``p_ned = S x``, ``R_ned_frd = S R S``,
``omega_frd = S omega_flu``. rotorpy's gravity (9.81 m/s^2) is set to ours (9.80665).

Vehicle mapping (:func:`rotorpy_params`): mass, inertia, rotor positions and spin from our
profile (its allocation matrix); ``k_eta`` from a nominal top rotor speed; rotor drag ``k_d``
so that the hubs at the hover rotor speed give our body-horizontal linear drag
(``n w_hover k_d = c_d + m mu``), ``k_z`` our vertical linear drag (``c_d``); parasitic drag
``c_D = rho m / (2 B)`` from our ballistic coefficient horizontally, none vertically;
translational lift scaled from rotorpy's AscTec Hummingbird by the hover thrust per rotor (we
have none); no flapping moment (the Hummingbird has none either). docs/simulator.md, "rotorpy
cross-check", says what differs and by how much.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tether_companion.errors import InputError
from tether_companion.frames import rotation_ned_to_body
from tether_companion.physics.aerodynamics import AIR_DENSITY_KG_M3
from tether_companion.physics.rigid_body import N_RIGID_STATES
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.sim.scenario import Scenario
from tether_companion.sim.simulator import Simulator

FloatArray = NDArray[np.float64]

FLIP = np.diag((1.0, -1.0, -1.0))
"""NED <-> rotorpy world (x north, y west, z up), FRD <-> FLU: the same diagonal map."""
NOMINAL_TOP_ROTOR_SPEED_RAD_S = 1000.0
"""Rotor speed at full thrust (sets k_eta; only the product k_eta w^2 matters)."""
HUMMINGBIRD_K_H = 3.39e-3
"""rotorpy ``vehicles/hummingbird_params.py``: translational lift per rotor [N/(m/s)^2] ..."""
HUMMINGBIRD_HOVER_THRUST_PER_ROTOR_N = 0.5 * 9.81 / 4.0
"""... at this hover thrust per rotor (0.5 kg, 4 rotors)."""
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


def rotorpy_params(vehicle: VehicleProfile, gravity_mps2: float) -> dict:
    """rotorpy ``quad_params`` for our ``vehicle`` (see the module docstring)."""
    n = vehicle.n_motors
    k_eta = vehicle.thrust_curve.max_thrust_n / NOMINAL_TOP_ROTOR_SPEED_RAD_S**2
    hover_n = hover_thrust_per_rotor_n(vehicle, gravity_mps2)
    hover_speed = math.sqrt(hover_n / k_eta)
    linear = vehicle.drag_coefficient_n_s_per_m
    horizontal = linear + vehicle.mass_kg * vehicle.rotor_drag_per_s
    ballistic = vehicle.ballistic_coefficient_kg_per_m2
    parasitic = 0.5 * AIR_DENSITY_KG_M3 * vehicle.mass_kg / ballistic if ballistic > 0 else 0.0
    # allocation columns (1, -y, x, yaw) in FRD: rotor at FLU (x, -y_frd); a positive FRD yaw
    # torque (ccw rotor) is negative about z-up
    allocation = vehicle.allocation_matrix()
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
        "rotor_pos": {
            f"r{i + 1}": np.array((column[2], column[1], 0.0))
            for i, column in enumerate(allocation.T)
        },
        "rotor_directions": -np.sign(allocation[3]),
        "c_Dx": parasitic,
        "c_Dy": parasitic,
        "c_Dz": 0.0,
        "k_eta": k_eta,
        "k_m": vehicle.yaw_moment_per_thrust_m * k_eta,
        "k_d": horizontal / (n * hover_speed),
        "k_z": linear / (n * hover_speed),
        "k_h": HUMMINGBIRD_K_H * hover_n / HUMMINGBIRD_HOVER_THRUST_PER_ROTOR_N,
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


def _no_force(*_: float) -> tuple[float, float, float]:
    return (0.0, 0.0, 0.0)


class RotorpyBody:
    """rotorpy's multirotor behind the part of :class:`RigidBody`'s interface the simulator
    uses (airborne only: it never lands).

    Parameters
    ----------
    vehicle
        Our profile (mapped by :func:`rotorpy_params`).
    gravity_mps2
        Gravity [m/s^2] (rotorpy's own 9.81 is replaced by it).
    """

    def __init__(self, vehicle: VehicleProfile, gravity_mps2: float) -> None:
        multirotor_cls = require_rotorpy()
        from scipy.spatial.transform import Rotation

        self._rotation = Rotation
        self.vehicle = vehicle
        self.mass_kg = vehicle.mass_kg
        self.gravity_mps2 = gravity_mps2
        self.params = rotorpy_params(vehicle, gravity_mps2)
        self._k_eta = self.params["k_eta"]
        self.external_force: Callable[..., tuple[float, float, float]] = _no_force
        self.ground_down_m: Callable[[float, float], float] = lambda north, east: 0.0
        self.landed = False
        self._tug_ned_n = (0.0, 0.0, 0.0)
        self._wind_ned_m_s = (0.0, 0.0, 0.0)
        self._command = np.zeros(vehicle.n_motors)
        body = self

        class TetheredMultirotor(multirotor_cls):  # type: ignore[misc, valid-type]
            """rotorpy's multirotor with the tether's force in its equations of motion."""

            def _s_dot_fn(self, t: float, s: FloatArray, cmd: FloatArray) -> FloatArray:
                s_dot = super()._s_dot_fn(t, s, cmd)
                s_dot[3:6] += body._external_world_n(s) / self.mass
                return s_dot

        self.multirotor = TetheredMultirotor(
            self.params, control_abstraction="cmd_motor_speeds", aero=True, enable_ground=False
        )
        self.multirotor.g = gravity_mps2
        self.multirotor.weight = np.array((0.0, 0.0, -self.mass_kg * gravity_mps2))
        self._state: dict[str, FloatArray] = {}
        self.x: list[float] = [0.0] * N_RIGID_STATES

    def _external_world_n(self, s: FloatArray) -> FloatArray:
        fn, fe, fd = self.external_force(s[0], -s[1], -s[2], s[3], -s[4], -s[5])
        tn, te, td = self._tug_ned_n
        return np.array((fn + tn, -(fe + te), -(fd + td)))

    # ------------------------------------------------------------------ forces
    @property
    def tug_force_ned_n(self) -> tuple[float, float, float]:
        """Extra NED force on the drone [N]."""
        return self._tug_ned_n

    @tug_force_ned_n.setter
    def tug_force_ned_n(self, force_ned_n: Sequence[float]) -> None:
        self._tug_ned_n = tuple(float(f) for f in force_ned_n)  # type: ignore[assignment]

    @property
    def wind_ned_m_s(self) -> tuple[float, float, float]:
        """Wind velocity, NED [m/s] (rotorpy's ``wind`` state)."""
        return self._wind_ned_m_s

    @wind_ned_m_s.setter
    def wind_ned_m_s(self, wind_ned_m_s: Sequence[float]) -> None:
        self._wind_ned_m_s = tuple(float(w) for w in wind_ned_m_s)  # type: ignore[assignment]
        if self._state:
            self._state["wind"] = FLIP @ np.asarray(self._wind_ned_m_s)

    # ------------------------------------------------------------------ state
    def set_state(self, state: Sequence[float], *, landed: bool = False) -> None:
        """Our layout (position NED, body velocity FRD, Euler, rates FRD, motor thrusts)."""
        if landed:
            raise InputError(
                "the rotorpy cross-check flies airborne starts only "
                "(this scenario starts on the ground: initial.airborne false)"
            )
        values = np.asarray(state, dtype=float)
        to_body = rotation_ned_to_body(*values[6:9])
        rotation_flu = FLIP @ to_body.T @ FLIP
        self._state = {
            "x": FLIP @ values[0:3],
            "v": FLIP @ (to_body.T @ values[3:6]),
            "q": self._rotation.from_matrix(rotation_flu).as_quat(),
            "w": FLIP @ values[9:12],
            "wind": FLIP @ np.asarray(self._wind_ned_m_s),
            "rotor_speeds": np.sqrt(np.maximum(values[N_RIGID_STATES:], 0.0) / self._k_eta),
        }
        self._command = self._state["rotor_speeds"].copy()
        self._refresh()

    def _refresh(self) -> None:
        s = self._state
        rotation = self._rotation.from_quat(s["q"]).as_matrix()
        self._body_to_ned = FLIP @ rotation @ FLIP
        velocity = FLIP @ s["v"]
        body_velocity = self._body_to_ned.T @ velocity
        self.x = [
            *(FLIP @ s["x"]).tolist(),
            *body_velocity.tolist(),
            *euler_from_rotation(self._body_to_ned),
            *(FLIP @ s["w"]).tolist(),
        ]
        self._velocity_ned = tuple(velocity.tolist())

    @property
    def state(self) -> FloatArray:
        """Our layout, shape (12 + n_motors,)."""
        return np.array(self.x + self.motor_thrusts_n)

    @property
    def motor_thrusts_n(self) -> list[float]:
        """Rotor thrusts ``k_eta w^2`` [N]."""
        return (self._k_eta * self._state["rotor_speeds"] ** 2).tolist()

    def step(self, dt_s: float, steady_state_thrusts_n: Sequence[float]) -> None:
        """rotorpy's own step with rotor speeds commanded to give these steady thrusts."""
        thrusts = np.maximum(np.asarray(steady_state_thrusts_n, dtype=float), 0.0)
        self._command = np.sqrt(thrusts / self._k_eta)
        self._state = self.multirotor.step(self._state, {"cmd_motor_speeds": self._command}, dt_s)
        self._refresh()

    def velocity_ned_m_s(self) -> tuple[float, float, float]:
        """NED velocity [m/s]."""
        return self._velocity_ned

    def specific_force_body_mps2(self) -> tuple[float, float, float]:
        """Non-gravitational force per unit mass, FRD [m/s^2], from rotorpy's state
        derivative (thrust, lift, drag, the tether): ``R^T (v_dot - g)``."""
        packed = self.multirotor._pack_state(self._state)
        s_dot = self.multirotor._s_dot_fn(0.0, packed, self._command)
        world = FLIP @ s_dot[3:6] - np.array((0.0, 0.0, self.gravity_mps2))
        return tuple((self._body_to_ned.T @ world).tolist())  # type: ignore[return-value]


class RotorpySimulator(Simulator):
    """:class:`Simulator` with rotorpy's airframe (:class:`RotorpyBody`); the same arguments.

    Raises
    ------
    InputError
        rotorpy is not installed, or the scenario starts on the ground.
    """

    def __init__(self, scenario: Scenario, *args: Any, **kwargs: Any) -> None:
        super().__init__(scenario, *args, **kwargs)
        ours = self.body
        body = RotorpyBody(self.vehicle, self.gravity_mps2)
        body.external_force = ours.external_force
        body.ground_down_m = ours.ground_down_m
        body.wind_ned_m_s = ours.wind_ned_m_s
        body.tug_force_ned_n = ours.tug_force_ned_n
        body.set_state(ours.state, landed=ours.landed)
        self.body = body  # type: ignore[assignment]
