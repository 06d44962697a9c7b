"""``bench sysid``: fly -> identify -> estimate, and what the identified thrust model is worth.

1. The section 5.1 identification flight is flown in the simulator (slack tether) and
   recorded as a .tlog (or ``--log`` gives a recorded flight);
2. every structure is identified from it (Table 1 printed);
3. the paper scenario (``paper-circle``: 2.5 m circle at 1 m/s, 4 N winch, sensors at 200 Hz,
   60 s) is flown with the 4-state EKF fed by three thrust inputs in turn:
   a naive linear map (the paper's eq. 19, ``f = k cmd`` per motor with ``k`` fitted by least
   squares on the same identification data), the identified model (the one ``sysid --out``
   writes, :mod:`tether_companion.sysid.selection`), the one the old rule (best simulation
   Fit%) picked, and, for reference, the vehicle's true static curve;
4. position and tension RMSE per axis (mean over seeds) and the thrust RMSE against the
   simulator's true rotor thrust are printed for each.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from tether_companion.errors import InputError
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.pipeline import TetherEstimator
from tether_companion.estimation.thrust_input import StaticThrustInput, ThrustInput
from tether_companion.physics.thrust import ThrustCurve
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.scenario import Scenario, load_scenario
from tether_companion.sim.simulator import Simulator
from tether_companion.sysid.flight import record_identification_flight
from tether_companion.sysid.identify import best_result, identify
from tether_companion.sysid.logs import load_flight_log
from tether_companion.sysid.processing import IdData, prepare
from tether_companion.sysid.report import results_table
from tether_companion.sysid.selection import select
from tether_companion.sysid.thrust_model import StaticModelFile, thrust_input_from_mapping

HELP = "Identify a thrust model from an emulated flight; EKF RMSE with it vs a naive linear map."

AXES = ("north_m", "east_m", "down_m")


class RecordingThrust:
    """Wraps a :class:`ThrustInput` and keeps its last output [N] for error statistics."""

    def __init__(self, inner: ThrustInput) -> None:
        self.inner = inner
        self.last_n = float("nan")

    def total_thrust_n(self, pwm_us: np.ndarray, time_s: float) -> float:
        """The wrapped input's thrust [N], remembered."""
        self.last_n = self.inner.total_thrust_n(pwm_us, time_s)
        return self.last_n


def naive_linear_curve(estimation: list[IdData], pwm_range_us: tuple[float, float]) -> ThrustCurve:
    """Eq. 19 of the paper, ``f = k cmd`` per motor, ``k`` by least squares [N per unit cmd]."""
    command = np.concatenate([e.command.sum(axis=1) for e in estimation])
    thrust = np.concatenate([e.thrust_n for e in estimation])
    k = float(command @ thrust / (command @ command))
    return ThrustCurve(
        pwm_min_us=pwm_range_us[0], pwm_max_us=pwm_range_us[1], coefficients_n=(0.0, k, 0.0)
    )


