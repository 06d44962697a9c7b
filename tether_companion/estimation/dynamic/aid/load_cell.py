"""Optional load cell at the drone: the magnitude of the cable's force [N] (generated
``tension_*``: chord pull plus half the hanging weight)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic.aiding import AidStatus, fuse
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.models import ModelConstants, evaluate

FloatArray = NDArray[np.float64]

NAME = "load_cell"


class LoadCellAid:
    """Fuses a measured tension [N] with noise ``noise_std_n`` [N]."""

    def __init__(self, noise_std_n: float) -> None:
        self.status = AidStatus()
        self._r = np.array([[noise_std_n**2]])

    def fuse(
        self, bank: FilterBank, constants: ModelConstants, tension_n: float, time_s: float
    ) -> bool:
        """Fuse one reading [N]."""
        model = constants.models.tension
        c = constants.values()

        def measure(xs: FloatArray) -> tuple[FloatArray, FloatArray]:
            return evaluate(model, xs, (), c, 1)

        return fuse(bank, NAME, self.status, np.array((tension_n,)), measure, self._r, time_s)
