"""The identification flight of the paper's section 5.1, flown in the simulator.

Take off from the anchor, hover, then excite one axis at a time: roll (east position steps),
pitch (north steps), yaw (heading steps) and collective (height steps), repeated in cycles of
varying amplitude so both the estimation and the validation part of the log hold every kind
of excitation; then land. The cable is slack (tension 0) or pulls with a known constant
tension. The samples go to a .tlog, .bin or .csv recorder, so the whole loop runs without
hardware: fly, identify (``tether-companion sysid``), configure, estimate.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from tether_companion.config import spec
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample
from tether_companion.sim.controller import Setpoint
from tether_companion.sim.scenario import InitialConfig, Scenario, load_scenario
from tether_companion.sim.simulator import Simulator
from tether_companion.sim.trajectory import TrajectoryConfig
from tether_companion.sysid.recorders import open_recorder


@dataclass(frozen=True)
class FlightPlan:
    """Section 5.1 flight: hover, then roll, pitch, yaw and collective excited one at a time."""

    hover_height_m: float = spec(
        2.0, minimum=1.0, maximum=20.0, doc="hover height above the anchor [m]"
    )
    lateral_step_m: float = spec(
        0.8, exclusive_minimum=0.0, maximum=5.0, doc="roll/pitch position step [m]"
    )
    yaw_step_deg: float = spec(30.0, exclusive_minimum=0.0, maximum=90.0, doc="yaw step [deg]")
    height_step_m: float = spec(
        0.6, exclusive_minimum=0.0, maximum=5.0, doc="collective height step [m]"
    )
    dwell_s: float = spec(1.5, minimum=0.3, maximum=10.0, doc="time on each step [s]")
    hover_s: float = spec(5.0, minimum=1.0, doc="hover before the excitation [s]")
    cable_tension_n: float = spec(0.0, minimum=0.0, doc="constant cable tension; 0 = slack [N]")
    cycle_amplitudes: tuple[float, ...] = spec(
        (1.0, 0.6, 1.3, 0.8),
        exclusive_minimum=0.0,
        maximum=2.0,
        doc="relative step amplitude of each roll-pitch-yaw-collective cycle",
    )

    def setpoints(self) -> list[tuple[float, Setpoint]]:
        """Timed set-points ``(time_s, Setpoint)`` of the whole flight, the landing last."""
        h = -self.hover_height_m
        plan = [(1.0, Setpoint(position_ned_m=(0.0, 0.0, h), yaw_rad=0.0))]
        t = 1.0 + self.hover_s
        yaw = math.radians(self.yaw_step_deg)
        for scale in self.cycle_amplitudes:
            lateral, dz = scale * self.lateral_step_m, scale * self.height_step_m
            steps = [
                ((0.0, lateral, h), 0.0),
                ((0.0, -lateral, h), 0.0),
                ((0.0, 0.0, h), 0.0),
                ((lateral, 0.0, h), 0.0),
                ((-lateral, 0.0, h), 0.0),
                ((0.0, 0.0, h), 0.0),
                ((0.0, 0.0, h), scale * yaw),
                ((0.0, 0.0, h), -scale * yaw),
                ((0.0, 0.0, h), 0.0),
                ((0.0, 0.0, h - dz), 0.0),
                ((0.0, 0.0, h + dz), 0.0),
                ((0.0, 0.0, h), 0.0),
            ]
            for position, heading in steps:
                plan.append((t, Setpoint(position_ned_m=position, yaw_rad=heading)))
                t += self.dwell_s
        plan.append((t, Setpoint(position_ned_m=(0.0, 0.0, 0.0), yaw_rad=0.0)))
        return plan

    @property
    def duration_s(self) -> float:
        """Flight length including 6 s for the landing [s]."""
        return self.setpoints()[-1][0] + 6.0


def identification_scenario(plan: FlightPlan, base: Scenario | None = None) -> Scenario:
    """The scenario of the flight: landed at the anchor, armed, no trajectory, plan's cable."""
    base = base or load_scenario("hover")
    return replace(
        base,
        duration_s=plan.duration_s,
        trajectory=TrajectoryConfig(kind="none"),
        initial=InitialConfig(airborne=False, armed=True),
        cable=replace(base.cable, model="constant_tension", tension_n=plan.cable_tension_n),
        events=(),
    )


Tick = tuple[ImuSample, AttitudeSample, np.ndarray, PwmSample, RangeSample | None, float]
"""IMU, attitude, body rates [rad/s], PWM, rangefinder (None: no reading), battery [V]."""


def fly(plan: FlightPlan, simulator: Simulator) -> Iterator[Tick]:
    """Fly the plan, yielding the sensor samples and the battery voltage at the scenario's
    IMU rate."""
    period = 1.0 / simulator.scenario.sensors.imu_rate_hz
    schedule = plan.setpoints()
    next_setpoint = 0
    for k in range(1, int(plan.duration_s / period) + 1):
        t = k * period
        while next_setpoint < len(schedule) and schedule[next_setpoint][0] <= t:
            simulator.set_setpoint(schedule[next_setpoint][1])
            next_setpoint += 1
        simulator.advance_to(t)
        rates = simulator.truth.body_rates_rad_s
        yield (
            simulator.read_imu(),
            simulator.read_attitude(),
            rates,
            simulator.read_pwm(),
            simulator.read_rangefinder(),
            simulator.battery_voltage_v,
        )


def record_identification_flight(
    path: str | Path,
    plan: FlightPlan | None = None,
    scenario: Scenario | None = None,
    seed: int = 0,
) -> Simulator:
    """Fly the identification flight in the simulator and write it to ``path``.

    Parameters
    ----------
    path
        Output log; the extension picks the format (.tlog, .bin, .csv).
    plan
        The flight (defaults: 2 m hover, 0.8 m, 30 deg and 0.6 m steps, slack cable).
    scenario
        Base scenario for vehicle, sensors and controller (default: built-in ``hover``).
    seed
        Seed of the simulator's noise.

    Returns
    -------
    Simulator
        The simulator after the flight (its vehicle holds the true motor curve and lag).
    """
    plan = plan or FlightPlan()
    simulator = Simulator(identification_scenario(plan, scenario), rng=np.random.default_rng(seed))
    sensors = simulator.scenario.sensors
    with contextlib.closing(open_recorder(path, (sensors.range_min_m, sensors.range_max_m))) as out:
        for tick in fly(plan, simulator):
            out.write(*tick)
    return simulator
