"""Scenario files written for tests (not collected: no ``test_`` prefix)."""

from __future__ import annotations

import math
from pathlib import Path


def reel_in_scenario(tmp_path: Path, duration_s: float) -> Path:
    """Hover 5 m up, 1 m from the anchor, on an elastic line just past taut (for winch
    reel-in landings); returns the scenario file's path."""
    length = math.hypot(1.0, 5.0) - 0.03
    path = tmp_path / "reel-in.yaml"
    path.write_text(
        f"""
duration_s: {duration_s}
seed: 21
physics_rate_hz: 1000
vehicle: default-quad
cable: {{model: elastic, length_m: {length:.4f}, stiffness_n_per_m: 100.0,
        damping_n_s_per_m: 5.0, linear_density_kg_per_m: 0.0167, min_length_m: 0.2}}
trajectory: {{kind: hover, position_ned_m: [1.0, 0.0, -5.0]}}
initial: {{airborne: true}}
""",
        encoding="utf-8",
    )
    return path


REALISTIC_GROUND_STATION = "{enabled: true, cable_axial_stiffness_n: 50000.0}"
"""The realistic scenarios' ``ground_station`` section (sitl/scenarios/realistic-circle.yaml:
its other values are the section's defaults): the winch encoder's 1 % scale and 0.1 m offset
per flight, 0.1 s late, 1 cm steps, the cable's stretch; the angle 0.05 s late, 0.01 rad of
noise, 1.5 deg azimuth and 0.4 deg elevation biases per flight, 12-bit steps."""


def gusty_hover_takeoff_scenario(
    tmp_path: Path,
    duration_s: float,
    seed: int,
    ground_station: bool = False,
    vehicle: str = "default-quad",
) -> Path:
    """The hover scenario's quad and 4 N winch in realistic-gusty-hover's wind (3 m/s mean,
    light Dryden turbulence), taking off from the ground under the hover point (4, 0, -2.5) m;
    the thrust map exact, no sensor biases; with ``ground_station`` the ground station's
    sensors have the realistic errors (:data:`REALISTIC_GROUND_STATION`), else none (the
    exact length, the angle with 0.01 rad of white noise). ``vehicle``: the profile flown
    (default-quad has no drag, so the wind moves only the cable; realistic-quad has the rotor
    drag and body drag of a 450-class quad, so the gusts push the drone). Returns the
    scenario file's path."""
    section = REALISTIC_GROUND_STATION if ground_station else "{enabled: false}"
    path = tmp_path / f"gusty-hover-takeoff-{seed}.yaml"
    path.write_text(
        f"""
base: hover
vehicle: {vehicle}
duration_s: {duration_s}
seed: {seed}
wind: {{velocity_ned_m_s: [-2.0, 2.2, 0.0], turbulence_w20_mps: 7.7}}
trajectory: {{kind: hover, position_ned_m: [4.0, 0.0, -2.5]}}
initial: {{airborne: false, armed: true, position_ned_m: [4.0, 0.0, 0.0]}}
ground_station: {section}
""",
        encoding="utf-8",
    )
    return path
