"""Optional ground-station cable angle: elevation (up from horizontal) and azimuth (from
north) of the cable where it leaves the anchor [rad] (generated ``cable_angle_*``: the
catenary's tangent there, flat where the cable rests on the ground). The azimuth innovation is
wrapped to [-pi, pi). The sensor's noise is a direction noise ``sigma`` per axis [rad]: the
elevation's is ``sigma``, the azimuth's ``sigma / cos(elevation)`` (a direction error across
a steep cable turns its azimuth by more). Skipped while the cable is slack."""

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
    """Fuses (elevation, azimuth) [rad] while the chord tension is above ``slack_tension_n``
    [N]."""

    MIN_COS_ELEVATION = 0.05
    """The azimuth's noise is at most ``sigma / MIN_COS_ELEVATION`` (a cable within 3 degrees
    of the vertical)."""

    def __init__(self, slack_tension_n: float) -> None:
        self.status = AidStatus()
        self._slack_n = slack_tension_n

    def fuse(
        self,
        bank: FilterBank,
        constants: ModelConstants,
        elevation_rad: float,
        azimuth_rad: float,
        time_s: float,
        noise_std_rad: float,
    ) -> bool:
        """Fuse one reading [rad] of direction noise ``noise_std_rad`` [rad]."""
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
        cos_elevation = max(np.cos(elevation_rad), self.MIN_COS_ELEVATION)
        r = np.diag((noise_std_rad**2, (noise_std_rad / cos_elevation) ** 2))
        return fuse(bank, NAME, self.status, z, measure, r, time_s)
