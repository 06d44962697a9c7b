"""The ground station's readings into the dynamic filter: :class:`GroundStationFeed`.

The load cell (at the drone or the winch's), the winch's paid-out length and the cable angle at
the anchor, as :class:`~tether_companion.estimation.dynamic.estimator.DynamicTetherEstimator`
takes them: checked by
:class:`~tether_companion.estimation.dynamic.ground_station.GroundStationInputs`, given to the
start while there is no state, and fused once the members are stepped to the reading's time.

Pure.
"""

from __future__ import annotations

import math

from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.ground_station import GroundStationInputs
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.estimation.dynamic.startup import FilterStartup
from tether_companion.estimation.dynamic.tension_walk import TensionWalk


class GroundStationFeed:
    """``set_known_tension_n``, ``set_winch_tension_n``, ``set_paid_out_length_m`` and
    ``on_cable_angle`` of the dynamic estimator, which holds these attributes and steps its
    members over the batch with ``_step_batch``."""

    config: EstimatorConfig
    dynamic: DynamicFilterConfig
    constants: ModelConstants
    ground_station: GroundStationInputs
    bank: FilterBank | None
    _startup: FilterStartup
    _walk: TensionWalk
    _time_s: float

    def _step_batch(self) -> None:
        """Step the members to the filter time (the estimator's)."""
        raise NotImplementedError

    def _fresh(self, time_s: float, bound_s: float) -> bool:
        """Whether ``time_s`` [s] is within ``bound_s`` [s] of the filter time."""
        return not math.isnan(self._time_s) and abs(time_s - self._time_s) <= bound_s

    def set_known_tension_n(self, tension_n: float, time_s: float) -> None:
        """Load-cell tension at the drone [N] at ``time_s`` [s]: fused when initialised."""
        if self.ground_station.tension_ok(tension_n, time_s) and self._stepped_to(time_s):
            assert self.bank is not None
            self.ground_station.fuse_tension(self.bank, self.constants, tension_n, self._time_s)
            self.constants.tension_measured |= self.ground_station.load_cell.status.fused > 0

    def set_winch_tension_n(self, tension_n: float, time_s: float) -> None:
        """The winch's load cell at ``time_s`` [s]: the tension where the cable leaves the
        winch [N], fused when initialised as the anchor's end of the filter's cable
        (``|F_c| - w b``, generated ``anchor_tension_*``). While these readings are fused
        (each within ``staleness.tension_s`` of the last) the chord tension walks at
        ``noise.winch_tension_n2ps`` instead of ``noise.tension_n2ps``: a constant-tension
        winch holds the anchor's tension, and the chord tension then moves only as far as
        the winch's control lets it and the geometry turns a held anchor tension into a
        chord tension (docs/estimation-history.md, sag13)."""
        if not self.ground_station.tension_ok(tension_n, time_s):
            return
        if self.bank is None:  # with a cable angle it places a heavy cable's start
            self._startup.add_winch_tension(time_s - self.dynamic.winch_latency_s, tension_n)
        elif self._stepped_to(time_s):
            assert self.bank is not None
            if self.ground_station.fuse_winch_tension(
                self.bank, self.constants, tension_n, self._time_s
            ):
                self.constants.tension_measured = True
                self._walk.winch_fused(self._time_s, self.bank.filters)

    def set_paid_out_length_m(self, length_m: float, time_s: float) -> None:
        """Winch paid-out length [m]: the cable model's length from now on, and fused."""
        if not self.ground_station.length_ok(length_m, time_s):
            return
        self.constants.length_m = length_m
        if self._stepped_to(time_s):
            assert self.bank is not None
            self.ground_station.fuse_length(
                self.bank, self.constants, length_m, self._time_s, self._time_s - time_s
            )

    def on_cable_angle(
        self,
        elevation_rad: float,
        azimuth_rad: float,
        time_s: float,
        noise_std_rad: float,
        calibration_std_rad: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        """Ground-station cable angle at the anchor [rad]: elevation up, azimuth from north,
        the sensor's direction noise ``noise_std_rad`` [rad] (aid/cable_angle.py) and its
        calibration errors (elevation, azimuth) [rad] (position_information.py)."""
        inputs = self.ground_station
        if not inputs.angle_ok(
            elevation_rad, azimuth_rad, time_s, noise_std_rad, calibration_std_rad
        ):
            return
        if self.bank is None:  # it places the start (taken the sensor's latency earlier)
            self._startup.add_angle(
                time_s - self.dynamic.cable_angle_latency_s,
                elevation_rad,
                azimuth_rad,
                noise_std_rad,
                calibration_std_rad,
            )
        elif self._stepped_to(time_s):
            assert self.bank is not None
            inputs.fuse_angle(
                self.bank,
                self.constants,
                elevation_rad,
                azimuth_rad,
                self._time_s,
                noise_std_rad,
                calibration_std_rad,
                self._time_s - time_s,
            )

    def _stepped_to(self, time_s: float) -> bool:
        """Whether a ground-station reading at ``time_s`` [s] can be fused now: the filter is
        initialised, the reading within ``staleness.tension_s`` of the filter time, and the
        members stepped to that time without diverging."""
        if self.bank is None or not self._fresh(time_s, self.config.staleness.tension_s):
            return False
        self._step_batch()
        return self.bank is not None
