"""The ground station's readings fused into the dynamic filter: :class:`GroundStationInputs`.

Three optional sensors at the anchor, each with its own measurement module under ``aid/``:

* the load cell's tension at the drone [N] (:class:`LoadCellAid`), or the winch's where the
  cable leaves it [N] (the same aid at the anchor: ``|F_c| - w b``);
* the winch's paid-out cable length [m] (:class:`WinchAid`);
* the cable angle at the anchor [rad]: elevation up from the horizontal, azimuth from north
  (:class:`CableAngleAid`). A fused angle also feeds the bearing window (the azimuth's noise
  across the cable) and :class:`PositionInformation` (what it tells about the position within
  the unmodelled force's correlation time, which narrows the published covariance's
  unmodelled term); while one was fused within :data:`ANGLE_FRESH_S` the estimate's status
  waives the weak-pull rule (:meth:`GroundStationInputs.status_settings`).

The winch's and the angle's calibration errors (the encoder's zero and scale, the angle
sensor's zero against north and its level) are not white: they are states of the filter
(``state.py``), constants of the flight whose prior (the configured standard deviations)
enters with the start where a reading placed it (``initialise.py``, correlated with the
position) or else with the sensor's first reading (:func:`open_calibration`). They are held as
consider states until the filter has settled (:mod:`.calibration_release`: the readings move
the position, not them, while the start may be wrong), then learnt where the flight makes
them observable (a circle: the rangefinder's height against the length and the elevation); in
a hover they stay at their prior and the position's covariance keeps their spread. The
azimuth zero stays a consider state throughout (``state.NEVER_RELEASED``).

Each reading is checked here (a non-finite or impossible value is counted in
``health.nonfinite_rejected`` and dropped); when to fuse it (the filter initialised, the reading
fresh, the members stepped to the filter time) is the estimator's decision
(:class:`~tether_companion.estimation.dynamic.estimator.DynamicTetherEstimator`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.aid.cable_angle import NAME as ANGLE_NAME
from tether_companion.estimation.dynamic.aid.cable_angle import CableAngleAid
from tether_companion.estimation.dynamic.aid.load_cell import LoadCellAid
from tether_companion.estimation.dynamic.aid.winch import NAME as WINCH_NAME
from tether_companion.estimation.dynamic.aid.winch import WinchAid
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.calibration_release import (
    ELEVATION,
    WINCH,
    CalibrationRelease,
)
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.consistency import BearingWindow
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.estimation.dynamic.offset_term import offset_rows
from tether_companion.estimation.dynamic.output import DynamicHealth
from tether_companion.estimation.dynamic.position_information import PositionInformation
from tether_companion.estimation.dynamic.published import StatusSettings

ANGLE_FRESH_S = 1.0
"""A ground-station cable angle fused within this [s] measures the bearing: the rule that
withholds a pull too weak against the wind's drag (observability.py) is waived meanwhile."""


LOAD_CELL_BELOW_ZERO_STDS = 5.0
"""A load cell reads a tension near zero as that tension plus its noise, below zero about half
the time at zero: a reading down to this many of its noise standard deviations below zero is
a measurement, lower a fault (dropped, counted). Dropping every negative reading fused only the
upper part of the noise: on the fixed-length sagging circle (anchor tension ~0.07 N, the
winch's 0.2 N of noise) the readings fused averaged ~0.19 N."""


