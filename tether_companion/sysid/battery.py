"""Battery-compensated identification: the motor commands scaled by the measured voltage.

The estimator's thrust inputs scale every motor command by the battery's voltage ratio
(:meth:`tether_companion.physics.battery.BatteryCompensation.ratio`, ArduPilot's
``MOT_BAT_VOLT_MAX/MIN``): a thrust map identified on the raw commands of a flight whose
battery sagged would hold only at that flight's voltages. Identification therefore fits the
compensated commands, written as pulse widths so every later step (filtering, ``cmd`` and
``cmd^2``, the input maps) is unchanged, and the model file records the voltage range so the
estimator applies the same compensation when it runs the model.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tether_companion.physics.battery import BatteryCompensation
from tether_companion.sysid.logs.flightlog import FlightLog, Series
from tether_companion.sysid.processing import normalised_command

FloatArray = NDArray[np.float64]

UNCOMPENSATED = "; identified on uncompensated commands (the model holds at that flight's voltage)"
NO_RANGE = (
    " (profile battery.voltage_max_v/min_v, or --battery-voltage-max-v/--battery-voltage-min-v)"
)


def compensated_pwm_us(
    pwm_us: ArrayLike, pwm_range_us: tuple[float, float], voltage_ratio: ArrayLike
) -> FloatArray:
    """Pulse widths [us] whose normalised command is that of ``pwm_us`` (clipped to the
    range) times ``voltage_ratio`` (a scalar, or one per row of ``pwm_us``)."""
    lo, hi = pwm_range_us
    command = normalised_command(np.asarray(pwm_us, dtype=float), pwm_range_us)
    return lo + command * np.asarray(voltage_ratio, dtype=float) * (hi - lo)


def compensate_log(
    log: FlightLog, battery: BatteryCompensation, pwm_range_us: tuple[float, float]
) -> FlightLog:
    """``log`` with each PWM sample's command scaled by the voltage ratio at its time.

    The voltage is interpolated linearly at the PWM stamps (held before the first and after
    the last reading). The log must carry a voltage and ``battery`` must be enabled.

    Raises
    ------
    ValueError
        When the log has no voltage or ``battery`` is off (a programming error: check first).
    """
    series = log.battery_voltage_v
    if series is None or not battery.enabled:
        raise ValueError("compensate_log needs a logged voltage and an enabled battery range")
    voltage = np.interp(log.pwm_us.time_s, series.time_s, series.values[:, 0])
    ratio = np.array([battery.ratio(float(v)) for v in voltage])[:, None]
    pwm = compensated_pwm_us(log.pwm_us.values, pwm_range_us, ratio)
    return dataclasses.replace(log, pwm_us=Series(time_s=log.pwm_us.time_s, values=pwm))


def compensate_logs(
    logs: Sequence[FlightLog], battery: BatteryCompensation, pwm_range_us: tuple[float, float]
) -> tuple[list[FlightLog], bool, str]:
    """Compensate every log (:func:`compensate_log`) when all carry a voltage and the range
    is known; else leave all as they are (mixed data would fit no single map).

    Returns
    -------
    logs
        The logs to identify from.
    compensated
        Whether the commands were scaled (the model file then records ``battery``).
    note
        One line saying which was done and why.
    """
    without = [log.source for log in logs if log.battery_voltage_v is None]
    if without:
        note = f"battery: no voltage in {', '.join(without)}"
        return list(logs), False, note + UNCOMPENSATED
    low = min(float(np.min(log.battery_voltage_v.values)) for log in logs)
    high = max(float(np.max(log.battery_voltage_v.values)) for log in logs)
    if not battery.enabled:
        note = f"battery: logged {low:.2f}-{high:.2f} V but no voltage range is known{NO_RANGE}"
        return list(logs), False, note + UNCOMPENSATED
    note = (
        f"battery: logged {low:.2f}-{high:.2f} V; commands scaled by the voltage ratio over "
        f"{battery.voltage_min_v:.2f}-{battery.voltage_max_v:.2f} V as the estimator does"
    )
    return [compensate_log(log, battery, pwm_range_us) for log in logs], True, note
