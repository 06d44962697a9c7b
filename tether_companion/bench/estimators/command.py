"""The body of ``bench estimators`` (imported only when it runs)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
import uuid

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from tether_companion.bench.estimators import DEFAULT_SCENARIOS
from tether_companion.bench.estimators.cluster import dask_client, map_tasks, require_distributed
from tether_companion.bench.estimators.registry import EstimatorKind, kinds
from tether_companion.bench.estimators.report import (
    json_safe,
    print_tables,
    scorecard,
    write_plots,
)
from tether_companion.bench.estimators.tasks import FlightTask, score_flight
from tether_companion.errors import InputError
from tether_companion.sim.scenario import Scenario, load_scenario


def _selected_kinds(names: list[str] | None) -> list[EstimatorKind]:
    registry = kinds()
    if names is None:
        return list(registry.values())
    unknown = [n for n in names if n not in registry]
    if unknown:
        raise InputError(
            f"--estimator {unknown[0]!r} is not a registered kind (choose from "
            f"{', '.join(registry)})"
        )
    return [registry[n] for n in dict.fromkeys(names)]


def _scenarios(
    names: list[str],
    duration_s: float | None,
    settle_s: float,
    simulator: str,
    console: Console,
) -> dict[str, Scenario]:
    """The scenarios to fly; on rotorpy, ground starts are refused (named ones) or skipped
    (the default set, with a note)."""
    loaded = {}
    for name in dict.fromkeys(names or DEFAULT_SCENARIOS):
        scenario = load_scenario(name)
        if simulator == "rotorpy" and not scenario.initial.airborne:
            if names:
                raise InputError(
                    f"--simulator rotorpy flies airborne starts only; {name!r} starts on the ground"
                )
            console.print(f"skipped {name}: rotorpy flies airborne starts only")
            continue
        if duration_s is not None:
            scenario = dataclasses.replace(scenario, duration_s=duration_s)
        if settle_s >= scenario.duration_s:
            raise InputError(
                f"--settle-s {settle_s:g} leaves nothing to score in {name!r} "
                f"({scenario.duration_s:g} s long)"
            )
        loaded[name] = scenario
    return loaded


def run_scorecard(args: argparse.Namespace) -> int:
    """Fly, score and report (see the package docstring)."""
    require_distributed()
    if args.simulator == "rotorpy":
        from tether_companion.crosscheck.rotorpy_sim import require_rotorpy

        require_rotorpy()
    selected = _selected_kinds(args.estimator)
    console = Console(stderr=args.json)
    scenarios = _scenarios(
        args.scenario or [], args.duration_s, args.settle_s, args.simulator, console
    )
    names = list(scenarios)
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    tasks = [
        FlightTask(
            name,
            dataclasses.replace(scenario, seed=seed),
            tuple(k.name for k in selected),
            args.settle_s,
            args.converged_m,
            args.simulator,
        )
        for name, scenario in scenarios.items()
        for seed in seeds
    ]
    token = uuid.uuid4().hex[:8]
    keys = [f"bench-estimators-{t.scenario_name}-{t.seed}-{token}" for t in tasks]
    started = time.perf_counter()
    with dask_client(args.scheduler, args.workers) as client:
        with Progress(
            TextColumn("[bold]bench estimators"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=console,
            transient=args.json,
        ) as progress:
            bar = progress.add_task("flights", total=len(tasks))
            scores = map_tasks(client, score_flight, tasks, keys, lambda: progress.advance(bar))
        workers = len(client.scheduler_info().get("workers", {}))
    elapsed = time.perf_counter() - started
    card = scorecard(scores, selected, names)
    if args.plot is not None:
        for path in write_plots(args.plot, scores, selected, names):
            console.print(f"wrote {path}")
    if args.json:
        document = {
            "seeds": seeds,
            "settle_s": args.settle_s,
            "converged_m": args.converged_m,
            "duration_s": {name: s.duration_s for name, s in scenarios.items()},
            "estimators": {
                k.name: {"label": k.label, "description": k.description, "crlb": k.crlb_model}
                for k in selected
            },
            "scenarios": card,
            "flights": len(tasks),
            "workers": workers,
            "scheduler": args.scheduler or "local",
            "simulator": args.simulator,
            "wall_time_s": elapsed,
        }
        print(json.dumps(json_safe(document), indent=2))
        return 0
    print_tables(console, card, selected, len(seeds), args.settle_s, args.converged_m)
    where = args.scheduler or "a local cluster"
    console.print(
        f"{len(tasks)} flights on the {args.simulator} simulator in {elapsed:.1f} s on "
        f"{workers} worker(s) of {where}"
    )
    return 0
