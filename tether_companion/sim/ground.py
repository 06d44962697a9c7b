"""The ground under the drone: the anchor's height above it and uneven terrain (truth side).

The world frame's origin is the tether anchor. A winch on a tripod or a truck stands
``anchor_height_m`` above the ground, so the ground's mean level is at ``down = +anchor_height_m``.
Terrain adds a seeded, smooth elevation ``e(n, e)``: a sum of ``TERRAIN_WAVES`` plane waves with
random directions and phases and wavelengths spread around ``terrain_wavelength_m``, scaled to
the standard deviation ``terrain_std_m``. The ground's down coordinate under (n, e) is
``anchor_height_m - e(n, e)``; the rigid body lands on it and the rangefinder measures to it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tether_companion.config import spec

TERRAIN_WAVES = 6


@dataclass(frozen=True)
class GroundConfig:
    """The ``ground`` section of a scenario (SI units)."""

    anchor_height_m: float = spec(
        0.0,
        minimum=0.0,
        maximum=50.0,
        doc="height of the tether anchor above the mean ground (winch on a tripod/truck) [m]",
    )
    terrain_std_m: float = spec(
        0.0, minimum=0.0, maximum=2.0, doc="standard deviation of the terrain's elevation [m]"
    )
    terrain_wavelength_m: float = spec(
        5.0, minimum=0.5, maximum=1000.0, doc="typical wavelength of the terrain's undulation [m]"
    )


class Ground:
    """The ground surface of a :class:`GroundConfig` (random terrain drawn from ``rng``).

    No numbers are drawn when the terrain is flat, so flat scenarios keep their noise stream.
    """

    def __init__(self, config: GroundConfig, rng: np.random.Generator) -> None:
        self.config = config
        self._waves: list[tuple[float, float, float, float]] = []
        if config.terrain_std_m > 0.0:
            directions = rng.uniform(0.0, 2.0 * math.pi, TERRAIN_WAVES)
            phases = rng.uniform(0.0, 2.0 * math.pi, TERRAIN_WAVES)
            wavelengths = config.terrain_wavelength_m * rng.uniform(0.5, 1.5, TERRAIN_WAVES)
            amplitude = config.terrain_std_m * math.sqrt(2.0 / TERRAIN_WAVES)
            for d, ph, lam in zip(directions, phases, wavelengths, strict=True):
                k = 2.0 * math.pi / lam
                self._waves.append((k * math.cos(d), k * math.sin(d), float(ph), amplitude))

    def elevation_m(self, north_m: float, east_m: float) -> float:
        """Terrain elevation above the mean ground at (north, east) [m]."""
        return sum([a * math.sin(kn * north_m + ke * east_m + ph) for kn, ke, ph, a in self._waves])

    def down_m(self, north_m: float, east_m: float) -> float:
        """NED down coordinate of the ground surface at (north, east) [m]."""
        if not self._waves:  # flat: the anchor's height (the elevation is 0)
            return self.config.anchor_height_m
        return self.config.anchor_height_m - self.elevation_m(north_m, east_m)
