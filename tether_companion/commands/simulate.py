"""``tether-companion simulate``: fly a scenario offline and run the 3-state and 4-state EKFs."""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

from rich.console import Console

from tether_companion.commands import int_at_least
from tether_companion.estimation.config import load_estimator_config
from tether_companion.estimation.metrics import rmse
from tether_companion.estimation.report import rmse_table, write_csv, write_plots
from tether_companion.estimation.runner import run_scenario
from tether_companion.sim.scenario import load_scenario

HELP = "Simulate a scenario and estimate position and tension with the 3-state and 4-state EKFs."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments: scenario, seed, CSV output, plot directory, estimator config."""
    parser.add_argument(
        "scenario", help="scenario YAML file, or a built-in name (e.g. paper-circle)"
    )
    parser.add_argument(
        "--seed", type=int_at_least(0), default=None, help="override the scenario's seed (>= 0)"
    )
    parser.add_argument("--out", type=Path, default=None, help="write the time series to this CSV")
    parser.add_argument(
        "--plots", type=Path, default=None, help="write PNG figures (paper Figs 8-11) here"
    )
    parser.add_argument(
        "--config", type=Path, default=None, help="estimator YAML (default configs/estimator.yaml)"
    )
    parser.add_argument(
        "--settle", type=float, default=5.0, help="also report RMSE after this many seconds [s]"
    )


def run(args: argparse.Namespace) -> int:
    """Run the simulation; print RMSE tables; write CSV and plots when asked."""
    scenario = load_scenario(args.scenario)
    if args.seed is not None:
        scenario = dataclasses.replace(scenario, seed=args.seed)
    config = load_estimator_config(args.config)
    console = Console()
    started = time.perf_counter()
    result = run_scenario(scenario, config)
    elapsed = time.perf_counter() - started
    console.print(
        f"{args.scenario}: {scenario.duration_s:g} s simulated (seed {scenario.seed}) "
        f"in {elapsed:.2f} s wall time ({scenario.duration_s / elapsed:.1f}x real time)"
    )
    console.print(rmse_table(rmse(result), "RMSE over the whole run"))
    if scenario.duration_s > args.settle > 0.0:
        console.print(rmse_table(rmse(result, args.settle), f"RMSE after {args.settle:g} s"))
    health = result.health_4s
    console.print(
        f"4S: {health.accel_fused} accel and {health.range_fused} range updates fused, "
        f"{health.accel_gated + health.range_gated} gated, {health.resets} resets"
    )
    if args.out is not None:
        write_csv(result, args.out)
        console.print(f"wrote {args.out}")
    if args.plots is not None:
        try:
            paths = write_plots(result, args.plots, Path(str(args.scenario)).stem)
        except ImportError:
            console.print("plots skipped: matplotlib is not installed (pip install -e '.[plot]')")
        else:
            console.print(f"wrote {len(paths)} plots to {args.plots}")
    return 0
