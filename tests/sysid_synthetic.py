"""Synthetic identification data with a known truth, shared by the sysid tests.

Not a test module (no ``test_`` prefix): helpers that build :class:`IdData` from a known ARX
system or from known motors (the vehicle profile's quadratic curve and first-order lag,
decaying as ``physics.motors.MotorLag``), so the tests can check what is recovered.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from tether_companion.physics.motors import MotorLag
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.sysid.processing import IdData, lowpass, normalised_command

ARX_A = np.array([1.0, -1.5, 0.6])
"""Known ARX denominator (poles 0.75 +- 0.19j)."""
ARX_B = np.array(
    [[0.0, 0.010, 0.005], [0.0, 0.012, 0.004], [0.0, 0.008, 0.006], [0.0, 0.011, 0.003]]
)
"""Known ARX numerators, one row per input, nk = 1, nb = 2."""


def id_data(
    pwm_us: np.ndarray, thrust_n: np.ndarray, dt_s: float, pwm_range=(1000.0, 2000.0)
) -> IdData:
    """IdData from (already filtered or noise-free) PWM and thrust."""
    cmd = normalised_command(pwm_us, pwm_range)
    return IdData(np.arange(len(thrust_n)) * dt_s, pwm_us, cmd, cmd**2, thrust_n, dt_s)


def arx_data(rng: np.random.Generator, n: int = 4000, noise_n: float = 0.01) -> IdData:
    """Data of the known ARX system ``A y = B u + e`` about (1500 us, 10 N), white inputs."""
    u = 1500.0 + 50.0 * rng.standard_normal((n, 4))
    e = noise_n * rng.standard_normal(n)
    y = sum(lfilter(ARX_B[i], ARX_A, u[:, i] - 1500.0) for i in range(4)) + lfilter([1.0], ARX_A, e)
    return id_data(u, 10.0 + y, 0.01)


def motor_flight(
    vehicle: VehicleProfile,
    rng: np.random.Generator,
    duration_s: float = 60.0,
    noise_mps2: float = 0.1,
) -> IdData:
    """Known motors driven by random collective and differential PWM steps.

    Thrust is simulated at 400 Hz (steady-state curve, exact first-order lag), read through
    an accelerometer with white noise, low-passed at 10 Hz (zero phase) and decimated to
    100 Hz, as the processing does.
    """
    dt = 0.0025
    n = int(duration_s / dt)
    hover = float(vehicle.thrust_curve.pwm_for_thrust(vehicle.mass_kg * 9.80665 / 4))
    pwm = np.empty((n, 4))
    level = np.full(4, hover)
    next_change = 0.0
    for k in range(n):
        if k * dt >= next_change:
            level = hover + rng.uniform(-60, 60) + rng.uniform(-30, 30, 4)
            next_change = k * dt + rng.uniform(0.2, 1.0)
        pwm[k] = np.round(level)
    decay = MotorLag(vehicle.motor_time_constant_s).decay(dt)
    thrust = vehicle.thrust_curve.thrust_n(pwm[0])
    total = np.empty(n)
    for k in range(n):
        target = vehicle.thrust_curve.thrust_n(pwm[k])
        thrust = target + (thrust - target) * decay
        total[k] = thrust.sum()
    measured = total + vehicle.mass_kg * noise_mps2 * rng.standard_normal(n)
    cmd = normalised_command(
        pwm, (vehicle.thrust_curve.pwm_min_us, vehicle.thrust_curve.pwm_max_us)
    )
    columns = lowpass(np.column_stack([pwm, cmd, cmd**2, measured]), 1.0 / dt, 10.0, 5)[::4]
    return IdData(
        np.arange(columns.shape[0]) * 0.01,
        columns[:, :4],
        columns[:, 4:8],
        columns[:, 8:12],
        columns[:, 12],
        0.01,
    )


def split(data: IdData, fraction: float = 0.6) -> tuple[IdData, IdData]:
    """Estimation and validation parts."""
    k = int(fraction * len(data))
    return data.part(0, k), data.part(k, len(data))


def log_signals(
    duration_s: float = 40.0, rate_hz: float = 50.0, ground_s: float = 3.0, constant: bool = False
) -> dict[str, np.ndarray]:
    """Signals of a simple flight for log-format tests (all on one clock, SI units).

    On the ground for ``ground_s`` (motors at 1100 us, height 0), then airborne at 1.5 m with
    PWM steps of each motor (unless ``constant``) and a static quadratic thrust
    ``f = 0.5 u + 7.5 u^2`` per motor, accelerometer ``z = -T / 1.5 kg``.
    """
    t = np.arange(int(duration_s * rate_hz)) / rate_hz + 0.5
    airborne = t >= t[0] + ground_s
    pwm = np.full((t.size, 4), 1100.0)
    steps = 40.0 * np.sign(np.sin(2.0 * np.pi * np.outer(t, [0.3, 0.4, 0.5, 0.7])))
    pwm[airborne] = 1668.0 + (0.0 if constant else steps[airborne])
    u = (pwm - 1000.0) / 1000.0
    thrust = np.where(airborne, np.sum(0.5 * u + 7.5 * u * u, axis=1), 1.5 * 9.80665)
    accel = np.column_stack([0.05 * np.sin(t), -0.03 * np.cos(t), -thrust / 1.5])
    euler = np.column_stack([0.02 * np.sin(0.5 * t), -0.01 * np.cos(0.3 * t), 0.1 * t % 3.0])
    height = np.where(airborne, 1.5, 0.0)
    return {"time_s": t, "pwm_us": pwm, "accel_mps2": accel, "euler_rad": euler, "height_m": height}
