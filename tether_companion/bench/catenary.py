"""``bench catenary``: position from tension and catenary vs the 4-state EKF on a heavy cable.

The simulator flies on its catenary cable (a heavy elastic cable hanging as a catenary, lying
on the ground near the anchor when slack; ``physics/cable.py``). Two estimators run on the
same sensor stream at 200 Hz:

* ``4-state EKF``: :class:`~tether_companion.estimation.pipeline.TetherEstimator` with the
  default configuration (straight-cable model: the pull is along the anchor-drone line);
* ``catenary``: :class:`~tether_companion.estimation.tension_kf.TensionEstimator` (derivative
  model) followed by
  :class:`~tether_companion.estimation.catenary_position.CatenaryPositionEstimator` (known
  length: the winch's paid-out length, anchor on the ground).

Two flights: ``hover`` (the ``catenary-hover`` scenario without its winch events) and
``circle`` (the paper's circle, 2.5 m radius at 1 m/s around the anchor, altitude 1.5-2.5 m,
on a 3.7 m catenary cable). RMSE per axis after a warm-up; ticks where an estimator has no
position are counted, not scored. Then the tension-based position control table
(:func:`~tether_companion.sim.tension_control.control_table`, section 5.2).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from rich.console import Console
from rich.table import Table

from tether_companion.estimation.catenary_position import (
    KNOWN_LENGTH,
    CatenaryPositionConfig,
    CatenaryPositionEstimator,
)
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.pipeline import TetherEstimator
from tether_companion.estimation.tension_kf import TensionEstimator, TensionFilterConfig
from tether_companion.physics.cable import CableConfig
from tether_companion.sim.scenario import Scenario, load_scenario
from tether_companion.sim.simulator import Simulator
from tether_companion.sim.tension_control import control_table

FloatArray = NDArray[np.float64]

HELP = "Position from tension + catenary vs the 4-state EKF on the simulator's catenary cable."

AXES = ("north", "east", "down")
WARMUP_S = 5.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``bench catenary``."""
    parser.add_argument("--seed", type=int, default=1, help="simulator seed (default 1)")
    parser.add_argument(
        "--flight",
        choices=("hover", "circle", "both"),
        default="both",
        help="which flight to run (default both)",
    )
    parser.add_argument(
        "--duration-s", type=float, default=None, help="override the flight duration [s]"
    )
    parser.add_argument(
        "--no-control",
        action="store_true",
        help="skip the tension-based position control table (section 5.2)",
    )


def flight(name: str, seed: int, duration_s: float | None = None) -> Scenario:
    """The ``hover`` or ``circle`` flight on a catenary cable."""
    if name == "hover":
        scenario = dataclasses.replace(load_scenario("catenary-hover"), events=())
    else:
        base = load_scenario("paper-circle")
        hover = load_scenario("catenary-hover")
        scenario = dataclasses.replace(
            base, cable=dataclasses.replace(hover.cable, length_m=3.7), events=()
        )
    scenario = dataclasses.replace(scenario, seed=seed)
    if duration_s is not None:
        scenario = dataclasses.replace(scenario, duration_s=duration_s)
    return scenario


@dataclass(frozen=True)
class Comparison:
    """RMSE per axis [m] of each estimator, and ticks without a position."""

    rmse_ekf_m: FloatArray
    rmse_catenary_m: FloatArray
    missing_ekf: int
    missing_catenary: int
    ticks: int


def _cable_weight_n_per_m(cable: CableConfig, gravity_mps2: float) -> float:
    return cable.linear_density_kg_per_m * gravity_mps2


def compare(scenario: Scenario) -> Comparison:
    """Fly ``scenario`` and score both estimators against the truth."""
    sim = Simulator(scenario)
    vehicle = sim.vehicle
    ekf = TetherEstimator(EstimatorConfig(), vehicle)
    tension = TensionEstimator(TensionFilterConfig(), vehicle)
    catenary = CatenaryPositionEstimator(
        CatenaryPositionConfig(
            case=KNOWN_LENGTH,
            weight_per_length_n_per_m=_cable_weight_n_per_m(scenario.cable, sim.gravity_mps2),
            anchor_on_ground=True,
        )
    )
    rate_hz = scenario.sensors.imu_rate_hz
    n = int(scenario.duration_s * rate_hz)
    err_ekf = np.full((n, 3), math.nan)
    err_cat = np.full((n, 3), math.nan)
    times = np.empty(n)
    for k in range(n):
        t = (k + 1) / rate_hz
        sim.advance_to(t)
        attitude, pwm, imu = sim.read_attitude(), sim.read_pwm(), sim.read_imu()
        reading = sim.read_rangefinder()
        truth = sim.truth.position_ned_m
        times[k] = sim.time_s
        for est in (ekf, tension):
            est.on_attitude(attitude)
            est.on_pwm(pwm)
        if reading is not None:
            ekf.on_range(reading)
        estimate = ekf.on_imu(imu)
        if estimate is not None:
            err_ekf[k] = estimate.position_ned_m - truth
        tension_estimate = tension.on_imu(imu)
        catenary.set_paid_out_length_m(sim.cable.paid_out_m, sim.time_s)
        if tension_estimate is not None:
            position = catenary.on_tension(tension_estimate)
            if position.valid:
                err_cat[k] = position.position_ned_m - truth
    scored = times >= WARMUP_S

    def rmse(err: FloatArray) -> FloatArray:
        rows = err[scored]
        rows = rows[np.isfinite(rows).all(axis=1)]
        return np.sqrt(np.mean(rows**2, axis=0)) if rows.size else np.full(3, math.nan)

    def missing(err: FloatArray) -> int:
        return int((~np.isfinite(err[scored]).all(axis=1)).sum())

    return Comparison(
        rmse(err_ekf), rmse(err_cat), missing(err_ekf), missing(err_cat), int(scored.sum())
    )


def run(args: argparse.Namespace) -> int:
    """Print the RMSE table (and the tension-based control table)."""
    console = Console()
    table = Table(
        title=f"position RMSE on a catenary cable, m (after {WARMUP_S:g} s, seed {args.seed})"
    )
    for column in ("flight", "estimator", *AXES, "ticks without position"):
        table.add_column(column)
    names = ("hover", "circle") if args.flight == "both" else (args.flight,)
    for name in names:
        result = compare(flight(name, args.seed, args.duration_s))
        for label, values, missing in (
            ("4-state EKF", result.rmse_ekf_m, result.missing_ekf),
            ("catenary", result.rmse_catenary_m, result.missing_catenary),
        ):
            table.add_row(name, label, *(f"{v:.3f}" for v in values), f"{missing}/{result.ticks}")
    console.print(table)
    if not args.no_control:
        console.print(control_table(seed=args.seed))
    return 0
