"""``bench dynamic``: the dynamic filter's cost per IMU tick beside the paper's 4-state EKF.

Records every sample of a simulated flight (attitude, PWM, rangefinder, IMU at their own
rates), then replays the same list through the paper's 4-state
:class:`~tether_companion.estimation.pipeline.TetherEstimator` and through the
:class:`~tether_companion.estimation.dynamic.estimator.DynamicTetherEstimator` (whole
pipelines: alignment, prediction, every measurement, the output object), alternately
``--repeat`` times, and prints the best CPU time per IMU tick of each and their ratio (CPU
time, not wall time: the shared machine's other jobs stay out of it). The dynamic filter's
cost is given four times: over the whole flight with the default settings (including its
thrust-scale bank while several members run; the estimates not read: their values are computed
when read), the same with each estimate's status read as the service reads it at every tick,
the same with the former, dearer defaults
(:func:`former_settings`: the force balance every IMU tick, the bank up to 30 s), and once the
bank has kept one member (the steady state). Numbers
depend on the machine and its load; the ratios are measured in the same run.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time

import numpy as np

from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.feed import hand_over, imu_ticks, schedule, simulated
from tether_companion.estimation.pipeline import TetherEstimator
from tether_companion.sim.scenario import load_scenario
from tether_companion.sim.simulator import Simulator

HELP = "Dynamic filter cost per IMU tick beside the paper's 4-state EKF (same samples, same run)."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Scenario, duration, repeats, JSON."""
    parser.add_argument(
        "--scenario", default="paper-circle", help="scenario (default paper-circle)"
    )
    parser.add_argument(
        "--duration", type=float, default=40.0, help="flight seconds recorded (default 40)"
    )
    parser.add_argument(
        "--repeat", type=int, default=3, choices=range(1, 21), metavar="N", help="best of N"
    )
    parser.add_argument("--json", action="store_true", help="print the results as JSON only")
    parser.add_argument(
        "--errors",
        action="store_true",
        help="instead of the cost: accuracy and honesty with the error sources on (paper circle)",
    )
    parser.add_argument(
        "--seeds", default="4-8", help="--errors: seeds, FIRST-LAST (default 4-8; tuned on 1-3)"
    )


def record(scenario_name: str, duration_s: float) -> list[tuple[int, object]]:
    """Every sample of the flight in time order, as ``(kind, sample)``."""
    scenario = dataclasses.replace(load_scenario(scenario_name), duration_s=duration_s)
    return list(simulated(Simulator(scenario), schedule(scenario)))


def replay(
    estimator, samples: list[tuple[int, object]], start: int = 0, *, read_status: bool = False
) -> tuple[float, int]:
    """Feed ``samples[start:]``; CPU seconds and IMU ticks. ``read_status``: read each
    estimate's ``status`` as the service does at every tick (the dynamic filter computes its
    estimate's values when they are read)."""
    on_imu = estimator.on_imu
    ticks = 0
    begin = time.process_time()
    for imu in imu_ticks(samples[start:], estimator):
        estimate = on_imu(imu)
        if read_status and estimate is not None:
            estimate.status  # noqa: B018 - read, as the service reads it
        ticks += 1
    return time.process_time() - begin, ticks


def _decided_index(samples: list[tuple[int, object]], config: EstimatorConfig, vehicle) -> int:
    """Index of the first sample after the dynamic filter's bank kept one member."""
    est = DynamicTetherEstimator(config, vehicle)
    for i, (kind, sample) in enumerate(samples):
        if not hand_over(kind, sample, (est,)):
            est.on_imu(sample)
            if est.bank is not None and est.bank.decided:
                return i + 1
    return len(samples)


def _seeds(text: str) -> list[int]:
    first, _, last = text.partition("-")
    return list(range(int(first), int(last or first) + 1))


def run_errors(args: argparse.Namespace) -> int:
    """The error-source matrix of ``evaluation``: one line per case, means over seeds."""
    from tether_companion.estimation.dynamic.evaluation import ALL_ON, ErrorSources, fly, score

    exact = ErrorSources()
    map_and_bias = ErrorSources(accel_bias_mps2=(0.15, 0.15, 0.15), true_thrust_over_map=1.1)
    cases = [(f"all sources, {t:g} N", t, ALL_ON) for t in (0.5, 1.0, 2.0, 4.0, 10.0)]
    cases += [
        ("exact map, no bias, 4 N", 4.0, exact),
        ("map +10 %, bias 0.15, 4 N", 4.0, map_and_bias),
    ]
    cases += [
        (f"bias {b:g} m/s^2, {t:g} N", t, ErrorSources(accel_bias_mps2=(b, b, b)))
        for t in (0.5, 1.0)
        for b in (0.0, 0.15, 0.3)
    ]
    seeds = _seeds(args.seeds)
    results = []
    for label, tension, sources in cases:
        scores = [score(fly(tension, sources, seed, args.duration)) for seed in seeds]
        row = {
            "case": label,
            "seeds": seeds,
            "dynamic_rmse_m": np.mean([s.dynamic_rmse_m for s in scores], axis=0).tolist(),
            "dynamic_velocity_rmse_mps": np.mean(
                [s.dynamic_velocity_rmse_mps for s in scores], axis=0
            ).tolist(),
            "paper_rmse_m": np.mean([s.paper_rmse_m for s in scores], axis=0).tolist(),
            "nees_position": float(np.mean([s.nees_position for s in scores])),
            "nees_position_velocity": float(np.mean([s.nees_position_velocity for s in scores])),
            "published_share": float(np.mean([s.published_share for s in scores])),
            "published_beyond_3_sigma": float(
                np.mean([s.published_beyond_3_sigma for s in scores])
            ),
        }
        results.append(row)
        if not args.json:
            d, v, p = row["dynamic_rmse_m"], row["dynamic_velocity_rmse_mps"], row["paper_rmse_m"]
            print(
                f"{label:28s} dyn N/E/D {d[0]:.3f} {d[1]:.3f} {d[2]:.3f} m"
                f"  vel {max(v):.3f} m/s  paper N/E/D {p[0]:.3f} {p[1]:.3f} {p[2]:.3f} m"
                f"  NEES3 {row['nees_position']:.2f} NEES6 {row['nees_position_velocity']:.2f}"
                f"  published {row['published_share']:.0%}"
                f" (>3 sigma {row['published_beyond_3_sigma']:.1%})",
                flush=True,
            )
    if args.json:
        print(json.dumps(results, indent=2))
    return 0


