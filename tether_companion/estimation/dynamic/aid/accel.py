"""Accelerometer force balance: the specific force equals thrust, drag and cable per unit mass
plus the bias (``h = f + b``, generated ``accel_*``); skipped on the ground (thrust far below
the weight: the ground pushes too) and near the anchor (cable direction undefined).

Fused at the IMU rate into every bank member, so through the members' lean update
(:mod:`~tether_companion.estimation.dynamic.member`) with the generated model evaluated on the
state as a list."""

from __future__ import annotations

import math
from collections.abc import Sequence

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.aiding import AidStatus, fuse_force_balance
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.models import UNDEFINED, ModelConstants

NAME = "accel"
ON_GROUND = "on_ground"
NEAR_ANCHOR = "near_anchor"

_UNDEFINED_VALUE = (math.nan,) * 3
_UNDEFINED_JACOBIAN = (math.nan,) * (3 * state.N_STATES)


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
        self._r_variance = noise_std_mps2**2
        self._min_distance_sq = min_distance_m**2

    def fuse(
        self,
        bank: FilterBank,
        constants: ModelConstants,
        inputs: list[float],
        specific_force_body_mps2: Sequence[float],
        time_s: float,
        on_ground: bool,
    ) -> bool:
        """Fuse one IMU sample; ``inputs`` = ``(R_v^b row-major, thrust_n)``, the specific
        force (3 floats) [m/s^2]."""
        if on_ground:
            self.status.skip(ON_GROUND)
            return False
        x = bank.best.x_values()
        if x[0] * x[0] + x[1] * x[1] + x[2] * x[2] < self._min_distance_sq:
            self.status.skip(NEAR_ANCHOR)
            return False
        model = constants.models.accel
        c = constants.values()

        def measure(xs: list[float]) -> tuple[Sequence[float], Sequence[float]]:
            try:
                return model(xs, inputs, c)
            except UNDEFINED:  # counted non-finite by the update
                return _UNDEFINED_VALUE, _UNDEFINED_JACOBIAN

        return fuse_force_balance(
            bank, NAME, self.status, specific_force_body_mps2, measure, self._r_variance, time_s
        )
