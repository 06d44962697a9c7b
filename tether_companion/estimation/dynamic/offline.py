"""Offline runs of the dynamic filter on the simulator, beside the paper's 4-state filter.

One run flies a scenario with :class:`~tether_companion.sim.simulator.Simulator`, feeds its
samples at their own rates to a :class:`DynamicTetherEstimator` and to the paper's 4-state
:class:`~tether_companion.estimation.pipeline.TetherEstimator` (one shared aligner), and
keeps the truth, both estimates, the dynamic filter's 6x6 covariance and status per IMU tick.
Pure and synchronous (the simulator's randomness comes from the scenario seed or ``rng``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.output import OK
from tether_companion.estimation.feed import imu_count, imu_ticks, schedule, simulated
from tether_companion.estimation.pipeline import TetherEstimator
from tether_companion.estimation.thrust_input import ThrustInput
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.sim.scenario import Scenario
from tether_companion.sim.simulator import Simulator

FloatArray = NDArray[np.float64]


class ScaledThrustInput:
    """Another thrust map times ``scale``: a thrust map ``scale - 1`` off (e.g. 1/1.1 when the
    true thrust is 10 % above the map's)."""

    def __init__(self, inner: ThrustInput, scale: float) -> None:
        self.inner = inner
        self.scale = scale

    def total_thrust_n(self, pwm_us: FloatArray, time_s: float) -> float:
        """The inner map's total thrust [N] times the scale."""
        return self.scale * self.inner.total_thrust_n(pwm_us, time_s)


@dataclass(frozen=True)
class DynamicRun:
    """Per-tick series of one run (N IMU ticks; NaN where a filter had no estimate).

    Attributes
    ----------
    time_s
        (N,) [s].
    truth_position_ned_m, truth_velocity_ned_mps, truth_tension_n
        Simulator truth, (N, 3) [m], (N, 3) [m/s], (N,) [N].
    position_ned_m, velocity_ned_mps, tension_n
        Dynamic filter, (N, 3) [m], (N, 3) [m/s], (N,) [N].
    covariance
        Its position-velocity covariance, (N, 6, 6).
    status
        Its status per tick, (N,) str.
    thrust_scale, accel_bias_body_mps2
        Its thrust scale (N,) and bias (N, 3) [m/s^2].
    paper_position_ned_m, paper_variance_m2
        The paper's 4-state filter on the same samples: (N, 3) [m] and its position
        variances (N, 3) [m^2].
    accel_nis
        NIS of the accelerometer force balance at each tick (N,) (``nan`` when not fused).
    estimator
        The dynamic estimator at the end (health, aid statuses).
    """

    time_s: FloatArray
    truth_position_ned_m: FloatArray
    truth_velocity_ned_mps: FloatArray
    truth_tension_n: FloatArray
    position_ned_m: FloatArray
    velocity_ned_mps: FloatArray
    tension_n: FloatArray
    covariance: FloatArray
    status: NDArray[np.str_]
    thrust_scale: FloatArray
    accel_bias_body_mps2: FloatArray
    paper_position_ned_m: FloatArray
    paper_variance_m2: FloatArray
    accel_nis: FloatArray
    estimator: DynamicTetherEstimator

    @property
    def published(self) -> NDArray[np.bool_]:
        """Ticks whose status is ``ok``, (N,)."""
        return self.status == OK


def run_dynamic(
    scenario: Scenario,
    config: EstimatorConfig,
    dynamic: DynamicFilterConfig | None = None,
    *,
    rng: np.random.Generator | None = None,
    thrust_input: ThrustInput | None = None,
    vehicle: VehicleProfile | None = None,
) -> DynamicRun:
    """Fly ``scenario``; run the dynamic filter and the paper's 4-state filter on its sensors.

    ``thrust_input``: the PWM-to-thrust map both filters use (default: the vehicle profile's
    static curve; a :class:`ScaledThrustInput` makes it wrong on purpose). ``vehicle``: the
    simulated vehicle when not the scenario's profile (both filters are given it too).
    """
    sim = Simulator(scenario, vehicle, rng=rng)
    vehicle = sim.vehicle
    paper = TetherEstimator(dataclasses.replace(config, kind="four_state"), vehicle, thrust_input)
    est = DynamicTetherEstimator(config, vehicle, dynamic, aligner=paper.aligner)
    due = schedule(scenario)
    n = imu_count(due)
    t = np.full(n, np.nan)
    tp, tv, tt = np.full((n, 3), np.nan), np.full((n, 3), np.nan), np.full(n, np.nan)
    pos, vel, ten = np.full((n, 3), np.nan), np.full((n, 3), np.nan), np.full(n, np.nan)
    cov = np.full((n, 6, 6), np.nan)
    status = np.full(n, "none", dtype=object)
    scale, bias = np.full(n, np.nan), np.full((n, 3), np.nan)
    pp, pv = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    nis = np.full(n, np.nan)
    tick = 0
    for imu in imu_ticks(simulated(sim, due), paper, est):
        truth = sim.truth  # the simulator is at the IMU sample's instant
        t[tick] = imu.time_s
        tp[tick], tv[tick], tt[tick] = (
            truth.position_ned_m,
            truth.velocity_ned_m_s,
            truth.tension_n,
        )
        e4 = paper.on_imu(imu)
        if e4 is not None:
            pp[tick], pv[tick] = e4.position_ned_m, e4.covariance.diagonal()[:3]
        e = est.on_imu(imu)
        if e is not None:
            pos[tick], vel[tick], ten[tick] = e.position_ned_m, e.velocity_ned_mps, e.tension_n
            cov[tick] = e.position_velocity_covariance
            status[tick] = e.status
            scale[tick], bias[tick] = e.thrust_scale, e.accel_bias_body_mps2
            if e.accel_fused:
                nis[tick] = est.health.last_accel_nis
        tick += 1
    return DynamicRun(
        time_s=t[:tick],
        truth_position_ned_m=tp[:tick],
        truth_velocity_ned_mps=tv[:tick],
        truth_tension_n=tt[:tick],
        position_ned_m=pos[:tick],
        velocity_ned_mps=vel[:tick],
        tension_n=ten[:tick],
        covariance=cov[:tick],
        status=status[:tick].astype(str),
        thrust_scale=scale[:tick],
        accel_bias_body_mps2=bias[:tick],
        paper_position_ned_m=pp[:tick],
        paper_variance_m2=pv[:tick],
        accel_nis=nis[:tick],
        estimator=est,
    )
