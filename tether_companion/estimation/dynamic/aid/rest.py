"""The drone at rest on the ground: zero velocity and the centre of mass at its rest height
above the ground (a zero-velocity update, as every inertial navigator makes when it knows it
stands still).

While the drone rests, nothing else holds the inertial prediction: the force balance is not
fused (the ground's contact force is no part of its model) and the rangefinder is below its
minimum range. Without this the velocity the filter had at the touchdown ran on: on the
realistic take-off's landing (tuning seeds 1-2) the filter kept descending at 1.5-1.9 m/s
through the ground, 3 m off within 3 s with a claimed 0.5 m (NEES 300-700 on the withheld
ticks).

Resting is decided by the estimator (motors idling or the flight controller's land detector,
and the accelerometer reading the ground's reaction, about ``g``: a drone falling with its
motors stopped reads about 0). The touchdown itself is a force the model leaves out, so the
filter's velocity and height may be far off when rest begins: a component whose innovation is
beyond 3 sigma of its own is first given the variance that puts it at 1 sigma (the filter
admits what the unmodelled impact did; :attr:`RestAid.settled` counts it) and only then fused,
so the error is taken out of the velocity and height themselves and not read into the biases
and the tension through their correlations.

Measurement: ``(v_n, v_e, v_d, -p_d + anchor_height)`` = ``(0, 0, 0, rest_height)``, linear
(the height row is the rangefinder's generated model). The velocity at rest is zero up to the
airframe's rocking, new at each sample; the rest height's error (the landing gear told, the
ground under the drone) is one constant for the whole rest, so the height row is fused at the
rest's first sample and after that only while the filter's own height variance is above that
error's: repeated, it would average a constant as noise and claim the height better than the
ground is known.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.config import GroundStation
from tether_companion.estimation.dynamic import generated, state
from tether_companion.estimation.dynamic.aiding import AidStatus, fuse
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.config import DynamicFilterConfig

FloatArray = NDArray[np.float64]

NAME = "rest"
SETTLE_SIGMAS = 3.0
"""A component's innovation beyond this many of its standard deviations is taken as the
touchdown's unmodelled impact (its variance raised to put it at 1 sigma)."""
REST_SPECIFIC_FORCE_TOLERANCE_MPS2 = 2.0
"""How far from ``g`` the specific force's magnitude may be at rest [m/s^2]: idling motors'
vibration and a landing gear rocking stay well within it, a fall reads ``g`` less."""
NEW_REST_AFTER_S = 1.0
"""A rest sample this long [s] after the last one starts a new rest (a new touchdown)."""
_NO_CONSTANTS = (0.0, 0.0, 0.0)
"""The height model uses none of the constants ``c``."""


def resting_on_ground(motors_idle_or_landed: bool, specific_force_mps2: Sequence[float]) -> bool:
    """Whether the drone rests on the ground: the motors idle or the flight controller says
    landed, and the specific force's magnitude (FRD [m/s^2]) is within
    :data:`REST_SPECIFIC_FORCE_TOLERANCE_MPS2` of ``g`` (the ground's reaction; a drone
    falling with its motors stopped reads about 0)."""
    if not motors_idle_or_landed:
        return False
    fx, fy, fz = specific_force_mps2
    norm = math.sqrt(fx * fx + fy * fy + fz * fz)
    return abs(norm - GRAVITY_MPS2) <= REST_SPECIFIC_FORCE_TOLERANCE_MPS2


