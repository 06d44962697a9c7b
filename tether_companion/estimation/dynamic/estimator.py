"""The dynamic tether filter fed by typed samples: :class:`DynamicTetherEstimator`.

Same call pattern as :class:`~tether_companion.estimation.pipeline.TetherEstimator` (pure,
synchronous, samples in time order, one :class:`NavigationEstimate` per IMU tick), so the
service, replay and the offline runner can use either:

* ``on_attitude``, ``on_pwm``: through the shared
  :class:`~tether_companion.estimation.alignment.InputAligner`;
* ``on_imu``: until initialised, the tick feeds the
  :class:`~tether_companion.estimation.dynamic.startup.FilterStartup`; afterwards the filter
  predicts to the IMU time with the previous tick's inputs (force balance, or the previous
  specific force in the inertial formulation) and fuses the accelerometer force balance;
* ``on_range``: the tilt-corrected height above the ground (validity checked and counted);
* ``set_known_tension_n`` (load cell at the drone), ``set_winch_tension_n`` (the winch's load
  cell; while fused the chord tension walks at ``noise.winch_tension_n2ps``),
  ``set_paid_out_length_m`` (winch; also switches the
  cable model to the known length), ``on_cable_angle`` (ground-station cable angle): checked
  and fused by :class:`~tether_companion.estimation.dynamic.ground_station.GroundStationInputs`
  once the filter is initialised and the reading is fresh.

Divergence (:mod:`~tether_companion.estimation.dynamic.divergence`: a non-finite state, an
accelerometer innovation gated for ``DIVERGED_AFTER_S`` in a row, or a position beyond
``MAX_DISTANCE_M``) restarts the initialisation; ``reset_counter`` counts it and the tick's
status is ``reset`` with the reason.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.alignment import (
    NONFINITE_INPUT,
    STALE_ATTITUDE,
    STALE_PWM,
    AlignedInputs,
    InputAligner,
    aligner_for,
)
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.accel_fusion import AccelFusion
from tether_companion.estimation.dynamic.aid.rangefinder import RangefinderAid
from tether_companion.estimation.dynamic.aid.rest import RestAid
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.config import INERTIAL, DynamicFilterConfig, drag_per_s
from tether_companion.estimation.dynamic.consistency import (
    BearingWindow,
    GustWalk,
    sample_bearing,
)
from tether_companion.estimation.dynamic.divergence import (
    MAX_DISTANCE_M,
    step_bank,
    too_far,
)
from tether_companion.estimation.dynamic.ground_station import GroundStationInputs
from tether_companion.estimation.dynamic.ground_station_feed import GroundStationFeed
from tether_companion.estimation.dynamic.imu_batch import ImuBatch
from tether_companion.estimation.dynamic.mixture import MixtureValues
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.estimation.dynamic.noise import accel_measurement_std_mps2, wind_decay_per_s
from tether_companion.estimation.dynamic.on_ground import AutopilotLanded, on_ground_reason
from tether_companion.estimation.dynamic.output import DynamicHealth, NavigationEstimate
from tether_companion.estimation.dynamic.published import StatusSettings, TickSource
from tether_companion.estimation.dynamic.sag_range import NO_SAG, SagMemo
from tether_companion.estimation.dynamic.startup import FilterStartup
from tether_companion.estimation.dynamic.tension_walk import TensionWalk
from tether_companion.estimation.ekf import ExtendedKalmanFilter
from tether_companion.estimation.inputs import InputFeed, range_height_m, range_reading_ok
from tether_companion.estimation.pipeline import default_thrust_input
from tether_companion.estimation.thrust_input import ThrustInput
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.samples import ImuSample, RangeSample

FloatArray = NDArray[np.float64]


class DynamicTetherEstimator(InputFeed, GroundStationFeed):
    """Position, velocity, tension, thrust scale, accelerometer bias and wind from samples.

    Parameters
    ----------
    config
        The shared estimator settings (staleness, gate, rangefinder validity and noise,
        ``min_cable_length_m``, ``thrust_model``).
    vehicle
        Vehicle profile (mass, thrust curve, drag).
    dynamic
        This filter's own settings (default: :class:`DynamicFilterConfig` defaults).
    thrust_input, aligner
        As for :class:`~tether_companion.estimation.pipeline.TetherEstimator`.
    """

    has_tension_state = True

    def __init__(
        self,
        config: EstimatorConfig,
        vehicle: VehicleProfile,
        dynamic: DynamicFilterConfig | None = None,
        thrust_input: ThrustInput | None = None,
        *,
        aligner: InputAligner | None = None,
    ) -> None:
        self.config = config
        self.dynamic = dynamic = dynamic if dynamic is not None else DynamicFilterConfig()
        self.vehicle = vehicle
        stale = config.staleness
        self.aligner = aligner_for(
            aligner,
            stale.attitude_s,
            stale.pwm_s,
            thrust_input,
            lambda: default_thrust_input(config, vehicle),
        )
        self.thrust_input: ThrustInput = self.aligner.thrust_input
        self.constants = ModelConstants(
            vehicle.mass_kg, drag_per_s(dynamic, vehicle), dynamic.cable_weight_n_per_m
        )
        self.health = DynamicHealth()
        self._on_ground_thrust_n = dynamic.min_thrust_fraction * (vehicle.mass_kg * GRAVITY_MPS2)
        """Below this total thrust [N] (a fraction of the weight) the drone stands on the
        ground."""
        self._ground_down_m = config.ground_station.anchor_height_m
        """The ground's down position, NED from the anchor [m] (taken flat)."""
        self.autopilot_landed = AutopilotLanded()
        """The flight controller's latest landed state."""
        self._inertial = dynamic.formulation == INERTIAL
        self._ticks_per_fusion = dynamic.imu_ticks_per_fusion if self._inertial else 1
        """IMU ticks per prediction and force-balance fusion (the inertial formulation's
        correlated residual makes every tick's sample mostly redundant; the force balance is
        the process in the other formulation, fused every tick)."""
        self._ticks_since_fusion = 0
        self._batch = ImuBatch(wind_decay_per_s(dynamic)) if self._inertial else None
        """The inertial prediction summed over the ticks since the members last stepped."""
        self._walk = TensionWalk(dynamic, config.staleness.tension_s)
        """The members' process noise: the chord tension's walk as the winch's tension allows."""
        status_settings = StatusSettings.of_filter(
            dynamic, vehicle.mass_kg, self.constants.drag_per_s
        )
        self._mixture: MixtureValues | None = None
        """The bank's latest mixture with its values as floats (kept while it is the same)."""
        self._sag = SagMemo()
        self.accel = AccelFusion(
            accel_measurement_std_mps2(dynamic),
            config.min_cable_length_m,
            self.health,
            RestAid.of_config(dynamic, config.ground_station),
        )
        self.rangefinder = RangefinderAid.of_config(config)
        self.bearing = BearingWindow(
            vehicle.mass_kg * self.constants.drag_per_s,
            dynamic.initial.wind_std_mps,
            dynamic.unmodelled_force_std_n,
            dynamic.unmodelled_force_correlation_s,
            dynamic.bearing_position_walk_m2ps,
            dynamic.bearing_wind_walk_m2ps3,
        )
        self.gusts = GustWalk(self.constants.drag_per_s)
        """The wind's walk the force balance's innovations show (the bearing window's)."""
        drag_n_s_per_m = vehicle.mass_kg * self.constants.drag_per_s
        self.ground_station = GroundStationInputs(
            dynamic,
            self.bearing,
            self.health,
            status_settings,
            dynamic.confirmed_pull_over_wind_drag * drag_n_s_per_m,
        )
        """The load cell, the winch and the cable angle."""
        self.bank: FilterBank | None = None
        self._startup = FilterStartup(
            config,
            dynamic,
            self.constants,
            self._walk.default,
            inertial=self._inertial,
            ticks_per_fusion=self._ticks_per_fusion,
        )
        self._time_s = math.nan
        self._inputs: list[float] | None = None
        self._resets = 0
        self._reset_reason: str | None = None
        self._last_tick_s = math.nan

    # ------------------------------------------------------------------ properties
    @property
    def time_s(self) -> float:
        """Filter time [s] (``nan`` before the first IMU tick)."""
        return self._time_s

    @property
    def reset_counter(self) -> int:
        """Restarts after divergence so far."""
        return self._resets

    @property
    def initialised(self) -> bool:
        """Whether the filter has a state."""
        return self.bank is not None

    @property
    def filter(self) -> ExtendedKalmanFilter | None:
        """The filter (the most likely member while several thrust-scale hypotheses run)."""
        return None if self.bank is None else self.bank.best

    # ------------------------------------------------------------------ inputs
    def set_autopilot_landed(self, landed: bool, time_s: float) -> None:
        """The flight controller's landed state at ``time_s`` [s] (EXTENDED_SYS_STATE;
        ``landed``: ON_GROUND): while fresh and landed the drone is on the ground (status
        ``on_ground``, the force balance not fused: the ground's contact force is not in the
        model); without one, the filter's own signs alone (thrust, height)."""
        self.autopilot_landed = AutopilotLanded(landed, time_s)

    def on_range(self, sample: RangeSample) -> None:
        """A downward rangefinder reading along the body z axis [m]: the height above the ground
        (tilt and the sensor's ``config.rangefinder.offset_frd_m`` lever arm corrected)."""
        health = self.health
        cfg = self.config.rangefinder
        if not range_reading_ok(sample, cfg, health):
            return
        height_m = range_height_m(
            sample, self.aligner, cfg, self.config.staleness.attitude_s, 0.0, health
        )
        if height_m is None:
            return
        height_above_anchor_m = height_m - self.config.ground_station.anchor_height_m
        if self.bank is None:
            self._startup.add_height(height_above_anchor_m)
            return
        if not self._fresh(sample.time_s, self.config.staleness.range_s):
            health.range_stale += 1
            return
        self._step_batch()
        if self.bank is None:  # the step diverged and restarted
            return
        fused = self.rangefinder.fuse(self.bank, height_m, self._time_s)
        health.last_range_nis = self.bank.best.sensors["rangefinder"].last_nis
        if fused:
            health.range_fused += 1
        elif self.rangefinder.status.gated:
            health.range_gated = self.rangefinder.status.gated

    # ------------------------------------------------------------------ the tick
    def on_imu(self, sample: ImuSample) -> NavigationEstimate | None:
        """Predict to the IMU time and fuse the force balance; the estimate (status
        ``initialising`` with the reason until the first window gives a state), or ``None``
        when the sample is rejected (non-finite, older than the filter)."""
        aligned = self.aligner.align(sample)
        health = self.health
        if aligned is NONFINITE_INPUT:
            health.nonfinite_rejected += 1
            return None
        t = sample.time_s
        previous_s = self._time_s
        if not math.isnan(previous_s):
            if t < previous_s:
                health.out_of_order += 1
                return None
            gap_s = t - previous_s
            if gap_s > self.config.staleness.max_gap_s and self.bank is not None:
                self._restart(f"IMU gap of {gap_s:.2f} s")
        self._time_s = t
        health.imu_ticks += 1
        stale = False
        if aligned is STALE_ATTITUDE:
            health.stale_attitude += 1
            stale = True
        elif aligned is STALE_PWM:
            health.stale_pwm += 1
            stale = True
        if self.bank is None:
            return self._initialise_tick(aligned, stale)
        self._ticks_since_fusion += 1
        fusion_tick = self._ticks_since_fusion >= self._ticks_per_fusion
        dt_s, self._last_tick_s = t - self._last_tick_s, t
        batch = self._batch
        assert self._inputs is not None
        if batch is None:  # formulation (a): the force balance is the process, every tick
            inputs = self._inputs
            self._step_members(lambda bank: bank.predict(dt_s, inputs))
        elif not batch.add(dt_s, self._inputs, self.constants.values()):
            health.nonfinite_rejected += 1
        if fusion_tick:
            self._walk.check(t, self.bank.filters)
            self._step_batch()
        bank = self.bank
        if bank is None:  # the prediction diverged and restarted
            return self._estimate(False, stale, False)
        on_ground = False
        accel_fused = False
        if not stale:
            assert isinstance(aligned, AlignedInputs)
            on_ground = aligned.thrust_n < self._on_ground_thrust_n
            rows = aligned.rotation.rows  # Python floats, made once per attitude sample
            force = self.aligner.specific_force_values
            if fusion_tick or not self._inertial:
                inputs = [*rows[0], *rows[1], *rows[2], aligned.thrust_n]
                if fusion_tick:
                    resting = on_ground or self.autopilot_landed.on_ground(self._time_s)
                    accel_fused = self.accel.fuse(bank, self.constants, inputs, force, t, resting)
                    self._ticks_since_fusion = 0
                    if accel_fused:
                        self._sample_bearing(t, rows)
                if not self._inertial:
                    self._inputs = inputs
            if self._inertial:  # the next tick's batch step: R_v^b and the specific force
                self._inputs = [*rows[0], *rows[1], *rows[2], *force]
        self._check_divergence(t, fusion_tick)
        return self._estimate(accel_fused, stale, on_ground)

    @property
    def initialising_reason(self) -> str:
        """Why there is no state yet (empty once initialised)."""
        return "" if self.bank is not None else self._startup.reason

    # ------------------------------------------------------------------ internals
    def _initialise_tick(self, aligned: AlignedInputs | str, stale: bool) -> NavigationEstimate:
        if stale:
            return self._estimate(False, True, False)
        assert isinstance(aligned, AlignedInputs)
        bank = self._startup.add_tick(aligned)
        if bank is not None:
            self.bank = bank
            self.health.initialisations += 1
            t, force, rotation, thrust = aligned
            inputs = [*rotation.ravel().tolist(), thrust]
            self._inputs = [*inputs[:9], *force.tolist()] if self._inertial else inputs
            self._last_tick_s = t
            self.accel.gated.clear()
            self._ticks_since_fusion = 0
            if self._batch is not None:
                self._batch.clear()
        return self._estimate(False, False, False)

    def _step_batch(self) -> None:
        """Step the members over the IMU ticks summed since they last stepped (inertial)."""
        batch = self._batch
        if batch is None or batch.ticks == 0 or self.bank is None:
            return
        self._step_members(lambda bank: bank.predict_batch(batch, self._walk.matrix))
        batch.clear()

    def _step_members(self, step: Callable[[FilterBank], None]) -> None:
        """Run a prediction ``step`` on the bank (:func:`step_bank`); restart when it says."""
        bank = self.bank
        assert bank is not None
        reason = step_bank(bank, step)
        if reason is not None:
            self._restart(reason)
            return
        self.health.pd_repairs = sum(kf.pd_repairs for kf in bank.filters)

    def _sample_bearing(self, t: float, rows: list[list[float]]) -> None:
        """The mixture after a force-balance fusion into the bearing window, its innovation
        (``R_v^b``'s ``rows``) into the gusts' walk, which the window then takes."""
        bank = self.bank
        if bank is None or not self.bearing.enabled:
            return
        innovation = self.accel.status.last_innovation.tolist()
        sample_bearing(self.bearing, self.gusts, t, bank.mixture(), bank.decided, innovation, rows)

    def _check_divergence(self, t: float, fusion_tick: bool) -> None:
        bank = self.bank
        if bank is None:
            return
        reason = self.accel.gated.diverged(t)
        if reason is None and fusion_tick:  # else the members have not stepped since
            bank.drop_unhealthy(MAX_DISTANCE_M)
            bank.maybe_decide(t)
            x = bank.best.x_values()
            reason = too_far(x)
            if bank.bearing_confirmed and x[state.TENSION] < self.dynamic.slack_tension_n:
                bank.bearing_confirmed = False  # a slack cable's pull holds no bearing
        if reason is not None:
            self._restart(reason)

    def _restart(self, reason: str) -> None:
        """Drop the state and initialise again from fresh data; counted in reset_counter."""
        self.bank = None
        self._startup.restart()
        self.bearing.clear()
        self.gusts.clear()
        self.rangefinder.ground.clear()
        self.ground_station.clear()
        self._walk.restart()
        self._resets += 1
        self.health.resets = self._resets
        self._reset_reason = f"filter restarted: {reason}"

    def _estimate(self, accel_fused: bool, stale: bool, on_ground: bool) -> NavigationEstimate:
        """The tick's estimate: what its values are computed from, kept (they are computed
        when read: :mod:`~tether_companion.estimation.dynamic.published`)."""
        bank = self.bank
        reset_reason, self._reset_reason = self._reset_reason, None
        mixture = None
        if bank is not None:
            x, p = bank.mixture()
            mixture = self._mixture
            if mixture is None or mixture.x is not x or mixture.p is not p:
                mixture = self._mixture = MixtureValues(x, p)
        batch = self._batch
        health = self.health
        winch_fused = bool(health.winch_fused)
        sag_std_m, sag_m2 = NO_SAG
        if mixture is not None and self.constants.weight_n_per_m > 0.0:
            sag_std_m, sag_m2 = self._sag.at(mixture, self.constants, winch_fused)
        source = TickSource(
            mixture,
            None if batch is None or bank is None else batch.step(),
            self._walk.noise,
            self.constants,
            self.ground_station.status_settings(
                self._time_s, bank is not None and bank.bearing_confirmed
            ),
            self.rangefinder.excess.variance,
            winch_fused,
            self.bearing.force_std_n,
            self.ground_station.position_information.at(self._time_s),
            0 if bank is None else len(bank.filters),
            None if bank is not None else self._startup.reason,
            reset_reason,
            on_ground_reason(
                on_ground,
                math.nan if mixture is None else mixture.x_values[2],
                self._ground_down_m,
                self.dynamic.touchdown_height_m,
                self.autopilot_landed.on_ground(self._time_s),
            ),
            stale,
            sag_std_m,
            sag_m2,
            self.rangefinder.ground.variance_m2,
        )
        return NavigationEstimate.of_tick(
            self._time_s,
            self._resets,
            accel_fused,
            health.values(),
            DynamicHealth,
            source,
        )