class GroundStationInputs:
    """Checks and fuses the load cell's tension, the winch's length and the cable angle.

    Parameters
    ----------
    dynamic
        The filter's settings (the sensors' noise, the slack tension, the unmodelled force's
        correlation time).
    bearing
        The estimator's bearing window: a fused angle adds its azimuth's noise across the
        cable [m], and the window's unmodelled force [N] sizes the angle's information.
    health
        The estimator's counters (``nonfinite_rejected``, ``*_fused``).
    status_settings
        The rules the estimate's status is judged by without a fresh cable angle.
    """

    def __init__(
        self,
        dynamic: DynamicFilterConfig,
        bearing: BearingWindow,
        health: DynamicHealth,
        status_settings: StatusSettings,
        confirmed_pull_per_wind_n_s_per_m: float,
    ) -> None:
        self.load_cell = LoadCellAid(dynamic.load_cell_noise_std_n)
        self._least_tension_n = -LOAD_CELL_BELOW_ZERO_STDS * dynamic.load_cell_noise_std_n
        """The lowest load-cell reading [N] taken as a measurement."""
        self.winch_tension = LoadCellAid(dynamic.load_cell_noise_std_n, at_anchor=True)
        self.winch = WinchAid(
            dynamic.winch_length_noise_std_m, dynamic.slack_tension_n, dynamic.winch_latency_s
        )
        self.cable_angle = CableAngleAid(dynamic.slack_tension_n, dynamic.cable_angle_latency_s)
        self.position_information = PositionInformation(dynamic.unmodelled_force_correlation_s)
        """What the fused cable angles tell about the position within the unmodelled force's
        correlation time (it narrows the unmodelled term of the published covariance)."""
        self.calibration_release = CalibrationRelease(dynamic.learn_calibration)
        """When the bank's calibration states stop being consider states."""
        self._winch_length_noise_std_m = dynamic.winch_length_noise_std_m
        self._winch_calibration_m = (
            dynamic.winch_length_offset_std_m,
            dynamic.winch_length_scale_std,
        )
        """The winch length's zero error [m] and scale error [1] (standard deviations): the
        prior of the calibration states."""
        self._elevation_calibration_std_rad = 0.0
        """The angle sensor's elevation zero's prior standard deviation [rad] (the last
        angle's)."""
        self._elevation_noise_std_rad = 0.0
        """The last angle's elevation noise standard deviation [rad]."""
        self._bearing = bearing
        self._health = health
        self._status_settings = status_settings
        self._angle_status_settings = dataclasses.replace(
            status_settings, pull_per_wind_n_s_per_m=0.0
        )
        """The status settings while a cable angle measures the bearing (ANGLE_FRESH_S)."""
        self._confirmed_status_settings = dataclasses.replace(
            status_settings, pull_per_wind_n_s_per_m=confirmed_pull_per_wind_n_s_per_m
        )
        """The status settings once the bank's bearing hypotheses converged to one."""

    # ------------------------------------------------------------------ checks
    def tension_ok(self, tension_n: float, time_s: float) -> bool:
        """Whether a load-cell reading (tension [N] at ``time_s`` [s]) is usable: finite and
        not below zero by more than its noise explains (counted in ``nonfinite_rejected`` when
        not)."""
        if not (math.isfinite(tension_n) and math.isfinite(time_s)) or (
            tension_n < self._least_tension_n
        ):
            self._health.nonfinite_rejected += 1
            return False
        return True

    def length_ok(self, length_m: float, time_s: float) -> bool:
        """Whether a winch reading (paid-out length [m] at ``time_s`` [s]) is usable (counted
        in ``nonfinite_rejected`` when not)."""
        if not (math.isfinite(length_m) and math.isfinite(time_s)) or length_m <= 0.0:
            self._health.nonfinite_rejected += 1
            return False
        return True

    def angle_ok(
        self,
        elevation_rad: float,
        azimuth_rad: float,
        time_s: float,
        noise_std_rad: float,
        calibration_std_rad: tuple[float, float] = (0.0, 0.0),
    ) -> bool:
        """Whether a cable-angle reading is usable: finite, the elevation within +-pi/2 [rad],
        a positive noise [rad], calibration errors (elevation, azimuth) finite and not
        negative [rad] (counted in ``nonfinite_rejected`` when not)."""
        values = (elevation_rad, azimuth_rad, time_s, noise_std_rad, *calibration_std_rad)
        if (
            not all(math.isfinite(v) for v in values)
            or abs(elevation_rad) > math.pi / 2
            or noise_std_rad <= 0.0
            or min(calibration_std_rad) < 0.0
        ):
            self._health.nonfinite_rejected += 1
            return False
        return True

    # ------------------------------------------------------------------ fusion
    def fuse_tension(
        self, bank: FilterBank, constants: ModelConstants, tension_n: float, time_s: float
    ) -> None:
        """Fuse a load-cell tension at the drone [N] at filter time ``time_s`` [s]."""
        if self.load_cell.fuse(bank, constants, tension_n, time_s):
            self._health.load_cell_fused += 1

    def fuse_winch_tension(
        self, bank: FilterBank, constants: ModelConstants, tension_n: float, time_s: float
    ) -> bool:
        """Fuse the winch's load cell, the tension where the cable leaves the winch [N], at
        filter time ``time_s`` [s] (counted in ``load_cell_fused``); whether it was fused."""
        fused = self.winch_tension.fuse(bank, constants, tension_n, time_s)
        if fused:
            self._health.load_cell_fused += 1
        return fused

    def fuse_length(
        self,
        bank: FilterBank,
        constants: ModelConstants,
        length_m: float,
        time_s: float,
        age_s: float = 0.0,
    ) -> None:
        """Fuse a winch paid-out length [m] at filter time ``time_s`` [s], stamped ``age_s``
        [s] before it."""
        open_calibration(bank, (state.WINCH_OFFSET, state.WINCH_SCALE), self._winch_calibration_m)
        gated_before = self.winch.status.gated
        slack = self.winch.maybe_slack(bank, constants, length_m)
        release = self.calibration_release
        release.follow_length(bank, not slack)  # a bound or a skip: no length's model
        fused = self.winch.fuse(bank, constants, length_m, time_s, age_s, slack)
        if fused:
            self._health.winch_fused += 1
        # a bound's (pseudo) innovation is no length's: the release rule sees the model's only
        if not slack and (fused or self.winch.status.gated != gated_before):
            self._settle(bank, WINCH_NAME, time_s, 1)
        if not fused:
            release.follow_length(bank, False)

    def fuse_angle(
        self,
        bank: FilterBank,
        constants: ModelConstants,
        elevation_rad: float,
        azimuth_rad: float,
        time_s: float,
        noise_std_rad: float,
        calibration_std_rad: tuple[float, float] = (0.0, 0.0),
        age_s: float = 0.0,
    ) -> None:
        """Fuse a cable angle at the anchor (elevation up, azimuth from north [rad], the
        sensor's direction noise ``noise_std_rad`` [rad], its calibration errors
        ``calibration_std_rad`` (elevation, azimuth) [rad]) at filter time ``time_s`` [s],
        stamped ``age_s`` [s] before it; its innovation, and once fused its information,
        calibration and bearing, are recorded."""
        open_calibration(bank, (state.ELEVATION_ZERO, state.AZIMUTH_ZERO), calibration_std_rad)
        self._elevation_calibration_std_rad = calibration_std_rad[0]
        self._elevation_noise_std_rad = CableAngleAid.noise_std_rad(elevation_rad, noise_std_rad)[0]
        status = self.cable_angle.status
        gated_before = status.gated
        fused = self.cable_angle.fuse(
            bank, constants, elevation_rad, azimuth_rad, time_s, noise_std_rad, age_s
        )
        if fused or status.gated != gated_before:  # an innovation of this reading
            self.position_information.add_angle_innovation(
                status.last_innovation,
                status.last_innovation_variance.tolist(),
                bank.best.x_values()[:3],
                time_s,
            )
            self._settle(bank, ANGLE_NAME, time_s, 2)
        if fused:
            self._health.cable_angle_fused += 1
            x = bank.best.x_values()
            self._add_angle_information(constants, x, elevation_rad, noise_std_rad, time_s)
            # the azimuth's noise across the cable: times the span
            azimuth_std_rad = CableAngleAid.noise_std_rad(elevation_rad, noise_std_rad)[1]
            self._bearing.add_bearing(math.hypot(x[0], x[1]) * azimuth_std_rad)

    def status_settings(self, time_s: float, bearing_confirmed: bool) -> StatusSettings:
        """The rules the estimate's status at filter time ``time_s`` [s] is judged by: the
        weak-pull rule waived while a cable angle fused within :data:`ANGLE_FRESH_S`
        measures the bearing, relaxed (``confirmed_pull_over_wind_drag``) while the bank's
        bearing hypotheses have converged to one (``bearing_confirmed``)."""
        if time_s - self.cable_angle.status.last_fused_time_s <= ANGLE_FRESH_S:
            return self._angle_status_settings
        if bearing_confirmed:
            return self._confirmed_status_settings
        return self._status_settings

    def clear(self) -> None:
        """Forget the angles' information and the innovations the calibration's release
        watches (the filter restarts)."""
        self.position_information.clear()
        self.calibration_release.clear()

    def _settle(self, bank: FilterBank, sensor: str, time_s: float, dof: int) -> None:
        """The best member's NIS of the ``sensor``'s sample just tested (``dof`` degrees of
        freedom) at filter time ``time_s`` [s] to the calibration's release rule, once a
        cable angle has been fused: without one the winch's calibration is told only by the
        force balance's cable direction, whose errors (wind, unmodelled forces) it then takes
        (the realistic 4 N circle, winch alone, tuning seed 9: 4.5 % of the published ticks
        beyond 3 sigma released, none held); it stays a consider state, its spread in the
        position's covariance. The sample's innovation (the winch's length [m], the angle's
        elevation [rad]) goes to the rule's steadiness test with the prior and the noise of
        what it would teach."""
        if not self._health.cable_angle_fused:
            return
        status = bank.best.sensors.get(sensor)
        if status is not None:
            innovation = status.innovation[0] if len(status.innovation) else math.nan
            if sensor == WINCH_NAME:
                watched = (
                    WINCH,
                    innovation,
                    self._winch_calibration_m[0],
                    self._winch_length_noise_std_m,
                )
            else:
                watched = (
                    ELEVATION,
                    innovation,
                    self._elevation_calibration_std_rad,
                    self._elevation_noise_std_rad,
                )
            ranged = bool(self._health.winch_fused)
            self.calibration_release.add(bank, time_s, status.last_nis, dof, watched, ranged)

    def _add_angle_information(
        self,
        constants: ModelConstants,
        x: list[float],
        elevation_rad: float,
        noise_std_rad: float,
        time_s: float,
    ) -> None:
        """The fused angle's information about the position at the updated state ``x``
        (its Jacobian's position columns, the noise as :class:`CableAngleAid` fuses it).

        The azimuth always; the elevation only once a winch length was fused: the unmodelled
        term turns the cable at a known range, and only with the length is its vertical part
        the elevation the reading measures. Without a length the filter's range comes from
        the height through the elevation (``rho = h / tan(el)``), and the term's vertical part
        stands for that range's error, which the elevation does not remove in the filter
        (docs/estimation-history.md, "The unmodelled term and the cable angle (nees10)")."""
        _, jac_rows = self.cable_angle.evaluate(constants, np.array(x))
        jac = jac_rows.ravel().tolist()
        if not all(math.isfinite(v) for v in jac):
            return
        n = state.N_STATES
        elevation_std, azimuth_std = CableAngleAid.noise_std_rad(elevation_rad, noise_std_rad)
        winch = bool(self._health.winch_fused)
        if winch:
            rows, variances = (jac[0:3], jac[n : n + 3]), (elevation_std**2, azimuth_std**2)
        else:
            rows, variances = (jac[n : n + 3],), (azimuth_std**2,)
        added = offset_rows(  # as the published term takes it (offset_term.py)
            x,
            constants.weight_n_per_m,
            self._bearing.force_std_n,
            self._winch_length_noise_std_m if winch else 0.0,
            winch,
        )
        self.position_information.add(rows, variances, time_s, added)


def open_calibration(bank: FilterBank, indices: tuple[int, int], std: tuple[float, float]) -> None:
    """Give the calibration states ``indices`` of every member their prior standard
    deviations ``std`` (state units) where they have had none yet (their variance still at
    the start's :data:`~tether_companion.estimation.dynamic.state.UNSET_CALIBRATION_VARIANCE`:
    no reading of the sensor since the member started). Exact: until a model reads them
    they are uncorrelated with the rest, so this is the prior they would have had from the
    start."""
    unset = 2.0 * state.UNSET_CALIBRATION_VARIANCE
    for member in bank.filters:
        p = member.P
        if p[indices[0], indices[0]] > unset and p[indices[1], indices[1]] > unset:
            continue
        p = p.copy()
        for i, sd in zip(indices, std, strict=True):
            if p[i, i] <= unset:
                p[i, i] = max(sd * sd, state.UNSET_CALIBRATION_VARIANCE)
        member.P = p
