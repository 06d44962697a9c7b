"""Every frame flies: the simulator (the emulator's physics and controller) holds a tethered
hover with the '+' quad on ArduPilot's curve, the hexa X, the octa X and every named layout."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tether_companion.physics.frames import FRAMES
from tether_companion.physics.vehicle import VehicleProfile, load_vehicle
from tether_companion.sim.scenario import load_scenario
from tether_companion.sim.simulator import Simulator


def _hover_error_m(vehicle: VehicleProfile, seconds: float = 8.0) -> float:
    """Largest distance [m] from the hover set-point over the second half of the flight."""
    scenario = dataclasses.replace(load_scenario("hover"), duration_s=seconds)
    sim = Simulator(scenario, vehicle, rng=np.random.default_rng(1))
    target = np.array(scenario.trajectory.position_ned_m)
    worst = 0.0
    for k in range(1, int(seconds * 10) + 1):
        sim.advance_to(0.1 * k)
        if k * 0.1 > seconds / 2:
            worst = max(worst, float(np.linalg.norm(sim.truth.position_ned_m - target)))
    return worst


@pytest.mark.parametrize("name", ["ardupilot-sitl-plus", "hexa-x", "octa-x"])
def test_builtin_frames_hold_a_tethered_hover(name: str) -> None:
    vehicle = load_vehicle(name)
    assert vehicle.frame in FRAMES and vehicle.n_motors == len(FRAMES[vehicle.frame])
    assert _hover_error_m(vehicle) < 0.15


@pytest.mark.parametrize("frame", sorted(set(FRAMES) - {"quad-x", "quad-plus", "hexa-x", "octa-x"}))
def test_every_other_layout_holds_a_hover(frame: str) -> None:
    base = load_vehicle("octa-x" if len(FRAMES[frame]) == 8 else "hexa-x")
    vehicle = dataclasses.replace(base, frame=frame, motors=FRAMES[frame])
    if vehicle.n_motors == 4:
        vehicle = dataclasses.replace(vehicle, mass_kg=1.5)
    assert _hover_error_m(vehicle, seconds=6.0) < 0.15
