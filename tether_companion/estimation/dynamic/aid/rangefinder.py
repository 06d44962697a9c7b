"""Rangefinder: the tilt-corrected reading is the height above the ground,
``-p_d + anchor_height_m`` (the anchor's height above the ground under the drone; flat
ground). Validity (range, tilt, staleness) is checked by the estimator, which counts it. The
innovations' variance beyond the predicted (:class:`InnovationExcess`) and the ground's
unevenness the height carries (:class:`GroundFootprint`: the readings' gains and where they
were taken) are kept for the published height variance."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import generated, state
from tether_companion.estimation.dynamic.aiding import AidStatus, fuse
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.observability import InnovationExcess
from tether_companion.estimation.dynamic.terrain import GroundFootprint

FloatArray = NDArray[np.float64]

NAME = "rangefinder"
EXCESS_TIME_CONSTANT_S = 2.0
"""Averaging time of the innovations' excess variance [s] (40 readings at 20 Hz)."""
_NO_CONSTANTS = (0.0, 0.0, 0.0)
"""The height model uses none of the constants ``c``."""


class RangefinderAid:
    """Fuses a height above the ground [m].

    Parameters
    ----------
    noise_variance_m2
        Reading noise [m^2].
    anchor_height_m
        Height of the anchor above the ground [m].
    terrain_std_m, terrain_correlation_m
        The ground's unevenness about the anchor's ground level [m] and the distance over
        which it stays correlated [m] (:class:`GroundFootprint`).
    """

    def __init__(
        self,
        noise_variance_m2: float,
        anchor_height_m: float,
        terrain_std_m: float = 0.0,
        terrain_correlation_m: float = 1.0,
    ) -> None:
        self.status = AidStatus()
        self.excess = InnovationExcess(EXCESS_TIME_CONSTANT_S)
        """Height variance [m^2] the innovations show beyond the filter's (published only)."""
        self.ground = GroundFootprint(terrain_std_m, terrain_correlation_m)
        """The ground's variance the height carries [m^2] (published only)."""
        self._r = np.array([[noise_variance_m2]])
        self._u = [anchor_height_m]
        # the model is linear: its Jacobian is the same everywhere
        _, jac = generated.height_above_ground([0.0] * state.N_STATES, self._u, _NO_CONSTANTS)
        self._jacobian = np.array(jac, dtype=float).reshape(1, state.N_STATES)

    @classmethod
    def of_config(cls, config: EstimatorConfig) -> RangefinderAid:
        """The aid with ``config``'s reading noise and ground station (the anchor's height,
        the terrain's unevenness and correlation)."""
        ground = config.ground_station
        return cls(
            config.altimeter_noise_variance_m2,
            ground.anchor_height_m,
            ground.terrain_std_m,
            ground.terrain_correlation_m,
        )

    def fuse(self, bank: FilterBank, height_above_ground_m: float, time_s: float) -> bool:
        """Fuse one tilt-corrected reading [m]."""
        u, jacobian = self._u, self._jacobian

        def measure(xs: FloatArray) -> tuple[FloatArray, FloatArray]:
            h, _ = generated.height_above_ground(xs.tolist(), u, _NO_CONSTANTS)
            return np.array(h), jacobian

        z = np.array((height_above_ground_m,))
        status = self.status
        fused = fuse(bank, NAME, status, z, measure, self._r, time_s)
        if status.last_innovation.size:
            variance = float(status.last_innovation_variance[0])
            self.excess.add(float(status.last_innovation[0]), variance, time_s)
            if fused and variance > 0.0:  # the best member's gain on the height: P / S
                north, east = bank.best.x_values()[:2]
                self.ground.add(1.0 - float(self._r[0, 0]) / variance, north, east)
        return fused
