"""One simulated flight with every estimator kind riding along: truth and outputs per IMU tick.

The scenario is flown once by :class:`~tether_companion.sim.simulator.Simulator`; its samples
are handed to each kind in time order (the schedule of
:mod:`~tether_companion.estimation.runner`: attitude, PWM, rangefinder, then the ground
station and the IMU at each instant). Pure and synchronous; runs on a Dask worker.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.bench.estimators import SIMULATORS
from tether_companion.bench.estimators.registry import (
    EstimatorKind,
    FlightContext,
    GroundStation,
)
from tether_companion.estimation.feed import RANGE, hand_over, imu_count, schedule, simulated
from tether_companion.physics.cable import cable_weight_n_per_m
from tether_companion.physics.vehicle import VehicleProfile, load_vehicle
from tether_companion.sim.ground_sensors import GroundSensors
from tether_companion.sim.scenario import Scenario
from tether_companion.sim.simulator import Simulator

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class KindTrace:
    """One kind's outputs at every IMU tick (``nan`` rows where it had none).

    Attributes
    ----------
    position_ned_m, position_covariance_m2
        Shapes (N, 3) [m] and (N, 3, 3) [m^2].
    velocity_ned_mps
        Shape (N, 3) [m/s].
    tension_n, tension_variance_n2
        Shapes (N,) [N], [N^2].
    published
        Shape (N,), bool.
    """

    position_ned_m: FloatArray
    position_covariance_m2: FloatArray
    velocity_ned_mps: FloatArray
    tension_n: FloatArray
    tension_variance_n2: FloatArray
    published: NDArray[np.bool_]


@dataclass(frozen=True)
class FlightRecord:
    """Truth and every kind's trace at the IMU ticks of one flight.

    Attributes
    ----------
    time_s
        Tick times, shape (N,) [s].
    position_ned_m, velocity_ned_mps, euler_rad
        True position [m], velocity [m/s], (roll, pitch, yaw) [rad], shapes (N, 3).
    tension_n, thrust_n
        True cable tension at the drone and total rotor thrust, shapes (N,) [N].
    range_seen
        Whether a rangefinder sample was produced since the previous tick, shape (N,).
    cable_force_ned_n, wind_ned_mps
        The cable's force on the drone [N] and the wind at the drone [m/s], NED, (N, 3).
    specific_force_body_mps2
        The accelerometer's true specific force without noise or bias, FRD, (N, 3) [m/s^2].
    angle_seen
        Whether the ground station's cable-angle sensor reported at the tick, shape (N,).
    winch_seen
        Whether the ground station's winch reported its length at the tick, shape (N,).
    landed
        Whether the drone rested on the ground at the tick, shape (N,).
    traces
        Kind name -> :class:`KindTrace`.
    """

    time_s: FloatArray
    position_ned_m: FloatArray
    velocity_ned_mps: FloatArray
    euler_rad: FloatArray
    tension_n: FloatArray
    thrust_n: FloatArray
    range_seen: NDArray[np.bool_]
    cable_force_ned_n: FloatArray
    wind_ned_mps: FloatArray
    specific_force_body_mps2: FloatArray
    angle_seen: NDArray[np.bool_]
    winch_seen: NDArray[np.bool_]
    landed: NDArray[np.bool_]
    traces: dict[str, KindTrace]


def make_simulator(scenario: Scenario, simulator: str = "ours") -> Simulator:
    """The simulator named ``simulator`` (one of :data:`SIMULATORS`) flying ``scenario``."""
    if simulator == "rotorpy":
        from tether_companion.crosscheck.rotorpy_sim import RotorpySimulator

        return RotorpySimulator(scenario)  # type: ignore[return-value]
    if simulator != "ours":
        raise ValueError(f"simulator must be one of {SIMULATORS}, got {simulator!r}")
    return Simulator(scenario)


def fly(
    scenario: Scenario,
    kinds: list[EstimatorKind],
    simulator: str = "ours",
    estimator_vehicle: VehicleProfile | None = None,
) -> FlightRecord:
    """Fly ``scenario`` (seeded by ``scenario.seed``) on ``simulator`` with every kind.

    The kinds are given ``estimator_vehicle`` as the nominal profile (default: the
    scenario's), while the simulator flies the scenario's vehicle (``bench sensitivity``).
    """
    sim = make_simulator(scenario, simulator)
    nominal = estimator_vehicle or load_vehicle(scenario.vehicle)
    context = FlightContext(scenario, nominal, sim.gravity_mps2)
    estimators = [kind.build(context) for kind in kinds]
    due = schedule(scenario)
    n = imu_count(due)
    time_s = np.empty(n)
    truth = {
        name: np.empty((n, 3))
        for name in ("position", "velocity", "euler", "cable", "wind", "force")
    }
    tension, thrust = np.empty(n), np.empty(n)
    range_seen = np.zeros(n, dtype=bool)
    angle_seen = np.zeros(n, dtype=bool)
    winch_seen = np.zeros(n, dtype=bool)
    landed = np.zeros(n, dtype=bool)
    outputs = [_empty_trace(n) for _ in kinds]
    tick = 0
    seen = False
    ground = GroundSensors(
        scenario.ground_station,
        scenario.cable.model,
        scenario.seed,
        cable_weight_n_per_m(scenario.cable, sim.gravity_mps2),
    )
    for what, imu in simulated(sim, due):
        if hand_over(what, imu, estimators):  # an input, not an IMU sample
            seen = seen or what == RANGE
            continue
        state = sim.truth
        readings = ground.read(imu.time_s, sim.cable, tuple(state.position_ned_m), state.tension_n)
        station = GroundStation(
            imu.time_s,
            state.tension_n,
            readings.paid_out_m,
            readings.cable_angle_rad,
            readings.winch_tension_n,
        )
        angle_seen[tick] = readings.cable_angle_rad is not None
        winch_seen[tick] = readings.paid_out_m is not None
        time_s[tick] = imu.time_s
        truth["position"][tick] = state.position_ned_m
        truth["velocity"][tick] = state.velocity_ned_m_s
        truth["euler"][tick] = state.euler_rad
        truth["cable"][tick] = state.cable_force_ned_n
        truth["wind"][tick] = state.wind_ned_m_s
        truth["force"][tick] = state.specific_force_body_mps2
        tension[tick] = state.tension_n
        thrust[tick] = float(state.motor_thrust_n.sum())
        landed[tick] = state.landed
        range_seen[tick] = seen
        seen = False
        for estimator, out in zip(estimators, outputs, strict=True):
            estimator.on_ground_station(station)
            result = estimator.on_imu(imu)
            if result is not None:
                out["position"][tick] = result.position_ned_m
                out["covariance"][tick] = result.position_covariance_m2
                out["velocity"][tick] = result.velocity_ned_mps
                out["tension"][tick] = result.tension_n
                out["tension_variance"][tick] = result.tension_variance_n2
                out["published"][tick] = result.published
        tick += 1
    return FlightRecord(
        time_s=time_s,
        position_ned_m=truth["position"],
        velocity_ned_mps=truth["velocity"],
        euler_rad=truth["euler"],
        tension_n=tension,
        thrust_n=thrust,
        range_seen=range_seen,
        cable_force_ned_n=truth["cable"],
        wind_ned_mps=truth["wind"],
        specific_force_body_mps2=truth["force"],
        angle_seen=angle_seen,
        winch_seen=winch_seen,
        landed=landed,
        traces={
            kind.name: KindTrace(
                position_ned_m=out["position"],
                position_covariance_m2=out["covariance"],
                velocity_ned_mps=out["velocity"],
                tension_n=out["tension"],
                tension_variance_n2=out["tension_variance"],
                published=out["published"],
            )
            for kind, out in zip(kinds, outputs, strict=True)
        },
    )


def _empty_trace(n: int) -> dict[str, np.ndarray]:
    return {
        "position": np.full((n, 3), math.nan),
        "covariance": np.full((n, 3, 3), math.nan),
        "velocity": np.full((n, 3), math.nan),
        "tension": np.full(n, math.nan),
        "tension_variance": np.full(n, math.nan),
        "published": np.zeros(n, dtype=bool),
    }
