"""Tension-based position control in the offline simulator (Martins 2019, section 5.2).

No position sensor closes the horizontal loop: a goal position is turned into a goal cable
force through the catenary (``force_from_position_ned_n``: known paid-out length, anchor on the
ground), and the outer loop drives the **filtered tension estimate** toward it. Altitude is
held on the rangefinder, as the thesis does (its vertical tension estimate was too poor at
the start; fig. 13 and the text after it).

Outer loop (horizontal). With ``J = dF_h/dp_h`` the 2x2 Jacobian of the horizontal cable
force with respect to the horizontal position at the goal (central differences of the
catenary model), the tension error is mapped to a position error and a velocity target::

    v_h = -k J^-1 (F_h,measured - F_h,goal)

``J`` only scales and rotates the tension error: the cable's horizontal pull grows with the
distance at a rate ``dH/dr`` that varies by more than ten times between a slack and a nearly
taut cable (0.5 to 8.5 N/m on the 5.2 m cable of the ``catenary-hover`` scenario), so a fixed
gain on the raw tension error would be either sluggish or unstable over the workspace.
Moving sideways turns the pull with magnitude ``H``, ``|dF/dp_t| = H / r``.

Vertical: ``v_d = k_z (h_measured - h_goal)`` with ``h`` the tilt-corrected rangefinder
height (flat ground at the anchor's level).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from rich.table import Table

from tether_companion.config import spec
from tether_companion.estimation.catenary_position import force_from_position_ned_n
from tether_companion.estimation.tension_kf import TensionEstimator, TensionFilterConfig
from tether_companion.sim.controller import Setpoint
from tether_companion.sim.scenario import Scenario, load_scenario
from tether_companion.sim.simulator import Simulator

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class TensionControlConfig:
    """Gains and limits of the tension-based position controller."""

    gain_per_s: float = spec(0.8, exclusive_minimum=0.0, doc="horizontal outer-loop gain k [1/s]")
    altitude_gain_per_s: float = spec(
        1.0, exclusive_minimum=0.0, doc="altitude gain on the rangefinder k_z [1/s]"
    )
    max_speed_mps: float = spec(1.0, exclusive_minimum=0.0, doc="largest horizontal speed [m/s]")
    max_vertical_speed_mps: float = spec(
        0.5, exclusive_minimum=0.0, doc="largest vertical speed [m/s]"
    )
    jacobian_step_m: float = spec(
        0.01, exclusive_minimum=0.0, doc="position step of the force Jacobian [m]"
    )


class TensionPositionController:
    """Velocity targets from the tension error (see the module docstring). Pure.

    Parameters
    ----------
    config
        Gains and limits.
    length_m
        Paid-out cable length [m].
    weight_per_length_n_per_m
        Cable weight per length [N/m].
    """

    def __init__(
        self, config: TensionControlConfig, length_m: float, weight_per_length_n_per_m: float
    ) -> None:
        self.config = config
        self.length_m = float(length_m)
        self.weight_per_length_n_per_m = float(weight_per_length_n_per_m)
        self.goal_position_ned_m = np.full(3, math.nan)
        self.goal_force_ned_n = np.full(3, math.nan)
        self._inverse_jacobian = np.full((2, 2), math.nan)

    def _force(self, position: FloatArray) -> FloatArray:
        return force_from_position_ned_n(position, self.length_m, self.weight_per_length_n_per_m)

    def set_goal(self, goal_position_ned_m: FloatArray) -> None:
        """Set the goal position (NED, anchor origin) [m]; computes the goal force and ``J``.

        Raises
        ------
        ValueError
            When no catenary of the paid-out length reaches the goal, or the goal has no
            horizontal pull to steer with (``J`` singular: straight above the anchor or on a
            cable slack enough to rise vertically from the ground).
        """
        goal = np.asarray(goal_position_ned_m, dtype=float).copy()
        step = self.config.jacobian_step_m
        jacobian = np.empty((2, 2))
        for j in range(2):
            delta = np.zeros(3)
            delta[j] = step
            jacobian[:, j] = (self._force(goal + delta)[:2] - self._force(goal - delta)[:2]) / (
                2.0 * step
            )
        if not np.isfinite(jacobian).all() or abs(np.linalg.det(jacobian)) < 1e-9:
            raise ValueError(
                f"goal {goal.tolist()} gives no horizontal pull to steer with on a "
                f"{self.length_m} m cable"
            )
        self.goal_position_ned_m = goal
        self.goal_force_ned_n = self._force(goal)
        self._inverse_jacobian = np.linalg.inv(jacobian)

    def velocity_setpoint(self, measured_force_ned_n: FloatArray, height_m: float) -> FloatArray:
        """Velocity target, NED [m/s], shape (3,), from the measured force and height.

        A non-finite height holds the altitude (zero vertical speed).
        """
        cfg = self.config
        error = np.asarray(measured_force_ned_n, dtype=float)[:2] - self.goal_force_ned_n[:2]
        velocity = np.zeros(3)
        velocity[:2] = -cfg.gain_per_s * (self._inverse_jacobian @ error)
        speed = math.hypot(velocity[0], velocity[1])
        if speed > cfg.max_speed_mps:
            velocity[:2] *= cfg.max_speed_mps / speed
        if math.isfinite(height_m):
            goal_height = -self.goal_position_ned_m[2]
            vertical = cfg.altitude_gain_per_s * (height_m - goal_height)
            limit = cfg.max_vertical_speed_mps
            velocity[2] = max(-limit, min(limit, vertical))
        return velocity


@dataclass(frozen=True)
class GoalResult:
    """Goal and reached state at the end of one goal's hold."""

    goal_ned_m: FloatArray
    reached_ned_m: FloatArray
    goal_force_ned_n: FloatArray
    reached_force_ned_n: FloatArray

    @property
    def error_m(self) -> float:
        """Distance between goal and reached position [m]."""
        return float(np.linalg.norm(self.reached_ned_m - self.goal_ned_m))


