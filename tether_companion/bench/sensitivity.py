"""``bench sensitivity``: how much each vehicle-profile key the estimator reads matters.

The simulator flies a scenario's vehicle as it is; the estimators (scorecard kinds,
:mod:`tether_companion.bench.estimators`) are given that profile with one key changed by a
stated amount (:data:`PERTURBATIONS`), and the horizontal and vertical position RMSE after
:data:`SCORE_FROM_S` is printed beside the unchanged profile's, mean over the seeds. Keys a
datasheet lacks (the thrust scale, i.e. ``MOT_THST_HOVER``; the rotor drag; the motor lag)
are the ones to look at: a large ratio says "identify it" (``sysid``), a ratio near 1 says a
rough value will do.

The realistic scenarios' profile (``realistic-quad``) is itself not the truth
(``propulsion``): their thrust is 5 % below its curve at 4.0 V per cell, but the pack starts
at 4.2 V and sags 0.1 V per cell per minute, so over a 30 s flight the real thrust is 2-5 %
*above* the curve at the same command. A change towards the truth lowers the RMSE; both
signs are run for that reason.
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Callable

import numpy as np
from rich.console import Console
from rich.table import Table

from tether_companion.bench.estimators.flight import fly
from tether_companion.bench.estimators.registry import kinds as registered_kinds
from tether_companion.errors import InputError
from tether_companion.physics.vehicle import VehicleProfile, load_vehicle
from tether_companion.sim.scenario import load_scenario

HELP = "Estimator RMSE with one vehicle-profile key changed, per key (sensitivity table)."

SCORE_FROM_S = 5.0
"""Errors are scored from this flight time on [s]."""


def _scaled_thrust(factor: float) -> Callable[[VehicleProfile], VehicleProfile]:
    def change(v: VehicleProfile) -> VehicleProfile:
        coefficients = tuple(factor * c for c in v.thrust_curve.coefficients_n)
        return dataclasses.replace(
            v, thrust_curve=dataclasses.replace(v.thrust_curve, coefficients_n=coefficients)
        )

    return change


def _key(name: str, value: Callable[[float], float]) -> Callable[[VehicleProfile], VehicleProfile]:
    return lambda v: dataclasses.replace(v, **{name: value(getattr(v, name))})


PERTURBATIONS: dict[str, Callable[[VehicleProfile], VehicleProfile]] = {
    "none (the scenario's profile)": lambda v: v,
    "mass_kg +5 %": _key("mass_kg", lambda m: 1.05 * m),
    "mass_kg -5 %": _key("mass_kg", lambda m: 0.95 * m),
    "thrust curve +5 % (MOT_THST_HOVER -4.8 %)": _scaled_thrust(1.05),
    "thrust curve -5 % (MOT_THST_HOVER +5.3 %)": _scaled_thrust(0.95),
    "rotor_drag_per_s x2": _key("rotor_drag_per_s", lambda d: 2.0 * d),
    "rotor_drag_per_s 0": _key("rotor_drag_per_s", lambda d: 0.0),
    "ballistic_coefficient 0 (none)": _key("ballistic_coefficient_kg_per_m2", lambda b: 0.0),
    "motor_time_constant_s x2": _key("motor_time_constant_s", lambda t: 2.0 * t),
}
"""Label -> the change made to the estimators' profile."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Scenarios, seeds, kinds, duration."""
    parser.add_argument(
        "--scenario",
        action="append",
        help="scenario (name or path; repeat; default realistic-circle)",
    )
    parser.add_argument("--seeds", type=int, default=2, help="flights per change")
    parser.add_argument("--first-seed", type=int, default=1, help="seed of the first flight")
    parser.add_argument("--duration-s", type=float, default=30.0, help="flight length [s]")
    parser.add_argument(
        "--estimator",
        action="append",
        help="scorecard kind (repeat; default ekf-4s and dynamic)",
    )


def horizontal_vertical_rmse_m(error_ned_m: np.ndarray) -> tuple[float, float]:
    """Horizontal and vertical RMSE [m] of the finite rows of ``error_ned_m`` (N, 3)."""
    ok = np.all(np.isfinite(error_ned_m), axis=1)
    e = error_ned_m[ok]
    return float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1)))), float(
        np.sqrt(np.mean(e[:, 2] ** 2))
    )


def run(args: argparse.Namespace) -> int:
    """Fly every change on every scenario and seed; print one table per scenario."""
    if args.seeds < 1 or not args.duration_s > SCORE_FROM_S:
        raise InputError(f"--seeds must be >= 1 and --duration-s > {SCORE_FROM_S}")
    available = registered_kinds()
    names = args.estimator or ["ekf-4s", "dynamic"]
    unknown = [n for n in names if n not in available]
    if unknown:
        raise InputError(f"--estimator {unknown[0]}: not one of {', '.join(available)}")
    kinds = [available[n] for n in names]
    console = Console()
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    for scenario_name in args.scenario or ["realistic-circle"]:
        scenario = dataclasses.replace(load_scenario(scenario_name), duration_s=args.duration_s)
        nominal = load_vehicle(scenario.vehicle)
        table = Table(
            title=f"{scenario_name} ({args.duration_s:g} s), {nominal.name}: horizontal / "
            f"vertical RMSE after {SCORE_FROM_S:g} s [m], mean of seeds {seeds[0]}-{seeds[-1]}"
        )
        table.add_column("estimator's profile")
        for kind in kinds:
            table.add_column(f"{kind.name} h / v [m]", justify="right")
            table.add_column(f"{kind.name} h / h0", justify="right")
        reference: dict[str, float] = {}
        for label, change in PERTURBATIONS.items():
            profile = change(nominal)
            sums = {k.name: np.zeros(2) for k in kinds}
            for seed in seeds:
                record = fly(dataclasses.replace(scenario, seed=seed), kinds, "ours", profile)
                late = record.time_s >= SCORE_FROM_S
                for kind in kinds:
                    error = record.traces[kind.name].position_ned_m - record.position_ned_m
                    sums[kind.name] += horizontal_vertical_rmse_m(error[late])
            cells = []
            for kind in kinds:
                h, v = sums[kind.name] / len(seeds)
                reference.setdefault(kind.name, h)
                cells += [f"{h:.3f} / {v:.3f}", f"{h / reference[kind.name]:.2f}"]
            table.add_row(label, *cells)
        console.print(table)
    return 0
