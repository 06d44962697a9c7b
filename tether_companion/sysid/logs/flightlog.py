"""The typed flight log every loader produces: time series in SI units, FRD body, NED world.

Each stream keeps its own time stamps (flight-controller time [s]); resampling onto one
time base is the job of :mod:`tether_companion.sysid.processing`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from tether_companion.errors import InputError

FloatArray = NDArray[np.float64]

N_MOTORS = 4
"""The identification works on quadcopters: four motor outputs."""


@dataclass(frozen=True)
class Series:
    """Samples of one signal.

    Attributes
    ----------
    time_s
        Flight-controller time [s], shape (n,), strictly increasing.
    values
        Samples, shape (n, k); the unit is given by the field of :class:`FlightLog` holding it.
    """

    time_s: FloatArray
    values: FloatArray

    def __len__(self) -> int:
        return int(self.time_s.shape[0])


@dataclass(frozen=True)
class FlightLog:
    """One flight's identification signals, SI units.

    Attributes
    ----------
    source
        Where the data came from (file path), for messages.
    pwm_us
        Motor output pulse widths [us], values shape (n, 4), ArduPilot motor order.
    specific_force_body_mps2
        Accelerometer specific force, FRD body [m/s^2], values shape (n, 3).
    euler_rad
        Roll, pitch, yaw [rad], values shape (n, 3).
    height_m
        Height above ground or take-off point [m] (rangefinder or barometer), values shape
        (n, 1), or None when the log has none.
    tension_n
        Measured cable tension [N] (load cell), values shape (n, 1), or None.
    velocity_ned_mps
        Velocity over ground, NED [m/s] (LOCAL_POSITION_NED, GPS), values shape (n, 3), or
        None; used to identify the rotor drag (:mod:`tether_companion.sysid.drag`).
    battery_voltage_v
        The flight controller's battery voltage [V] (SYS_STATUS, BATTERY_STATUS, dataflash
        BAT/CURR), values shape (n, 1), or None; identification scales the motor commands by
        it as the estimator does (:mod:`tether_companion.sysid.battery`).
    notes
        Non-fatal remarks from loading (e.g. a trailing partial record dropped).
    """

    source: str
    pwm_us: Series
    specific_force_body_mps2: Series
    euler_rad: Series
    height_m: Series | None = None
    tension_n: Series | None = None
    velocity_ned_mps: Series | None = None
    battery_voltage_v: Series | None = None
    notes: tuple[str, ...] = field(default=())


def make_series(source: str, name: str, time_s: object, values: object, width: int) -> Series:
    """Build a :class:`Series`, sorting by time, dropping duplicate stamps and bad rows.

    Parameters
    ----------
    source
        File name for error messages.
    name
        Signal name for error messages (e.g. ``"RAW_IMU"``).
    time_s
        Time stamps [s], shape (n,).
    values
        Samples, shape (n, width) (or (n,) when ``width`` is 1).
    width
        Number of columns expected.

    Raises
    ------
    InputError
        When the signal has no usable (finite) sample.
    """
    t = np.asarray(time_s, dtype=float).reshape(-1)
    v = (
        np.asarray(values, dtype=float).reshape(t.shape[0], width)
        if t.size
        else np.empty((0, width))
    )
    keep = np.isfinite(t) & np.all(np.isfinite(v), axis=1)
    t, v = t[keep], v[keep]
    order = np.argsort(t, kind="stable")
    t, v = t[order], v[order]
    if t.size:
        unique = np.concatenate(([True], np.diff(t) > 0.0))
        t, v = t[unique], v[unique]
    if t.size < 2:
        raise InputError(f"{source}: no usable {name} samples (found {t.size})")
    return Series(time_s=t, values=v)
