"""``tether-companion bench NAME``: benchmarks that print numbers, one module per benchmark.

Each benchmark is ``tether_companion.bench.<name>`` with ``HELP: str``,
``add_arguments(parser)`` and ``run(args) -> int``; add a line to :data:`BENCHMARKS`.
"""

from __future__ import annotations

import argparse

from tether_companion.commands.lazy import add_lazy_subcommands

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
    "sensitivity",
)
"""Benchmark names, one per line, in the order ``bench --help`` lists them."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """One sub-parser per benchmark module; only the one named is imported."""
    sub = parser.add_subparsers(dest="benchmark", metavar="BENCHMARK", required=True)
    argv = parser.get_default("command_argv") or ()
    add_lazy_subcommands(sub, "tether_companion.bench", BENCHMARKS, argv, "run_benchmark")


def run(args: argparse.Namespace) -> int:
    """Run the selected benchmark."""
    return int(args.run_benchmark(args) or 0)
