"""``bench speed``: real-time factor of simulator + both EKFs, and the EKF step vs filterpy's.

1. Flies the paper scenario (60 s) once with the simulator alone and once with the
   simulator and both EKFs (the ``simulate`` path), and prints wall times and real-time
   factors (simulated seconds per wall-clock second).
2. Records the 4-state filter's inputs from a simulated run, then replays them through our
   :class:`ExtendedKalmanFilter` and through ``filterpy.kalman.ExtendedKalmanFilter`` with
   the same model, Q, R and Joseph-form update, and prints the cost per IMU step (predict +
   accelerometer update + altimeter update) of each, their ratio, and the largest difference
   between the two filters' estimates (they compute the same thing; gating is off here).
3. Replays the same 20 s synthetic hover, written as a .tlog and as an ArduPilot dataflash
   .bin, through the service pipeline with the service's default estimator (the dynamic
   filter) and with the paper 4-state, and prints each one's CPU real-time factor.
4. Replays the same 20 s of the realistic circle's samples through the paper 4-state
   estimator and the dynamic 17-state one (whole pipelines, ``bench dynamic``'s
   measurement, CPU time), with its default settings and its former, dearer ones, and prints
   each one's time per IMU tick and the ratios.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from tether_companion.bench.dynamic import FORMER_LABEL, step_costs
from tether_companion.estimation.config import EstimatorConfig, load_estimator_config
from tether_companion.estimation.ekf import ExtendedKalmanFilter
from tether_companion.estimation.runner import run_scenario
from tether_companion.estimation.tether_models import FourStateModel, altimeter
from tether_companion.estimation.thrust_input import StaticThrustInput
from tether_companion.frames import rotation_ned_to_body
from tether_companion.sim.scenario import Scenario, load_scenario
from tether_companion.sim.simulator import Simulator

FILTER_SCENARIO = "realistic-circle"
"""The flight the dynamic and the paper 4-state estimators are timed on (every error source)."""

HELP = "Real-time factor of simulator + EKFs, and EKF step cost against filterpy's EKF."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Scenario, estimator config, JSON output."""
    parser.add_argument(
        "--scenario", default="paper-circle", help="scenario (default paper-circle)"
    )
    parser.add_argument(
        "--config", default=None, help="estimator YAML (default configs/estimator.yaml)"
    )
    parser.add_argument("--json", action="store_true", help="print the results as JSON only")
    parser.add_argument(
        "--repeat",
        type=int,
        default=3,
        choices=range(1, 21),
        metavar="N",
        help="time each run N times and keep the fastest (default 3)",
    )


def _fly_sim_only(scenario: Scenario) -> None:
    """Fly the scenario and read every sensor (and the truth) at the IMU rate."""
    sim = Simulator(scenario)
    period = 1.0 / scenario.sensors.imu_rate_hz
    for k in range(1, int(scenario.duration_s / period + 1e-9) + 1):
        sim.advance_to(k * period)
        sim.read_attitude()
        sim.read_pwm()
        sim.read_imu()
        sim.read_rangefinder()
        sim.position_ned_m  # noqa: B018  (the runner reads the true position and tension too)
        sim.tension_n  # noqa: B018


def _best_times(job, repeat: int) -> tuple[float, float]:
    """Smallest wall-clock and process CPU time [s] of ``repeat`` calls of ``job()``."""
    wall, cpu = math.inf, math.inf
    for _ in range(repeat):
        wall0, cpu0 = time.perf_counter(), time.process_time()
        job()
        wall = min(wall, time.perf_counter() - wall0)
        cpu = min(cpu, time.process_time() - cpu0)
    return wall, cpu


def _record(scenario: Scenario, ticks: int) -> list[tuple]:
    """(dt, rotation, thrust, specific force, height or None) per IMU tick."""
    sim = Simulator(scenario)
    thrust_input = StaticThrustInput(sim.vehicle)
    period = 1.0 / scenario.sensors.imu_rate_hz
    rows = []
    for k in range(1, ticks + 1):
        sim.advance_to(k * period)
        att, pwm, imu, rng = (
            sim.read_attitude(),
            sim.read_pwm(),
            sim.read_imu(),
            sim.read_rangefinder(),
        )
        rotation = rotation_ned_to_body(att.roll_rad, att.pitch_rad, att.yaw_rad)
        height = None
        if rng is not None:
            height = rng.distance_m * math.cos(att.roll_rad) * math.cos(att.pitch_rad)
        thrust = float(thrust_input.total_thrust_n(pwm.pwm_us, pwm.time_s))
        rows.append((period, rotation, thrust, imu.specific_force_body_mps2, height))
    return rows


