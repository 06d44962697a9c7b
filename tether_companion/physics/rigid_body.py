"""6-DOF rigid-body quadcopter (Al-Radaideh & Sun 2021, eqs. 3-6), fixed-step RK4, ground contact.

State (layout declared once, here; named indices below)::

    x = (p_n, p_e, p_d,  u, v, w,  phi, theta, psi,  p, q, r,  f_1 .. f_n)

position of the centre of mass relative to the tether anchor in NED [m], velocity in the FRD
body frame [m/s], Euler angles roll/pitch/yaw [rad], body rates [rad/s], and each motor's
thrust [N].

Dynamics (R = R_v^b of eq. 2, F the sum of external forces in NED except thrust)::

    d(p_n, p_e, p_d)/dt = R^T (u, v, w)                                         (eq. 3)
    d(u, v, w)/dt       = (r v - q w, p w - r u, q u - p v) + f_b / m            (eq. 4)
    d(phi, theta, psi)/dt = E(phi, theta) (p, q, r)                               (eq. 5)
    d(p, q, r)/dt       = ((J_y - J_z) q r / J_x, (J_z - J_x) p r / J_y,
                           (J_x - J_y) p q / J_z) + (tau_l/J_x, tau_m/J_y, tau_n/J_z)  (eq. 6)

    f_b = (0, 0, -T) + R (F_cable + F_tug + (0, 0, m g) - c_d (v_ned - v_wind)) + m a_drag

where ``a_drag`` is the body-horizontal rotor and body drag of
:mod:`tether_companion.physics.aerodynamics` on the air velocity ``R (v_ned - v_wind)``.

with ``T`` and ``(tau_l, tau_m, tau_n)`` the allocation matrix applied to the motor thrusts.
Motor thrusts lag their PWM steady-state values with time constant ``tau`` (eq. of
:mod:`tether_companion.physics.motors`); with PWM held over a step the lag is integrated
exactly and the wrench is evaluated at each RK4 stage time, so the scheme stays fourth order.

Ground contact: the ground is the surface ``p_d = ground_down_m(p_n, p_e)`` (by default the
plane ``p_d = 0`` through the anchor; a winch on a tripod puts it below). A drone reaching it
while descending (or at rest) is ``landed``: pinned there, level, at rest, yaw kept. A landed
drone lifts off in the step where its thrust exceeds its weight plus the downward pull of the
cable and any tug; horizontal forces on a landed drone are taken by friction.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.physics.motors import MotorLag, lag_function
from tether_companion.physics.rigid_body_code import NO_SLOPE, generated
from tether_companion.physics.vehicle import VehicleProfile

FloatArray = NDArray[np.float64]

POS_N, POS_E, POS_D = 0, 1, 2
VEL_U, VEL_V, VEL_W = 3, 4, 5
ROLL, PITCH, YAW = 6, 7, 8
RATE_P, RATE_Q, RATE_R = 9, 10, 11
N_RIGID_STATES = 12
"""Number of rigid-body states; motor thrusts follow from index ``MOTOR_THRUST_START``."""
MOTOR_THRUST_START = N_RIGID_STATES

POSITION = slice(POS_N, POS_D + 1)
VELOCITY_BODY = slice(VEL_U, VEL_W + 1)
EULER = slice(ROLL, YAW + 1)
BODY_RATES = slice(RATE_P, RATE_R + 1)


def motor_thrusts_slice(n_motors: int) -> slice:
    """Slice of the full state holding the ``n_motors`` motor thrusts [N]."""
    return slice(MOTOR_THRUST_START, MOTOR_THRUST_START + n_motors)


ExternalForce = Callable[[float, float, float, float, float, float], tuple[float, float, float]]
"""``(p_n, p_e, p_d, v_n, v_e, v_d) -> (F_n, F_e, F_d)``: a state-dependent NED force [N]."""


def _flat_ground(north_m: float, east_m: float) -> float:
    """The plane through the anchor: down = 0 everywhere."""
    return 0.0


def _no_force(
    pn: float, pe: float, pd: float, vn: float, ve: float, vd: float
) -> tuple[float, float, float]:
    return 0.0, 0.0, 0.0


class RigidBody:
    """The quadcopter's state and its RK4 integration (see the module docstring).

    Parameters
    ----------
    vehicle
        Mass, inertia, drag, motor layout and lag.
    external_force
        The cable's force as a function of position and NED velocity (e.g. a cable model's
        ``force_components``); evaluated at every RK4 stage.
    gravity_mps2
        Gravitational acceleration [m/s^2].

    Attributes
    ----------
    tug_force_ned_n
        An extra constant NED force [N] (a tug on the line); (0, 0, 0) when none.
    wind_ned_m_s
        Wind velocity in NED [m/s]; acts through the vehicle's linear drag.
    landed
        True while the drone rests on the ground plane.
    x
        The 12 rigid-body states as a list of floats (live; read it, set it via ``set_state``).
    """

    def __init__(
        self,
        vehicle: VehicleProfile,
        external_force: ExternalForce = _no_force,
        gravity_mps2: float = GRAVITY_MPS2,
    ) -> None:
        self.vehicle = vehicle
        self.n_motors = vehicle.n_motors
        self.external_force = external_force
        self.gravity_mps2 = float(gravity_mps2)
        self.mass_kg = float(vehicle.mass_kg)
        self._inv_mass = 1.0 / self.mass_kg
        jx, jy, jz = (float(j) for j in vehicle.inertia_kg_m2)
        self._inertia = (jx, jy, jz)
        self._gyro = ((jy - jz) / jx, (jz - jx) / jy, (jx - jy) / jz)
        self._inv_inertia = (1.0 / jx, 1.0 / jy, 1.0 / jz)
        self._drag = float(vehicle.drag_coefficient_n_s_per_m)
        self._rotor_drag_per_s = float(vehicle.rotor_drag_per_s)
        self._ballistic_coefficient = float(vehicle.ballistic_coefficient_kg_per_m2)
        has_aero_drag = self._rotor_drag_per_s > 0.0 or self._ballistic_coefficient > 0.0
        self._derivative, self._rk4, self._rk4_after = generated(has_aero_drag)
        self.ground_down_m: Callable[[float, float], float] = _flat_ground
        """Down coordinate of the ground under (north, east) [m] (default: the anchor's level)."""
        self._lag = MotorLag(vehicle.motor_time_constant_s)
        self._lag_all = lag_function(self.n_motors)
        allocation = vehicle.allocation_matrix()
        self._allocation_rows = tuple(tuple(float(a) for a in row) for row in allocation)
        self._tug_force_ned_n: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._wind_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._constant_force_ned_n = (0.0, 0.0, self.mass_kg * self.gravity_mps2)
        self._coefficients: tuple[float, ...] = ()
        """What :meth:`derivative` reads besides the state, as one tuple (one unpack per call)."""
        self._update_constant_force()
        self.x: list[float] = [0.0] * N_RIGID_STATES
        self._motor_n: list[float] = [0.0] * self.n_motors
        self._wrench: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
        self._targets_ref: Sequence[float] | None = None
        self._targets_wrench: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
        self.landed = False
        self._decay_dt = math.nan
        self._decay_half = self._decay_full = 1.0
        self.force_history_free = True
        """Whether :attr:`external_force` gives the same floats for the same arguments whatever
        it was asked before: then the derivative :meth:`specific_force_body_mps2` evaluates is
        the next step's first RK4 stage (else every stage is evaluated, in the usual order)."""
        self._first_stage: tuple | None = None
        """``(x, wrench, coefficients, external_force, derivative)`` of the last
        :meth:`specific_force_body_mps2`: the next step's first RK4 stage while all four are
        the same objects (and :meth:`forget_forces` was not called)."""

    # ------------------------------------------------------------------ constant forces
    @property
    def tug_force_ned_n(self) -> tuple[float, float, float]:
        """Extra constant NED force on the drone [N] (a tug on the line)."""
        return self._tug_force_ned_n

    @tug_force_ned_n.setter
    def tug_force_ned_n(self, force_ned_n: Sequence[float]) -> None:
        self._tug_force_ned_n = tuple(float(f) for f in force_ned_n)  # type: ignore[assignment]
        self._update_constant_force()

    @property
    def wind_ned_m_s(self) -> tuple[float, float, float]:
        """Wind velocity, NED [m/s]."""
        return self._wind_ned_m_s

    @wind_ned_m_s.setter
    def wind_ned_m_s(self, wind_ned_m_s: Sequence[float]) -> None:
        self._wind_ned_m_s = tuple(float(w) for w in wind_ned_m_s)  # type: ignore[assignment]
        self._update_constant_force()

    def _update_constant_force(self) -> None:
        """Gravity + tug + the wind's share of the drag, NED [N], precomputed for the RK4."""
        c = self._drag
        tug, wind = self._tug_force_ned_n, self._wind_ned_m_s
        self._constant_force_ned_n = (
            tug[0] + c * wind[0],
            tug[1] + c * wind[1],
            tug[2] + c * wind[2] + self.mass_kg * self.gravity_mps2,
        )
        self._coefficients = (
            *self._constant_force_ned_n,
            c,
            self._inv_mass,
            *wind,
            *self._gyro,
            *self._inv_inertia,
            self._rotor_drag_per_s,
            self._ballistic_coefficient,
        )

    # ------------------------------------------------------------------ state access
    @property
    def state(self) -> FloatArray:
        """Full state, shape (12 + n_motors,), in the module's layout (a copy)."""
        return np.array(self.x + self._motor_n)

    def set_state(self, state: Sequence[float], *, landed: bool = False) -> None:
        """Replace the full state (12 + n_motors values, module layout)."""
        values = [float(v) for v in state]
        if len(values) != N_RIGID_STATES + self.n_motors:
            raise ValueError(
                f"state must have {N_RIGID_STATES + self.n_motors} values, got {len(values)}"
            )
        if not all(math.isfinite(v) for v in values):
            raise ValueError("state must be finite")
        self.x = values[:N_RIGID_STATES]
        self._motor_n = values[N_RIGID_STATES:]
        self._wrench = self.wrench(self._motor_n)
        self.landed = landed
        if landed:
            self._pin_to_ground()

    @property
    def motor_thrusts_n(self) -> list[float]:
        """Current motor thrusts [N] (a copy)."""
        return list(self._motor_n)

    def wrench(self, motor_thrusts_n: Sequence[float]) -> tuple[float, float, float, float]:
        """(collective thrust [N], roll, pitch, yaw torque [N m]) of motor thrusts [N]."""
        return tuple(  # type: ignore[return-value]
            sum(a * f for a, f in zip(row, motor_thrusts_n, strict=True))
            for row in self._allocation_rows
        )

    # ------------------------------------------------------------------ dynamics
    def derivative(
        self,
        x: Sequence[float],
        thrust_n: float,
        tau_l: float,
        tau_m: float,
        tau_n: float,
        slope: Sequence[float] | None = None,
        step_s: float = 0.0,
    ) -> tuple[float, ...]:
        """Time derivative of the 12 rigid-body states (eqs. 3-6) for a given wrench.

        Parameters
        ----------
        x
            Rigid-body state, 12 values in the module's layout.
        thrust_n
            Collective thrust along body -z [N].
        tau_l, tau_m, tau_n
            Body torques about FRD x, y, z [N m].
        slope, step_s
            When given, the derivative is taken at ``x + step_s * slope`` (an RK4 stage).
        """
        return self._derivative(
            x,
            (thrust_n, tau_l, tau_m, tau_n),
            slope if slope is not None else NO_SLOPE,
            step_s,
            self._coefficients,
            self.external_force,
        )

    def step(self, dt_s: float, steady_state_thrusts_n: Sequence[float]) -> None:
        """Advance the state by ``dt_s`` seconds with the motors' steady-state thrusts held.

        One classical RK4 step of the rigid body (wrench at each stage time from the exact motor
        lag solution), then the motors' exact lag update, then ground contact. Pass the same
        sequence object while the targets are unchanged: their wrench is cached by identity.
        """
        if dt_s != self._decay_dt:
            self._decay_dt = dt_s
            self._decay_half = self._lag.decay(0.5 * dt_s)
            self._decay_full = self._lag.decay(dt_s)
        fss = steady_state_thrusts_n
        if fss is not self._targets_ref:
            self._targets_ref = fss
            self._targets_wrench = self.wrench(fss)
        # the wrench at the stage times, in scalars (4 values: a comprehension costs more)
        st, sl, sm, sn = self._targets_wrench
        w_start = self._wrench
        t0, l0, m0, n0 = w_start
        dh = self._decay_half
        df = self._decay_full
        w_half = (
            st + (t0 - st) * dh,
            sl + (l0 - sl) * dh,
            sm + (m0 - sm) * dh,
            sn + (n0 - sn) * dh,
        )
        w_full = (
            st + (t0 - st) * df,
            sl + (l0 - sl) * df,
            sm + (m0 - sm) * df,
            sn + (n0 - sn) * df,
        )
        self._wrench = w_full
        self._motor_n = self._lag_all(fss, self._motor_n, df)

        known, self._first_stage = self._first_stage, None
        if self.landed:
            if not self._lifts_off(t0):
                return
            self.landed = False
        x, coefficients, force = self.x, self._coefficients, self.external_force
        if (
            known is not None
            and known[0] is x
            and known[1] is w_start
            and known[2] is coefficients
            and known[3] is force
        ):  # the first stage is the derivative the accelerometer read: the same floats
            x = self._rk4_after(x, known[4], w_half, w_full, dt_s, coefficients, force)
        else:
            x = self._rk4(x, w_start, w_half, w_full, dt_s, coefficients, force)
        self.x = x
        if x[POS_D] >= self.ground_down_m(x[POS_N], x[POS_E]):
            self._touch_ground()

    def forget_forces(self) -> None:
        """Call when the external force changes without a new function (a cable's tension
        set-point or length set in place): the next step evaluates every stage afresh."""
        self._first_stage = None

    # ------------------------------------------------------------------ ground contact
    def _lifts_off(self, thrust_n: float) -> bool:
        pn, pe, pd = self.x[POS_N], self.x[POS_E], self.x[POS_D]
        _, _, cable_down_n = self.external_force(pn, pe, pd, 0.0, 0.0, 0.0)
        down_n = (
            self.mass_kg * self.gravity_mps2 + cable_down_n + self.tug_force_ned_n[2] - thrust_n
        )
        return down_n < 0.0

    def _touch_ground(self) -> None:
        x = self.x
        vd = self.velocity_ned_m_s()[2]
        x[POS_D] = self.ground_down_m(x[POS_N], x[POS_E])
        if vd >= 0.0:
            self.landed = True
            self._pin_to_ground()

    def _pin_to_ground(self) -> None:
        x = self.x
        x[POS_D] = self.ground_down_m(x[POS_N], x[POS_E])
        for i in (VEL_U, VEL_V, VEL_W, ROLL, PITCH, RATE_P, RATE_Q, RATE_R):
            x[i] = 0.0

    # ------------------------------------------------------------------ outputs
    def velocity_ned_m_s(self, x: Sequence[float] | None = None) -> tuple[float, float, float]:
        """NED velocity [m/s] of the current state, or of the rigid-body state ``x`` (eq. 3)."""
        _, _, _, u, v, w, phi, theta, psi = (self.x if x is None else x)[:9]
        cr, sr = math.cos(phi), math.sin(phi)
        cp, sp = math.cos(theta), math.sin(theta)
        cy, sy = math.cos(psi), math.sin(psi)
        # columns of R_v^b (eq. 2): v_ned = R^T (u, v, w)
        return (
            cp * cy * u + (sr * sp * cy - cr * sy) * v + (cr * sp * cy + sr * sy) * w,
            cp * sy * u + (sr * sp * sy + cr * cy) * v + (cr * sp * sy - sr * cy) * w,
            -sp * u + sr * cp * v + cr * cp * w,
        )

    def specific_force_body_mps2(self) -> tuple[float, float, float]:
        """Noise-free accelerometer specific force, FRD body [m/s^2] (paper eq. 11, 20 in SI).

        The sum of non-gravitational forces over the mass, in the body frame: thrust, cable,
        tug and drag while flying; the ground's reaction (``-g`` rotated into the body) while
        landed.
        """
        x = self.x
        phi, theta = x[ROLL], x[PITCH]
        g = self.gravity_mps2
        # gravity in body: R (0, 0, g) = g * (-sin(theta), sin(phi)cos(theta), cos(phi)cos(theta))
        grav_body = (
            -math.sin(theta) * g,
            math.sin(phi) * math.cos(theta) * g,
            math.cos(phi) * math.cos(theta) * g,
        )
        if self.landed:
            return -grav_body[0], -grav_body[1], -grav_body[2]
        wrench, coefficients, force = self._wrench, self._coefficients, self.external_force
        d = self._derivative(x, wrench, NO_SLOPE, 0.0, coefficients, force)
        if self.force_history_free:
            self._first_stage = (x, wrench, coefficients, force, d)
        u, v, w = x[VEL_U], x[VEL_V], x[VEL_W]
        p, q, r = x[RATE_P], x[RATE_Q], x[RATE_R]
        # kinematic acceleration (eq. 7-10): du/dt + Omega x eta; minus gravity (eq. 11)
        ax = d[VEL_U] + q * w - r * v - grav_body[0]
        ay = d[VEL_V] + r * u - p * w - grav_body[1]
        az = d[VEL_W] + p * v - q * u - grav_body[2]
        return ax, ay, az
