"""``bench vehicle``: the estimator with ``vehicle: from_autopilot`` and only the mass, against
the true profile, on the '+' quad with ArduPilot's curve, the hexa X and the octa X.

For each vehicle the emulator's physics flies the scenario (default ``paper-circle`` with that
vehicle); the 4-state EKF runs on its sensors three times per seed, given:

* the true profile (the simulated vehicle's);
* the profile built from the ArduPilot parameters the emulator answers for that vehicle
  (``FRAME_CLASS``, ``FRAME_TYPE``, ``MOT_*``; :mod:`tether_companion.vehicle_params`) and
  the mass alone (every other key from the default profile);
* the same with ``MOT_THST_HOVER`` 5 % high (a hover throttle learned while the tether pulled
  down, or not yet converged): the sensitivity of the result to the one learned parameter.

It prints the 3-D position RMSE after the first 5 s (mean over seeds) and the ratio to the
true profile's.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
from rich.console import Console
from rich.table import Table

from tether_companion.errors import InputError
from tether_companion.estimation.config import load_estimator_config
from tether_companion.estimation.runner import run_scenario
from tether_companion.physics.vehicle import VehicleProfile, load_vehicle
from tether_companion.sim.scenario import load_scenario
from tether_companion.vehicle_params.emulated import ardupilot_parameters
from tether_companion.vehicle_params.profile import profile_from_parameters

HELP = "EKF RMSE with vehicle: from_autopilot (mass only) vs the true profile, per frame."

VEHICLES = ("ardupilot-sitl-plus", "hexa-x", "octa-x")
SETTLE_S = 5.0
HOVER_ERROR = 1.05


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Scenario, seeds, vehicles."""
    parser.add_argument("--scenario", default="paper-circle", help="scenario (name or path)")
    parser.add_argument("--seeds", type=int, default=2, help="runs per profile")
    parser.add_argument("--duration-s", type=float, default=30.0, help="flight length [s]")
    parser.add_argument(
        "--vehicle", action="append", help=f"vehicle profile (repeat; default {VEHICLES})"
    )


def profiles(true: VehicleProfile) -> dict[str, VehicleProfile]:
    """The three profiles the estimator is given (module docstring)."""
    params = ardupilot_parameters(true)
    learned = {**params, "MOT_THST_HOVER": params["MOT_THST_HOVER"] * HOVER_ERROR}
    return {
        "true profile": true,
        "from_autopilot": profile_from_parameters(params, true.mass_kg),
        "from_autopilot, hover +5 %": profile_from_parameters(learned, true.mass_kg),
    }


def rmse_3d_m(scenario, vehicle: VehicleProfile, seed: int) -> float:
    """3-D position RMSE [m] of the 4-state EKF after :data:`SETTLE_S`."""
    config = load_estimator_config(None)
    result = run_scenario(
        dataclasses.replace(scenario, seed=seed), config, estimator_vehicle=vehicle
    )
    late = result.time_s > SETTLE_S
    error = result.position_4s_ned_m[late] - result.truth_position_ned_m[late]
    ok = np.all(np.isfinite(error), axis=1)
    return float(np.sqrt(np.mean(np.sum(error[ok] ** 2, axis=1))))


def run(args: argparse.Namespace) -> int:
    """Fly each vehicle, print the table."""
    if args.seeds < 1 or not args.duration_s > SETTLE_S:
        raise InputError(f"--seeds must be >= 1 and --duration-s > {SETTLE_S}")
    console = Console()
    base = load_scenario(args.scenario)
    table = Table(
        title=f"4-state EKF on {args.scenario} ({args.duration_s:g} s), 3-D RMSE after "
        f"{SETTLE_S:g} s, mean of {args.seeds} seeds"
    )
    for column in ("vehicle", "estimator's profile", "RMSE [m]", "/ true"):
        table.add_column(column, justify="left" if column.startswith(("v", "e")) else "right")
    for name in args.vehicle or VEHICLES:
        true = load_vehicle(name)
        scenario = dataclasses.replace(base, vehicle=name, duration_s=args.duration_s)
        reference = None
        for label, profile in profiles(true).items():
            rmse = float(
                np.mean([rmse_3d_m(scenario, profile, seed) for seed in range(1, args.seeds + 1)])
            )
            reference = rmse if reference is None else reference
            table.add_row(name, label, f"{rmse:.4f}", f"{rmse / reference:.3f}")
    console.print(table)
    return 0