def _ours(
    rows: list[tuple], config: EstimatorConfig, model: FourStateModel, *, scalar: bool = True
) -> tuple[float, np.ndarray]:
    """Our filter on the recorded inputs: the service's scalar update (``update_values``), or
    with ``scalar=False`` the numpy reference path (``update`` with a measurement function)."""
    ekf = ExtendedKalmanFilter(config.x0(), config.p0(), config.q_density())
    r_acc = config.accel_noise.variance_mps2_sq
    r_alt = config.altimeter_noise_variance_m2
    alt_jacobian = tuple(altimeter(ekf.x)[1].ravel().tolist())
    inputs = [
        (dt, rotation.tolist(), thrust, accel.tolist(), height, rotation, accel)
        for dt, rotation, thrust, accel, height in rows
    ]
    out = []
    started = time.process_time()
    for dt, rot_rows, thrust, acc, height, rotation, accel in inputs:
        ekf.predict(dt)
        if scalar:
            predicted, jacobian = model.accel_values(ekf.x_values(), rot_rows, thrust)
            innovation = [acc[0] - predicted[0], acc[1] - predicted[1], acc[2] - predicted[2]]
            ekf.update_values("accel", innovation, jacobian, r_acc)
            if height is not None:
                innovation = [height + ekf.x_values()[2]]
                ekf.update_values("altimeter", innovation, alt_jacobian, r_alt, constant=True)
        else:
            ekf.update(
                "accel",
                accel,
                lambda x, r=rotation, t=thrust: model.accel(x, r, t),
                np.eye(3) * r_acc,
            )
            if height is not None:
                ekf.update("altimeter", np.array((height,)), altimeter, np.array([[r_alt]]))
        out.append(ekf.x_values())
    return time.process_time() - started, np.array(out)


def _filterpy(
    rows: list[tuple], config: EstimatorConfig, model: FourStateModel
) -> tuple[float, np.ndarray]:
    from filterpy.kalman import ExtendedKalmanFilter as FilterpyEKF

    ekf = FilterpyEKF(dim_x=4, dim_z=3)
    ekf.x = config.x0().reshape(4, 1)
    ekf.P = config.p0()
    ekf.F = np.eye(4)
    r_acc = np.eye(3) * config.accel_noise.variance_mps2_sq
    r_alt = np.array([[config.altimeter_noise_variance_m2]])
    q_density = config.q_density()

    def h_acc(x, rotation, thrust):
        return model.accel(x.ravel(), rotation, thrust)[0].reshape(3, 1)

    def jac_acc(x, rotation, thrust):
        return model.accel(x.ravel(), rotation, thrust)[1]

    def h_alt(x):
        return np.array([[-x[2, 0]]])

    def jac_alt(x):
        return altimeter(x.ravel())[1]

    out = np.empty((len(rows), 4))
    started = time.process_time()
    for i, (dt, rotation, thrust, accel, height) in enumerate(rows):
        ekf.Q = q_density * dt
        ekf.predict()
        args = (rotation, thrust)
        ekf.update(accel.reshape(3, 1), jac_acc, h_acc, R=r_acc, args=args, hx_args=args)
        if height is not None:
            ekf.update(np.array([[height]]), jac_alt, h_alt, R=r_alt)
        out[i] = ekf.x.ravel()
    return time.process_time() - started, out


