"""From the first data to a running bank of filters: :class:`FilterStartup`.

Until the dynamic filter has a state, every IMU tick with fresh inputs and every rangefinder
height goes to the :class:`~tether_companion.estimation.dynamic.initialise.Initialiser`; once
it has hypotheses (position, velocity, tension, thrust scale, ... with their covariances) each
becomes a :class:`~tether_companion.estimation.dynamic.member.MemberFilter` of a new
:class:`~tether_companion.estimation.dynamic.bank.FilterBank`. After a divergence the
estimator calls :meth:`FilterStartup.restart`: initialisation starts again from fresh data.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.alignment import AlignedInputs
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import generated
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.initialise import Initialiser
from tether_companion.estimation.dynamic.member import MemberFilter
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.estimation.dynamic.noise import wind_decay_per_s


class FilterStartup:
    """Feeds the initialiser and builds the bank from its hypotheses.

    Parameters
    ----------
    config
        The shared estimator settings (the gate, the rangefinder's noise).
    dynamic
        The filter's settings (the initial uncertainties, the thrust-scale bank's duration).
    constants
        The models' constants (mass [kg], drag [1/s], cable weight [N/m], and the winch's
        paid-out length [m] when known, read at each tick).
    process_noise_density
        The members' process noise density per state, shape (13,) (state units^2 per s).
    inertial
        Whether the members predict with the inertial formulation (the accelerometer as the
        input) rather than the force balance.
    ticks_per_fusion
        IMU ticks per prediction and force-balance fusion (the bank's decision count).
    """

    def __init__(
        self,
        config: EstimatorConfig,
        dynamic: DynamicFilterConfig,
        constants: ModelConstants,
        process_noise_density: NDArray[np.float64],
        *,
        inertial: bool,
        ticks_per_fusion: int,
    ) -> None:
        self._config = config
        self._dynamic = dynamic
        self._constants = constants
        self._q = process_noise_density
        self._inertial = inertial
        self._ticks_per_fusion = ticks_per_fusion
        self._initialiser = self._new_initialiser()

    @property
    def reason(self) -> str:
        """Why there are no hypotheses yet."""
        return self._initialiser.reason

    def restart(self) -> None:
        """Forget the data so far: initialise again from fresh data."""
        self._initialiser = self._new_initialiser()

    def add_height(self, height_above_anchor_m: float) -> None:
        """A rangefinder height above the anchor [m] (tilt and lever arm corrected)."""
        self._initialiser.add_height(height_above_anchor_m)

    def add_angle(
        self,
        time_s: float,
        elevation_rad: float,
        azimuth_rad: float,
        noise_std_rad: float,
        calibration_std_rad: tuple[float, float],
    ) -> None:
        """A ground-station cable angle taken at ``time_s`` [s] (elevation, azimuth [rad],
        its noise and calibration errors (elevation, azimuth) [rad]) with the winch's latest
        length (the constants'): they place the drone
        (:meth:`~tether_companion.estimation.dynamic.initialise.Initialiser.add_angle`)."""
        self._initialiser.add_angle(
            time_s,
            elevation_rad,
            azimuth_rad,
            noise_std_rad,
            calibration_std_rad,
            self._constants.length_m,
        )

    def add_winch_tension(self, time_s: float, tension_n: float) -> None:
        """The winch's tension where the cable leaves it [N], taken at ``time_s`` [s]
        (:meth:`~tether_companion.estimation.dynamic.initialise.Initialiser.add_winch_tension`)."""
        self._initialiser.add_winch_tension(time_s, tension_n)

    def add_tick(self, aligned: AlignedInputs) -> FilterBank | None:
        """One IMU tick with its aligned attitude and thrust; the bank of one member per
        hypothesis once the data give hypotheses, else ``None``."""
        t, force, rotation, thrust = aligned
        self._initialiser.add_tick(t, force, rotation, thrust)
        c = self._constants
        starts = self._initialiser.hypotheses(t, self._dynamic.initial, c.length_m)
        if not starts:
            return None
        process = generated.inertial if self._inertial else c.models.force_balance
        gate = self._config.gate
        members = [
            MemberFilter(
                start.x,
                start.p,
                self._q,
                c,
                process,
                gate_probability=gate.probability,
                max_consecutive_rejections=gate.max_consecutive_rejections,
                wind_decay_per_s=wind_decay_per_s(self._dynamic),
            )
            for start in starts
        ]
        return FilterBank(
            members,
            t,
            self._dynamic.initial.thrust_scale_bank_max_s,
            self._ticks_per_fusion,
            [start.log_prior for start in starts],
            [i if start.bearing_rival else 0 for i, start in enumerate(starts)],
        )

    def _new_initialiser(self) -> Initialiser:
        return Initialiser(
            self._dynamic,
            self._constants.mass_kg,
            self._constants.drag_per_s,
            self._dynamic.accel_noise_std_mps2,
            math.sqrt(self._config.altimeter_noise_variance_m2),
        )
