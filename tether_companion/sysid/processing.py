"""Data processing before identification (paper section 5.2).

Steps: compute the total thrust at the accelerometer's own rate
(:mod:`tether_companion.sysid.thrust_signal`); low-pass the thrust and the motor signals
(PWM, normalised command ``cmd`` and ``cmd^2`` per motor) with a fifth-order Butterworth at
10 Hz run forward and backward (``sosfiltfilt``: zero phase, so filtering adds no lag the
models would then have to learn); resample everything onto one time base (100 Hz by
default, linear interpolation); keep the longest airborne segment, trimmed at both ends to
drop take-off and landing transients; check the inputs excite the system; split into an
estimation and a validation part.

Two choices differ from filtering after resampling, as the paper describes it:

- each stream is filtered at its own rate (on a uniform grid at its median rate) *before*
  it is resampled, so nothing above the new Nyquist frequency aliases into the band;
- ``cmd`` and ``cmd^2`` are formed *before* filtering. A flight controller's outputs carry
  strong fast chatter (tens of us above 10 Hz), and thrust is about quadratic in command:
  the mean of ``cmd^2`` is not the square of the mean ``cmd``, so squaring filtered PWM
  would lose the thrust the chatter makes. Filtering is linear, so a model linear in the
  filtered ``cmd`` and ``cmd^2`` sees exactly the filtered static thrust.

Bias (the operating point: the estimation part's mean input and thrust) is removed by each
linear model, which stores it so the model still maps absolute PWM to absolute thrust.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.signal import butter, sosfiltfilt

from tether_companion.config import ConfigError, spec
from tether_companion.errors import InputError
from tether_companion.sysid.logs.flightlog import FlightLog, Series
from tether_companion.sysid.thrust_signal import total_thrust_n

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ProcessingOptions:
    """Settings of :func:`prepare`."""

    rate_hz: float = spec(100.0, minimum=10.0, maximum=2000.0, doc="common sample rate [Hz]")
    cutoff_hz: float = spec(10.0, exclusive_minimum=0.0, doc="low-pass cut-off [Hz]")
    filter_order: int = spec(5, minimum=1, maximum=10, doc="Butterworth order")
    estimation_fraction: float = spec(
        0.6, minimum=0.2, maximum=0.9, doc="share of samples used for estimation"
    )
    airborne_height_m: float = spec(
        0.3,
        exclusive_minimum=0.0,
        doc="height above ground (0 or the lowest reading) counted as airborne [m]",
    )
    airborne_pwm_us: float = spec(
        1150.0,
        minimum=900.0,
        maximum=2100.0,
        doc="mean PWM counting as airborne when the log has no height [us]",
    )
    trim_s: float = spec(1.0, minimum=0.0, doc="dropped at each end of the airborne segment [s]")
    min_airborne_s: float = spec(
        10.0, exclusive_minimum=0.0, doc="shortest usable airborne segment [s]"
    )
    min_excitation_us: float = spec(
        2.0,
        exclusive_minimum=0.0,
        doc="smallest PWM standard deviation that excites the system [us]",
    )
    max_gap_s: float = spec(
        0.5, exclusive_minimum=0.0, doc="longest gap in a signal bridged by interpolation [s]"
    )
    cable_tension_n: float = spec(
        0.0, minimum=0.0, doc="known constant cable tension [N]; 0 = untethered or slack"
    )

    def validate(self) -> None:
        """The cut-off must lie below the Nyquist frequency."""
        if self.cutoff_hz >= 0.5 * self.rate_hz:
            raise ConfigError(
                "",
                "cutoff_hz",
                self.cutoff_hz,
                f"must be below half the rate ({0.5 * self.rate_hz} Hz)",
            )


@dataclass(frozen=True)
class IdData:
    """Uniformly sampled, filtered identification data.

    Attributes
    ----------
    time_s
        Sample times [s], shape (n,), step ``dt_s``.
    pwm_us
        Motor inputs [us], shape (n, 4).
    command
        Normalised throttle ``cmd = (pwm - pwm_min) / (pwm_max - pwm_min)`` clipped to [0, 1],
        filtered, shape (n, 4).
    command_sq
        ``cmd^2`` formed before filtering, shape (n, 4).
    thrust_n
        Total thrust [N], shape (n,).
    dt_s
        Sample time [s].
    """

    time_s: FloatArray
    pwm_us: FloatArray
    command: FloatArray
    command_sq: FloatArray
    thrust_n: FloatArray
    dt_s: float

    def __len__(self) -> int:
        return int(self.time_s.shape[0])

    def part(self, start: int, stop: int) -> IdData:
        """Samples ``start`` to ``stop`` (exclusive)."""
        return replace(
            self,
            time_s=self.time_s[start:stop],
            pwm_us=self.pwm_us[start:stop],
            command=self.command[start:stop],
            command_sq=self.command_sq[start:stop],
            thrust_n=self.thrust_n[start:stop],
        )


@dataclass(frozen=True)
class Dataset:
    """A processed flight: estimation and validation parts and what processing found."""

    estimation: IdData
    validation: IdData
    airborne_s: tuple[float, float]
    source: str


def normalised_command(pwm_us: FloatArray, pwm_range_us: tuple[float, float]) -> FloatArray:
    """``(pwm - pwm_min) / (pwm_max - pwm_min)`` clipped to [0, 1], same shape as ``pwm_us``."""
    lo, hi = pwm_range_us
    return np.clip((np.asarray(pwm_us, dtype=float) - lo) / (hi - lo), 0.0, 1.0)


def _interpolate(time_s: FloatArray, values: FloatArray, at_s: FloatArray) -> FloatArray:
    return np.column_stack([np.interp(at_s, time_s, values[:, j]) for j in range(values.shape[1])])


def _gaps(series: Series, at_s: FloatArray, max_gap_s: float) -> NDArray[np.bool_]:
    """Flags of the times ``at_s`` that fall in a gap longer than ``max_gap_s`` of ``series``."""
    index = np.clip(np.searchsorted(series.time_s, at_s), 1, len(series) - 1)
    return (series.time_s[index] - series.time_s[index - 1]) > max_gap_s


def lowpass(values: FloatArray, rate_hz: float, cutoff_hz: float, order: int) -> FloatArray:
    """Zero-phase Butterworth low-pass along axis 0 (forward-backward, ``sosfiltfilt``)."""
    sos = butter(order, cutoff_hz, btype="low", fs=rate_hz, output="sos")
    return sosfiltfilt(sos, values, axis=0)


def filtered_resample(
    time_s: FloatArray, values: FloatArray, at_s: FloatArray, options: ProcessingOptions
) -> FloatArray:
    """Low-pass ``values`` (shape (n, k)) at their own rate, then interpolate onto ``at_s``.

    The samples are first put on a uniform grid at their median rate (at least the common
    rate) so the filter sees evenly spaced data.
    """
    rate_hz = max(1.0 / float(np.median(np.diff(time_s))), options.rate_hz)
    grid = time_s[0] + np.arange(int(np.floor((time_s[-1] - time_s[0]) * rate_hz)) + 1) / rate_hz
    uniform = _interpolate(time_s, values, grid)
    if grid.shape[0] > 3 * (options.filter_order + 1) * 2:
        uniform = lowpass(uniform, rate_hz, options.cutoff_hz, options.filter_order)
    return _interpolate(grid, uniform, at_s)


def _airborne(log: FlightLog, time_s: FloatArray, options: ProcessingOptions) -> NDArray[np.bool_]:
    """Per-sample flag: airborne and inside no gap of any signal."""
    streams = [log.pwm_us, log.specific_force_body_mps2, log.euler_rad]
    gap = np.zeros(time_s.shape, dtype=bool)
    for series in streams:
        gap |= _gaps(series, time_s, options.max_gap_s)
    if log.height_m is not None:
        # ground is 0 (rangefinder, or barometer zeroed at take-off) or the lowest reading when
        # it drifts below; times without a height reading nearby are not counted as airborne
        series = log.height_m
        height = np.interp(time_s, series.time_s, series.values[:, 0])
        ground = min(float(np.min(series.values)), 0.0)
        covered = (time_s >= series.time_s[0]) & (time_s <= series.time_s[-1])
        airborne = (
            (height > ground + options.airborne_height_m)
            & covered
            & ~_gaps(series, time_s, options.max_gap_s)
        )
    else:
        pwm = _interpolate(log.pwm_us.time_s, log.pwm_us.values, time_s)
        airborne = np.mean(pwm, axis=1) > options.airborne_pwm_us
    return airborne & ~gap


def resample_log(
    log: FlightLog, mass_kg: float, pwm_range_us: tuple[float, float], options: ProcessingOptions
) -> tuple[IdData, NDArray[np.bool_]]:
    """Filtered signals on the common time base over the span all signals cover.

    Returns
    -------
    data
        Filtered PWM, command, command squared and thrust at ``options.rate_hz``.
    airborne
        Per-sample flag, shape (n,): airborne and not inside a gap of any signal.
    """
    streams = [log.pwm_us, log.specific_force_body_mps2, log.euler_rad]
    start = max(s.time_s[0] for s in streams)
    stop = min(s.time_s[-1] for s in streams)
    dt_s = 1.0 / options.rate_hz
    if stop - start < options.min_airborne_s:
        raise InputError(
            f"{log.source}: the signals overlap for {max(stop - start, 0.0):.1f} s; "
            f"at least {options.min_airborne_s:.0f} s of flight is needed (log too short)"
        )
    time_s = start + dt_s * np.arange(int(np.floor((stop - start) / dt_s)) + 1)
    pwm = log.pwm_us.values
    command = normalised_command(pwm, pwm_range_us)
    motors = filtered_resample(
        log.pwm_us.time_s, np.hstack([pwm, command, command**2]), time_s, options
    )
    n = pwm.shape[1]
    accel = log.specific_force_body_mps2
    tension: FloatArray | float = options.cable_tension_n
    if log.tension_n is not None:
        tension = np.interp(accel.time_s, log.tension_n.time_s, log.tension_n.values[:, 0])
    thrust = total_thrust_n(accel.values, mass_kg, tension)
    thrust_f = filtered_resample(accel.time_s, thrust[:, None], time_s, options)[:, 0]
    data = IdData(
        time_s=time_s,
        pwm_us=motors[:, :n],
        command=motors[:, n : 2 * n],
        command_sq=motors[:, 2 * n :],
        thrust_n=thrust_f,
        dt_s=dt_s,
    )
    return data, _airborne(log, time_s, options)


def prepare(
    log: FlightLog,
    mass_kg: float,
    pwm_range_us: tuple[float, float],
    options: ProcessingOptions | None = None,
) -> Dataset:
    """Turn a flight log into estimation and validation data (see module docstring).

    Parameters
    ----------
    log
        The loaded flight.
    mass_kg
        Vehicle mass [kg] (from the vehicle profile) to turn specific force into force.
    pwm_range_us
        PWM at zero and at full command [us] (from the vehicle profile).
    options
        Processing settings; defaults follow the paper (100 Hz, 5th-order 10 Hz low-pass).

    Raises
    ------
    InputError
        When the log is too short, never airborne, or its inputs are constant.
    """
    options = options or ProcessingOptions()
    data, airborne = resample_log(log, mass_kg, pwm_range_us, options)
    start, stop = _longest_run(airborne)
    if stop == start:
        raise InputError(
            f"{log.source}: the vehicle is never airborne "
            "(no height or PWM above the airborne threshold)"
        )
    trim = int(round(options.trim_s * options.rate_hz))
    start, stop = start + trim, stop - trim
    seconds = (stop - start) * data.dt_s
    if seconds < options.min_airborne_s:
        raise InputError(
            f"{log.source}: the longest airborne segment lasts "
            f"{max(seconds, 0.0):.1f} s after trimming; "
            f"at least {options.min_airborne_s:.0f} s is needed (log too short)"
        )
    flight = data.part(start, stop)
    spread_us = float(np.max(np.std(flight.pwm_us, axis=0)))
    if spread_us < options.min_excitation_us:
        raise InputError(
            f"{log.source}: the motor inputs are constant in flight "
            "(largest PWM standard deviation "
            f"{spread_us:.2f} us < {options.min_excitation_us} us): nothing is excited to identify"
        )
    split = int(round(options.estimation_fraction * len(flight)))
    return Dataset(
        estimation=flight.part(0, split),
        validation=flight.part(split, len(flight)),
        airborne_s=(float(flight.time_s[0]), float(flight.time_s[-1])),
        source=log.source,
    )


def _longest_run(mask: NDArray[np.bool_]) -> tuple[int, int]:
    """Start and stop (exclusive) of the longest run of True, (0, 0) when none."""
    padded = np.concatenate(([False], mask, [False])).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    starts, stops = edges[0::2], edges[1::2]
    if starts.size == 0:
        return 0, 0
    k = int(np.argmax(stops - starts))
    return int(starts[k]), int(stops[k])