DEFAULT_GOALS_NED_M: tuple[tuple[float, float, float], ...] = (
    (3.5, 1.5, -2.5),
    (2.5, -2.0, -3.5),
    (4.2, 0.5, -2.8),
    (3.0, 0.0, -3.0),
)
"""Goals on the 5.2 m cable of the ``catenary-hover`` scenario (start: 4, 0, -3)."""


def control_scenario(seed: int, hold_s: float, n_goals: int) -> Scenario:
    """The ``catenary-hover`` scenario without winch events, long enough for the goals."""
    base = load_scenario("catenary-hover")
    return dataclasses.replace(base, events=(), seed=seed, duration_s=hold_s * n_goals + 1.0)


def fly_to_goals(
    goals_ned_m: tuple[tuple[float, float, float], ...] = DEFAULT_GOALS_NED_M,
    *,
    hold_s: float = 20.0,
    average_s: float = 4.0,
    seed: int = 1,
    config: TensionControlConfig | None = None,
) -> list[GoalResult]:
    """Fly each goal for ``hold_s`` under tension-based control; average the last seconds."""
    scenario = control_scenario(seed, hold_s, len(goals_ned_m))
    sim = Simulator(scenario)
    weight = scenario.cable.linear_density_kg_per_m * sim.gravity_mps2
    controller = TensionPositionController(
        config or TensionControlConfig(), sim.cable.paid_out_m, weight
    )
    tension = TensionEstimator(TensionFilterConfig(), sim.vehicle)
    rate_hz = scenario.sensors.imu_rate_hz
    height_m = math.nan
    results = []
    t = 0.0
    for goal in goals_ned_m:
        controller.set_goal(np.array(goal))
        positions, forces = [], []
        end_s = t + hold_s
        while t < end_s - 1e-9:
            t = round((t + 1.0 / rate_hz) * rate_hz) / rate_hz
            sim.advance_to(t)
            attitude = sim.read_attitude()
            tension.on_attitude(attitude)
            tension.on_pwm(sim.read_pwm())
            estimate = tension.on_imu(sim.read_imu())
            reading = sim.read_rangefinder()
            if reading is not None:
                tilt = math.cos(attitude.roll_rad) * math.cos(attitude.pitch_rad)
                height_m = reading.distance_m * tilt
            if estimate is not None and estimate.valid:
                velocity = controller.velocity_setpoint(estimate.tension_ned_n, height_m)
                sim.set_setpoint(Setpoint(velocity_ned_m_s=tuple(velocity.tolist())))
            if t > end_s - average_s:
                truth = sim.truth
                positions.append(truth.position_ned_m)
                forces.append(truth.cable_force_ned_n)
        results.append(
            GoalResult(
                np.array(goal),
                np.mean(positions, axis=0),
                controller.goal_force_ned_n.copy(),
                np.mean(forces, axis=0),
            )
        )
    return results


def control_table(seed: int = 1) -> Table:
    """Goal versus reached position and pull, as a rich table (``bench catenary``)."""
    table = Table(
        title="tension-based position control (Martins 5.2) on the catenary cable, "
        f"last 4 s of 20 s per goal, seed {seed}"
    )
    for column in (
        "goal N, E, D (m)",
        "reached N, E, D (m)",
        "error (m)",
        "goal pull N, E, D (N)",
        "reached pull N, E, D (N)",
    ):
        table.add_column(column)

    def triple(v: FloatArray, digits: int) -> str:
        return ", ".join(f"{x:.{digits}f}" for x in v)

    for r in fly_to_goals(seed=seed):
        table.add_row(
            triple(r.goal_ned_m, 2),
            triple(r.reached_ned_m, 2),
            f"{r.error_m:.3f}",
            triple(r.goal_force_ned_n, 3),
            triple(r.reached_force_ned_n, 3),
        )
    return table
