"""``tether-companion sysid``: identify a thrust model from flight logs (paper section 5)."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from rich.console import Console

from tether_companion.config import from_mapping
from tether_companion.errors import InputError
from tether_companion.physics.battery import BatteryCompensation
from tether_companion.physics.vehicle import VehicleProfile, load_vehicle
from tether_companion.sim.scenario import load_scenario
from tether_companion.sysid.battery import compensate_logs
from tether_companion.sysid.drag import DragFit, identify_drag
from tether_companion.sysid.flight import FlightPlan, record_identification_flight
from tether_companion.sysid.identify import STRUCTURES, best_result, identify
from tether_companion.sysid.input_map import INPUT_MAPS
from tether_companion.sysid.logs import load_flight_log
from tether_companion.sysid.metrics import DEFAULT_K_STEPS
from tether_companion.sysid.processing import ProcessingOptions, prepare
from tether_companion.sysid.report import plot_validation, results_table
from tether_companion.sysid.selection import select
from tether_companion.sysid.thrust_model import model_file_mapping, save_thrust_model

HELP = "Identify a PWM-to-thrust model from flight logs (.tlog, .bin, .ulg, .csv)."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Logs, structures, processing options, output file, emulated identification flight."""
    parser.add_argument(
        "logs", nargs="*", metavar="LOG", help="flight logs (.tlog, .bin, .ulg, .csv)"
    )
    parser.add_argument(
        "--vehicle",
        help="vehicle profile (mass, PWM range; default: the --fly-scenario's vehicle with "
        "--fly-emulated, else default-quad)",
    )
    parser.add_argument(
        "--structure",
        action="append",
        choices=tuple(STRUCTURES),
        help="structure to fit (repeat; default: all)",
    )
    parser.add_argument(
        "--input-map", choices=INPUT_MAPS, default="quadratic", help="input of the linear models"
    )
    parser.add_argument(
        "--k-steps", type=int, default=DEFAULT_K_STEPS, help="prediction horizon [samples]"
    )
    parser.add_argument("--rate-hz", type=float, default=100.0, help="resampling rate [Hz]")
    parser.add_argument("--cutoff-hz", type=float, default=10.0, help="low-pass cut-off [Hz]")
    parser.add_argument(
        "--estimation-fraction", type=float, default=0.6, help="share used for estimation"
    )
    parser.add_argument(
        "--cable-tension-n",
        type=float,
        default=0.0,
        help="known constant tether tension during the flight [N] (0: untethered or slack)",
    )
    parser.add_argument("--out", type=Path, help="write the chosen model to this YAML file")
    parser.add_argument(
        "--write",
        choices=tuple(STRUCTURES),
        help="structure to write (default: the admitted model with the smallest steady and "
        "transient thrust error from PWM alone, docs/sysid.md)",
    )
    parser.add_argument(
        "--plot", type=Path, metavar="PNG", help="save measured vs model thrust plots"
    )
    parser.add_argument(
        "--fly-emulated",
        type=Path,
        metavar="OUT",
        help="first fly the section 5.1 identification flight in the simulator, record it to "
        "OUT (.tlog, .bin or .csv) and identify from it",
    )
    parser.add_argument("--seed", type=int, default=0, help="noise seed of the emulated flight")
    parser.add_argument(
        "--fly-scenario",
        default="hover",
        help="scenario whose vehicle, sensors, wind and propulsion the emulated flight has "
        "(e.g. realistic-circle: drag, battery sag, thrust map error, bias, wind)",
    )
    parser.add_argument(
        "--from-params",
        action="append",
        type=Path,
        metavar="FILE",
        help="instead of fitting: write the vehicle profile the autopilot's parameters define "
        "(.tlog PARAM_VALUE, .bin PARM, .ulg, .parm; repeat to merge) to --out; needs --mass-kg",
    )
    parser.add_argument("--mass-kg", type=float, help="take-off mass for --from-params [kg]")
    parser.add_argument(
        "--profile-out",
        type=Path,
        metavar="YAML",
        help="write --vehicle's profile with rotor_drag_per_s identified from the logs' "
        "velocity (LOCAL_POSITION_NED) to this file",
    )
    parser.add_argument(
        "--fly-tension-n", type=float, default=0.0, help="cable tension in the emulated flight [N]"
    )
    add_battery_arguments(parser, "the vehicle profile's battery section")


