"""``bench sysid``: fly -> identify -> estimate, and what the identified thrust model is worth.

1. The section 5.1 identification flight is flown in the simulator (slack tether) and
   recorded as a .tlog (or ``--log`` gives a recorded flight). ``--flight-scenario`` names
   the scenario whose vehicle, sensors, wind and propulsion it is flown with: the default
   ``hover`` is exact, ``realistic-circle`` has every error source on (rotor drag, battery
   sag, a thrust map 5 % weak, accelerometer bias, vibration, the flight controller's
   attitude error, wind);
2. every structure is identified from it (Table 1 printed), on motor commands scaled by the
   logged battery voltage (:mod:`tether_companion.sysid.battery`) over the range
   ``--battery-voltage-max-v/min-v`` (default: the flight scenario's pack, full to empty
   cell voltage, as a user sets ``MOT_BAT_VOLT_MAX/MIN``; the vehicle profile's with
   ``--log``; ``--battery-voltage-max-v 0`` identifies uncompensated);
3. each evaluation scenario (``--scenario``, repeatable; default the paper's ``paper-circle``)
   is flown with seeds ``--first-seed`` onwards (never the identification flight's noise) by
   the 4-state EKF, configured with the scenario's anchor height and rangefinder offset, fed
   by each thrust input in turn: a naive linear map (the paper's eq. 19, ``f = k cmd`` per
   motor with ``k`` fitted by least squares on the same identification data), the model
   ``sysid --out`` writes (:mod:`tether_companion.sysid.selection`), the best by k-step Fit%
   (Table 1's criterion, ARX in practice), the best by simulation Fit% (the old rule), the
   true map and, when the scenario's propulsion differs from the profile, the profile's own
   curve;
4. position RMSE per axis and horizontal, tension RMSE (mean over seeds, scored from
   :data:`SCORE_FROM_S`), the thrust RMSE against the simulator's true rotor thrust, and the
   3-D position RMSE over the true map's are printed per scenario.

The true map is the thrust the simulator makes (:mod:`tether_companion.sim.propulsion`): the
profile's curve times ``thrust_scale`` with the command scaled by the battery voltage, the
voltage fed each tick as SYS_STATUS would (:func:`true_thrust_input`).
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from tether_companion.bench.estimators.registry import FlightContext
from tether_companion.commands.sysid import add_battery_arguments, battery_range
from tether_companion.errors import InputError
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.pipeline import TetherEstimator
from tether_companion.estimation.thrust_input import StaticThrustInput, ThrustInput
from tether_companion.physics.battery import BatteryCompensation
from tether_companion.physics.thrust import ThrustCurve
from tether_companion.physics.vehicle import VehicleProfile, load_vehicle
from tether_companion.sim.propulsion import PropulsionConfig
from tether_companion.sim.scenario import Scenario, load_scenario
from tether_companion.sim.simulator import Simulator
from tether_companion.sysid.battery import compensate_logs
from tether_companion.sysid.flight import record_identification_flight
from tether_companion.sysid.identify import STRUCTURES, StructureResult, best_result, identify
from tether_companion.sysid.logs import load_flight_log
from tether_companion.sysid.processing import IdData, prepare
from tether_companion.sysid.report import results_table
from tether_companion.sysid.selection import SelectionScore, select
from tether_companion.sysid.thrust_model import (
    StaticModelFile,
    model_file_mapping,
    thrust_input_from_mapping,
)

HELP = "Identify a thrust model from an emulated flight; EKF RMSE with it vs a naive linear map."

AXES = ("north_m", "east_m", "down_m")
SCORE_FROM_S = 5.0
"""Position and tension errors are scored from this flight time on [s] (the filter starts
from the paper's x0, metres from the drone)."""


class RecordingThrust:
    """Wraps a :class:`ThrustInput` and keeps its last output [N] for error statistics."""

    def __init__(self, inner: ThrustInput) -> None:
        self.inner = inner
        self.last_n = float("nan")

    def set_battery_voltage_v(self, voltage_v: float) -> None:
        """Pass the measured battery voltage [V] on, when the wrapped input uses one."""
        setter = getattr(self.inner, "set_battery_voltage_v", None)
        if setter is not None:
            setter(voltage_v)

    def total_thrust_n(self, pwm_us: np.ndarray, time_s: float) -> float:
        """The wrapped input's thrust [N], remembered."""
        self.last_n = self.inner.total_thrust_n(pwm_us, time_s)
        return self.last_n


def naive_linear_curve(estimation: list[IdData], pwm_range_us: tuple[float, float]) -> ThrustCurve:
    """Eq. 19 of the paper, ``f = k cmd`` per motor, ``k`` by least squares [N per unit cmd]."""
    command = np.concatenate([e.command.sum(axis=1) for e in estimation])
    thrust = np.concatenate([e.thrust_n for e in estimation])
    k = float(command @ thrust / (command @ command))
    return ThrustCurve(
        pwm_min_us=pwm_range_us[0], pwm_max_us=pwm_range_us[1], coefficients_n=(0.0, k, 0.0)
    )


def true_thrust_input(vehicle: VehicleProfile, propulsion: PropulsionConfig) -> StaticThrustInput:
    """The simulator's real thrust map as a static input fed with the battery voltage.

    The simulator gives ``s c(u V / V_ref)`` per motor (``c`` the profile's quadratic,
    ``s = thrust_scale``, ``V_ref`` the pack at the reference cell voltage). With the
    battery model's maximum at the full pack ``V_full`` and ``k = V_full / V_ref`` this is
    ``s c(k u V / V_full)``: coefficients ``(s c0, s k c1, s k^2 c2)`` with the command
    scaled by ``V / V_full``, exactly (down to the empty cell voltage, where both stop).
    """
    battery = propulsion.battery
    full_v = battery.cells * battery.full_cell_voltage_v
    k = battery.full_cell_voltage_v / battery.reference_cell_voltage_v
    s = propulsion.thrust_scale
    c0, c1, c2 = vehicle.thrust_curve.coefficients_n
    curve = dataclasses.replace(
        vehicle.thrust_curve, coefficients_n=(s * c0, s * k * c1, s * k * k * c2)
    )
    true_vehicle = dataclasses.replace(
        vehicle,
        thrust_curve=curve,
        battery=BatteryCompensation(
            voltage_max_v=full_v, voltage_min_v=battery.cells * battery.empty_cell_voltage_v
        ),
    )
    return StaticThrustInput(true_vehicle)


def run_four_state(scenario: Scenario, thrust: ThrustInput, seed: int) -> dict[str, float]:
    """Fly ``scenario`` with the 4-state EKF on ``thrust``; RMSE of position, tension, thrust.

    Every sensor is read at the IMU rate (the scenarios' sensors run at 200 Hz, the
    rangefinder slower), attitude and PWM before the IMU sample that uses them; the battery
    voltage is handed to the thrust input each tick (inputs without a battery model ignore
    it). Position and tension are scored from :data:`SCORE_FROM_S`, the thrust throughout.
    """
    sim = Simulator(scenario, rng=np.random.default_rng(seed))
    recorder = RecordingThrust(thrust)
    context = FlightContext(scenario, sim.vehicle, sim.gravity_mps2)
    config = context.estimator_config(dataclasses.replace(EstimatorConfig(), kind="four_state"))
    estimator = TetherEstimator(config, sim.vehicle, thrust_input=recorder)
    period = 1.0 / scenario.sensors.imu_rate_hz
    position_err, tension_err, thrust_err = [], [], []
    for k in range(1, int(scenario.duration_s / period) + 1):
        sim.advance_to(k * period)
        recorder.set_battery_voltage_v(sim.battery_voltage_v)
        estimator.on_attitude(sim.read_attitude())
        estimator.on_pwm(sim.read_pwm())
        reading = sim.read_rangefinder()
        if reading is not None:
            estimator.on_range(reading)
        estimate = estimator.on_imu(sim.read_imu())
        truth = sim.truth
        thrust_err.append(recorder.last_n - float(np.sum(truth.motor_thrust_n)))
        if estimate is not None and k * period >= SCORE_FROM_S:
            position_err.append(estimate.position_ned_m - truth.position_ned_m)
            tension_err.append(estimate.tension_n - truth.tension_n)
    errors = np.array(position_err)
    result = {axis: float(np.sqrt(np.mean(errors[:, i] ** 2))) for i, axis in enumerate(AXES)}
    result["horizontal_m"] = float(np.hypot(result["north_m"], result["east_m"]))
    result["position_m"] = float(np.sqrt(np.mean(np.sum(errors**2, axis=1))))
    result["tension_n"] = float(np.sqrt(np.mean(np.square(tension_err))))
    result["thrust_n"] = float(np.sqrt(np.nanmean(np.square(thrust_err))))
    return result


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Flight source, scenarios and seeds."""
    parser.add_argument("--log", type=Path, help="identify from this log instead of flying one")
    parser.add_argument(
        "--flight-seed", type=int, default=0, help="noise seed of the identification flight"
    )
    parser.add_argument(
        "--flight-scenario",
        default="hover",
        help="scenario whose vehicle, sensors, wind and propulsion the identification flight "
        "is flown with (e.g. realistic-circle: every error source on)",
    )
    parser.add_argument(
        "--scenario",
        action="append",
        help="evaluation scenario (name or path; repeat; default paper-circle)",
    )
    parser.add_argument("--seeds", type=int, default=3, help="estimation runs per thrust input")
    parser.add_argument(
        "--first-seed", type=int, default=1, help="seed of the first evaluation run"
    )
    parser.add_argument(
        "--duration-s", type=float, help="evaluation flight length [s] (default: the scenario's)"
    )
    add_battery_arguments(parser, "the flight scenario's pack; the profile's with --log")


def thrust_inputs(
    results: list[StructureResult],
    chosen: StructureResult,
    data: IdData,
    vehicle: VehicleProfile,
    pwm_range: tuple[float, float],
    battery: BatteryCompensation | None = None,
) -> dict[str, Callable[[Scenario], ThrustInput]]:
    """Row label -> a fresh thrust input for a scenario (the true map depends on it); the
    identified ones compensate over ``battery`` (the range they were identified with)."""
    by_prediction = best_result(results, "prediction")
    by_simulation = best_result(results, "simulation")
    naive = naive_linear_curve([data], pwm_range)

    roles: dict[str, list[str]] = {chosen.structure: ["written"]}
    if by_prediction is not None:
        roles.setdefault(by_prediction.structure, []).append("best k-step Fit% (Table 1)")
    if by_simulation is not None:
        roles.setdefault(by_simulation.structure, []).append("best sim. Fit% (old rule)")
    models = {r.structure: r.model for r in results if r.ok}
    if "arx" in models:  # the structure Table 1's criterion picked in the issue's flight
        roles.setdefault("arx", [])
    inputs: dict[str, Callable[[Scenario], ThrustInput]] = {
        "naive linear (eq. 19)": lambda _: StaticThrustInput(
            StaticModelFile(
                n_motors=vehicle.n_motors,
                thrust_curve=naive,
                battery=battery or BatteryCompensation(),
            )
        ),
    }
    for structure, what in roles.items():
        mapping = model_file_mapping(models[structure].to_mapping(), {}, battery)
        inputs[f"{structure}: {', '.join(what)}" if what else structure] = lambda _, m=mapping: (
            thrust_input_from_mapping(m)
        )
    inputs["true map (scale, battery)"] = lambda s: true_thrust_input(vehicle, s.propulsion)
    inputs["profile's curve"] = lambda _: StaticThrustInput(vehicle)
    return inputs


COLUMNS = (
    ("North [m]", "north_m"),
    ("East [m]", "east_m"),
    ("Down [m]", "down_m"),
    ("Horiz. [m]", "horizontal_m"),
    ("Tension [N]", "tension_n"),
    ("Thrust [N]", "thrust_n"),
)


def evaluation_table(
    name: str,
    scenario: Scenario,
    inputs: dict[str, Callable[[Scenario], ThrustInput]],
    seeds: list[int],
) -> Table:
    """One scenario's table: mean RMSE over ``seeds`` per thrust input, and / true map."""
    table = Table(
        title=f"4-state EKF on {name}: RMSE after {SCORE_FROM_S:.0f} s, mean of seeds "
        f"{seeds[0]}-{seeds[-1]}"
    )
    table.add_column("Thrust input")
    for column, _ in COLUMNS:
        table.add_column(escape(column), justify="right")
    table.add_column("3-D / true", justify="right")
    means: dict[str, dict[str, float]] = {}
    for label, make in inputs.items():
        if label == "profile's curve" and scenario.propulsion.exact:
            continue  # the same as the true map
        runs = [run_four_state(scenario, make(scenario), seed) for seed in seeds]
        means[label] = {key: float(np.mean([r[key] for r in runs])) for key in runs[0]}
    reference = means["true map (scale, battery)"]["position_m"]
    for label, mean in means.items():
        table.add_row(
            label,
            *(f"{mean[key]:.3f}" for _, key in COLUMNS),
            f"{mean['position_m'] / reference:.2f}",
        )
    return table


@dataclasses.dataclass(frozen=True)
class Identified:
    """An identification flight's outcome: what ``sysid`` prints and writes."""

    vehicle: VehicleProfile
    estimation: IdData
    results: list[StructureResult]
    chosen: StructureResult | None
    scores: dict[str, SelectionScore]
    battery: BatteryCompensation | None = None
    """The range the commands were compensated with (None: uncompensated)."""
    battery_note: str = ""
    """One line saying whether and why the commands were compensated."""


def pack_range(scenario: Scenario) -> BatteryCompensation:
    """The compensation range a user sets for ``scenario``'s pack: full and empty cell voltage
    times the cells (ArduPilot's advice for MOT_BAT_VOLT_MAX/MIN: 4.2 and 3.3 V per cell)."""
    pack = scenario.propulsion.battery
    return BatteryCompensation(
        voltage_max_v=pack.cells * pack.full_cell_voltage_v,
        voltage_min_v=pack.cells * pack.empty_cell_voltage_v,
    )


def identify_flight(
    log: Path | None,
    base: Scenario,
    seed: int,
    structures: Sequence[str] = tuple(STRUCTURES),
    battery: BatteryCompensation | None = None,
) -> Identified:
    """Identify ``structures`` (default all) from ``log``, or from the identification flight
    flown now with ``base``'s vehicle, sensors, wind and propulsion and noise ``seed``; the
    commands compensated over ``battery`` (default: the vehicle profile's range) when the log
    has a voltage."""
    with tempfile.TemporaryDirectory() as folder:
        if log is None:
            log = Path(folder) / "identification.tlog"
            vehicle = record_identification_flight(log, scenario=base, seed=seed).vehicle
        else:
            vehicle = load_vehicle(base.vehicle)
        curve = vehicle.thrust_curve
        pwm_range = (curve.pwm_min_us, curve.pwm_max_us)
        battery = battery or vehicle.battery
        logs, compensated, note = compensate_logs([load_flight_log(log)], battery, pwm_range)
        data = prepare(logs[0], vehicle.mass_kg, pwm_range)
    results = identify([data.estimation], [data.validation], pwm_range, structures)
    chosen, scores = select(results, [data.validation], pwm_range)
    used = battery if compensated else None
    return Identified(vehicle, data.estimation, results, chosen, scores, used, note)


def run(args: argparse.Namespace) -> int:
    """Identify, then run the EKF with each thrust input; print the tables."""
    console = Console()
    if args.seeds < 1:
        raise InputError(f"--seeds must be >= 1, got {args.seeds}")
    if args.duration_s is not None and not args.duration_s > SCORE_FROM_S:
        raise InputError(f"--duration-s must be > {SCORE_FROM_S}, got {args.duration_s}")
    names = args.scenario or ["paper-circle"]
    scenarios = [load_scenario(name) for name in names]
    if args.duration_s is not None:
        scenarios = [dataclasses.replace(s, duration_s=args.duration_s) for s in scenarios]
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    if args.log is None:
        base = load_scenario(args.flight_scenario)
        battery = battery_range(args, pack_range(base))
        identified = identify_flight(None, base, args.flight_seed, battery=battery)
        console.print(
            f"identification flight: simulated on {args.flight_scenario}, seed "
            f"{args.flight_seed}, vehicle {identified.vehicle.name}"
        )
        if args.flight_seed in seeds:
            console.print("[yellow]the identification seed is also an evaluation seed[/]")
    else:
        base = load_scenario(names[0])
        battery = battery_range(args, load_vehicle(base.vehicle).battery)
        identified = identify_flight(args.log, base, 0, battery=battery)
    console.print(identified.battery_note)
    vehicle, data, results = identified.vehicle, identified.estimation, identified.results
    chosen, scores = identified.chosen, identified.scores
    best = best_result(results, "prediction")
    console.print(
        results_table(
            results,
            5,
            best.structure if best else None,
            chosen.structure if chosen else None,
            scores=scores,
        )
    )
    if chosen is None:
        console.print("[red]no structure could be identified[/red]")
        return 1
    curve = vehicle.thrust_curve
    inputs = thrust_inputs(
        results, chosen, data, vehicle, (curve.pwm_min_us, curve.pwm_max_us), identified.battery
    )
    for name, scenario in zip(names, scenarios, strict=True):
        if load_vehicle(scenario.vehicle).name != vehicle.name:
            console.print(
                f"[yellow]{name} flies {scenario.vehicle}, the model was identified on "
                f"{vehicle.name}[/]"
            )
        console.print(evaluation_table(name, scenario, inputs, seeds))
    return 0
