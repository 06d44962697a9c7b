"""Optional ground-station cable angle: elevation (up from horizontal) and azimuth (from
north) of the cable where it leaves the anchor [rad] (generated ``cable_angle_*``). The
azimuth innovation is wrapped to [-pi, pi). Skipped while the cable is slack."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.aiding import AidStatus, fuse
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.frames import wrap_pi

FloatArray = NDArray[np.float64]

NAME = "cable_angle"
SLACK = "slack"


class CableAngleAid:
    """Fuses (elevation, azimuth) [rad] with noise ``noise_std_rad`` each."""

    def __init__(self, noise_std_rad: float, slack_tension_n: float) -> None:
        self.status = AidStatus()
        self._r = np.eye(2) * noise_std_rad**2
        self._slack_n = slack_tension_n

    def fuse(
        self,
        bank: FilterBank,
        constants: ModelConstants,
        elevation_rad: float,
        azimuth_rad: float,
        time_s: float,
    ) -> bool:
        """Fuse one reading [rad]."""
        if bank.best.x[state.TENSION] < self._slack_n:
            self.status.skip(SLACK)
            return False
        model = constants.models.cable_angle
        c = constants.values()

        def measure(xs: FloatArray) -> tuple[FloatArray, FloatArray]:
            (elevation, azimuth), jac = model(xs.tolist(), (), c)
            # predicted azimuth moved by whole turns next to the measured one
            azimuth = azimuth_rad - wrap_pi(azimuth_rad - azimuth)
            return np.array((elevation, azimuth)), np.array(jac).reshape(2, state.N_STATES)

        z = np.array((elevation_rad, azimuth_rad))
        return fuse(bank, NAME, self.status, z, measure, self._r, time_s)