def add_battery_arguments(parser: argparse.ArgumentParser, default: str) -> None:
    """``--battery-voltage-max-v`` / ``--battery-voltage-min-v``: the compensation range."""
    parser.add_argument(
        "--battery-voltage-max-v",
        type=float,
        help="voltage the identified map holds at (ArduPilot MOT_BAT_VOLT_MAX) [V]; the motor "
        f"commands are scaled by the logged voltage's ratio to it; 0: off (default: {default})",
    )
    parser.add_argument(
        "--battery-voltage-min-v",
        type=float,
        help=f"lower voltages count as this one (MOT_BAT_VOLT_MIN) [V] (default: {default})",
    )


def battery_range(args: argparse.Namespace, default: BatteryCompensation) -> BatteryCompensation:
    """The range from the command line, each value not given taken from ``default``.

    Raises
    ------
    ConfigError
        When a value is out of range or min >= max.
    """
    given = {
        "voltage_max_v": args.battery_voltage_max_v,
        "voltage_min_v": args.battery_voltage_min_v,
    }
    values = {k: v if v is not None else getattr(default, k) for k, v in given.items()}
    return from_mapping(BatteryCompensation, values, source="command line", prefix="battery")


def run(args: argparse.Namespace) -> int:
    """Fit, print the table, write the model; 0 on success."""
    console = Console()
    if args.from_params:
        return write_profile_from_parameters(args, console)
    flight_base = load_scenario(args.fly_scenario) if args.fly_emulated is not None else None
    default_vehicle = flight_base.vehicle if flight_base is not None else "default-quad"
    vehicle = load_vehicle(args.vehicle or default_vehicle)
    if args.k_steps < 1:
        raise InputError(f"--k-steps must be >= 1, got {args.k_steps}")
    options = from_mapping(
        ProcessingOptions,
        {
            "rate_hz": args.rate_hz,
            "cutoff_hz": args.cutoff_hz,
            "estimation_fraction": args.estimation_fraction,
            "cable_tension_n": args.cable_tension_n,
        },
        source="command line",
    )
    logs = list(args.logs)
    if args.fly_emulated is not None:
        plan = from_mapping(
            FlightPlan, {"cable_tension_n": args.fly_tension_n}, source="command line"
        )
        record_identification_flight(args.fly_emulated, plan, flight_base, seed=args.seed)
        console.print(
            f"identification flight recorded to {args.fly_emulated} ({plan.duration_s:.0f} s)"
        )
        logs.append(args.fly_emulated)
    if not logs:
        raise InputError("give at least one LOG, or --fly-emulated OUT to fly one in the simulator")
    pwm_range = (vehicle.thrust_curve.pwm_min_us, vehicle.thrust_curve.pwm_max_us)
    battery = battery_range(args, vehicle.battery)
    flight_logs = [load_flight_log(path) for path in logs]
    flight_logs, compensated, note = compensate_logs(flight_logs, battery, pwm_range)
    console.print(note)
    datasets = [prepare(log, vehicle.mass_kg, pwm_range, options) for log in flight_logs]
    drag = next(
        (fit for log in flight_logs if (fit := identify_drag(log, vehicle.mass_kg)) is not None),
        None,
    )
    for data in datasets:
        console.print(
            f"{data.source}: airborne {data.airborne_s[0]:.1f}-{data.airborne_s[1]:.1f} s, "
            f"{len(data.estimation)} estimation + {len(data.validation)} validation samples"
        )
    estimation = [d.estimation for d in datasets]
    validation = [d.validation for d in datasets]
    structures = args.structure or tuple(STRUCTURES)
    if "static" not in structures:  # the steady-state reference of every dynamic model
        structures = ("static", *structures)
    results = identify(estimation, validation, pwm_range, structures, args.k_steps, args.input_map)
    best = best_result(results, "prediction")
    chosen, scores = select(results, validation, pwm_range)
    if args.write is not None:
        written = next((r for r in results if r.structure == args.write and r.ok), None)
        if written is None:
            raise InputError(f"--write {args.write}: that structure was not fitted or failed")
    else:
        written = chosen
    console.print(
        results_table(
            results,
            args.k_steps,
            best.structure if best else None,
            written.structure if written and args.out else None,
            scores=scores,
        )
    )
    if written is None:
        console.print("[red]every structure failed: no model to write[/red]")
        return 1
    if args.out is not None:
        mapping = model_file_mapping(
            written.model.to_mapping(), vars(written.metrics), battery if compensated else None
        )
        header = (
            f"Thrust model identified by tether-companion sysid from {', '.join(map(str, logs))}\n"
            f"vehicle {vehicle.name}; structure {written.structure} ({written.model.orders})"
        )
        try:
            save_thrust_model(args.out, mapping, header)
        except OSError as exc:
            raise InputError(f"{args.out}: cannot write ({exc.strerror})") from None
        console.print(f"wrote {written.structure} model to {args.out}")
    report_drag(console, drag, vehicle, args.profile_out)
    if args.plot is not None:
        plot_validation(args.plot, results, validation[0], args.k_steps)
        console.print(f"plot saved to {args.plot}")
    return 0


