"""``bench tension``: a step of tension through both tension filters (Martins 2019, figs 5-7).

Two sources of readings, both fed to a constant-model and a derivative-model
:class:`~tether_companion.estimation.tension_kf.TensionEstimator` side by side:

* ``synthetic`` (Martins' set-up: readings of a drone in force balance passed through additive
  white Gaussian noise): accelerometer, attitude and PWM of a hovering drone whose cable force
  steps on the north axis. Settling time is measured on a noise-free copy of the run (the
  filters are linear, so that is the mean response); the steady-state standard deviation on
  the noisy run, after the settling.
* ``sim``: the offline simulator hovering on the paper's constant-tension winch, whose tension
  steps (the drone reacts, the motors lag, the sensors are noisy as configured). Settling and
  standard deviation are measured on the error against the simulator's true cable force.

Settling time: from the step until the estimate stays within 5 % of the step size of the
final value (``synthetic``), or within 10 % of the step of the truth (``sim``, where the noise
is also in the data). ``--sweep`` prints the trade-off between the two for several process
noises of each model.
"""

from __future__ import annotations

import argparse
import dataclasses
import math

import numpy as np
from numpy.typing import NDArray
from rich.console import Console
from rich.table import Table

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.tension_kf import (
    CONSTANT,
    DERIVATIVE,
    TensionEstimator,
    TensionFilterConfig,
)
from tether_companion.frames import rotation_ned_to_body
from tether_companion.physics.cable import CableConfig
from tether_companion.physics.vehicle import VehicleProfile, load_vehicle
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample
from tether_companion.sim.scenario import load_scenario
from tether_companion.sim.simulator import Simulator

FloatArray = NDArray[np.float64]

HELP = "Step of tension through the constant and derivative tension filters (Martins figs 5-7)."

