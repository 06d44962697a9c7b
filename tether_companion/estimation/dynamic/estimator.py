"""The dynamic tether filter fed by typed samples: :class:`DynamicTetherEstimator`.

Same call pattern as :class:`~tether_companion.estimation.pipeline.TetherEstimator` (pure,
synchronous, samples in time order, one :class:`NavigationEstimate` per IMU tick), so the
service, replay and the offline runner can use either:

* ``on_attitude``, ``on_pwm``: through the shared
  :class:`~tether_companion.estimation.alignment.InputAligner`;
* ``on_imu``: until initialised, the tick feeds the
  :class:`~tether_companion.estimation.dynamic.initialise.Initialiser`; afterwards the filter
  predicts to the IMU time with the previous tick's inputs (force balance, or the previous
  specific force in the inertial formulation) and fuses the accelerometer force balance;
* ``on_range``: the tilt-corrected height above the ground (validity checked and counted);
* ``set_known_tension_n`` (load cell), ``set_paid_out_length_m`` (winch; also switches the
  cable model to the known length), ``on_cable_angle`` (ground-station cable angle).

Divergence: a non-finite state (the EKF resets), an accelerometer innovation gated for
``DIVERGED_AFTER_S`` in a row, or a position beyond ``MAX_DISTANCE_M`` restarts the
initialisation; ``reset_counter`` counts it and the tick's status is ``reset`` with the reason.
"""

from __future__ import annotations

import dataclasses
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
from tether_companion.estimation.dynamic import generated, state
from tether_companion.estimation.dynamic.aid.accel import NEAR_ANCHOR, ON_GROUND, AccelAid
from tether_companion.estimation.dynamic.aid.cable_angle import CableAngleAid
from tether_companion.estimation.dynamic.aid.load_cell import LoadCellAid
from tether_companion.estimation.dynamic.aid.rangefinder import RangefinderAid
from tether_companion.estimation.dynamic.aid.winch import WinchAid
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.config import INERTIAL, DynamicFilterConfig, drag_per_s
from tether_companion.estimation.dynamic.consistency import BearingWindow
from tether_companion.estimation.dynamic.imu_batch import ImuBatch
from tether_companion.estimation.dynamic.initialise import Initialiser
from tether_companion.estimation.dynamic.member import MemberFilter
from tether_companion.estimation.dynamic.mixture import MixtureValues, ProcessNoise
from tether_companion.estimation.dynamic.models import UNDEFINED, ModelConstants
from tether_companion.estimation.dynamic.noise import (
    accel_measurement_std_mps2,
    process_noise_density,
)
from tether_companion.estimation.dynamic.observability import unmodelled_position_rows
from tether_companion.estimation.dynamic.output import DynamicHealth, NavigationEstimate
from tether_companion.estimation.dynamic.position_information import PositionInformation
from tether_companion.estimation.dynamic.published import StatusSettings, TickSource
from tether_companion.estimation.ekf import ExtendedKalmanFilter
from tether_companion.estimation.inputs import InputFeed, range_height_m, range_reading_ok
from tether_companion.estimation.pipeline import default_thrust_input
from tether_companion.estimation.thrust_input import ThrustInput
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.samples import ImuSample, RangeSample

FloatArray = NDArray[np.float64]

DIVERGED_AFTER_S = 1.0
"""Accelerometer innovations gated this long in a row [s]: the filter has diverged."""
MAX_DISTANCE_M = 1000.0
"""A position farther than this from the anchor [m] is a divergence."""
ANGLE_FRESH_S = 1.0
"""A ground-station cable angle fused within this [s] measures the bearing: the rule that
withholds a pull too weak against the wind's drag (observability.py) is waived meanwhile."""


