"""The process noise the members step with, and the chord tension's walk in it: ``noise.
tension_n2ps``, or ``noise.winch_tension_n2ps`` while a winch's tension is fused.

The state's tension is the chord tension (``state.py``); a constant-tension winch holds the
tension where the cable leaves it, and at a held anchor tension the chord tension moves only
with the geometry (the heavy cable's as the drone climbs or swings out), slowly: the winch
flights' true chord tension changes by at most 0.07 N^2 per second of flight and 0.01 N^2 per
0.1 s (tuning seeds 1-2 of the six realistic-winch scenarios; the heavy 5 N figure-8 the most).
Without a winch the chord tension of a fixed-length or elastic cable moves as fast as the drone
pulls on it, which the default walk (2 N^2/s) is for. A winch silent for longer than the
tension's staleness bound gives the default walk back, as does a restart.

Pure; the arrays are replaced, never changed in place (the IMU batch keeps its step's noise
while ``q`` is the same object).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.member import MemberFilter
from tether_companion.estimation.dynamic.mixture import ProcessNoise
from tether_companion.estimation.dynamic.noise import process_noise_density

FloatArray = NDArray[np.float64]


class TensionWalk:
    """The members' process noise with the chord tension's walk as the winch's tension allows.

    Parameters
    ----------
    dynamic
        The filter's settings (``noise``).
    stale_s
        A winch tension older than this [s] no longer holds the walk down.
    """

    def __init__(self, dynamic: DynamicFilterConfig, stale_s: float) -> None:
        self.default = process_noise_density(dynamic)
        """The default density, diagonal (n,): what a starting bank's members get."""
        self._default_n2ps = dynamic.noise.tension_n2ps
        self._winch_n2ps = dynamic.noise.winch_tension_n2ps
        self._stale_s = stale_s
        self._winch_s = math.nan
        """Filter time [s] of the last fused winch tension (``nan``: none since the start)."""
        self.matrix = np.diag(self.default)
        """The density (n, n) the members step with now."""
        self.noise = ProcessNoise(self.matrix)

    def winch_fused(self, time_s: float, members: Iterable[MemberFilter]) -> None:
        """A winch tension was fused at filter time ``time_s`` [s]: the winch's walk."""
        self._winch_s = time_s
        self._set(self._winch_n2ps, members)

    def check(self, time_s: float, members: Iterable[MemberFilter]) -> None:
        """Before the members step to ``time_s`` [s]: the default walk if the winch fell
        silent."""
        if time_s - self._winch_s > self._stale_s:
            self._set(self._default_n2ps, members)

    def restart(self) -> None:
        """The bank restarts from :attr:`default`: so does the walk."""
        self._winch_s = math.nan
        self._set(self._default_n2ps, ())

    def _set(self, n2ps: float, members: Iterable[MemberFilter]) -> None:
        if self.matrix[state.TENSION, state.TENSION] == n2ps:
            return
        q = self.default.copy()
        q[state.TENSION] = n2ps
        self.matrix = np.diag(q)
        self.noise = ProcessNoise(self.matrix)
        for member in members:
            member.set_process_noise(q)
