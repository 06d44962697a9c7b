"""How much of the ground's unevenness the filter's height carries: :class:`GroundFootprint`.

The rangefinder reads the height above the ground under the drone; the filter takes the ground
as flat at the anchor's level, so each reading is off by the ground's elevation where it was
taken (standard deviation ``terrain_std_m``, what the user states about the field). The
filter's height is a weighted average of its readings: a fused reading moves it by the gain
``K = 1 - R / S`` (``S`` its innovation variance, ``R`` the reading's noise) and leaves the
older readings' weight times ``1 - K``. The height therefore carries the ground averaged over
the positions its readings were taken at, weighted the same way, and the readings' white
noise model does not know it.

Right under a hovering drone that average is the ground at one point: the whole variance
``sigma^2``. A drone that moves samples the ground along its path: ground whose elevation is
correlated over ``correlation_m`` (``l``, the integral of its correlation along a line;
undulations of wavelength ``lambda`` in random directions, the simulator's terrain, have
``lambda / 2 pi``) is averaged down. With the readings weighted exponentially along a straight
path and the correlation of such undulations, ``J0(r / l)``, the average's variance is

    sigma^2 / sqrt(1 + (D / l)^2),

``D`` the readings' weighted spread of positions (``v tau`` at speed ``v`` and memory ``tau``;
the Laplace transform of ``J0``). Ground with an exponential correlation averages faster
(``sigma^2 / (1 + D / l)``); the form above keeps more. Measured on the realistic circle
with the cable angle alone, tuning seed 1 (a 0.1 m step added to every reading from 15 s):
the down estimate reached 63 % of it after about 2.1 s, the gain's memory ``dt / K`` read
1.7 s (docs/estimation-history.md, "The ground a moving drone averages, and the bearing before
the data tell it (terrain12)").

Pure.
"""

from __future__ import annotations

import math


class GroundFootprint:
    """The ground's variance the filter's height carries [m^2] (:attr:`variance_m2`).

    Parameters
    ----------
    terrain_std_m
        Standard deviation of the ground's height about the anchor's ground level [m].
    correlation_m
        The distance over which the ground's height stays correlated [m] (> 0).
    """

    def __init__(self, terrain_std_m: float, correlation_m: float) -> None:
        self._variance_m2 = terrain_std_m * terrain_std_m
        self._inverse_length2 = 1.0 / (correlation_m * correlation_m)
        self._mean: tuple[float, float] | None = None
        self._spread_m2 = 0.0
        self.variance_m2 = self._variance_m2
        """The ground's variance in the height now [m^2]: all of it before a reading."""

    def clear(self) -> None:
        """Forget the readings (the filter restarts)."""
        self._mean = None
        self._spread_m2 = 0.0
        self.variance_m2 = self._variance_m2

    def add(self, gain: float, north_m: float, east_m: float) -> None:
        """A reading fused with gain ``gain`` on the height (0 < gain <= 1; others are
        ignored) with the estimate at (``north_m``, ``east_m``) from the anchor [m]."""
        if not (0.0 < gain <= 1.0 and math.isfinite(north_m) and math.isfinite(east_m)):
            return
        mean = self._mean
        if mean is None:
            self._mean = (north_m, east_m)
            return
        dn, de = north_m - mean[0], east_m - mean[1]
        self._mean = (mean[0] + gain * dn, mean[1] + gain * de)
        # the exponentially weighted spread about the weighted mean
        self._spread_m2 = (1.0 - gain) * (self._spread_m2 + gain * (dn * dn + de * de))
        self.variance_m2 = self._variance_m2 / math.sqrt(
            1.0 + self._spread_m2 * self._inverse_length2
        )