FORMER_LABEL = "every tick, 30 s bank"
"""The dynamic filter's settings before ``imu_ticks_per_fusion`` 4 and the 6 s bank became its
defaults (2-3x dearer: docs/estimation-history.md, "Cost per IMU tick")."""


def former_settings() -> DynamicFilterConfig:
    """The default dynamic settings with ``imu_ticks_per_fusion`` 1 and
    ``initial.thrust_scale_bank_max_s`` 30 s (the defaults until issue 10 made the dynamic
    filter the service's)."""
    default = DynamicFilterConfig()
    initial = dataclasses.replace(default.initial, thrust_scale_bank_max_s=30.0)
    return dataclasses.replace(default, imu_ticks_per_fusion=1, initial=initial)


def step_costs(scenario_name: str, duration_s: float, repeat: int) -> dict:
    """CPU time per IMU tick of the paper 4-state estimator and of the dynamic one (whole
    run with the default settings and with :func:`former_settings`, and once its bank keeps
    one member)
    on the same recorded samples, replayed alternately ``repeat`` times (best of each), and
    their ratios to the paper 4-state."""
    from tether_companion.physics.vehicle import load_vehicle

    vehicle = load_vehicle(load_scenario(scenario_name).vehicle)
    config = EstimatorConfig()
    samples = record(scenario_name, duration_s)
    decided = _decided_index(samples, config, vehicle)
    former = former_settings()
    names = ("paper_4s", "dynamic", "dynamic_status", "dynamic_former", "dynamic_steady")
    best = dict.fromkeys(names, float("inf"))
    ticks = {}
    for _ in range(repeat):
        wall, n = replay(TetherEstimator(config, vehicle), samples)
        best["paper_4s"], ticks["paper_4s"] = min(best["paper_4s"], wall / n), n
        wall, n = replay(DynamicTetherEstimator(config, vehicle), samples)
        best["dynamic"], ticks["dynamic"] = min(best["dynamic"], wall / n), n
        wall, n = replay(DynamicTetherEstimator(config, vehicle), samples, read_status=True)
        best["dynamic_status"], ticks["dynamic_status"] = min(best["dynamic_status"], wall / n), n
        wall, n = replay(DynamicTetherEstimator(config, vehicle, former), samples)
        best["dynamic_former"], ticks["dynamic_former"] = min(best["dynamic_former"], wall / n), n
        warm = DynamicTetherEstimator(config, vehicle)
        replay(warm, samples[:decided])
        wall, n = replay(warm, samples, decided)
        if n:
            best["dynamic_steady"], ticks["dynamic_steady"] = (
                min(best["dynamic_steady"], wall / n),
                n,
            )
    return {
        "scenario": scenario_name,
        "duration_s": duration_s,
        "us_per_tick": {k: v * 1e6 for k, v in best.items()},
        "ticks": ticks,
        "ratio_dynamic_to_paper": best["dynamic"] / best["paper_4s"],
        "ratio_dynamic_status_to_paper": best["dynamic_status"] / best["paper_4s"],
        "ratio_dynamic_former_to_paper": best["dynamic_former"] / best["paper_4s"],
        "ratio_steady_to_paper": best["dynamic_steady"] / best["paper_4s"],
        "states": {"paper_4s": 4, "dynamic": 13},
    }


def run(args: argparse.Namespace) -> int:
    """Record, replay alternately, print (or the error matrix with ``--errors``)."""
    if args.errors:
        return run_errors(args)
    result = step_costs(args.scenario, args.duration, args.repeat)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    us = result["us_per_tick"]
    whole, steady = result["ratio_dynamic_to_paper"], result["ratio_steady_to_paper"]
    print(f"per IMU tick, best of {args.repeat} (same {args.duration:g} s of samples):")
    print(f"  paper 4-state EKF           {us['paper_4s']:8.1f} us")
    former = result["ratio_dynamic_former_to_paper"]
    print(f"  dynamic 17-state, whole run {us['dynamic']:8.1f} us  ({whole:.2f}x)")
    status = result["ratio_dynamic_status_to_paper"]
    print(f"  same, status read each tick {us['dynamic_status']:8.1f} us  ({status:.2f}x)")
    print(f"  same, {FORMER_LABEL:21s} {us['dynamic_former']:8.1f} us  ({former:.2f}x)")
    if math.isinf(us["dynamic_steady"]):
        print("  dynamic, one member left    (the bank kept several members to the end)")
    else:
        print(f"  dynamic, one member left    {us['dynamic_steady']:8.1f} us  ({steady:.2f}x)")
    return 0