def run_four_state(scenario: Scenario, thrust: ThrustInput, seed: int) -> dict[str, float]:
    """Fly ``scenario`` with the 4-state EKF on ``thrust``; RMSE of position, tension, thrust.

    Every sensor is read at the IMU rate (the paper scenario's sensors all run at 200 Hz),
    attitude and PWM before the IMU sample that uses them.
    """
    sim = Simulator(scenario, rng=np.random.default_rng(seed))
    recorder = RecordingThrust(thrust)
    config = dataclasses.replace(EstimatorConfig(), kind="four_state")
    estimator = TetherEstimator(config, sim.vehicle, thrust_input=recorder)
    period = 1.0 / scenario.sensors.imu_rate_hz
    position_err, tension_err, thrust_err = [], [], []
    for k in range(1, int(scenario.duration_s / period) + 1):
        sim.advance_to(k * period)
        estimator.on_attitude(sim.read_attitude())
        estimator.on_pwm(sim.read_pwm())
        reading = sim.read_rangefinder()
        if reading is not None:
            estimator.on_range(reading)
        estimate = estimator.on_imu(sim.read_imu())
        truth = sim.truth
        thrust_err.append(recorder.last_n - float(np.sum(truth.motor_thrust_n)))
        if estimate is not None:
            position_err.append(estimate.position_ned_m - truth.position_ned_m)
            tension_err.append(estimate.tension_n - truth.tension_n)
    errors = np.array(position_err)
    result = {axis: float(np.sqrt(np.mean(errors[:, i] ** 2))) for i, axis in enumerate(AXES)}
    result["tension_n"] = float(np.sqrt(np.mean(np.square(tension_err))))
    result["thrust_n"] = float(np.sqrt(np.nanmean(np.square(thrust_err))))
    return result


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Flight source, scenario and seeds."""
    parser.add_argument("--log", type=Path, help="identify from this log instead of flying one")
    parser.add_argument(
        "--flight-seed", type=int, default=0, help="noise seed of the identification flight"
    )
    parser.add_argument(
        "--scenario", default="paper-circle", help="estimation scenario (name or path)"
    )
    parser.add_argument("--seeds", type=int, default=3, help="estimation runs per thrust input")


def run(args: argparse.Namespace) -> int:
    """Identify, then run the EKF with each thrust input; print both tables."""
    console = Console()
    if args.seeds < 1:
        raise InputError(f"--seeds must be >= 1, got {args.seeds}")
    scenario = load_scenario(args.scenario)
    with tempfile.TemporaryDirectory() as folder:
        log_path = args.log
        if log_path is None:
            log_path = Path(folder) / "identification.tlog"
            vehicle = record_identification_flight(log_path, seed=args.flight_seed).vehicle
            console.print(
                f"identification flight: simulated, seed {args.flight_seed}, vehicle {vehicle.name}"
            )
        else:
            vehicle = load_vehicle(scenario.vehicle)
        curve = vehicle.thrust_curve
        pwm_range = (curve.pwm_min_us, curve.pwm_max_us)
        data = prepare(load_flight_log(log_path), vehicle.mass_kg, pwm_range)
    results = identify([data.estimation], [data.validation], pwm_range)
    chosen, scores = select(results, [data.validation], pwm_range)
    by_fit = best_result(results, "simulation")
    best = best_result(results, "prediction")
    console.print(
        results_table(
            results,
            5,
            best.structure if best else None,
            chosen.structure if chosen else None,
            scores=scores,
        )
    )
    if chosen is None:
        console.print("[red]no structure could be identified[/red]")
        return 1
    inputs = {
        "naive linear (eq. 19)": lambda: StaticThrustInput(
            StaticModelFile(
                n_motors=vehicle.n_motors,
                thrust_curve=naive_linear_curve([data.estimation], pwm_range),
            )
        ),
        f"identified, written ({chosen.structure})": lambda: thrust_input_from_mapping(
            chosen.model.to_mapping()
        ),
        f"best simulation Fit%, the old rule ({by_fit.structure})": lambda: (
            thrust_input_from_mapping(by_fit.model.to_mapping())
        ),
        "true static curve": lambda: StaticThrustInput(vehicle),
    }
    table = Table(title=f"4-state EKF on {args.scenario}: RMSE, mean of {args.seeds} seeds")
    table.add_column("Thrust input")
    for column in ("North [m]", "East [m]", "Down [m]", "Tension [N]", "Thrust [N]"):
        table.add_column(escape(column), justify="right")
    for name, make in inputs.items():
        runs = [run_four_state(scenario, make(), seed) for seed in range(1, args.seeds + 1)]
        means = {
            key: float(np.mean([r[key] for r in runs])) for key in (*AXES, "tension_n", "thrust_n")
        }
        table.add_row(name, *(f"{means[key]:.3f}" for key in (*AXES, "tension_n", "thrust_n")))
    console.print(table)
    return 0
