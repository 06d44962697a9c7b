"""Accelerometer force balance: the specific force equals thrust, drag and cable per unit mass
plus the bias (``h = f + b``, generated ``accel_*``); skipped on the ground (thrust far below
the weight: the ground pushes too) and near the anchor (cable direction undefined)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic.aiding import AidStatus, fuse
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.models import ModelConstants, evaluate

FloatArray = NDArray[np.float64]

NAME = "accel"
ON_GROUND = "on_ground"
NEAR_ANCHOR = "near_anchor"


class AccelAid:
    """Fuses the accelerometer's specific force [m/s^2], FRD body.

    Parameters
    ----------
    noise_std_mps2
        Noise per axis [m/s^2] (sensor noise and unmodelled forces).
    min_distance_m
        No fusion closer than this to the anchor [m].
    """

    def __init__(self, noise_std_mps2: float, min_distance_m: float) -> None:
        self.status = AidStatus()
        self._r = np.eye(3) * noise_std_mps2**2
        self._min_distance_sq = min_distance_m**2

    def fuse(
        self,
        bank: FilterBank,
        constants: ModelConstants,
        inputs: list[float],
        specific_force_body_mps2: FloatArray,
        time_s: float,
        on_ground: bool,
    ) -> bool:
        """Fuse one IMU sample; ``inputs`` = ``(R_v^b row-major, thrust_n)``."""
        if on_ground:
            self.status.skip(ON_GROUND)
            return False
        x = bank.best.x
        if x[0] * x[0] + x[1] * x[1] + x[2] * x[2] < self._min_distance_sq:
            self.status.skip(NEAR_ANCHOR)
            return False
        model = constants.models.accel
        c = constants.values()

        def measure(xs: FloatArray) -> tuple[FloatArray, FloatArray]:
            return evaluate(model, xs, inputs, c, 3)

        return fuse(bank, NAME, self.status, specific_force_body_mps2, measure, self._r, time_s)