def _write_logs(directory: Path, seconds: float) -> tuple[Path, Path]:
    """The same synthetic hover (RAW_IMU at 200 Hz, ATTITUDE and SERVO_OUTPUT_RAW at 100 Hz,
    DISTANCE_SENSOR at 20 Hz: :meth:`HoverStreams.messages`) as a .tlog and as an ArduPilot
    dataflash .bin (IMU, ATT, RCOU, RFND in the log's own units)."""
    from tether_companion.mavlink.framing import FrameEncoder
    from tether_companion.mavlink.units import (
        attitude_from_attitude,
        imu_from_raw_imu,
        pwm_from_servo_output_raw,
        range_from_distance_sensor,
    )
    from tether_companion.service.config import load_service_config, load_vehicle_for
    from tether_companion.service.recording import RecordingLimits, TlogWriter
    from tether_companion.service.replay import DATAFLASH_DOWNWARD
    from tether_companion.service.synthetic import HoverStreams
    from tether_companion.sysid.logs.dataflash_writer import DataflashWriter

    vehicle = load_vehicle_for(load_service_config(None, {}))
    streams = HoverStreams(vehicle, np.array([2.0, 1.0, -3.0]), 4.0, rng=np.random.default_rng(5))
    encoder = FrameEncoder(1, 1)
    limits = RecordingLimits(max_file_bytes=1 << 30, max_total_bytes=1 << 31, flush_interval_s=1.0)
    writer = TlogWriter(directory, limits)
    bin_path = directory / "hover.bin"
    channels = tuple(f"C{i + 1}" for i in range(vehicle.n_motors))
    with bin_path.open("wb") as stream:
        log = DataflashWriter(stream)
        log.declare(
            "IMU", "QBffffff", ("TimeUS", "I", "GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ")
        )
        log.declare("ATT", "Qfff", ("TimeUS", "Roll", "Pitch", "Yaw"))
        log.declare("RCOU", "Q" + "H" * len(channels), ("TimeUS", *channels))
        log.declare("RFND", "QBfB", ("TimeUS", "Instance", "Dist", "Orient"))
        for k in range(int(seconds * 200)):
            for msg in streams.messages(20.0 + k * 0.005, k):
                writer.write(encoder.encode(msg))
                kind = msg.get_type()
                if kind == "RAW_IMU":
                    imu = imu_from_raw_imu(msg)
                    t_us = round(imu.time_s * 1e6)
                    log.write(
                        "IMU", t_us, 0, *imu.angular_rate_body_rad_s, *imu.specific_force_body_mps2
                    )
                elif kind == "ATTITUDE":
                    att = attitude_from_attitude(msg)
                    angles = (att.roll_rad, att.pitch_rad, att.yaw_rad)
                    log.write("ATT", round(att.time_s * 1e6), *(math.degrees(a) for a in angles))
                elif kind == "SERVO_OUTPUT_RAW":
                    pwm = pwm_from_servo_output_raw(msg, vehicle.n_motors)
                    log.write("RCOU", round(pwm.time_s * 1e6), *(round(p) for p in pwm.pwm_us))
                elif kind == "DISTANCE_SENSOR" and (rng := range_from_distance_sensor(msg)):
                    log.write(
                        "RFND", round(rng.time_s * 1e6), 0, rng.distance_m, DATAFLASH_DOWNWARD
                    )
    writer.close()
    assert writer.current_path is not None
    return writer.current_path, bin_path


REPLAY_ESTIMATORS = ("dynamic", "four_state")
"""Estimator kinds replay is timed with: the service's default, and the paper's 4-state."""


def _replay_cpu(repeat: int, seconds: float = 20.0) -> dict[tuple[str, str], float]:
    """Least CPU time [s] of replaying ``seconds`` of a synthetic hover through the service
    pipeline, from a .tlog (``tlog``) and from a dataflash .bin (``bin``), with each of
    :data:`REPLAY_ESTIMATORS`; keyed ``(estimator kind, log kind)``."""
    import io
    import tempfile

    from tether_companion.service.config import load_service_config, load_vehicle_for
    from tether_companion.service.replay import replay_log

    configs = {
        kind: load_service_config(
            None, {"recording": {"enabled": False}, "estimator": {"kind": kind}}
        )
        for kind in REPLAY_ESTIMATORS
    }
    vehicle = load_vehicle_for(configs[REPLAY_ESTIMATORS[0]])
    best = {(kind, log): math.inf for kind in REPLAY_ESTIMATORS for log in ("tlog", "bin")}
    with tempfile.TemporaryDirectory() as directory:
        paths = dict(zip(("tlog", "bin"), _write_logs(Path(directory), seconds), strict=True))
        for _ in range(repeat):  # interleaved
            for kind, log in best:
                started = time.process_time()
                replay_log(paths[log], configs[kind], vehicle, io.StringIO())
                best[kind, log] = min(best[kind, log], time.process_time() - started)
    return best


