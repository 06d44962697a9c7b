"""Where a dynamic kind's RMSE / own CRLB comes from: the bound split by what the filter leaves
unused by design (docs/estimation-history.md, "RMSE / own CRLB where it is missed (crlb14)").

For one scenario and one dynamic kind, each seed is flown with the kind (``flight.fly``), its
estimated ticks from ``settle_s`` are scored as ``bench estimators`` scores them, and the
bound of its own model (:func:`~tether_companion.estimation.dynamic.scorecard.own_model_bound`)
is recomputed with the filter's design choices, one after the other:

1. ``own CRLB``: the scorecard's bound (every tick of the flight, the calibration learnt from
   the first reading);
2. ``from the filter's start``: the recursion starts at the filter's first estimate (the ticks
   before, on the ground and in its first second, unused);
3. ``+ azimuth zero held``: the cable angle's azimuth zero a consider state for the whole
   flight (``state.NEVER_RELEASED``: the filter never learns it);
4. ``+ calibration held until released``: the winch's offset and scale and the elevation zero
   consider states until the tick the filter released them (``calibration_release.py``; the
   whole flight when it did not).

Rows 3 and 4 are not bounds but the covariance of the best estimator with those choices
(Schmidt gain): the RMSE over row 4 says how close the filter comes to what its own design
allows. Each row: the RMS per axis (north, east, down) and horizontal [m], and the RMSE over it.

Run: ``python -m tether_companion.bench.estimators.bound_split --scenario NAME
--estimator KIND --seeds N --first-seed S --duration-s D``.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.bench.estimators.flight import fly
from tether_companion.bench.estimators.registry import EstimatorKind, FlightContext, kinds
from tether_companion.config import ConfigError
from tether_companion.constants import GRAVITY_MPS2
from tether_companion.errors import InputError
from tether_companion.estimation.dynamic.crlb_nuisance import (
    AZIMUTH_BIAS,
    ELEVATION_BIAS,
    OFFSET,
    SCALE,
)
from tether_companion.estimation.dynamic.scorecard import DynamicKind, own_model_bound
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.scenario import Scenario, load_scenario

FloatArray = NDArray[np.float64]

LABELS: tuple[str, ...] = (
    "own CRLB",
    "from the filter's start",
    "+ azimuth zero held",
    "+ calibration held until released",
)
"""The rows, each adding a design choice to the one before (module docstring)."""


@dataclass(frozen=True)
class SplitRow:
    """One row of the split, pooled over seeds.

    Attributes
    ----------
    label
        One of :data:`LABELS`, or ``RMSE`` for the kind's error.
    axis_m
        RMS per axis over the scored ticks, (north, east, down) [m].
    """

    label: str
    axis_m: tuple[float, float, float]

    @property
    def horizontal_m(self) -> float:
        """The horizontal (2-D) RMS [m]."""
        return math.hypot(self.axis_m[0], self.axis_m[1])


def split_flight(
    scenario: Scenario, kind: EstimatorKind, settle_s: float
) -> tuple[FloatArray, list[FloatArray], int]:
    """Fly ``scenario`` with ``kind`` (a dynamic kind) and return the sums over the scored
    ticks of the squared error per axis (3,) [m^2], of each row's variance per axis (3,)
    [m^2], and the number of scored ticks."""
    built: list[DynamicKind] = []

    def build(context: FlightContext) -> DynamicKind:
        estimator = kind.build(context)
        if not isinstance(estimator, DynamicKind):
            raise InputError(f"{kind.name!r} is not a dynamic kind: it has no own-model bound")
        built.append(estimator)
        return estimator

    record = fly(scenario, [dataclasses.replace(kind, build=build)])
    (dynamic,) = built
    trace = record.traces[kind.name]
    context = FlightContext(scenario, load_vehicle(scenario.vehicle), GRAVITY_MPS2)
    error = trace.position_ned_m - record.position_ned_m
    has_state = np.isfinite(error).all(axis=1)
    scored = has_state & (record.time_s >= settle_s)
    start = int(np.argmax(has_state)) if has_state.any() else len(record.time_s)
    released_s = dynamic.estimator.ground_station.calibration_release.released_time_s
    released = None if math.isnan(released_s) else int(np.searchsorted(record.time_s, released_s))
    winch, angle = dynamic.measurements
    options = (
        {},
        {"start_tick": start},
        {"start_tick": start, "held": {AZIMUTH_BIAS: None}},
        {
            "start_tick": start,
            "held": {
                AZIMUTH_BIAS: None,
                OFFSET: released,
                SCALE: released,
                ELEVATION_BIAS: released,
            },
        },
    )
    bounds = [
        own_model_bound(context, record, winch=winch, angle=angle, **option)[scored, :3].sum(0)
        for option in options
    ]
    return (error[scored] ** 2).sum(0), bounds, int(scored.sum())


def bound_split(
    scenario: Scenario, kind: EstimatorKind, seeds: list[int], settle_s: float = 5.0
) -> list[SplitRow]:
    """The split pooled over ``seeds``: the kind's RMSE first, then a row per :data:`LABELS`."""
    error = np.zeros(3)
    bounds = [np.zeros(3) for _ in LABELS]
    count = 0
    for seed in seeds:
        e, b, n = split_flight(dataclasses.replace(scenario, seed=seed), kind, settle_s)
        error += e
        for total, part in zip(bounds, b, strict=True):
            total += part
        count += n
    if count == 0:
        raise InputError("no scored tick: the kind never had an estimate after the settle time")

    def row(label: str, total: FloatArray) -> SplitRow:
        rms = np.sqrt(total / count)
        return SplitRow(label, (float(rms[0]), float(rms[1]), float(rms[2])))

    return [row("RMSE", error)] + [row(label, b) for label, b in zip(LABELS, bounds, strict=True)]


def format_split(rows: list[SplitRow]) -> str:
    """The split as a text table: RMS per axis and horizontal [m], the RMSE over each row."""
    rmse = rows[0]
    lines = [f"{'':<36} {'north':>7} {'east':>7} {'down':>7} {'h':>7}  RMSE/row h  v"]
    for r in rows:
        n, e, d = r.axis_m
        ratio_h = rmse.horizontal_m / r.horizontal_m if r.horizontal_m > 0 else math.nan
        ratio_v = rmse.axis_m[2] / d if d > 0 else math.nan
        lines.append(
            f"{r.label:<36} {n:7.4f} {e:7.4f} {d:7.4f} {r.horizontal_m:7.4f}  "
            f"{ratio_h:9.2f} {ratio_v:5.2f}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Command line (module docstring); bad input: one line, exit 2."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", required=True)
    parser.add_argument("--estimator", required=True)
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--first-seed", type=int, default=1)
    parser.add_argument("--duration-s", type=float, default=None)
    parser.add_argument("--settle-s", type=float, default=5.0)
    args = parser.parse_args(argv)
    try:
        registry = kinds()
        if args.estimator not in registry:
            raise InputError(f"unknown estimator kind {args.estimator!r}")
        if args.seeds < 1:
            raise InputError(f"--seeds must be at least 1, got {args.seeds}")
        scenario = load_scenario(args.scenario)
        if args.duration_s is not None:
            scenario = dataclasses.replace(scenario, duration_s=args.duration_s)
        seeds = list(range(args.first_seed, args.first_seed + args.seeds))
        rows = bound_split(scenario, registry[args.estimator], seeds, args.settle_s)
    except (InputError, ConfigError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(f"{args.scenario}, {args.estimator}, seeds {seeds[0]}-{seeds[-1]}")
    print(format_split(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
