"""Optional load cells: the tension at the drone [N] (generated ``tension_*``: the magnitude
of the cable's force on the drone) or the winch's at the anchor [N] (generated
``anchor_tension_*``: that less ``w b``, the hanging cable's weight term; derive.py)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic.aiding import AidStatus, fuse
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.models import (
    CableModels,
    Generated,
    ModelConstants,
    evaluate,
)

FloatArray = NDArray[np.float64]

NAME = "load_cell"
WINCH_TENSION_NAME = "winch_tension"


def _at_drone(models: CableModels) -> Generated:
    return models.tension


def _at_anchor(models: CableModels) -> Generated:
    return models.anchor_tension


class LoadCellAid:
    """Fuses a measured tension [N] with noise ``noise_std_n`` [N]: at the drone, or with
    ``at_anchor`` the winch's where the cable leaves it (status records under
    :data:`WINCH_TENSION_NAME` then)."""

    def __init__(self, noise_std_n: float, *, at_anchor: bool = False) -> None:
        self.status = AidStatus()
        self._r = np.array([[noise_std_n**2]])
        self._name = WINCH_TENSION_NAME if at_anchor else NAME
        self._model: Callable[[CableModels], Generated] = _at_anchor if at_anchor else _at_drone

    def fuse(
        self, bank: FilterBank, constants: ModelConstants, tension_n: float, time_s: float
    ) -> bool:
        """Fuse one reading [N]."""
        model = self._model(constants.models)
        c = constants.values()

        def measure(xs: FloatArray) -> tuple[FloatArray, FloatArray]:
            return evaluate(model, xs, (), c, 1)

        return fuse(bank, self._name, self.status, np.array((tension_n,)), measure, self._r, time_s)
