"""Rangefinder: the tilt-corrected reading is the height above the ground,
``-p_d + anchor_height_m`` (the anchor's height above the ground under the drone; flat
ground). Validity (range, tilt, staleness) is checked by the estimator, which counts it."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import generated, state
from tether_companion.estimation.dynamic.aiding import AidStatus, fuse
from tether_companion.estimation.dynamic.bank import FilterBank

FloatArray = NDArray[np.float64]

NAME = "rangefinder"
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
    """

    def __init__(self, noise_variance_m2: float, anchor_height_m: float) -> None:
        self.status = AidStatus()
        self._r = np.array([[noise_variance_m2]])
        self._u = [anchor_height_m]
        # the model is linear: its Jacobian is the same everywhere
        _, jac = generated.height_above_ground([0.0] * state.N_STATES, self._u, _NO_CONSTANTS)
        self._jacobian = np.array(jac, dtype=float).reshape(1, state.N_STATES)

    def fuse(self, bank: FilterBank, height_above_ground_m: float, time_s: float) -> bool:
        """Fuse one tilt-corrected reading [m]."""
        u, jacobian = self._u, self._jacobian

        def measure(xs: FloatArray) -> tuple[FloatArray, FloatArray]:
            h, _ = generated.height_above_ground(xs.tolist(), u, _NO_CONSTANTS)
            return np.array(h), jacobian

        z = np.array((height_above_ground_m,))
        return fuse(bank, NAME, self.status, z, measure, self._r, time_s)
