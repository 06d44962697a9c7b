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


def gusty_hover_takeoff_scenario(tmp_path: Path, duration_s: float, seed: int) -> Path:
    """The hover scenario's quad and 4 N winch in realistic-gusty-hover's wind (3 m/s mean,
    light Dryden turbulence), taking off from the ground under the hover point (4, 0, -2.5) m;
    the thrust map exact, no sensor biases. Returns the scenario file's path."""
    path = tmp_path / f"gusty-hover-takeoff-{seed}.yaml"
    path.write_text(
        f"""
base: hover
duration_s: {duration_s}
seed: {seed}
wind: {{velocity_ned_m_s: [-2.0, 2.2, 0.0], turbulence_w20_mps: 7.7}}
trajectory: {{kind: hover, position_ned_m: [4.0, 0.0, -2.5]}}
initial: {{airborne: false, armed: true, position_ned_m: [4.0, 0.0, 0.0]}}
""",
        encoding="utf-8",
    )
    return path
