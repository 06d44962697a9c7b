"""The ground station's cable angle in the dynamic filter's start: :class:`AngleReadings`.

The anchor measures the drone's bearing itself: a cable hangs in the vertical plane through
the anchor and the drone, so the azimuth of the cable where it leaves the anchor is the
drone's bearing, and for a weightless (straight) cable the elevation with the winch's length,
or with the height above the anchor, is its position (:func:`angle_position`). The window of
the start (:mod:`~tether_companion.estimation.dynamic.initialise`) keeps its readings here:
their mean and its standard deviations (the noise averages; the calibration does not, and is
the filter's calibration states' prior, correlated with the start's position), and
the motion they show (:meth:`AngleReadings.motion`: a quadratic in time through the positions
of the readings, each weighted by its variance, :func:`angle_position_variance`). Pure.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

MIN_RISE = 0.1
"""Sine of the elevation below which the cable is too close to horizontal for a height to
place the drone."""
MIN_READINGS = 5
"""Readings placed in the window from which :meth:`AngleReadings.motion` fits the motion."""
LIFTED_SD = 3.0
"""Standard deviations of a reading's elevation error above flat at which a reading shows the
cable lifted at the anchor (:meth:`AngleReadings.all_lifted`)."""


class AngleReadings:
    """The cable-angle readings of one start window."""

    def __init__(self) -> None:
        self._readings: list[tuple[float, float, float, float, float]] = []
        """(time taken [s], elevation, azimuth [rad], the latest height above the anchor
        then [m] or ``nan``, the winch length then [m] or ``nan``)."""
        self._noise = (0.0, 0.0, 0.0)
        """The latest reading's direction noise and calibration errors (elevation, azimuth)
        [rad]."""

    def __len__(self) -> int:
        return len(self._readings)

    def add(
        self,
        time_s: float,
        elevation_rad: float,
        azimuth_rad: float,
        noise_std_rad: float,
        calibration_std_rad: tuple[float, float],
        height_m: float,
        length_m: float,
    ) -> None:
        """A reading taken at ``time_s`` [s]: elevation (up) and azimuth (from north) at the
        anchor [rad], the sensor's direction noise [rad] and calibration errors (elevation,
        azimuth) [rad], the latest height above the anchor [m] and winch length [m] then
        (``nan``: none)."""
        self._readings.append((time_s, elevation_rad, azimuth_rad, height_m, length_m))
        self._noise = (noise_std_rad, *calibration_std_rad)

    def mean(self) -> tuple[float, float]:
        """The mean (elevation, azimuth) [rad] (the azimuth's circular mean); ``nan`` without
        a reading."""
        if not self._readings:
            return math.nan, math.nan
        angles = np.array([reading[1:3] for reading in self._readings])
        azimuth = math.atan2(
            float(np.mean(np.sin(angles[:, 1]))), float(np.mean(np.cos(angles[:, 1])))
        )
        return float(np.mean(angles[:, 0])), azimuth

    def angle_at(self, time_s: float) -> tuple[float, float]:
        """(elevation, azimuth) [rad] of the reading taken nearest ``time_s`` [s]; ``nan``
        without a reading."""
        if not self._readings:
            return math.nan, math.nan
        nearest = min(self._readings, key=lambda reading: abs(reading[0] - time_s))
        return nearest[1], nearest[2]

    def all_lifted(self) -> bool:
        """Whether every reading shows the cable leaving the anchor lifted: its elevation above
        :data:`LIFTED_SD` standard deviations of one reading's error (the direction noise
        and the elevation zero's calibration error). A heavy cable resting on the ground
        leaves the anchor flat whatever the drone's range beyond its touchdown, so a force
        placed on the free curve puts the drone at the touchdown kink (a bound, not a
        position): :meth:`.initialise.Initialiser.solve`. False without a reading."""
        if not self._readings:
            return False
        noise, elevation_zero, _ = self._noise
        least = LIFTED_SD * math.hypot(noise, elevation_zero)
        return all(reading[1] > least for reading in self._readings)

    def mean_noise_std(self, elevation_rad: float) -> tuple[float, float]:
        """Standard deviations of the mean elevation and azimuth [rad] at ``elevation_rad``
        from the direction noise, averaged over the readings (the azimuth's ``1 / cos(el)``
        larger); the calibration errors, which do not average, are
        :meth:`calibration_std`."""
        noise = self._noise[0]
        count = max(len(self._readings), 1)
        azimuth_noise = noise / max(math.cos(elevation_rad), MIN_RISE)
        return noise / math.sqrt(count), azimuth_noise / math.sqrt(count)

    def calibration_std(self) -> tuple[float, float]:
        """The sensor's calibration errors (elevation, azimuth zero) [rad] as the latest
        reading gave them: the prior of the filter's calibration states, which the start
        correlates with the position it places (``initialise.py``)."""
        return self._noise[1], self._noise[2]

    def motion(
        self, time_s: float, range_std_m: float, length_std_m: float
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray] | None:
        """Position [m] and velocity [m/s] at ``time_s`` [s] of a weightless cable's drone from
        a quadratic fit of its positions at the readings (:func:`angle_position`), each
        weighted by its variance (:func:`angle_position_variance`, the rangefinder's noise
        ``range_std_m`` [m] and the winch length's ``length_std_m`` [m]: a height through a
        low elevation places the span poorly), and the velocity's and the position's
        standard errors per axis [m/s, m]; None with fewer than :data:`MIN_READINGS`
        placed."""
        noise = self._noise[0]
        times, positions, variances = [], [], []
        for t, elevation, azimuth, height, length in self._readings:
            position = angle_position(elevation, azimuth, height, length)
            if position is not None:
                times.append(t)
                positions.append(position)
                variances.append(
                    angle_position_variance(
                        elevation,
                        azimuth,
                        height,
                        length,
                        noise,
                        range_std_m,
                        length_std_m,
                    )
                )
        if len(times) < MIN_READINGS:
            return None
        return quadratic_fit(
            np.asarray(times) - time_s,
            np.asarray(positions),
            1.0 / np.asarray(variances),
        )


def angle_position(
    elevation: float, azimuth: float, height: float, length: float
) -> FloatArray | None:
    """The drone's position NED from the anchor [m] on a straight cable leaving the anchor
    at ``elevation`` (up) and ``azimuth`` (from north) [rad]: ``length`` [m] along that
    direction (the winch's; the ground station alone fixes the drone), or without a length
    (``nan``) at ``height`` [m] above the anchor (span ``height / tan(elevation)``); None
    when the cable does not rise (:data:`MIN_RISE`) or neither is known."""
    rise = math.sin(elevation)
    if not rise >= MIN_RISE:
        return None
    if not math.isnan(length):
        if not length > 0.0:
            return None
        span, height = length * math.cos(elevation), length * rise
    elif height > 0.0:
        span = height * math.cos(elevation) / rise
    else:
        return None
    return np.array((span * math.cos(azimuth), span * math.sin(azimuth), -height))


def angle_position_variance(
    elevation: float,
    azimuth: float,
    height: float,
    length: float,
    noise_std_rad: float,
    range_std_m: float,
    length_std_m: float,
) -> tuple[float, float, float]:
    """The variances (north, east, down) [m^2] of :func:`angle_position` from one reading's
    direction noise ``noise_std_rad`` [rad] (the azimuth's ``1 / cos(el)`` larger) and the
    height's ``range_std_m`` [m] (or the length's ``length_std_m`` [m] when placed by the
    length): the span ``h cos(el) / sin(el)`` moves by ``cos(el) / sin(el)`` per metre of
    height and ``h / sin(el)^2`` per radian of elevation. Calibration errors are common to
    the window's readings and leave its motion as it is."""
    c, s = math.cos(elevation), math.sin(elevation)
    azimuth_std = noise_std_rad / max(c, MIN_RISE)
    if not math.isnan(length):
        span = length * c
        span_var = (length_std_m * c) ** 2 + (length * s * noise_std_rad) ** 2
        down_var = (length_std_m * s) ** 2 + (length * c * noise_std_rad) ** 2
    else:
        span = height * c / s
        span_var = (range_std_m * c / s) ** 2 + (height * noise_std_rad / (s * s)) ** 2
        down_var = range_std_m * range_std_m
    across_var = (span * azimuth_std) ** 2
    cn, sn = math.cos(azimuth), math.sin(azimuth)
    return (
        span_var * cn * cn + across_var * sn * sn,
        span_var * sn * sn + across_var * cn * cn,
        down_var,
    )


def quadratic_fit(
    times: FloatArray, positions: FloatArray, weights: FloatArray | None = None
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Value [m] and slope [m/s] at time 0 of a least-squares quadratic in time through
    ``positions`` (n, 3) [m] at ``times`` (n,) [s], and the slope's and the value's standard
    errors per axis [m/s, m]. ``weights`` (n, 3): the positions' inverse variances [1/m^2],
    the standard errors from them, larger by the residuals' own spread when that is larger
    than they say (the motion is not quadratic); None: unweighted, the standard errors from
    the residuals' spread (all axes alike)."""
    design = np.stack((np.ones_like(times), times, times * times), axis=1)
    if weights is None:
        coef, *_ = np.linalg.lstsq(design, positions, rcond=None)
        residual = positions - design @ coef
        sigma = float(np.sqrt(np.mean(residual**2)))
        inverse = np.linalg.inv(design.T @ design)
        slope_se = float(sigma * np.sqrt(inverse[1, 1]))
        value_se = float(sigma * np.sqrt(inverse[0, 0]))
        return coef[0], coef[1], np.full(3, slope_se), np.full(3, value_se)
    value, slope = np.zeros(3), np.zeros(3)
    slope_se, value_se = np.zeros(3), np.zeros(3)
    dof = max(len(times) - 3, 1)
    for axis in range(3):
        w = weights[:, axis]
        normal = design.T @ (design * w[:, None])
        cov = np.linalg.inv(normal)
        coef = cov @ (design.T @ (w * positions[:, axis]))
        residual = positions[:, axis] - design @ coef
        spread = max(float(np.sum(w * residual * residual)) / dof, 1.0)
        value[axis], slope[axis] = coef[0], coef[1]
        slope_se[axis] = math.sqrt(cov[1, 1] * spread)
        value_se[axis] = math.sqrt(cov[0, 0] * spread)
    return value, slope, slope_se, value_se


def held_slope_se(times: FloatArray, readings: FloatArray, slope_se: FloatArray) -> FloatArray:
    """The standard errors ``slope_se`` (3,) [m/s] of an unweighted quadratic's slope at time 0
    (:func:`quadratic_fit`, which counts the ``times`` (n,) [s] as independent samples) when
    the values hold readings from one to the next, ``readings`` (n,) the index of the reading
    each holds (a 20 Hz rangefinder under 200 Hz ticks): the slope's weights summed per
    reading, ``sum_k (sum_{t in k} a_t)^2`` against ``sum_t a_t^2``, scale the variance."""
    design = np.stack((np.ones_like(times), times, times * times), axis=1)
    weights = np.linalg.pinv(design)[1]  # the slope's weight on each value
    index = np.asarray(readings, dtype=np.int64)
    per_reading = np.bincount(index - index.min(), weights=weights)
    return slope_se * math.sqrt(float(per_reading @ per_reading) / float(weights @ weights))
