"""``bench estimators``: every estimator kind on every realistic scenario, one scorecard.

Each (scenario, seed) flight is flown once with every kind riding along (``flight.py``);
flights run as Dask tasks (``cluster.py``: a local cluster of processes by default, or
``--scheduler ADDRESS``); the scores (``scores.py``) pool over seeds into one table per
scenario (``report.py``). Kinds register themselves (``registry.py``). Docs: the scorecard
section of ``docs/estimation.md``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tether_companion.commands import float_at_least, int_at_least
from tether_companion.sim.scenario import REALISTIC_SCENARIOS

HELP = "Score every estimator on the realistic scenarios (RMSE, NEES, CRLB) by Monte Carlo."

DEFAULT_SCENARIOS: tuple[str, ...] = REALISTIC_SCENARIOS
"""Scored when no ``--scenario`` is given: every real-world error source on."""
SIMULATORS: tuple[str, ...] = ("ours", "rotorpy")
"""``ours``: :class:`~tether_companion.sim.simulator.Simulator`; ``rotorpy``: rotorpy's airframe
with our controller, cable and sensors (:mod:`tether_companion.crosscheck.rotorpy_sim`, the
``crosscheck`` extra)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``bench estimators``."""
    parser.add_argument(
        "--scenario",
        action="append",
        default=None,
        metavar="NAME",
        help=f"scenario name or YAML path, repeatable (default: {', '.join(DEFAULT_SCENARIOS)})",
    )
    parser.add_argument(
        "--estimator",
        action="append",
        default=None,
        metavar="KIND",
        help="estimator kind, repeatable (default: every registered kind)",
    )
    parser.add_argument(
        "--seeds",
        type=int_at_least(1),
        default=10,
        help="number of seeds per scenario (default 10)",
    )
    parser.add_argument(
        "--first-seed",
        type=int_at_least(0),
        default=1,
        help="seeds run from this one (default 1; e.g. report on seeds a tuning did not use)",
    )
    parser.add_argument(
        "--duration-s",
        type=float_at_least(0.0, exclusive=True),
        default=None,
        help="cut every flight to this [s]",
    )
    parser.add_argument(
        "--settle-s",
        type=float_at_least(0.0),
        default=5.0,
        help="scores start at this time [s] (default 5)",
    )
    parser.add_argument(
        "--converged-m",
        type=float_at_least(0.0, exclusive=True),
        default=0.5,
        help="converged once the 3-D error stays below this [m] (default 0.5)",
    )
    parser.add_argument(
        "--simulator",
        choices=SIMULATORS,
        default="ours",
        help="physics of the flights: ours, or rotorpy's airframe (the crosscheck extra)",
    )
    parser.add_argument("--json", action="store_true", help="print the scorecard as JSON only")
    parser.add_argument(
        "--plot",
        type=Path,
        default=None,
        metavar="DIR",
        help="write a PNG per scenario (error and 3 sigma over time) into DIR (needs matplotlib)",
    )
    parser.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="run on this dask.distributed scheduler (tcp://HOST:PORT) instead of a local cluster",
    )
    parser.add_argument(
        "--workers",
        type=int_at_least(1),
        default=None,
        help="processes of the local cluster (default: all cores)",
    )


def run(args: argparse.Namespace) -> int:
    """Run the flights on the cluster and print the scorecard."""
    from tether_companion.bench.estimators.command import run_scorecard

    return run_scorecard(args)
