"""Cascaded multicopter controller: position -> velocity -> attitude -> body rates -> PWM.

Loops (all gains in the ``controller`` section of a scenario)::

    v_cmd   = v_ff + K_p (p_sp - p)                       (clamped to max speeds)
    a_cmd   = a_ff + K_v (v_cmd - v) + I,  dI/dt = K_i (v_cmd - v)   (I clamped: anti-windup)
    F_des   = m (a_cmd - (0, 0, g))                       thrust vector wanted, NED [N]
    roll_d  = asin(F_y / |F|),  pitch_d = atan2(-F_x, -F_d)   (F rotated by -yaw; tilt clamped)
    T       = -F_des . z_b                                (collective along the current body -z)
    rates   = E^-1 (K_att (euler_d - euler))              (eq. 5 inverted)
    tau     = J K_rate (rates_cmd - omega) + omega x J omega
    motor thrusts = mixer(T, tau);  PWM = inverse thrust curve, whole microseconds

The integral term is what holds the drone against the cable's pull, which the controller does
not know. A set-point on the ground (``p_d >= -landed_threshold``) is a landing: the drone
descends at least at ``landing_speed_mps`` until it touches down, then the motors idle. While
landed the integrators are held at zero.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from tether_companion.config import spec
from tether_companion.physics.motors import MotorMixer
from tether_companion.physics.vehicle import VehicleProfile

Vector3 = tuple[float, float, float]


class Setpoint(NamedTuple):
    """What the vehicle is asked to do, NED frame (immutable; a named tuple because the
    trajectory makes one per controller step, which a frozen dataclass makes ~2.5x dearer).

    ``position_ned_m`` given: fly there, with ``velocity_ned_m_s`` and ``acceleration_ned_mps2``
    as feed-forward. Only ``velocity_ned_m_s``: fly at that velocity. Neither: hold the
    position where the set-point was received. ``yaw_rad`` None: hold the current yaw.
    """

    position_ned_m: Vector3 | None = None
    velocity_ned_m_s: Vector3 | None = None
    acceleration_ned_mps2: Vector3 | None = None
    yaw_rad: float | None = None


@dataclass(frozen=True)
class ControllerConfig:
    """The ``controller`` section of a scenario: loop rate, gains and limits."""

    rate_hz: float = spec(250.0, exclusive_minimum=0.0, doc="controller update rate [Hz]")
    position_gain_xy_per_s: float = spec(
        2.0, exclusive_minimum=0.0, doc="horizontal position gain [1/s]"
    )
    position_gain_z_per_s: float = spec(
        2.0, exclusive_minimum=0.0, doc="vertical position gain [1/s]"
    )
    velocity_gain_xy_per_s: float = spec(
        6.0, exclusive_minimum=0.0, doc="horizontal velocity gain [1/s]"
    )
    velocity_gain_z_per_s: float = spec(
        6.0, exclusive_minimum=0.0, doc="vertical velocity gain [1/s]"
    )
    velocity_integral_xy_per_s2: float = spec(
        6.0, minimum=0.0, doc="horizontal velocity-error integral gain [1/s^2]"
    )
    velocity_integral_z_per_s2: float = spec(
        6.0, minimum=0.0, doc="vertical velocity-error integral gain [1/s^2]"
    )
    max_integral_mps2: float = spec(8.0, minimum=0.0, doc="integrator limit per axis [m/s^2]")
    attitude_gain_per_s: float = spec(
        10.0, exclusive_minimum=0.0, doc="roll/pitch angle gain [1/s]"
    )
    yaw_gain_per_s: float = spec(3.0, exclusive_minimum=0.0, doc="yaw angle gain [1/s]")
    rate_gain_per_s: float = spec(25.0, exclusive_minimum=0.0, doc="roll/pitch rate gain [1/s]")
    yaw_rate_gain_per_s: float = spec(8.0, exclusive_minimum=0.0, doc="yaw rate gain [1/s]")
    max_tilt_deg: float = spec(
        35.0, exclusive_minimum=0.0, maximum=80.0, doc="largest commanded tilt [deg]"
    )
    max_speed_xy_mps: float = spec(
        5.0, exclusive_minimum=0.0, doc="largest commanded horizontal speed [m/s]"
    )
    max_speed_z_mps: float = spec(
        2.5, exclusive_minimum=0.0, doc="largest commanded vertical speed [m/s]"
    )
    max_rate_rad_s: float = spec(
        4.0, exclusive_minimum=0.0, doc="largest commanded roll/pitch rate [rad/s]"
    )
    max_yaw_rate_rad_s: float = spec(
        1.5, exclusive_minimum=0.0, doc="largest commanded yaw rate [rad/s]"
    )
    landing_speed_mps: float = spec(
        0.5, exclusive_minimum=0.0, doc="least descent speed toward a set-point on the ground [m/s]"
    )
    landed_threshold_m: float = spec(
        0.1, minimum=0.0, doc="a set-point this close to the ground keeps a landed drone idle [m]"
    )


def _clamp(value: float, limit: float) -> float:
    """``max(-limit, min(limit, value))``, the same float in every case (NaN gives ``limit``,
    a zero limit ``-0.0``), in comparisons: the two builtins cost ~4x as much."""
    below = value if value < limit else limit
    return below if below > -limit else -limit


def _wrap(angle_rad: float) -> float:
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


class CascadedController:
    """The cascade of the module docstring, for one vehicle.

    Parameters
    ----------
    config
        Gains and limits.
    vehicle
        Mass, inertia and motors (the controller knows the vehicle, not the cable).
    gravity_mps2
        Gravitational acceleration [m/s^2].
    """

    def __init__(
        self, config: ControllerConfig, vehicle: VehicleProfile, gravity_mps2: float
    ) -> None:
        self.config = config
        self.vehicle = vehicle
        self.mixer = MotorMixer(vehicle)
        self.gravity_mps2 = float(gravity_mps2)
        self.mass_kg = float(vehicle.mass_kg)
        self._inertia = tuple(float(j) for j in vehicle.inertia_kg_m2)
        self._tan_max_tilt = math.tan(math.radians(config.max_tilt_deg))
        self.integral_ned_mps2 = [0.0, 0.0, 0.0]
        self.setpoint = Setpoint()
        self._hold_position: Vector3 | None = None
        self._hold_yaw_rad: float | None = None
        self.last_pwm_us = self.mixer.idle_pwm_us()

    def set_setpoint(self, setpoint: Setpoint) -> None:
        """Replace the set-point; holds (position, yaw) are latched at the next update."""
        self.setpoint = setpoint
        self._hold_position = None
        self._hold_yaw_rad = None

    def reset(self) -> None:
        """Zero the integrators."""
        self.integral_ned_mps2 = [0.0, 0.0, 0.0]

    def preload_integral(self, acceleration_ned_mps2: Vector3) -> None:
        """Start the integrators at a trim acceleration [m/s^2] (e.g. for a start in flight)."""
        limit = self.config.max_integral_mps2
        self.integral_ned_mps2 = [_clamp(float(a), limit) for a in acceleration_ned_mps2]

    def idle(self) -> list[float]:
        """Motors stopped (disarmed or landed idle): reset and return pwm_min on every output."""
        self.reset()
        self.last_pwm_us = self.mixer.idle_pwm_us()
        return self.last_pwm_us

    def update(
        self,
        dt_s: float,
        position_ned_m: Vector3,
        velocity_ned_m_s: Vector3,
        euler_rad: Vector3,
        body_rates_rad_s: Vector3,
        *,
        landed: bool = False,
    ) -> list[float]:
        """One controller step; returns the PWM outputs (n_motors values) in whole microseconds."""
        c = self.config
        sp = self.setpoint
        roll, pitch, yaw = euler_rad
        if self._hold_yaw_rad is None:
            self._hold_yaw_rad = yaw
        yaw_sp = self._hold_yaw_rad if sp.yaw_rad is None else sp.yaw_rad

        # position -> velocity command
        if sp.position_ned_m is not None:
            target = sp.position_ned_m
        elif sp.velocity_ned_m_s is None:
            if self._hold_position is None:
                self._hold_position = tuple(position_ned_m)  # type: ignore[assignment]
            target = self._hold_position
        else:
            target = None
        landing = target is not None and target[2] >= -c.landed_threshold_m
        if landed and (target is None or landing):
            return self.idle()
        vn_ff, ve_ff, vd_ff = sp.velocity_ned_m_s or (0.0, 0.0, 0.0)
        if target is None:
            vn_cmd, ve_cmd, vd_cmd = vn_ff, ve_ff, vd_ff
        else:
            kxy, kz = c.position_gain_xy_per_s, c.position_gain_z_per_s
            pn, pe, pd = position_ned_m
            vn_cmd = vn_ff + kxy * (target[0] - pn)
            ve_cmd = ve_ff + kxy * (target[1] - pe)
            vd_cmd = vd_ff + kz * (target[2] - pd)
        speed_xy = math.hypot(vn_cmd, ve_cmd)
        max_xy = c.max_speed_xy_mps
        if speed_xy > max_xy:
            vn_cmd *= max_xy / speed_xy
            ve_cmd *= max_xy / speed_xy
        if landing:
            vd_cmd = max(vd_cmd, c.landing_speed_mps)
        max_z = c.max_speed_z_mps
        vd_cmd = _clamp(vd_cmd, max_z)

        # velocity -> acceleration command (PI), anti-windup by clamping
        an_ff, ae_ff, ad_ff = sp.acceleration_ned_mps2 or (0.0, 0.0, 0.0)
        kv_xy, kv_z = c.velocity_gain_xy_per_s, c.velocity_gain_z_per_s
        vn, ve, vd = velocity_ned_m_s
        en, ee, ed = vn_cmd - vn, ve_cmd - ve, vd_cmd - vd
        integral = self.integral_ned_mps2
        i_n, i_e, i_d = integral
        if not landed:
            ki_xy, ki_z = c.velocity_integral_xy_per_s2, c.velocity_integral_z_per_s2
            limit = c.max_integral_mps2
            i_n = _clamp(i_n + ki_xy * en * dt_s, limit)
            i_e = _clamp(i_e + ki_xy * ee * dt_s, limit)
            i_d = _clamp(i_d + ki_z * ed * dt_s, limit)
            integral[0], integral[1], integral[2] = i_n, i_e, i_d
        an_cmd = an_ff + kv_xy * en + i_n
        ae_cmd = ae_ff + kv_xy * ee + i_e
        ad_cmd = ad_ff + kv_z * ed + i_d

        # acceleration -> thrust vector -> attitude set-point
        g = self.gravity_mps2
        m = self.mass_kg
        fn, fe = m * an_cmd, m * ae_cmd
        fd, floor = m * (ad_cmd - g), -0.1 * m * g
        fd = floor if floor < fd else fd  # min(fd, floor) without the builtin's call
        horizontal = math.hypot(fn, fe)
        limit = self._tan_max_tilt * -fd
        if horizontal > limit:
            fn *= limit / horizontal
            fe *= limit / horizontal
        cy, sy = math.cos(yaw), math.sin(yaw)
        fx = cy * fn + sy * fe
        fy = -sy * fn + cy * fe
        magnitude = math.sqrt(fn * fn + fe * fe + fd * fd)
        roll_sp = math.asin(fy / magnitude)
        pitch_sp = math.atan2(-fx, -fd)
        cr, sr = math.cos(roll), math.sin(roll)
        cp, sp_ = math.cos(pitch), math.sin(pitch)
        # body z axis in NED: third row of R_v^b
        zb0, zb1, zb2 = cr * sp_ * cy + sr * sy, cr * sp_ * sy - sr * cy, cr * cp
        collective = -(fn * zb0 + fe * zb1 + fd * zb2)
        collective = 0.0 if 0.0 > collective else collective  # max(collective, 0.0)

        # attitude -> body rates (eq. 5 inverted) -> torques
        max_rate, max_yaw_rate = c.max_rate_rad_s, c.max_yaw_rate_rad_s
        droll = c.attitude_gain_per_s * (roll_sp - roll)
        dpitch = c.attitude_gain_per_s * (pitch_sp - pitch)
        dyaw = c.yaw_gain_per_s * _wrap(yaw_sp - yaw)
        dyaw = _clamp(dyaw, max_yaw_rate)
        p_cmd = _clamp(droll - sp_ * dyaw, max_rate)
        q_cmd = _clamp(cr * dpitch + sr * cp * dyaw, max_rate)
        r_cmd = _clamp(-sr * dpitch + cr * cp * dyaw, max_yaw_rate)
        p, q, r = body_rates_rad_s
        jx, jy, jz = self._inertia
        torque = (
            jx * c.rate_gain_per_s * (p_cmd - p) + (jz - jy) * q * r,
            jy * c.rate_gain_per_s * (q_cmd - q) + (jx - jz) * p * r,
            jz * c.yaw_rate_gain_per_s * (r_cmd - r) + (jy - jx) * p * q,
        )
        thrusts = self.mixer.motor_thrusts_n(collective, torque)
        self.last_pwm_us = self.mixer.pwm_us(thrusts)
        return self.last_pwm_us
