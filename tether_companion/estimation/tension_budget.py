"""Error budget of the tension observation: what eq. 50 leaves out, as a consider covariance.

The tension filter (:mod:`~tether_companion.estimation.tension_kf`) observes the cable's force
on the drone as ``F_obs = R (m f + T_hat e_z)`` (Martins 2019 eq. 50 in our frames: ``f`` the
accelerometer's specific force, FRD; ``T_hat`` the thrust the motor outputs give through the
profile's map; ``R`` the flight controller's body-to-NED attitude). The accelerometer feels
every force but gravity, so with the true thrust ``T``, the cable force ``F_c``, the airframe's
drag ``F_d``, the accelerometer's bias ``b`` and white noise ``n``, and the attitude error
``dtheta`` (``R = R_true exp([dtheta]x)``)::

    F_obs - F_c =  F_d                    (drag: rotor drag and body drag, body-horizontal)
                 - (T - T_hat) b3         (thrust-map error along the body's down axis b3)
                 + m R b                  (accelerometer bias)
                 + dtheta x F             (attitude error, F = F_c + F_d)
                 + m R n                  (white noise: what the filter's R models)

Only the last term is white. The others change over seconds to minutes (wind, battery sag,
bias random walk, the FC's attitude error: a Gauss-Markov process with a time constant of
tens of seconds), much slower than the filter's smoothing (a tenth of a second at 200 Hz), so
the filter passes them through unattenuated: they are biases of the estimate, which a
variance computed from the white noise alone ignores (the cause of NEES 200-15000 on the
realistic scorecard). They are neither estimated nor modelled; they enter as a *consider*
covariance added to the filter's (Tapley, Schutz & Born 2004, sec. 6.3; Schmidt's consider
filter), each term from the value that sets its size:

==================  ==============================  =====================================
term                1-sigma columns, NED [N]        from (``tension_filter.*``, profile)
==================  ==============================  =====================================
thrust map          ``s_T T_hat b3``                ``thrust_scale_std``
drag                ``s_D b1``, ``s_D b2``          ``air_speed_std_mps``; the profile's
                                                    ``rotor_drag_per_s``,
                                                    ``ballistic_coefficient_kg_per_m2``,
                                                    ``drag_coefficient_n_s_per_m``
accelerometer bias  ``m s_b`` on each NED axis      ``accel_bias_std_mps2``; ``mass_kg``
attitude            ``s_theta [F]x`` (3 columns)    ``attitude_error_std_rad``
==================  ==============================  =====================================

with ``b1, b2, b3`` the body axes in NED (the rows of ``R_v^b``). The drag's size: the body-
horizontal air velocity ``v`` per axis is unknown (wind plus flight speed), taken as
``N(0, s_v^2)``; the drag per axis is ``m (mu v + k v |v|) + c v`` (rotor drag ``mu``, body drag
``k = rho / (2 B)``, legacy linear drag ``c``), whose second moment is exactly

    s_D^2 = (m mu + c)^2 s_v^2 + 4 sqrt(2/pi) (m mu + c) m k s_v^3 + 3 (m k)^2 s_v^4

(``E|v|^3 = 2 sqrt(2/pi) s_v^3``, ``E v^4 = 3 s_v^4``). The vertical air speed is ignored (rotor
drag has no vertical part; body drag's is small at hover). The covariance of the estimate is

    Sigma_F = s_kf^2 I + G G^T,   G = [s_T T_hat b3, s_D b1, s_D b2, s_theta [F]x]

with ``s_kf^2`` the filter's variance plus ``(m s_b)^2``: symmetric positive definite by
construction, and the factor ``G`` is what the catenary estimator maps through its Jacobian.
Pure functions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tether_companion.physics.aerodynamics import AIR_DENSITY_KG_M3
from tether_companion.physics.vehicle import VehicleProfile

BUDGET_COLUMNS = 6
"""Columns of the consider factor: thrust, drag along b1, drag along b2, attitude x3."""


def drag_force_std_n(vehicle: VehicleProfile, air_speed_std_mps: float) -> float:
    """``s_D`` [N]: standard deviation of the drag force on one body-horizontal axis for an
    air velocity ``N(0, air_speed_std_mps^2)`` on that axis (module docstring)."""
    s = air_speed_std_mps
    linear = vehicle.mass_kg * vehicle.rotor_drag_per_s + vehicle.drag_coefficient_n_s_per_m
    b = vehicle.ballistic_coefficient_kg_per_m2
    quadratic = vehicle.mass_kg * 0.5 * AIR_DENSITY_KG_M3 / b if b > 0.0 else 0.0
    second_moment = (
        linear**2 * s**2
        + 4.0 * math.sqrt(2.0 / math.pi) * linear * quadratic * s**3
        + 3.0 * quadratic**2 * s**4
    )
    return math.sqrt(second_moment)


@dataclass(frozen=True, slots=True)
class TensionErrorBudget:
    """The sizes of the unmodelled terms of eq. 50 (module docstring).

    Attributes
    ----------
    thrust_scale_std
        ``s_T``: relative standard deviation of the thrust map [-].
    drag_force_std_n
        ``s_D``: drag force per body-horizontal axis [N].
    bias_force_std_n
        ``m s_b``: accelerometer bias times mass, per axis [N].
    attitude_error_std_rad
        ``s_theta``: the flight controller's attitude error per axis [rad].
    """

    thrust_scale_std: float
    drag_force_std_n: float
    bias_force_std_n: float
    attitude_error_std_rad: float

    @classmethod
    def of(
        cls,
        vehicle: VehicleProfile,
        thrust_scale_std: float,
        air_speed_std_mps: float,
        accel_bias_std_mps2: float,
        attitude_error_std_rad: float,
    ) -> TensionErrorBudget:
        """The budget of ``vehicle`` (mass, drag coefficients) with these error sizes."""
        return cls(
            thrust_scale_std=thrust_scale_std,
            drag_force_std_n=drag_force_std_n(vehicle, air_speed_std_mps),
            bias_force_std_n=vehicle.mass_kg * accel_bias_std_mps2,
            attitude_error_std_rad=attitude_error_std_rad,
        )

    def factor(
        self,
        rotation_rows: list[list[float]],
        thrust_n: float,
        force_ned_n: tuple[float, float, float] | list[float],
    ) -> list[float]:
        """``G`` (3 x :data:`BUDGET_COLUMNS`, row-major, NED [N]) at one tick.

        Parameters
        ----------
        rotation_rows
            ``R_v^b`` (NED to body) row by row: row ``i`` is body axis ``i`` in NED.
        thrust_n
            The modelled total thrust ``T_hat`` [N].
        force_ned_n
            The estimated force on the drone, NED [N] (the attitude term rotates it).
        """
        (b10, b11, b12), (b20, b21, b22), (b30, b31, b32) = rotation_rows
        st = self.thrust_scale_std * thrust_n
        sd = self.drag_force_std_n
        sa = self.attitude_error_std_rad
        fn, fe, fd = force_ned_n
        # [F]x: the cross-product matrix, dtheta x F = -[F]x dtheta; the sign does not matter
        return [
            st * b30, sd * b10, sd * b20, 0.0, -sa * fd, sa * fe,
            st * b31, sd * b11, sd * b21, sa * fd, 0.0, -sa * fn,
            st * b32, sd * b12, sd * b22, -sa * fe, sa * fn, 0.0,
        ]  # fmt: skip
