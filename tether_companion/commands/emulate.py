"""``tether-companion emulate``: the simulated tethered quadcopter as a MAVLink autopilot."""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import signal
import sys
import threading
import time
from pathlib import Path

from tether_companion.config import ConfigError, from_mapping
from tether_companion.emulator.autopilot import FlightController
from tether_companion.emulator.config import EmulatorConfig, load_emulator_scenario
from tether_companion.emulator.server import EmulatorServer
from tether_companion.mavlink.endpoints import parse_endpoint

HELP = "Emulate an ArduPilot-like flight controller flying a tethered quadcopter scenario."
DEFAULT_SCENARIO = "paper-circle"
DEFAULT_LISTEN = "udp:127.0.0.1:14550"
STATUS_PERIOD_S = 5.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``emulate``."""
    parser.add_argument(
        "scenario",
        nargs="?",
        default=DEFAULT_SCENARIO,
        help="scenario YAML or built-in name (default: %(default)s: the paper's circle, "
        "airborne in AUTO)",
    )
    parser.add_argument(
        "--listen",
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="serve here; repeatable, each endpoint one of the autopilot's ports, routed as"
        f" ArduPilot routes (default {DEFAULT_LISTEN} when no --connect)",
    )
    parser.add_argument(
        "--connect",
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="send to a ground station, e.g. udpout:127.0.0.1:14550; repeatable",
    )
    parser.add_argument("--speed", type=float, default=1.0, help="emulator seconds per wall second")
    parser.add_argument("--seed", type=int, help="override the scenario's seed")
    parser.add_argument(
        "--duration",
        type=float,
        metavar="S",
        help="stop after S emulator seconds (default: run until Ctrl-C)",
    )
    parser.add_argument("--score-out", metavar="FILE", help="write the estimate score as JSON")
    parser.add_argument(
        "--score-start", type=float, metavar="S", help="do not score estimates before S"
    )
    parser.add_argument("--nav", choices=("truth", "vision"), help="navigation source")
    parser.add_argument(
        "--landed",
        action="store_true",
        help="start on the ground, disarmed, in STABILIZE (to fly it from a ground station)",
    )
    parser.add_argument("--sysid", type=int, help="MAVLink system id (default 1)")
    parser.add_argument(
        "--autopilot",
        choices=("ardupilot", "px4"),
        help="flavour: px4 answers the vehicle as PX4 parameters (integers bytewise), says PX4 "
        "in its HEARTBEAT and streams HIGHRES_IMU (default ardupilot)",
    )
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="answer VALUE for parameter NAME, read-only vehicle parameters included (a "
        "misconfigured autopilot; the simulated vehicle is unchanged); repeatable",
    )
    parser.add_argument(
        "--rate",
        action="append",
        default=[],
        metavar="MSG=HZ",
        help="default stream rate, e.g. RAW_IMU=400 or SIM_STATE=0; repeatable",
    )
    parser.add_argument("--drop", type=float, metavar="P", help="probability a sent frame is lost")
    parser.add_argument(
        "--duplicate", type=float, metavar="P", help="probability a frame is sent twice"
    )
    parser.add_argument(
        "--corrupt", type=float, metavar="P", help="probability a frame gets a flipped byte"
    )
    parser.add_argument("--delay-ms", type=float, help="extra latency of every sent frame [ms]")
    parser.add_argument("--jitter-ms", type=float, help="random extra latency [ms]")
    parser.add_argument(
        "--outage",
        action="append",
        default=[],
        metavar="MSG:START:DURATION",
        help="stop a stream for a window [s]; repeatable",
    )
    parser.add_argument(
        "--reboot-at",
        action="append",
        default=[],
        type=float,
        metavar="T",
        help="reboot the flight controller at T [s]; repeatable",
    )
    parser.add_argument(
        "--range-out",
        action="append",
        default=[],
        metavar="START:DURATION",
        help="rangefinder out of range for a window [s]; repeatable",
    )
    parser.add_argument(
        "--winch",
        action="store_true",
        help="a ground-station winch sends WINCH_STATUS (system 255, component 169; its "
        "length's rate and errors: the scenario's ground_station section; the rest: its "
        "emulator.winch section)",
    )
    parser.add_argument(
        "--cable-angle",
        action="store_true",
        help="a ground-station cable-angle sensor sends the cable's direction at the anchor as "
        "DEBUG_VECT CABLE_ANG (system 255, component 158, x azimuth, y elevation [rad]; its "
        "rate and errors: the scenario's ground_station section; the rest: its "
        "emulator.cable_angle section)",
    )
    parser.add_argument("--quiet", action="store_true", help="no periodic status line")


def _split(text: str, flag: str, names: tuple[str, ...]) -> dict[str, object]:
    parts = text.split(":")
    if len(parts) != len(names):
        raise ConfigError("", flag, text, f"expected {':'.join(n.upper() for n in names)}")
    out: dict[str, object] = {}
    for name, part in zip(names, parts, strict=True):
        if name == "stream":
            out[name] = part
            continue
        try:
            out[name] = float(part)
        except ValueError:
            raise ConfigError("", flag, text, f"{name.upper()} must be a number") from None
    return out


def emulator_config_from_args(args: argparse.Namespace, base: EmulatorConfig) -> EmulatorConfig:
    """``base`` (the scenario's emulator section) with the command-line overrides applied."""
    data = dataclasses.asdict(base)
    faults = data["faults"]
    if args.nav:
        data["navigation"] = args.nav
    if args.sysid is not None:
        data["system_id"] = args.sysid
    if args.autopilot:
        data["autopilot"] = args.autopilot
    for text in args.param:
        name, value = _name_value(text, "--param", "NAME=VALUE, e.g. MOT_SPIN_MIN=0.5")
        data["parameters"][name] = value
    if args.score_start is not None:
        data["score_start_s"] = args.score_start
    if args.winch:
        data["winch"]["enabled"] = True
    if args.cable_angle:
        data["cable_angle"]["enabled"] = True
    for text in args.rate:
        name, value = _name_value(text, "--rate", "MSG=HZ, e.g. RAW_IMU=400")
        data["stream_rates_hz"][name] = value
    for flag, key in (
        ("drop", "drop_probability"),
        ("duplicate", "duplicate_probability"),
        ("corrupt", "corrupt_probability"),
        ("delay_ms", "delay_ms"),
        ("jitter_ms", "delay_jitter_ms"),
    ):
        value = getattr(args, flag)
        if value is not None:
            faults[key] = value
    faults["outages"] = list(faults["outages"]) + [
        _split(t, "--outage", ("stream", "start_s", "duration_s")) for t in args.outage
    ]
    faults["reboots_s"] = list(faults["reboots_s"]) + list(args.reboot_at)
    faults["rangefinder_out_of_range"] = list(faults["rangefinder_out_of_range"]) + [
        _split(t, "--range-out", ("start_s", "duration_s")) for t in args.range_out
    ]
    return from_mapping(EmulatorConfig, data, source="command line")


def run(args: argparse.Namespace) -> int:
    """Serve until --duration or Ctrl-C/SIGTERM; print (and write) the estimate score."""
    if not (args.speed > 0.0):
        raise ConfigError("", "--speed", args.speed, "must be > 0")
    if args.duration is not None and not args.duration > 0.0:
        raise ConfigError("", "--duration", args.duration, "must be > 0")
    scenario, emulator_config = load_emulator_scenario(args.scenario)
    config = emulator_config_from_args(args, emulator_config)
    if args.seed is not None:
        if args.seed < 0:
            raise ConfigError("", "--seed", args.seed, "must be >= 0")
        scenario = dataclasses.replace(scenario, seed=args.seed)
    if args.landed:
        scenario = dataclasses.replace(
            scenario, initial=dataclasses.replace(scenario.initial, airborne=False, armed=False)
        )
    listen = args.listen or ([] if args.connect else [DEFAULT_LISTEN])
    endpoints = [parse_endpoint(t, "listen") for t in listen] + [
        parse_endpoint(t, "connect") for t in args.connect
    ]
    controller = FlightController(scenario, config, unix_time_at_start_s=time.time())
    try:
        asyncio.run(_serve(controller, endpoints, args))
    except OSError as exc:
        print(f"tether-companion emulate: error: {exc}", file=sys.stderr)
        return 1
    report = controller.score()
    print(report.format_text())
    if args.score_out:
        report.to_json(Path(args.score_out))
        print(f"score written to {args.score_out}")
    return 0


async def _serve(controller: FlightController, endpoints: list, args: argparse.Namespace) -> None:
    async with EmulatorServer(controller, endpoints, speed=args.speed) as server:
        loop = asyncio.get_running_loop()
        handled = threading.current_thread() is threading.main_thread()
        for sig in (signal.SIGINT, signal.SIGTERM) if handled else ():
            loop.add_signal_handler(sig, server.stop)
        for index, endpoint in enumerate(endpoints):
            where = server.local_address(index)
            bound = f" (bound {where[0]}:{where[1]})" if where else ""
            print(f"emulate: {endpoint}{bound}", flush=True)
        print(
            f"emulate: {args.scenario}, mode {controller.mode.name}, "
            f"navigation {'vision' if controller.vision_navigation else 'truth'}, "
            f"speed {args.speed:g}x; Ctrl-C to stop",
            flush=True,
        )
        status = (
            None
            if args.quiet
            else asyncio.create_task(_status(controller, server), name="emulate-status")
        )
        try:
            await server.run(args.duration)
        finally:
            if status is not None:
                status.cancel()
            for sig in (signal.SIGINT, signal.SIGTERM) if handled else ():
                loop.remove_signal_handler(sig)


async def _status(controller: FlightController, server: EmulatorServer) -> None:
    while True:
        await asyncio.sleep(STATUS_PERIOD_S)
        north_m, east_m, down_m = controller.sim.position_ned_m
        armed = "ARMED" if controller.armed else "disarmed"
        tension_n = controller.sim.cable.tension_n
        print(
            f"t {controller.time_s:7.1f} s  {controller.mode.name:9s} {armed:8s} "
            f"NED ({north_m:6.2f}, {east_m:6.2f}, {down_m:6.2f}) m  tension {tension_n:5.2f} N  "
            f"in {controller.counters.messages_in}  slips {server.counters.slips}",
            flush=True,
        )


def _name_value(text: str, flag: str, form: str) -> tuple[str, float]:
    """``NAME=VALUE`` of a repeatable flag (ConfigError naming the flag when it is not one)."""
    name, sep, value = text.partition("=")
    try:
        number = float(value)
    except ValueError:
        number = None
    if not sep or number is None:
        raise ConfigError("", flag, text, f"expected {form}")
    return name.strip(), number
