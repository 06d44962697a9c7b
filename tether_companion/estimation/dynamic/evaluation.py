"""Error-source runs of the dynamic filter beside the paper's 4-state (for ``bench dynamic
--errors`` and docs/estimation.md): the paper circle with the error sources today's simulator
offers, scored per run.

Error sources (each a switch of :class:`ErrorSources`): accelerometer bias (body, the
simulator's ``sensors.accel_bias_mps2``), a thrust map off by a factor (both filters get
:class:`~tether_companion.estimation.dynamic.offline.ScaledThrustInput`), airframe drag
(the simulated vehicle's linear drag coefficient; the filter is given the same coefficient, as
a profile would state it) and a steady wind acting through that drag.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.offline import DynamicRun, ScaledThrustInput, run_dynamic
from tether_companion.estimation.thrust_input import StaticThrustInput
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.scenario import load_scenario

FloatArray = NDArray[np.float64]

CHI2_3DOF_9973 = 14.156
"""Chi-square quantile, 3 dof, probability 0.9973 ("3 sigma" for a 3-D error)."""


@dataclass(frozen=True)
class ErrorSources:
    """What is wrong with the world the filters see (SI units)."""

    accel_bias_mps2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    true_thrust_over_map: float = 1.0
    drag_n_s_per_m: float = 0.0
    wind_ned_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)


ALL_ON = ErrorSources((0.15, -0.15, 0.15), 1.1, 0.3, (2.0, 1.0, 0.0))
"""Every source on: 0.15 m/s^2 bias per axis, thrust 10 % above the map, 0.3 N/(m/s) drag,
a 2.2 m/s wind."""


@dataclass(frozen=True)
class RunScore:
    """Scores of one run after ``settle_s`` (RMSE per axis [m], [m/s]; NEES means)."""

    dynamic_rmse_m: FloatArray
    dynamic_velocity_rmse_mps: FloatArray
    paper_rmse_m: FloatArray
    nees_position: float
    nees_position_velocity: float
    published_share: float
    published_beyond_3_sigma: float
    thrust_scale_end: float


def fly(
    tension_n: float,
    sources: ErrorSources,
    seed: int,
    duration_s: float = 40.0,
    dynamic: DynamicFilterConfig | None = None,
) -> DynamicRun:
    """The paper circle at ``tension_n`` [N] with ``sources``, seed ``seed``."""
    scenario = load_scenario("paper-circle")
    scenario = dataclasses.replace(
        scenario,
        duration_s=duration_s,
        seed=seed,
        cable=dataclasses.replace(scenario.cable, tension_n=tension_n),
        sensors=dataclasses.replace(scenario.sensors, accel_bias_mps2=sources.accel_bias_mps2),
        wind=dataclasses.replace(scenario.wind, velocity_ned_m_s=sources.wind_ned_mps),
    )
    vehicle = dataclasses.replace(
        load_vehicle(scenario.vehicle), drag_coefficient_n_s_per_m=sources.drag_n_s_per_m
    )
    thrust = ScaledThrustInput(StaticThrustInput(vehicle), 1.0 / sources.true_thrust_over_map)
    return run_dynamic(scenario, EstimatorConfig(), dynamic, thrust_input=thrust, vehicle=vehicle)


def score(run: DynamicRun, settle_s: float = 5.0) -> RunScore:
    """RMSE, NEES (over all settled ticks) and publication honesty of one run."""
    settled = run.time_s >= settle_s
    error = run.position_ned_m - run.truth_position_ned_m
    v_error = run.velocity_ned_mps - run.truth_velocity_ned_mps
    paper = run.paper_position_ned_m - run.truth_position_ned_m
    idx = np.where(settled & np.all(np.isfinite(error), axis=1))[0]
    nees3 = np.array([error[i] @ np.linalg.solve(run.covariance[i, :3, :3], error[i]) for i in idx])
    joint = np.concatenate((error, v_error), axis=1)
    nees6 = np.array([joint[i] @ np.linalg.solve(run.covariance[i], joint[i]) for i in idx])
    published = run.published[idx]
    beyond = float(np.mean(nees3[published] > CHI2_3DOF_9973)) if published.any() else 0.0
    return RunScore(
        dynamic_rmse_m=np.sqrt(np.mean(error[idx] ** 2, axis=0)),
        dynamic_velocity_rmse_mps=np.sqrt(np.mean(v_error[idx] ** 2, axis=0)),
        paper_rmse_m=np.sqrt(np.nanmean(paper[settled] ** 2, axis=0)),
        nees_position=float(np.mean(nees3)) if idx.size else math.nan,
        nees_position_velocity=float(np.mean(nees6)) if idx.size else math.nan,
        published_share=float(np.mean(published)) if idx.size else 0.0,
        published_beyond_3_sigma=beyond,
        thrust_scale_end=float(run.thrust_scale[-1]),
    )
