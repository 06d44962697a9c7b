"""``tether-companion bench NAME``: benchmarks that print numbers, one module per benchmark.

Each benchmark is ``tether_companion.bench.<name>`` with ``HELP: str``,
``add_arguments(parser)`` and ``run(args) -> int``; add a line to :data:`BENCHMARKS`.
"""

from __future__ import annotations

import argparse
import importlib

HELP = "Run a benchmark (accuracy against the paper, speed, ...) and print its numbers."

BENCHMARKS: tuple[str, ...] = (
    "paper",
    "speed",
    "tension",
    "catenary",
    "emulator",
    "latency",
    "sysid",
    "estimators",
    "sitl",
    "dynamic",
    "vehicle",
)
"""Benchmark names, one per line, in the order ``bench --help`` lists them."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """One sub-parser per benchmark module."""
    sub = parser.add_subparsers(dest="benchmark", metavar="BENCHMARK", required=True)
    for name in BENCHMARKS:
        module = importlib.import_module(f"tether_companion.bench.{name}")
        bench_parser = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(bench_parser)
        bench_parser.set_defaults(run_benchmark=module.run)


def run(args: argparse.Namespace) -> int:
    """Run the selected benchmark."""
    return int(args.run_benchmark(args) or 0)
