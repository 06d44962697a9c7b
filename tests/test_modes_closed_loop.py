"""The tension modes closing the loop on the offline simulator (no MAVLink).

The simulator flies; its noisy IMU, attitude and PWM feed the tension filter; the modes turn
the filtered tension into set-points. The position given to the modes is the simulator's
truth (the service gives its EKF's estimate). The autopilot's LAND is played by a descent
at 0.5 m/s and a disarm once on the ground, as ArduPilot's LAND mode does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from tether_companion.estimation.tension_kf import TensionEstimator, TensionFilterConfig
from tether_companion.modes.config import TensionModeConfig
from tether_companion.modes.tension_following import (
    LAND,
    POSITION_TARGET,
    VELOCITY_TARGET,
    ModeInputs,
    TensionModes,
)
from tether_companion.physics.cable import CableConfig
from tether_companion.sim.controller import Setpoint
from tether_companion.sim.scenario import load_scenario
from tether_companion.sim.simulator import Simulator

SENSOR_DT = 0.005
LAND_SPEED_MPS = 0.5


@dataclass
class Run:
    """A simulator driven by the tension modes, logging what matters."""

    sim: Simulator
    modes: TensionModes
    filter_config: TensionFilterConfig = field(default_factory=TensionFilterConfig)
    corrupt_tension_after_s: float = math.inf
    flight_mode: str = "GUIDED"
    log: list[tuple[float, np.ndarray, float, bool, str]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.estimator = TensionEstimator(self.filter_config, self.sim.vehicle)
        self.sim.set_setpoint(Setpoint(position_ned_m=tuple(self.sim.truth.position_ned_m)))
        self._ground_since = math.inf

    def until(self, end_s: float) -> None:
        sim = self.sim
        while sim.time_s < end_s - 1e-9:
            sim.advance_to(sim.time_s + SENSOR_DT)
            self.estimator.on_attitude(sim.read_attitude())
            self.estimator.on_pwm(sim.read_pwm())
            estimate = self.estimator.on_imu(sim.read_imu())
            truth = sim.truth
            if sim.time_s >= self.corrupt_tension_after_s:
                estimate = None
            action = self.modes.step(
                ModeInputs(
                    time_s=sim.time_s,
                    tension=estimate,
                    armed=sim.armed,
                    flight_mode=self.flight_mode,
                    position_ned_m=truth.position_ned_m,
                    height_m=-truth.position_ned_m[2],
                )
            )
            self._apply(action)
            self._autopilot_land()
            self.log.append(
                (sim.time_s, truth.position_ned_m, truth.tension_n, sim.armed, self.modes.state)
            )

    def _apply(self, action) -> None:
        if action.kind == VELOCITY_TARGET:
            self.sim.set_setpoint(Setpoint(velocity_ned_m_s=tuple(action.velocity_ned_m_s)))
        elif action.kind == POSITION_TARGET:
            self.sim.set_setpoint(Setpoint(position_ned_m=tuple(action.position_ned_m)))
        elif action.kind == LAND and self.flight_mode != "LAND":
            self.flight_mode = "LAND"
            self.sim.set_setpoint(Setpoint(velocity_ned_m_s=(0.0, 0.0, LAND_SPEED_MPS)))

    def _autopilot_land(self) -> None:
        if self.flight_mode != "LAND" or not self.sim.armed:
            return
        if self.sim.landed:
            self._ground_since = min(self._ground_since, self.sim.time_s)
            if self.sim.time_s - self._ground_since > 1.0:
                self.sim.disarm()

    def positions(self, t0: float, t1: float) -> np.ndarray:
        return np.array([p for t, p, *_ in self.log if t0 <= t <= t1])


def _hover_sim(position, cable: CableConfig, seed: int = 11) -> Simulator:
    base = load_scenario("hover")
    trajectory = replace(base.trajectory, position_ned_m=tuple(position))
    return Simulator(replace(base, cable=cable, trajectory=trajectory, events=(), seed=seed))


def test_tug_moves_the_drone_along_the_pull_and_it_then_holds():
    """Paper winch (4 N constant tension): 3 N east for 3 s moves the hovering drone east."""
    sim = _hover_sim((2.0, 0.0, -3.0), CableConfig(model="constant_tension", tension_n=4.0))
    run = Run(sim, TensionModes(TensionModeConfig(enabled=True, land_on_first_tug=False)))
    run.until(5.0)
    start = sim.truth.position_ned_m.copy()
    sim.apply_tug((0.0, 3.0, 0.0), 3.0)
    run.until(8.0 + 1.0)
    moved = sim.truth.position_ned_m - start
    assert moved[1] > 0.8, moved  # along the pull
    assert abs(moved[0]) < 0.5 * moved[1] and abs(moved[2]) < 0.3
    run.until(16.0)
    # then it holds (after drifting back by up to the release threshold's worth of the
    # winch's own pull, whose horizontal part grows with the distance from the anchor)
    assert np.ptp(run.positions(11.0, 16.0), axis=0).max() < 0.1
    assert sim.truth.position_ned_m[1] - start[1] > 1.0
    assert sim.armed


def _reel_in_sim() -> Simulator:
    """Hover 5 m up, 1 m off the anchor, on an elastic line paid out just past taut; the
    winch then reels in at 0.3 m/s."""
    distance = math.hypot(1.0, 5.0)
    cable = CableConfig(
        model="elastic",
        length_m=distance - 0.03,
        stiffness_n_per_m=100.0,
        damping_n_s_per_m=5.0,
        linear_density_kg_per_m=0.0167,
        min_length_m=0.2,
    )
    return _hover_sim((1.0, 0.0, -5.0), cable, seed=12)


def test_winch_reel_in_lands_near_the_anchor_without_tension_spike():
    sim = _reel_in_sim()
    run = Run(sim, TensionModes(TensionModeConfig(enabled=True, land_on_first_tug=True)))
    run.until(4.0)
    sim.set_winch_rate_mps(-0.3)
    run.until(40.0)
    final = sim.truth.position_ned_m
    assert not sim.armed and sim.landed
    assert math.hypot(final[0], final[1]) < 1.0
    tensions = [tension for t, _, tension, armed, _ in run.log if t > 4.0 and armed]
    assert max(tensions) < 15.0, max(tensions)


def test_estimate_lost_mid_landing_still_lands():
    sim = _reel_in_sim()
    run = Run(
        sim,
        TensionModes(TensionModeConfig(enabled=True, land_on_first_tug=True)),
        corrupt_tension_after_s=9.0,
    )
    run.until(4.0)
    sim.set_winch_rate_mps(-0.3)
    run.until(9.0)
    assert run.modes.landing_flag and -sim.truth.position_ned_m[2] > 1.0  # mid-landing
    sim.set_winch_rate_mps(0.0)  # the winch stops too: only the autopilot's LAND brings it down
    run.until(30.0)
    assert run.flight_mode == "LAND"
    assert not sim.armed and sim.landed
