"""Posterior Cramer-Rao lower bound of the tether EKF's state along a true trajectory.

Tichavsky, Muravchik & Nehorai (1998), "Posterior Cramer-Rao bounds for discrete-time
nonlinear filtering", IEEE Trans. Signal Processing 46(5): for ``x_{k+1} = f(x_k) + w_k``,
``z_k = h(x_k) + v_k`` with Gaussian ``w ~ N(0, Q_k)``, ``v ~ N(0, R_k)``, the Fisher
information ``J_k`` of the state obeys

    J_{k+1} = D22 - D21 (J_k + D11)^{-1} D12,
    D11 = E[F^T Q^{-1} F],  D12 = D21^T = -E[F^T] Q^{-1},  D22 = Q^{-1} + E[H^T R^{-1} H],

and ``E[(x_hat - x)(x_hat - x)^T] >= J^{-1}`` for every estimator. For the paper's process
model, a random walk (``F = I``, ``Q_k = Q_c dt``), the recursion is the information form of
the Kalman covariance update with the Jacobians taken at the truth:

    P_pred = P_{k} + Q_c dt,   J_{k+1} = P_pred^{-1} + sum_sensors H^T R^{-1} H,   P = J^{-1}.

(With ``F = I``: ``D11 = Q^{-1}``, ``D12 = -Q^{-1}``, and the Woodbury identity turns
``Q^{-1} - Q^{-1} (J_k + Q^{-1})^{-1} Q^{-1}`` into ``(J_k^{-1} + Q)^{-1}``.) The expectations
over the true trajectory are replaced by the values along one simulated trajectory (the usual
"along the true trajectory" bound).

What the bound assumes (and so what it is a bound *for*):

* the filter's process model: a random walk with the estimator's ``Q_c`` and ``P0``
  (``configs/estimator.yaml``). A drone flying a circle does not move as a random walk: the
  bound holds for estimators that assume this model, not for one that knows the dynamics;
* the filter's measurement model: the straight-cable specific force ``h_acc`` of
  :mod:`~tether_companion.estimation.tether_models` with the *true* attitude and thrust, and
  the downward rangefinder over flat ground at the anchor's level
  (``d = -p_d / (cos(roll) cos(pitch))``);
* the sensors' *true* white noise (the scenario's ``accel_noise_std_mps2`` per axis at every
  IMU tick, ``range_noise_std_m`` at every range sample); biases, vibration, drag, wind and
  attitude noise are not in it: the bound says how well the model's own information could
  place the drone, not what the world allows.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.tether_models import FourStateModel, ThreeStateModel
from tether_companion.frames import rotation_ned_to_body

FloatArray = NDArray[np.float64]


def posterior_crlb(
    time_s: FloatArray,
    position_ned_m: FloatArray,
    tension_n: FloatArray,
    euler_rad: FloatArray,
    thrust_n: FloatArray,
    range_seen: NDArray[np.bool_],
    *,
    mass_kg: float,
    accel_std_mps2: float,
    range_std_m: float,
    q_density: FloatArray,
    p0: FloatArray,
    known_tension: bool,
    min_cable_length_m: float = 0.3,
) -> FloatArray:
    """Diagonal of the bound ``J_k^{-1}`` at every tick, shape (N, n): n = 3 (position,
    ``known_tension``) or 4 (position [m^2], tension [N^2]).

    Parameters
    ----------
    time_s
        IMU tick times, shape (N,) [s].
    position_ned_m, tension_n, euler_rad, thrust_n
        True position (N, 3) [m], tension (N,) [N], (roll, pitch, yaw) (N, 3) [rad] and total
        thrust (N,) [N] at each tick.
    range_seen
        Whether a rangefinder sample was taken at (just before) each tick, shape (N,).
    mass_kg
        Vehicle mass in the measurement model [kg].
    accel_std_mps2, range_std_m
        True white-noise sigmas [m/s^2 per axis], [m]; a zero sigma is an exact sensor and is
        refused (infinite information).
    q_density, p0
        The filter's random-walk spectral density ``Q_c`` and initial covariance, (n, n).
    known_tension
        3-state model (tension given) or 4-state (tension unknown).
    min_cable_length_m
        Closer to the anchor the accelerometer carries no information (as in the filter).
    """
    if not (accel_std_mps2 > 0.0 and range_std_m > 0.0):
        raise ValueError(
            f"noise sigmas must be > 0, got accel {accel_std_mps2!r}, range {range_std_m!r}"
        )
    model = (ThreeStateModel if known_tension else FourStateModel)(mass_kg, min_cable_length_m)
    n = model.n
    q_density = np.asarray(q_density, dtype=float)
    covariance = np.asarray(p0, dtype=float).copy()
    if q_density.shape != (n, n) or covariance.shape != (n, n):
        raise ValueError(
            f"Q_c and P0 must be ({n}, {n}); got {q_density.shape}, {covariance.shape}"
        )
    inv_accel_var = 1.0 / accel_std_mps2**2
    inv_range_var = 1.0 / range_std_m**2
    out = np.empty((len(time_s), n))
    state = np.zeros(n)
    previous_s = math.nan
    for k, t in enumerate(time_s):
        if math.isfinite(previous_s):
            covariance = covariance + q_density * (t - previous_s)
        previous_s = t
        information = np.linalg.inv(covariance)
        position = position_ned_m[k]
        roll, pitch, yaw = euler_rad[k]
        if float(position @ position) >= min_cable_length_m**2:
            state[:3] = position
            if not known_tension:
                state[3] = tension_n[k]
            rotation = rotation_ned_to_body(roll, pitch, yaw)
            _, jacobian = model.accel(state, rotation, float(thrust_n[k]), float(tension_n[k]))
            information += inv_accel_var * (jacobian.T @ jacobian)
        if range_seen[k]:
            cos_tilt = math.cos(roll) * math.cos(pitch)
            information[2, 2] += inv_range_var / (cos_tilt * cos_tilt)
        covariance = np.linalg.inv(information)
        covariance = 0.5 * (covariance + covariance.T)
        out[k] = np.diag(covariance)
    return out
