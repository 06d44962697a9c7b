"""Data processing before identification (paper section 5.2).

Steps, in order: resample every signal onto one time base (100 Hz by default, linear
interpolation); compute the total thrust (:mod:`tether_companion.sysid.thrust_signal`);
low-pass PWM and thrust with a fifth-order Butterworth at 10 Hz run forward and backward
(``sosfiltfilt``: zero phase, so filtering adds no lag that the models would then have to
learn); keep the longest airborne segment, trimmed at both ends to drop take-off and landing
transients; check the inputs excite the system; split into an estimation and a validation
part. Bias (the operating point: the estimation part's mean PWM and thrust) is removed by
each linear model, which stores it so the model still maps absolute PWM to absolute thrust.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.signal import butter, sosfiltfilt

from tether_companion.config import spec
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
        0.3, exclusive_minimum=0.0, doc="height above the log's lowest that counts as airborne [m]"
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
        from tether_companion.config import ConfigError

        if self.cutoff_hz >= 0.5 * self.rate_hz:
            raise ConfigError(
                "",
                "cutoff_hz",
                self.cutoff_hz,
                f"must be below half the rate ({0.5 * self.rate_hz} Hz)",
            )


@dataclass(frozen=True)
class IdData:
    """Uniformly sampled identification data.

    Attributes
    ----------
    time_s
        Sample times [s], shape (n,), step ``dt_s``.
    pwm_us
        Motor inputs [us], shape (n, 4).
    thrust_n
        Total thrust [N], shape (n,).
    dt_s
        Sample time [s].
    """

    time_s: FloatArray
    pwm_us: FloatArray
    thrust_n: FloatArray
    dt_s: float

    def __len__(self) -> int:
        return int(self.time_s.shape[0])


@dataclass(frozen=True)
class Dataset:
    """A processed flight: estimation and validation parts and what processing found."""

    estimation: IdData
    validation: IdData
    airborne_s: tuple[float, float]
    source: str


def _resample(
    series: Series, time_s: FloatArray, max_gap_s: float
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Linear interpolation onto ``time_s``; second output flags samples inside a gap."""
    values = np.column_stack(
        [
            np.interp(time_s, series.time_s, series.values[:, j])
            for j in range(series.values.shape[1])
        ]
    )
    index = np.clip(np.searchsorted(series.time_s, time_s), 1, len(series) - 1)
    gap = (series.time_s[index] - series.time_s[index - 1]) > max_gap_s
    return values, gap


def _longest_run(mask: NDArray[np.bool_]) -> tuple[int, int]:
    """Start and stop (exclusive) of the longest run of True, (0, 0) when none."""
    padded = np.concatenate(([False], mask, [False])).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    starts, stops = edges[0::2], edges[1::2]
    if starts.size == 0:
        return 0, 0
    k = int(np.argmax(stops - starts))
    return int(starts[k]), int(stops[k])


def resample_log(
    log: FlightLog, mass_kg: float, options: ProcessingOptions
) -> tuple[IdData, NDArray[np.bool_]]:
    """Resample and compute thrust over the span all signals cover.

    Returns
    -------
    data
        Unfiltered PWM [us] and thrust [N] at ``options.rate_hz``.
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
    pwm, pwm_gap = _resample(log.pwm_us, time_s, options.max_gap_s)
    accel, accel_gap = _resample(log.specific_force_body_mps2, time_s, options.max_gap_s)
    _, att_gap = _resample(log.euler_rad, time_s, options.max_gap_s)
    tension: FloatArray | float = options.cable_tension_n
    if log.tension_n is not None:
        tension = _resample(log.tension_n, time_s, options.max_gap_s)[0][:, 0]
    thrust = total_thrust_n(accel, mass_kg, tension)
    if log.height_m is not None:
        height, height_gap = _resample(log.height_m, time_s, options.max_gap_s)
        airborne = (
            height[:, 0] > float(np.min(log.height_m.values)) + options.airborne_height_m
        ) & ~height_gap
    else:
        airborne = np.mean(pwm, axis=1) > options.airborne_pwm_us
    airborne &= ~(pwm_gap | accel_gap | att_gap)
    return IdData(time_s=time_s, pwm_us=pwm, thrust_n=thrust, dt_s=dt_s), airborne


def lowpass(values: FloatArray, rate_hz: float, cutoff_hz: float, order: int) -> FloatArray:
    """Zero-phase Butterworth low-pass along axis 0 (forward-backward, ``sosfiltfilt``)."""
    sos = butter(order, cutoff_hz, btype="low", fs=rate_hz, output="sos")
    return sosfiltfilt(sos, values, axis=0)


def _slice(data: IdData, start: int, stop: int) -> IdData:
    return IdData(
        data.time_s[start:stop], data.pwm_us[start:stop], data.thrust_n[start:stop], data.dt_s
    )


def prepare(log: FlightLog, mass_kg: float, options: ProcessingOptions | None = None) -> Dataset:
    """Turn a flight log into estimation and validation data (see module docstring).

    Parameters
    ----------
    log
        The loaded flight.
    mass_kg
        Vehicle mass [kg] (from the vehicle profile) to turn specific force into force.
    options
        Processing settings; defaults follow the paper (100 Hz, 5th-order 10 Hz low-pass).

    Raises
    ------
    InputError
        When the log is too short, never airborne, or its inputs are constant.
    """
    options = options or ProcessingOptions()
    raw, airborne = resample_log(log, mass_kg, options)
    start, stop = _longest_run(airborne)
    if stop == start:
        raise InputError(
            f"{log.source}: the vehicle is never airborne "
            "(no height or PWM above the airborne threshold)"
        )
    trim = int(round(options.trim_s * options.rate_hz))
    start, stop = start + trim, stop - trim
    seconds = (stop - start) * raw.dt_s
    if seconds < options.min_airborne_s:
        raise InputError(
            f"{log.source}: the longest airborne segment lasts "
            f"{max(seconds, 0.0):.1f} s after trimming; "
            f"at least {options.min_airborne_s:.0f} s is needed (log too short)"
        )
    filtered = IdData(
        time_s=raw.time_s,
        pwm_us=lowpass(raw.pwm_us, options.rate_hz, options.cutoff_hz, options.filter_order),
        thrust_n=lowpass(raw.thrust_n, options.rate_hz, options.cutoff_hz, options.filter_order),
        dt_s=raw.dt_s,
    )
    flight = _slice(filtered, start, stop)
    spread_us = float(np.max(np.std(flight.pwm_us, axis=0)))
    if spread_us < options.min_excitation_us:
        raise InputError(
            f"{log.source}: the motor inputs are constant in flight "
            "(largest PWM standard deviation "
            f"{spread_us:.2f} us < {options.min_excitation_us} us): nothing is excited to identify"
        )
    split = int(round(options.estimation_fraction * len(flight)))
    return Dataset(
        estimation=_slice(flight, 0, split),
        validation=_slice(flight, split, len(flight)),
        airborne_s=(float(flight.time_s[0]), float(flight.time_s[-1])),
        source=log.source,
    )
