"""``tether-companion run``: the companion service (MAVLink in, VISION_POSITION_ESTIMATE out)."""

from __future__ import annotations

import argparse
import asyncio
import signal

from tether_companion.config import ConfigError
from tether_companion.resources import CONFIGS_DIR
from tether_companion.service.app import CompanionService
from tether_companion.service.config import ServiceConfig, load_service_config, load_vehicle_for

HELP = "Run the companion service against a flight controller (systemd-ready)."
DEFAULT_CONFIG = CONFIGS_DIR / "companion.yaml"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``run``."""
    parser.add_argument(
        "--config", default=str(DEFAULT_CONFIG), help="service YAML (default: %(default)s)"
    )
    parser.add_argument(
        "--connect",
        metavar="ENDPOINT",
        help="flight controller: serial:/dev/ttyAMA0:921600, udp:HOST:PORT, tcp:HOST:PORT "
        "(overrides link.connect)",
    )
    parser.add_argument(
        "--autopilot", choices=("ardupilot", "px4"), help="overrides link.autopilot"
    )
    parser.add_argument(
        "--record-dir",
        metavar="DIR",
        help="write .tlog recordings here (overrides recording.directory)",
    )
    parser.add_argument("--no-record", action="store_true", help="do not record .tlog files")
    parser.add_argument(
        "--status", action="store_true", help="show a live status view in the terminal"
    )
    parser.add_argument(
        "--tension-mode",
        action="store_true",
        help="enable tension-following and landing by the tether (overrides tension_mode.enabled; "
        "docs/landing.md)",
    )


def config_from_args(args: argparse.Namespace) -> ServiceConfig:
    """The service config with the command-line overrides applied (ConfigError when bad)."""
    link: dict = {}
    if args.connect is not None:  # an empty --connect is an error, not "use the config's"
        link["connect"] = args.connect
    if args.autopilot:
        link["autopilot"] = args.autopilot
    recording: dict = {}
    if args.record_dir:
        recording["directory"] = args.record_dir
    if args.no_record:
        recording["enabled"] = False
    overrides: dict = {"link": link, "recording": recording}
    if args.tension_mode:
        overrides["tension_mode"] = {"enabled": True}
    return load_service_config(args.config, overrides)


def run(args: argparse.Namespace) -> int:
    """Run until SIGTERM/SIGINT; 0 on a clean stop."""
    config = config_from_args(args)
    try:
        service = CompanionService(config, load_vehicle_for(config))
    except ConfigError as exc:  # the vehicle profile, the signing key: name the config file
        inner = f" (in {exc.source})" if exc.source and exc.source != exc.value else ""
        raise ConfigError(args.config, exc.key, exc.value, exc.allowed + inner) from None
    asyncio.run(serve(service, show_status=args.status))
    return 0


async def serve(
    service: CompanionService, *, show_status: bool = False, stop: asyncio.Event | None = None
) -> None:
    """Run ``service`` until SIGTERM/SIGINT (or ``stop``), optionally with the live view."""
    stop = stop or asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    view = None
    if show_status:
        from tether_companion.service.status import live_status

        view = asyncio.create_task(live_status(service, stop), name="status-view")
    try:
        await service.run(stop)
    finally:
        stop.set()
        if view is not None:
            await view
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.remove_signal_handler(sig)