def write_profile_from_parameters(args: argparse.Namespace, console: Console) -> int:
    """``--from-params``: the profile from parameter files and the mass, written to --out."""
    from tether_companion.vehicle_params.profile import profile_from_parameters
    from tether_companion.vehicle_params.profile_file import save_profile
    from tether_companion.vehicle_params.sources import merge, read_parameters

    if args.mass_kg is None:
        raise InputError("--from-params needs --mass-kg (the take-off mass; no parameter holds it)")
    if args.out is None:
        raise InputError("--from-params needs --out PROFILE.yaml")
    sources = ", ".join(map(str, args.from_params))
    params = merge(*(read_parameters(path) for path in args.from_params))
    profile = profile_from_parameters(
        params, args.mass_kg, load_vehicle(args.vehicle or "default-quad"), source=sources
    )
    header = (
        f"Vehicle profile from the autopilot parameters in {sources}\n"
        f"(tether-companion sysid --from-params; mass {args.mass_kg} kg given by the user)"
    )
    try:
        save_profile(args.out, profile, header)
    except OSError as exc:
        raise InputError(f"{args.out}: cannot write ({exc.strerror})") from None
    curve = profile.thrust_curve
    console.print(
        f"wrote {profile.name} to {args.out}: {profile.n_motors} motors, "
        f"{curve.max_thrust_n:.2f} N each at {curve.pwm_max_us:.0f} us"
    )
    return 0


def report_drag(
    console: Console, drag: DragFit | None, vehicle: VehicleProfile, path: Path | None
) -> None:
    """Print the identified rotor drag; with ``path``, write the profile carrying it."""
    if drag is None:
        console.print("rotor drag: not identified (no velocity in the logs, or too slow)")
        if path is not None:
            raise InputError(f"--profile-out {path}: no rotor drag could be identified")
        return
    console.print(
        f"rotor drag: mu = {drag.mu_per_s:.3f} 1/s (EK3_DRAG_MCOEF), "
        f"{drag.coefficient_n_s_per_m:.3f} N per m/s, {drag.samples} samples, "
        f"residual {drag.residual_rms_mps2:.3f} m/s^2"
    )
    if path is None:
        return
    from tether_companion.vehicle_params.profile_file import save_profile

    if not 0.0 <= drag.mu_per_s <= 2.0:
        raise InputError(
            f"--profile-out {path}: identified mu {drag.mu_per_s:.3f} 1/s is implausible"
        )
    profile = dataclasses.replace(vehicle, rotor_drag_per_s=drag.mu_per_s)
    try:
        save_profile(path, profile, "Rotor drag identified by tether-companion sysid")
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({exc.strerror})") from None
    console.print(f"wrote {profile.name} with the identified drag to {path}")
