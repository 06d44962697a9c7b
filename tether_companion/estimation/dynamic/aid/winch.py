"""Optional winch paid-out length: the cable's arc length (generated ``winch_length_*``: the
catenary's, ``|p|`` for a weightless cable). Skipped while the cable is slack (its length then
says only that the drone is closer than that)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.aiding import AidStatus, fuse
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.models import ModelConstants, evaluate

FloatArray = NDArray[np.float64]

NAME = "winch"
SLACK = "slack"


class WinchAid:
    """Fuses a paid-out length [m] with noise ``noise_std_m`` [m] while the chord tension is
    above ``slack_tension_n`` [N]."""

    def __init__(self, noise_std_m: float, slack_tension_n: float) -> None:
        self.status = AidStatus()
        self._r = np.array([[noise_std_m**2]])
        self._slack_n = slack_tension_n

    def fuse(
        self, bank: FilterBank, constants: ModelConstants, length_m: float, time_s: float
    ) -> bool:
        """Fuse one reading [m]."""
        if bank.best.x[state.TENSION] < self._slack_n:
            self.status.skip(SLACK)
            return False
        c = constants.values()
        model = constants.models.winch_length

        def measure(xs: FloatArray) -> tuple[FloatArray, FloatArray]:
            return evaluate(model, xs, (), c, 1)

        return fuse(bank, NAME, self.status, np.array((length_m,)), measure, self._r, time_s)