class DynamicTetherEstimator(InputFeed):
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
        self._weight_n = vehicle.mass_kg * GRAVITY_MPS2
        self._inertial = dynamic.formulation == INERTIAL
        self._ticks_per_fusion = dynamic.imu_ticks_per_fusion if self._inertial else 1
        """IMU ticks per prediction and force-balance fusion (the inertial formulation's
        correlated residual makes every tick's sample mostly redundant; the force balance is
        the process in the other formulation, fused every tick)."""
        self._ticks_since_fusion = 0
        self._batch = ImuBatch() if self._inertial else None
        """The inertial prediction summed over the ticks since the members last stepped."""
        self._q = process_noise_density(dynamic)
        self._q_matrix = np.diag(self._q)
        self._noise = ProcessNoise(self._q_matrix)
        self._status_settings = StatusSettings(
            slack_tension_n=dynamic.slack_tension_n,
            max_horizontal_std_m=dynamic.max_horizontal_std_m,
            winch_length_noise_std_m=dynamic.winch_length_noise_std_m,
            pull_per_wind_n_s_per_m=(
                dynamic.min_pull_over_wind_drag * vehicle.mass_kg * self.constants.drag_per_s
            ),
            wind_std_mps=dynamic.initial.wind_std_mps,
        )
        self._angle_status_settings = dataclasses.replace(
            self._status_settings, pull_per_wind_n_s_per_m=0.0
        )
        """The status settings while a cable angle measures the bearing (ANGLE_FRESH_S)."""
        self._mixture: MixtureValues | None = None
        """The bank's latest mixture with its values as floats (kept while it is the same)."""
        self.accel = AccelAid(accel_measurement_std_mps2(dynamic), config.min_cable_length_m)
        self.rangefinder = RangefinderAid(
            config.altimeter_noise_variance_m2, config.ground_station.anchor_height_m
        )
        self.load_cell = LoadCellAid(dynamic.load_cell_noise_std_n)
        self.winch = WinchAid(dynamic.winch_length_noise_std_m, dynamic.slack_tension_n)
        self.cable_angle = CableAngleAid(dynamic.slack_tension_n)
        self.bearing = BearingWindow(
            vehicle.mass_kg * self.constants.drag_per_s,
            dynamic.initial.wind_std_mps,
            dynamic.unmodelled_force_std_n,
            dynamic.unmodelled_force_correlation_s,
            dynamic.bearing_position_walk_m2ps,
            dynamic.bearing_wind_walk_m2ps3,
        )
        self.position_information = PositionInformation(dynamic.unmodelled_force_correlation_s)
        """What the fused cable angles tell about the position within the unmodelled force's
        correlation time (it narrows the unmodelled term of the published covariance)."""
        self.bank: FilterBank | None = None
        self._initialiser = self._new_initialiser()
        self._time_s = math.nan
        self._inputs: list[float] | None = None
        self._resets = 0
        self._reset_reason: str | None = None
        self._gated_since_s = math.nan
        self._last_tick_s = math.nan

    # ------------------------------------------------------------------ setup
    def _new_initialiser(self) -> Initialiser:
        return Initialiser(
            self.dynamic,
            self.vehicle.mass_kg,
            self.constants.drag_per_s,
            self.dynamic.accel_noise_std_mps2,
            math.sqrt(self.config.altimeter_noise_variance_m2),
        )

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
    def set_known_tension_n(self, tension_n: float, time_s: float) -> None:
        """Load-cell tension at the drone [N] at ``time_s`` [s]: fused when initialised."""
        if not (math.isfinite(tension_n) and math.isfinite(time_s)) or tension_n < 0.0:
            self.health.nonfinite_rejected += 1
            return
        if self.bank is not None and self._fresh(time_s, self.config.staleness.tension_s):
            self._step_batch()
            if self.load_cell.fuse(self.bank, self.constants, tension_n, self._time_s):
                self.health.load_cell_fused += 1

    def set_paid_out_length_m(self, length_m: float, time_s: float) -> None:
        """Winch paid-out length [m]: the cable model's length from now on, and fused."""
        if not (math.isfinite(length_m) and math.isfinite(time_s)) or length_m <= 0.0:
            self.health.nonfinite_rejected += 1
            return
        self.constants.length_m = length_m
        if self.bank is not None and self._fresh(time_s, self.config.staleness.tension_s):
            self._step_batch()
            if self.winch.fuse(self.bank, self.constants, length_m, self._time_s):
                self.health.winch_fused += 1

    def on_cable_angle(
        self, elevation_rad: float, azimuth_rad: float, time_s: float, noise_std_rad: float
    ) -> None:
        """Ground-station cable angle at the anchor [rad]: elevation up, azimuth from north,
        the sensor's direction noise ``noise_std_rad`` [rad] (aid/cable_angle.py)."""
        values = (elevation_rad, azimuth_rad, time_s, noise_std_rad)
        if (
            not all(math.isfinite(v) for v in values)
            or abs(elevation_rad) > math.pi / 2
            or noise_std_rad <= 0.0
        ):
            self.health.nonfinite_rejected += 1
            return
        if self.bank is not None and self._fresh(time_s, self.config.staleness.tension_s):
            self._step_batch()
            if self.bank is None:
                return
            status = self.cable_angle.status
            gated_before = status.gated
            fused = self.cable_angle.fuse(
                self.bank, self.constants, elevation_rad, azimuth_rad, self._time_s, noise_std_rad
            )
            if fused or status.gated != gated_before:  # an innovation of this reading
                self.position_information.add_angle_innovation(
                    status.last_innovation,
                    status.last_innovation_variance.tolist(),
                    self.bank.best.x_values()[:3],
                    self._time_s,
                )
            if fused:
                self.health.cable_angle_fused += 1
                x = self.bank.best.x_values()
                self._add_angle_information(x, elevation_rad, noise_std_rad)
                # the azimuth's noise across the cable: times the span
                azimuth_std_rad = CableAngleAid.noise_std_rad(elevation_rad, noise_std_rad)[1]
                self.bearing.add_bearing(math.hypot(x[0], x[1]) * azimuth_std_rad)

    def _add_angle_information(
        self, x: list[float], elevation_rad: float, noise_std_rad: float
    ) -> None:
        """The fused angle's information about the position at the updated state ``x``
        (its Jacobian's position columns, the noise as :class:`CableAngleAid` fuses it).

        The azimuth always; the elevation only once a winch length was fused: the unmodelled
        term turns the cable at a known range, and only with the length is its vertical part
        the elevation the reading measures. Without a length the filter's range comes from
        the height through the elevation (``rho = h / tan(el)``), and the term's vertical part
        stands for that range's error, which the elevation does not remove in the filter
        (docs/estimation.md, "The unmodelled term and the cable angle (nees10)")."""
        _, jac_rows = self.cable_angle.evaluate(self.constants, np.array(x))
        jac = jac_rows.ravel().tolist()
        if not all(math.isfinite(v) for v in jac):
            return
        n = state.N_STATES
        elevation_std, azimuth_std = CableAngleAid.noise_std_rad(elevation_rad, noise_std_rad)
        winch = bool(self.health.winch_fused)
        if winch:
            rows, variances = (jac[0:3], jac[n : n + 3]), (elevation_std**2, azimuth_std**2)
        else:
            rows, variances = (jac[n : n + 3],), (azimuth_std**2,)
        added = unmodelled_position_rows(  # at the chord tension (the drone's, straight)
            x[0],
            x[1],
            x[2],
            x[state.TENSION],
            self.bearing.force_std_n,
            self.dynamic.winch_length_noise_std_m if winch else 0.0,
        )
        self.position_information.add(rows, variances, self._time_s, added)

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
            self._initialiser.add_height(height_above_anchor_m)
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
        stale = aligned is STALE_ATTITUDE or aligned is STALE_PWM
        if aligned is STALE_ATTITUDE:
            health.stale_attitude += 1
        elif aligned is STALE_PWM:
            health.stale_pwm += 1
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
            self._step_batch()
        if self.bank is None:  # the prediction diverged and restarted
            return self._estimate(False, stale, False)
        on_ground = False
        accel_fused = False
        if not stale:
            assert isinstance(aligned, AlignedInputs)
            on_ground = aligned.thrust_n < self.dynamic.min_thrust_fraction * self._weight_n
            rows = aligned.rotation.rows  # Python floats, made once per attitude sample
            force = self.aligner.specific_force_values
            if fusion_tick or not self._inertial:
                inputs = [*rows[0], *rows[1], *rows[2], aligned.thrust_n]
                if fusion_tick:
                    accel_fused = self._fuse_accel(inputs, force, on_ground, t)
                    self._ticks_since_fusion = 0
                    if accel_fused:
                        self._sample_bearing(t)
                if not self._inertial:
                    self._inputs = inputs
            if self._inertial:  # the next tick's batch step: R_v^b and the specific force
                self._inputs = [*rows[0], *rows[1], *rows[2], *force]
        self._check_divergence(t, fusion_tick)
        return self._estimate(accel_fused, stale, on_ground)

    @property
    def initialising_reason(self) -> str:
        """Why there is no state yet (empty once initialised)."""
        return "" if self.bank is not None else self._initialiser.reason

    # ------------------------------------------------------------------ internals
    def _fresh(self, time_s: float, bound_s: float) -> bool:
        return not math.isnan(self._time_s) and abs(time_s - self._time_s) <= bound_s

    def _initialise_tick(self, aligned: AlignedInputs | str, stale: bool) -> NavigationEstimate:
        if stale:
            return self._estimate(False, True, False)
        assert isinstance(aligned, AlignedInputs)
        t, force, rotation, thrust = aligned
        self._initialiser.add_tick(t, force, rotation, thrust)
        starts = self._initialiser.hypotheses(t, self.dynamic.initial, self.constants.length_m)
        if not starts:
            return self._estimate(False, False, False)
        c = self.constants
        process = generated.inertial if self._inertial else c.models.force_balance
        gate = self.config.gate
        members = [
            MemberFilter(
                x0,
                p0,
                self._q,
                c,
                process,
                gate_probability=gate.probability,
                max_consecutive_rejections=gate.max_consecutive_rejections,
            )
            for x0, p0 in starts
        ]
        self.bank = FilterBank(
            members, t, self.dynamic.initial.thrust_scale_bank_max_s, self._ticks_per_fusion
        )
        self.health.initialisations += 1
        inputs = [*rotation.ravel().tolist(), thrust]
        self._inputs = [*inputs[:9], *force.tolist()] if self._inertial else inputs
        self._last_tick_s = t
        self._gated_since_s = math.nan
        self._ticks_since_fusion = 0
        if self._batch is not None:
            self._batch.clear()
        return self._estimate(False, False, False)

    def _step_batch(self) -> None:
        """Step the members over the IMU ticks summed since they last stepped (inertial)."""
        batch = self._batch
        if batch is None or batch.ticks == 0 or self.bank is None:
            return
        self._step_members(lambda bank: bank.predict_batch(batch, self._q_matrix))
        batch.clear()

    def _step_members(self, step: Callable[[FilterBank], None]) -> None:
        """Run a prediction ``step`` on the bank; drop the members it reset, restart when
        it reset all of them or the model is undefined."""
        bank = self.bank
        assert bank is not None
        resets_before = [kf.resets for kf in bank.filters]
        try:
            step(bank)
        except UNDEFINED:  # at the anchor, or zero tension: the cable model is undefined
            self._restart("position at the anchor or no tension")
            return
        reset = [kf.resets != r for kf, r in zip(bank.filters, resets_before, strict=True)]
        if all(reset):
            self._restart("state or covariance not finite")
            return
        if any(reset):  # drop the members that restarted
            bank.keep([i for i, r in enumerate(reset) if not r])
        self.health.pd_repairs = sum(kf.pd_repairs for kf in bank.filters)

    def _fuse_accel(
        self, inputs: list[float], force: list[float], on_ground: bool, t: float
    ) -> bool:
        health = self.health
        status = self.accel.status
        gated_before = status.gated
        bank = self.bank
        assert bank is not None
        fused = self.accel.fuse(bank, self.constants, inputs, force, t, on_ground)
        health.on_ground = status.skipped_by_reason.get(ON_GROUND, 0)
        health.near_anchor = status.skipped_by_reason.get(NEAR_ANCHOR, 0)
        health.accel_gated = status.gated
        sensors = bank.best.sensors
        if "accel" in sensors:
            health.last_accel_nis = sensors["accel"].last_nis
        if fused:
            health.accel_fused += 1
            self._gated_since_s = math.nan
        elif status.gated != gated_before and math.isnan(self._gated_since_s):
            self._gated_since_s = t
        return fused

    def _sample_bearing(self, t: float) -> None:
        """The mixture after a force-balance fusion into the bearing window."""
        bank = self.bank
        if bank is None or not self.bearing.enabled:
            return
        x, p = bank.mixture()
        self.bearing.add(t, x[:3].tolist(), float(x[state.TENSION]), (p[0, 0], p[0, 1], p[1, 1]))

    def _check_divergence(self, t: float, fusion_tick: bool) -> None:
        bank = self.bank
        if bank is None:
            return
        if not math.isnan(self._gated_since_s) and t - self._gated_since_s >= DIVERGED_AFTER_S:
            self._restart(f"accelerometer innovations gated for {DIVERGED_AFTER_S:g} s")
            return
        if not fusion_tick:  # the members have not stepped since the last check
            return
        bank.drop_unhealthy(MAX_DISTANCE_M)
        bank.maybe_decide(t)
        x = bank.best.x_values()
        if x[0] * x[0] + x[1] * x[1] + x[2] * x[2] > MAX_DISTANCE_M**2:
            self._restart(f"position beyond {MAX_DISTANCE_M:g} m")

    def _restart(self, reason: str) -> None:
        """Drop the state and initialise again from fresh data; counted in reset_counter."""
        self.bank = None
        self._initialiser = self._new_initialiser()
        self.bearing.clear()
        self.position_information.clear()
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
        source = TickSource(
            mixture,
            None if batch is None or bank is None else batch.step(),
            self._noise,
            self.constants,
            self._angle_status_settings
            if self._time_s - self.cable_angle.status.last_fused_time_s <= ANGLE_FRESH_S
            else self._status_settings,
            self.rangefinder.excess.variance,
            bool(self.health.winch_fused),
            self.bearing.force_std_n,
            self.position_information.at(self._time_s),
            0 if bank is None else len(bank.filters),
            None if bank is not None else self._initialiser.reason,
            reset_reason,
            on_ground,
            stale,
        )
        return NavigationEstimate.of_tick(
            self._time_s,
            self._resets,
            accel_fused,
            self.health.values(),
            DynamicHealth,
            source,
        )
