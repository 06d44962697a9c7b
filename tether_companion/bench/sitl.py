"""``bench sitl``: ArduCopter SITL (the real flight code) flies on our estimate.

Runs the flights of :mod:`tether_companion.ardupilot_sitl.flights` with ``tether-companion
run`` as a separate process and prints, per phase, the truth (SIM_STATE) against the target,
EKF3's own position and our VISION_POSITION_ESTIMATE against the truth, and EKF3's horizontal
position innovation test ratio (EKF_STATUS_REPORT). The peer in the same run is the GPS hold
before the switch: the same autopilot, the same tether, on GPS.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from pathlib import Path

from rich.console import Console
from rich.table import Table

from tether_companion.commands import float_at_least

HELP = "Fly ArduPilot SITL on our estimate (GPS -> external navigation switch, circle, land)."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``bench sitl``."""
    parser.add_argument(
        "--speedup",
        type=float_at_least(0.1),
        default=1.0,
        help="SIM_SPEEDUP during the flight (default 1: the service keeps up in real time)",
    )
    parser.add_argument(
        "--hold", type=float_at_least(1.0), default=60.0, help="hold after the switch [s]"
    )
    parser.add_argument(
        "--circle-speed", type=float_at_least(0.05), default=1.0, help="circle speed [m/s]"
    )
    parser.add_argument(
        "--laps", type=float_at_least(0.0), default=1.0, help="circle laps (0: none)"
    )
    parser.add_argument(
        "--keep", metavar="DIR", help="keep SITL's logs, the service's config, log and .tlog here"
    )
    parser.add_argument(
        "--flight",
        choices=("gps-switch", "gps-less", "both"),
        default="both",
        help="gps-switch: take off on GPS, switch to ours at a taut hover, hold, circle, land "
        "on GPS; gps-less: GPS1_TYPE 0, take off, hold above the anchor and land on ours alone "
        "(default both)",
    )
    parser.add_argument(
        "--fly-out",
        action="store_true",
        help="gps-less: after the hold above the anchor fly out to 6 m north, 4 m up and hold",
    )
    parser.add_argument(
        "--tether-landing",
        action="store_true",
        help="gps-less: land by reeling SITL's tether in with the service's tension mode",
    )
    parser.add_argument("--json", action="store_true", help="print the results as JSON")


def run(args: argparse.Namespace) -> int:
    """Fly and print; exit 2 when SITL is unavailable or fails to start."""
    from tether_companion.ardupilot_sitl.flights import (
        FlightOptions,
        gps_less,
        gps_to_external_nav,
    )
    from tether_companion.ardupilot_sitl.process import SitlFailed, SitlUnavailable

    options = FlightOptions(
        speedup=args.speedup,
        hold_s=args.hold,
        circle_speed_mps=args.circle_speed,
        circle_laps=args.laps,
        workdir=Path(args.keep) if args.keep else None,
        gps_less_fly_out=args.fly_out,
        land_by_tether=args.tether_landing,
    )
    console = Console(stderr=True)
    flights = {"gps-switch": gps_to_external_nav, "gps-less": gps_less}
    names = list(flights) if args.flight == "both" else [args.flight]
    results = []
    for name in names:
        console.print(f"{name}:")
        try:
            own = dataclasses.replace(
                options, workdir=options.workdir / name if options.workdir else None
            )
            results.append(flights[name](own, log=lambda text: console.print(f"  {text}")))
        except (SitlUnavailable, SitlFailed) as exc:
            print(f"tether-companion bench sitl: {exc}", file=sys.stderr)
            return 2
    if args.json:
        payload = [dataclasses.asdict(result) for result in results]
        for item in payload:
            item.pop("trace")
        print(json.dumps(payload, indent=2, default=_jsonable))
    else:
        for result in results:
            _print(result, args.speedup)
    return 0 if all(result.completed for result in results) else 1


def _print(result, speedup: float) -> None:  # noqa: ANN001 - FlightResult (lazy import)
    table = Table(title=f"{result.name}: SITL '+' quad, speedup {speedup:g}")
    for column in (
        "phase", "s", "truth-target rms/max [m]", "EKF3-truth rms/max [m]",
        "ours-truth rms/max [m]", "ours 3-D rms [m]", "ours stale", "test ratio mean/max",
        "pos lost",
        "yaw err max [deg]",
    ):  # fmt: skip
        table.add_column(column, justify="right" if column != "phase" else "left")
    for p in result.phases:
        table.add_row(
            p.name,
            f"{p.duration_s:.0f}",
            f"{p.truth_to_target_rms_m:.3f} / {p.truth_to_target_max_m:.3f}",
            f"{p.ekf3_error_rms_m:.3f} / {p.ekf3_error_max_m:.3f}",
            f"{p.ours_error_rms_m:.3f} / {p.ours_error_max_m:.3f}",
            f"{p.ours_error_3d_rms_m:.3f}",
            f"{p.ours_stale_samples}/{p.samples}",
            f"{p.test_ratio_mean:.3f} / {p.test_ratio_max:.3f}",
            str(p.position_lost_samples),
            f"{p.yaw_error_max_deg:.1f}",
        )
    out = Console(width=max(Console().width, 150))
    out.print(table)
    if result.name == "gps-to-external-nav":
        out.print(
            f"settled within 0.3 m of the target {result.settle_s:.1f} s after the source switch"
            if math.isfinite(result.settle_s)
            else "never settled within 0.3 m of the target after the source switch"
        )
    out.print(f"failsafes: {'; '.join(result.failsafes) or 'none'}")
    if not result.completed:
        out.print(f"flight stopped early: {result.stopped_at}")


def _jsonable(value: object) -> object:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return str(value)
