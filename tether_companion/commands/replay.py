"""``tether-companion replay``: run a recorded flight log through the service's pipeline."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from tether_companion.config import ConfigError
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.replay import replay_log

HELP = "Replay a .tlog or ArduPilot .bin log through the estimation pipeline into a CSV."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``replay``."""
    parser.add_argument(
        "log", help="MAVLink telemetry log (.tlog) or ArduPilot dataflash log (.bin)"
    )
    parser.add_argument(
        "--out", required=True, help="CSV of the published estimates ('-' = stdout)"
    )
    parser.add_argument(
        "--config",
        help="service YAML (estimator, vehicle, flight-controller ids); default: built-in defaults",
    )
    parser.add_argument(
        "--autopilot", choices=("ardupilot", "px4"), help="overrides link.autopilot"
    )
    parser.add_argument(
        "--allow-truncated",
        action="store_true",
        help="replay the complete part of a log whose end is cut off instead of refusing it",
    )


def run(args: argparse.Namespace) -> int:
    """Replay as fast as possible; print a one-line summary to stderr."""
    overrides: dict = {"recording": {"enabled": False}}
    if args.autopilot:
        overrides["link"] = {"autopilot": args.autopilot}
    config = load_service_config(args.config, overrides)
    vehicle = load_vehicle_for(config)
    started = time.perf_counter()
    if args.out == "-":
        summary = replay_log(
            args.log, config, vehicle, sys.stdout, allow_truncated=args.allow_truncated
        )
    else:
        out_path = Path(args.out)
        try:
            handle = out_path.open("w", encoding="utf-8", newline="")
        except OSError as exc:
            raise ConfigError("", "--out", args.out, f"cannot write ({exc.strerror})") from None
        with handle:
            summary = replay_log(
                args.log, config, vehicle, handle, allow_truncated=args.allow_truncated
            )
    elapsed = time.perf_counter() - started
    inputs = ", ".join(f"{k} {v}" for k, v in summary.inputs.items())
    speed = summary.fc_time_span_s / elapsed if elapsed > 0 else float("inf")
    print(
        f"replay: {summary.published} estimates over {summary.fc_time_span_s:.1f} s of flight "
        f"({inputs}; {summary.ingest_dropped} inputs dropped) in {elapsed:.2f} s "
        f"({speed:.0f}x real time) -> {args.out}",
        file=sys.stderr,
    )
    reasons = summary.reasons_text()
    if reasons:
        print(f"replay: {reasons}", file=sys.stderr)
    return 0