MODELS = (CONSTANT, DERIVATIVE)
RATE_HZ = 200.0
SWEEP_NOISE_N2: dict[str, tuple[float, ...]] = {
    CONSTANT: (1e-5, 3e-5, 1e-4, 3e-4, 1e-3),
    DERIVATIVE: (1e-7, 3e-7, 1e-6, 3e-6, 1e-5),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``bench tension``."""
    parser.add_argument("--step-n", type=float, default=1.0, help="tension step [N] (default 1)")
    parser.add_argument("--seed", type=int, default=1, help="noise seed (default 1)")
    parser.add_argument(
        "--source",
        choices=("synthetic", "sim", "both"),
        default="both",
        help="readings from AWGN on an equilibrium (synthetic), the simulator, or both",
    )
    parser.add_argument("--sweep", action="store_true", help="also sweep the process noise")


# ---------------------------------------------------------------------------------------------
# readings


def equilibrium_readings(
    vehicle: VehicleProfile, cable_ned_n: FloatArray
) -> tuple[FloatArray, float, float, float]:
    """Specific force (body), roll, pitch [rad] and total thrust [N] of a drone at rest.

    The thrust balances weight and cable (yaw 0); the accelerometer reads (thrust + cable)/m.
    """
    mass = vehicle.mass_kg
    thrust_ned = -(np.array((0.0, 0.0, mass * GRAVITY_MPS2)) + cable_ned_n)
    thrust = float(np.linalg.norm(thrust_ned))
    z_body = -thrust_ned / thrust  # body z (down) in NED = (cr sp, -sr, cr cp) at yaw 0
    roll = math.asin(-z_body[1])
    pitch = math.atan2(z_body[0], z_body[2])
    specific_force_ned = (thrust_ned + cable_ned_n) / mass
    return rotation_ned_to_body(roll, pitch, 0.0) @ specific_force_ned, roll, pitch, thrust


def synthetic_run(
    config: TensionFilterConfig,
    vehicle: VehicleProfile,
    step_n: float,
    rng: np.random.Generator | None,
    *,
    before_s: float = 5.0,
    after_s: float = 20.0,
    accel_std_mps2: float = 0.1,
    attitude_std_rad: float = math.radians(0.1),
    thrust_std_n: float = 0.05,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(time [s], truth north force [N], estimated north force [N]); noise-free if no rng."""
    n_before, n_after = int(before_s * RATE_HZ), int(after_s * RATE_HZ)
    base = np.array((-2.0, 0.0, 3.0))  # a cable pulling toward an anchor to the south, down
    estimator = TensionEstimator(config, vehicle, thrust_input=_ExactThrust())
    times = np.arange(n_before + n_after) / RATE_HZ
    truth = np.where(np.arange(times.size) < n_before, base[0], base[0] + step_n)
    estimate = np.empty_like(times)
    readings = {}
    for k, t in enumerate(times):
        cable = base.copy()
        cable[0] = truth[k]
        key = float(cable[0])
        if key not in readings:
            readings[key] = equilibrium_readings(vehicle, cable)
        f_body, roll, pitch, thrust = readings[key]
        if rng is not None:
            f_body = f_body + rng.normal(0.0, accel_std_mps2, 3)
            roll += rng.normal(0.0, attitude_std_rad)
            pitch += rng.normal(0.0, attitude_std_rad)
            thrust += rng.normal(0.0, thrust_std_n)
        estimator.on_attitude(AttitudeSample(t, roll, pitch, 0.0))
        estimator.on_pwm(PwmSample(t, np.array((thrust,))))
        out = estimator.on_imu(ImuSample(t, f_body, np.zeros(3)))
        estimate[k] = out.tension_ned_n[0] if out is not None else math.nan
    return times, truth, estimate


class _ExactThrust:
    """A ThrustInput whose single 'PWM' channel carries the total thrust [N] (synthetic runs)."""

    def total_thrust_n(self, pwm_us: FloatArray, time_s: float) -> float:
        """The total thrust [N] passed through unchanged."""
        return float(pwm_us[0])


def sim_run(
    configs: dict[str, TensionFilterConfig], step_n: float, seed: int
) -> tuple[FloatArray, FloatArray, dict[str, FloatArray], float]:
    """Hover on the constant-tension winch, step its tension by ``step_n`` at 10 s.

    Returns (time [s], true cable north force [N], estimated north force per model [N], step
    time [s]).
    """
    base = load_scenario("hover")
    step_s, duration_s = 10.0, 30.0
    scenario = dataclasses.replace(
        base,
        cable=CableConfig(model="constant_tension", tension_n=4.0),
        events=(),
        duration_s=duration_s,
        seed=seed,
    )
    sim = Simulator(scenario)
    estimators = {name: TensionEstimator(cfg, sim.vehicle) for name, cfg in configs.items()}
    n = int(duration_s * RATE_HZ)
    times, truth = np.empty(n), np.empty(n)
    estimates = {name: np.empty(n) for name in configs}
    for k in range(n):
        t = (k + 1) / RATE_HZ
        if abs(t - step_s) < 0.5 / RATE_HZ:
            sim.set_tension_n(4.0 + step_n)
        sim.advance_to(t)
        attitude, pwm, imu = sim.read_attitude(), sim.read_pwm(), sim.read_imu()
        times[k], truth[k] = sim.time_s, sim.truth.cable_force_ned_n[0]
        for name, est in estimators.items():
            est.on_attitude(attitude)
            est.on_pwm(pwm)
            out = est.on_imu(imu)
            estimates[name][k] = out.tension_ned_n[0] if out is not None else math.nan
    return times, truth, estimates, step_s


# ---------------------------------------------------------------------------------------------
# metrics


def settling_time_s(
    times: FloatArray, reference: FloatArray, estimate: FloatArray, step_s: float, band: float
) -> float:
    """Time from ``step_s`` until ``|estimate - reference|`` stays within ``band`` [s]."""
    after = times >= step_s
    outside = np.nonzero(after & ~(np.abs(estimate - reference) <= band))[0]
    if outside.size == 0:
        return 0.0
    last = outside[-1]
    return math.inf if last == times.size - 1 else float(times[last + 1] - step_s)


def steady_std(times: FloatArray, error: FloatArray, from_s: float) -> float:
    """Standard deviation of ``error`` after ``from_s`` [same unit]."""
    return float(np.std(error[times >= from_s]))


def synthetic_metrics(
    config: TensionFilterConfig, vehicle: VehicleProfile, step_n: float, seed: int
) -> tuple[float, float, float]:
    """(settling time [s], steady std [N], overshoot [N]) of one model on the synthetic step."""
    times, truth, clean = synthetic_run(config, vehicle, step_n, None)
    step_s = 5.0
    final = truth[-1]
    settle = settling_time_s(times, np.full_like(clean, final), clean, step_s, 0.05 * abs(step_n))
    overshoot = float(max(0.0, np.max(np.sign(step_n) * (clean[times >= step_s] - final))))
    _, _, noisy = synthetic_run(config, vehicle, step_n, np.random.default_rng(seed))
    std = steady_std(times, noisy - clean, step_s + 5.0)
    return settle, std, overshoot


def _configs(base: TensionFilterConfig) -> dict[str, TensionFilterConfig]:
    return {name: dataclasses.replace(base, model=name) for name in MODELS}


def run(args: argparse.Namespace) -> int:
    """Print settling times and steady-state standard deviations of both models."""
    console = Console()
    vehicle = load_vehicle("default-quad")
    configs = _configs(TensionFilterConfig())
    table = Table(title=f"tension step of {args.step_n:g} N on the north axis, filters at 200 Hz")
    columns = ("source", "model", "process noise (N^2/step)", "settling (s)", "steady std (N)")
    for column in columns:
        table.add_column(column)
    noise = {
        CONSTANT: configs[CONSTANT].constant_process_noise_n2,
        DERIVATIVE: configs[DERIVATIVE].derivative_process_noise_n2,
    }
    if args.source in ("synthetic", "both"):
        for name, cfg in configs.items():
            settle, std, _ = synthetic_metrics(cfg, vehicle, args.step_n, args.seed)
            table.add_row("synthetic", name, f"{noise[name]:.0e}", f"{settle:.3f}", f"{std:.4f}")
    if args.source in ("sim", "both"):
        times, truth, estimates, step_s = sim_run(configs, args.step_n, args.seed)
        for name, estimate in estimates.items():
            settle = settling_time_s(times, truth, estimate, step_s, 0.1 * abs(args.step_n))
            std = steady_std(times, estimate - truth, step_s + 5.0)
            table.add_row("sim", name, f"{noise[name]:.0e}", f"{settle:.3f}", f"{std:.4f}")
    console.print(table)
    if args.sweep:
        sweep = Table(title="trade-off (synthetic): process noise vs settling and noise")
        for column in ("model", "process noise (N^2/step)", "settling (s)", "steady std (N)"):
            sweep.add_column(column)
        for name, values in SWEEP_NOISE_N2.items():
            key = f"{name}_process_noise_n2"
            for q in values:
                cfg = dataclasses.replace(configs[name], **{key: q})
                settle, std, _ = synthetic_metrics(cfg, vehicle, args.step_n, args.seed)
                sweep.add_row(name, f"{q:.0e}", f"{settle:.3f}", f"{std:.4f}")
        console.print(sweep)
    return 0
