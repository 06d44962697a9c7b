"""``tether-companion demo``: the emulator and the service on loopback fly the paper's circle."""

from __future__ import annotations

import argparse
import asyncio
import sys
import tempfile
from pathlib import Path

from rich.console import Console

from tether_companion.commands.run import serve
from tether_companion.config import ConfigError
from tether_companion.service.app import CompanionService
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.emulator_process import EmulatorProcess
from tether_companion.service.systemd import SystemdNotifier
from tether_companion.sim.scenario import load_scenario

HELP = (
    "Fly the paper's circle on the built-in emulator with the service on loopback "
    "(no flags needed)."
)
DEFAULT_SCENARIO = "paper-circle"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``demo`` (all optional)."""
    parser.add_argument(
        "--scenario", default=DEFAULT_SCENARIO, help="emulator scenario (default: %(default)s)"
    )
    parser.add_argument(
        "--duration",
        type=float,
        metavar="S",
        help="flight time [s] (default: the scenario's, 60 s for the circle)",
    )
    parser.add_argument(
        "--speed", type=float, default=1.0, help="emulator seconds per wall second (default 1)"
    )
    parser.add_argument("--config", help="service YAML (default: built-in defaults)")
    parser.add_argument("--record-dir", metavar="DIR", help="also record the flight as .tlog here")
    parser.add_argument(
        "--no-status", action="store_true", help="no live view, only the final score"
    )
    parser.add_argument(
        "--winch",
        action="store_true",
        help="the emulator's ground station sends WINCH_STATUS and the service reads it "
        "(winch.enabled; its paid-out length goes to the dynamic filter)",
    )
    parser.add_argument(
        "--cable-angle",
        action="store_true",
        help="the emulator's ground station sends the cable's direction at the anchor "
        "(DEBUG_VECT CABLE_ANG) and the service reads it (cable_angle.enabled; fused by the "
        "dynamic filter)",
    )


def run(args: argparse.Namespace) -> int:
    """Run the demo; prints the emulator's score of the received estimates."""
    if not args.speed > 0.0 or args.speed > 20.0:
        raise ConfigError("", "--speed", args.speed, "must be > 0 and <= 20")
    scenario = load_scenario(args.scenario)
    duration_s = scenario.duration_s if args.duration is None else args.duration
    if not duration_s > 0.0:
        raise ConfigError("", "--duration", args.duration, "must be > 0")
    console = Console()
    console.print(
        f"[bold]tether-companion demo[/bold]: {args.scenario} ({duration_s:g} s of flight at "
        f"{args.speed:g}x) on the emulator, the service estimating from the tether's pull"
    )
    with tempfile.TemporaryDirectory(prefix="tether-demo-") as scratch:
        score_text = asyncio.run(_demo(args, duration_s, Path(scratch)))
    console.print()
    console.print(score_text)
    return 0


async def _demo(args: argparse.Namespace, duration_s: float, scratch: Path) -> str:
    emulator = EmulatorProcess(
        args.scenario,
        duration_s=duration_s,
        score_path=scratch / "score.json",
        speed=args.speed,
        extra_args=tuple(
            flag
            for flag, wanted in (("--winch", args.winch), ("--cable-angle", args.cable_angle))
            if wanted
        ),
    )
    async with emulator:
        overrides: dict = {"link": {"connect": f"udpout:127.0.0.1:{emulator.port}"}}
        if args.config is None:  # ask for the rates the simulated flight controller's sensors have
            sensors = load_scenario(args.scenario).sensors
            overrides["streams"] = {
                "imu_hz": sensors.imu_rate_hz,
                "attitude_hz": sensors.attitude_rate_hz,
                "servo_hz": sensors.pwm_rate_hz,
                "rangefinder_hz": sensors.range_rate_hz,
            }
        if args.winch:
            overrides["winch"] = {"enabled": True}
        if args.cable_angle:
            overrides["cable_angle"] = {"enabled": True}
        overrides["recording"] = (
            {"directory": args.record_dir} if args.record_dir else {"enabled": False}
        )
        config = load_service_config(args.config, overrides)
        service = CompanionService(config, load_vehicle_for(config), notifier=SystemdNotifier({}))
        stop = asyncio.Event()
        serving = asyncio.create_task(
            serve(service, show_status=not args.no_status, stop=stop), name="service"
        )
        waiting = asyncio.create_task(emulator.wait(), name="emulator")
        try:
            await asyncio.wait([serving, waiting], return_when=asyncio.FIRST_COMPLETED)
        finally:
            stop.set()
            await serving
        if not waiting.done():  # Ctrl-C stopped the service first
            await emulator.stop()
            return "demo interrupted"
        code = waiting.result()
    if code != 0:
        print("".join(emulator.output), file=sys.stderr)
        return f"[red]the emulator failed (exit code {code})[/red]"
    lines = [
        line.rstrip()
        for line in emulator.output
        if line.startswith(("estimates received", "RMSE", "rate"))
    ]
    published = service.session.publisher.counters.published
    dropped = service.session.ingest.counters.dropped
    return "\n".join(
        [
            "[bold]accuracy scored by the emulator against its ground truth:[/bold]",
            *lines,
            f"service: {published} positions sent, {dropped} inputs dropped",
        ]
    )