class RestAid:
    """Fuses the drone's rest on the ground.

    Parameters
    ----------
    velocity_std_mps
        Standard deviation of the velocity at rest [m/s] (the airframe rocking on its legs,
        the cable dragging it).
    rest_height_m, rest_height_std_m
        Height of the centre of mass above the ground when landed [m] (the landing gear;
        ArduPilot's RNGFND1_GNDCLEAR is the rangefinder's) and its uncertainty [m].
    anchor_height_m, terrain_std_m
        The anchor's height above the ground [m]; the ground's unevenness under the drone
        against the anchor's ground [m] (added to the height's variance).
    """

    def __init__(
        self,
        velocity_std_mps: float,
        rest_height_m: float,
        rest_height_std_m: float,
        anchor_height_m: float,
        terrain_std_m: float,
    ) -> None:
        self.status = AidStatus()
        self.settled = 0
        """Rest samples whose velocity or height the filter had beyond 3 sigma (a touchdown's
        impact), whose variance was raised before fusing."""
        self._z = np.array((0.0, 0.0, 0.0, rest_height_m))
        self._r_diagonal = np.array(
            (velocity_std_mps**2,) * 3 + (rest_height_std_m**2 + terrain_std_m**2,)
        )
        self._u = [anchor_height_m]
        _, height_row = generated.height_above_ground(
            [0.0] * state.N_STATES, self._u, _NO_CONSTANTS
        )
        jacobian = np.zeros((4, state.N_STATES))
        jacobian[0:3, state.VELOCITY] = np.eye(3)
        jacobian[3] = height_row
        self._jacobian = jacobian
        v = state.VELOCITY.start
        self._rows = (v, v + 1, v + 2, state.POSITION.start + 2)
        """The state index each measurement row reads (the height row: ``p_d``)."""
        self._last_time_s = -math.inf
        """Filter time of the last rest sample [s]."""

    @classmethod
    def of_config(cls, dynamic: DynamicFilterConfig, ground_station: GroundStation) -> RestAid:
        """The rest as the filter's settings and the ground station's describe it."""
        return cls(
            dynamic.rest_velocity_std_mps,
            dynamic.rest_height_m,
            dynamic.rest_height_std_m,
            ground_station.anchor_height_m,
            ground_station.terrain_std_m,
        )

    def _measure(self, xs: FloatArray, m: int) -> tuple[FloatArray, FloatArray]:
        """The first ``m`` rows (3: the velocity; 4: and the height) at the state ``xs``."""
        v = state.VELOCITY.start
        if m == 3:
            return xs[v : v + 3].copy(), self._jacobian[:3]
        height, _ = generated.height_above_ground(xs.tolist(), self._u, _NO_CONSTANTS)
        return np.array((xs[v], xs[v + 1], xs[v + 2], height[0])), self._jacobian

    def _settle(self, bank: FilterBank, m: int) -> bool:
        """Raise, in every member, the variance of each of the first ``m`` components whose
        innovation is beyond :data:`SETTLE_SIGMAS` of its own standard deviation to put it at
        1 sigma; whether any member's was."""
        any_settled = False
        z, r = self._z, self._r_diagonal
        for kf in bank.filters:
            value, _ = self._measure(kf.x, m)
            p = kf.P
            raise_by = np.zeros(state.N_STATES)
            for row in range(m):
                index = self._rows[row]
                s = p[index, index] + r[row]
                square = (z[row] - value[row]) ** 2
                if square > SETTLE_SIGMAS * SETTLE_SIGMAS * s:
                    raise_by[index] = square - s
            if raise_by.any():
                kf.P = p + np.diag(raise_by)
                any_settled = True
        return any_settled

    def fuse(self, bank: FilterBank, time_s: float) -> bool:
        """Fuse one rest sample at filter time ``time_s`` [s] (the height too at a rest's first
        sample and while the best member's height variance is above the rest height's);
        whether it was fused into the best member."""
        first = time_s - self._last_time_s > NEW_REST_AFTER_S
        self._last_time_s = time_s
        m = 4 if first or bank.best.P[2, 2] > self._r_diagonal[3] else 3
        if self._settle(bank, m):
            self.settled += 1
        return fuse(
            bank,
            NAME,
            self.status,
            self._z[:m],
            lambda xs: self._measure(xs, m),
            np.diag(self._r_diagonal[:m]),
            time_s,
        )
