"""The sample handling both tether estimators share (the paper's
:class:`~tether_companion.estimation.pipeline.TetherEstimator` and the dynamic
:class:`~tether_companion.estimation.dynamic.estimator.DynamicTetherEstimator`): attitude and
PWM into the :class:`~tether_companion.estimation.alignment.InputAligner`, and the rangefinder
reading's validity checks and its height (tilt and the sensor's lever arm,
:func:`~tether_companion.estimation.altimeter_geometry.height_above_anchor_m`).

Counters go into the estimator's health record, whose fields of these names mean the same in
both: ``nonfinite_rejected``, ``pwm_invalid``, ``range_out_of_range``, ``range_stale``. Pure and
synchronous.
"""

from __future__ import annotations

import math
from typing import Protocol

from tether_companion.estimation.alignment import InputAligner
from tether_companion.estimation.altimeter_geometry import height_above_anchor_m
from tether_companion.estimation.config import Rangefinder
from tether_companion.samples import AttitudeSample, PwmSample, RangeSample


class InputHealth(Protocol):
    """The counters :class:`InputFeed` and the range checks increment."""

    nonfinite_rejected: int
    pwm_invalid: int
    range_out_of_range: int
    range_stale: int


class InputFeed:
    """``on_attitude`` and ``on_pwm`` of an estimator with ``aligner`` and ``health``."""

    aligner: InputAligner
    health: InputHealth

    def on_attitude(self, sample: AttitudeSample) -> None:
        """Store the latest attitude (rejected and counted when not finite)."""
        if self.aligner.on_attitude(sample) is not None:
            self.health.nonfinite_rejected += 1

    def on_pwm(self, sample: PwmSample) -> None:
        """Store the total thrust [N] of the latest motor outputs (rejected and counted when
        not finite, or as ``pwm_invalid`` when the thrust input refuses the outputs)."""
        try:
            rejected = self.aligner.on_pwm(sample) is not None
        except ValueError:  # wrong number of outputs for this vehicle
            self.health.pwm_invalid += 1
            return
        if rejected:
            self.health.nonfinite_rejected += 1


def range_reading_ok(sample: RangeSample, config: Rangefinder, health: InputHealth) -> bool:
    """Whether the reading is finite and inside the sensor's range (else counted)."""
    if not (math.isfinite(sample.time_s) and math.isfinite(sample.distance_m)):
        health.nonfinite_rejected += 1
        return False
    if not (config.min_m <= sample.distance_m <= config.max_m):
        health.range_out_of_range += 1
        return False
    return True


def range_height_m(
    sample: RangeSample,
    aligner: InputAligner,
    config: Rangefinder,
    attitude_staleness_s: float,
    anchor_height_m: float,
    health: InputHealth,
) -> float | None:
    """Height of the centre of mass above the anchor [m] from a reading that passed
    :func:`range_reading_ok`, with the aligner's attitude; ``None`` (counted) when that attitude
    is missing or older than ``attitude_staleness_s`` [s] (``range_stale``) or tilted beyond
    ``config.max_tilt_rad`` (``range_out_of_range``). ``anchor_height_m`` [m] above the ground
    (0: the height above the ground)."""
    att = aligner.attitude
    if att is None or abs(sample.time_s - att.time_s) > attitude_staleness_s:
        health.range_stale += 1
        return None
    if aligner.cos_tilt < math.cos(config.max_tilt_rad):
        health.range_out_of_range += 1
        return None
    return height_above_anchor_m(
        sample.distance_m, aligner.rotation_rows, config.offset_frd_m, anchor_height_m
    )