def run(args: argparse.Namespace) -> int:
    """Time everything and print a table (or JSON).

    An EKF step is one IMU tick of the 4-state filter: predict, accelerometer update,
    altimeter update.
    """
    console = Console(stderr=args.json)
    scenario = load_scenario(args.scenario)
    config = load_estimator_config(args.config)
    console.print(f"flying {args.scenario} ({scenario.duration_s:g} s) ...")
    sim_s, sim_cpu_s = _best_times(lambda: _fly_sim_only(scenario), args.repeat)
    full_s, full_cpu_s = _best_times(lambda: run_scenario(scenario, config), args.repeat)

    ungated = dataclasses.replace(config, gate=dataclasses.replace(config.gate, probability=1.0))
    ticks = int(min(scenario.duration_s, 20.0) * scenario.sensors.imu_rate_hz)
    rows = _record(scenario, ticks)
    model = FourStateModel(Simulator(scenario).vehicle.mass_kg)
    ours_s, numpy_s, theirs_s = math.inf, math.inf, math.inf
    for _ in range(args.repeat):  # interleaved, so all see the same machine load
        elapsed, ours_x = _ours(rows, ungated, model)
        ours_s = min(ours_s, elapsed)
        elapsed, numpy_x = _ours(rows, ungated, model, scalar=False)
        numpy_s = min(numpy_s, elapsed)
        try:
            elapsed, theirs_x = _filterpy(rows, ungated, model)
        except ImportError:
            theirs_s, theirs_x = math.nan, np.full_like(ours_x, np.nan)
            console.print("filterpy is not installed (pip install -e '.[bench]'): no comparison")
            break
        theirs_s = min(theirs_s, elapsed)
    replay_flight_s = 20.0
    replay_cpu_s = _replay_cpu(args.repeat, replay_flight_s)
    filters = step_costs(FILTER_SCENARIO, replay_flight_s, args.repeat)
    results = {
        "scenario": args.scenario,
        "simulated_s": scenario.duration_s,
        "repeat": args.repeat,
        "sim_only_wall_s": sim_s,
        "sim_only_cpu_s": sim_cpu_s,
        "sim_only_real_time_factor": scenario.duration_s / sim_s,
        "sim_and_both_ekfs_wall_s": full_s,
        "sim_and_both_ekfs_cpu_s": full_cpu_s,
        "sim_and_both_ekfs_real_time_factor": scenario.duration_s / full_s,
        "sim_and_both_ekfs_real_time_factor_cpu": scenario.duration_s / full_cpu_s,
        "ekf_steps": len(rows),
        "ours_us_per_step": ours_s / len(rows) * 1e6,
        "ours_numpy_us_per_step": numpy_s / len(rows) * 1e6,
        "filterpy_us_per_step": theirs_s / len(rows) * 1e6,
        "filterpy_over_ours": theirs_s / ours_s,
        "max_state_difference": float(np.max(np.abs(ours_x - theirs_x))),
        "max_state_difference_scalar_vs_numpy": float(np.max(np.abs(ours_x - numpy_x))),
        "replay_flight_s": replay_flight_s,
        **{
            f"replay_{log}_{key}_{kind}": value
            for (kind, log), cpu in replay_cpu_s.items()
            for key, value in (("cpu_s", cpu), ("real_time_factor_cpu", replay_flight_s / cpu))
        },
        "filter_step_us_paper_4s": filters["us_per_tick"]["paper_4s"],
        "filter_step_us_dynamic": filters["us_per_tick"]["dynamic"],
        "filter_step_ratio_dynamic_to_paper": filters["ratio_dynamic_to_paper"],
        "filter_step_us_dynamic_former": filters["us_per_tick"]["dynamic_former"],
        "filter_step_ratio_dynamic_former_to_paper": filters["ratio_dynamic_former_to_paper"],
    }
    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    table = Table(title=f"bench speed: {args.scenario}, {scenario.duration_s:g} s simulated")
    table.add_column(f"measure (best of {args.repeat})")
    table.add_column("value", justify="right")
    duration = scenario.duration_s
    for label, wall, cpu in (
        ("sim alone", sim_s, sim_cpu_s),
        ("sim + 3S + 4S EKFs", full_s, full_cpu_s),
    ):
        table.add_row(f"{label}, wall", f"{wall:.2f} s = {duration / wall:.1f}x real time")
        table.add_row(f"{label}, CPU", f"{cpu:.2f} s = {duration / cpu:.1f}x real time")
    table.add_row("EKF step, ours (scalar, as run), CPU", f"{results['ours_us_per_step']:.1f} us")
    table.add_row("EKF step, ours (numpy reference), CPU", f"{numpy_s / len(rows) * 1e6:.1f} us")
    table.add_row("EKF step, filterpy (peer), CPU", f"{results['filterpy_us_per_step']:.1f} us")
    table.add_row("filterpy / ours", f"{results['filterpy_over_ours']:.2f}")
    table.add_row("max |x ours - x filterpy|", f"{results['max_state_difference']:.1e}")
    table.add_row(
        "max |x scalar - x numpy|", f"{results['max_state_difference_scalar_vs_numpy']:.1e}"
    )
    for (kind, log), cpu in replay_cpu_s.items():
        name = ".tlog" if log == "tlog" else "dataflash .bin"
        table.add_row(
            f"replay of a {replay_flight_s:.0f} s {name}, {kind} filter, CPU",
            f"{cpu:.2f} s = {replay_flight_s / cpu:.1f}x real time",
        )
    us = filters["us_per_tick"]
    label = f"{FILTER_SCENARIO} {replay_flight_s:.0f} s, per IMU tick"
    table.add_row(f"paper 4-state estimator, {label}", f"{us['paper_4s']:.1f} us")
    table.add_row(
        f"dynamic 17-state estimator (whole run), {label}",
        f"{us['dynamic']:.1f} us = {filters['ratio_dynamic_to_paper']:.2f}x the 4-state",
    )
    former_ratio = filters["ratio_dynamic_former_to_paper"]
    table.add_row(
        f"same, {FORMER_LABEL}",
        f"{us['dynamic_former']:.1f} us = {former_ratio:.2f}x the 4-state",
    )
    console.print(table)
    return 0
