"""CSV flight logs: one header row, one row per sample, all signals on one time base.

Required columns (any order, extra columns ignored):

=================================  ==========================================================
``time_s``                         flight-controller time [s], increasing
``pwm1_us`` .. ``pwm4_us``         motor outputs [us], ArduPilot motor order
``acc_x_mps2`` .. ``acc_z_mps2``   accelerometer specific force, FRD body [m/s^2]
                                   (about (0, 0, -9.81) at rest, level)
``roll_rad``, ``pitch_rad``,       attitude [rad]
``yaw_rad``
=================================  ==========================================================

Optional: ``height_m`` (height above ground [m], rangefinder or barometer), ``tension_n``
(measured cable tension [N]) and ``battery_voltage_v`` (the flight controller's battery
voltage [V], > 0). Empty cells in optional columns are missing samples.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from tether_companion.errors import InputError
from tether_companion.sysid.logs.flightlog import FlightLog, Series, make_series

TIME_COLUMN = "time_s"
PWM_COLUMNS = ("pwm1_us", "pwm2_us", "pwm3_us", "pwm4_us")
ACCEL_COLUMNS = ("acc_x_mps2", "acc_y_mps2", "acc_z_mps2")
EULER_COLUMNS = ("roll_rad", "pitch_rad", "yaw_rad")
HEIGHT_COLUMN = "height_m"
TENSION_COLUMN = "tension_n"
BATTERY_COLUMN = "battery_voltage_v"
OPTIONAL_COLUMNS = (HEIGHT_COLUMN, TENSION_COLUMN, BATTERY_COLUMN)
REQUIRED_COLUMNS = (TIME_COLUMN, *PWM_COLUMNS, *ACCEL_COLUMNS, *EULER_COLUMNS)


def _parse(source: str, row_number: int, column: str, text: str, required: bool) -> float:
    text = text.strip()
    if not text:
        if required:
            raise InputError(f"{source}: line {row_number}: column {column} is empty")
        return float("nan")
    try:
        value = float(text)
    except ValueError:
        raise InputError(
            f"{source}: line {row_number}: column {column} = {text!r} is not a number"
        ) from None
    if column == BATTERY_COLUMN and not (math.isfinite(value) and value > 0.0):
        raise InputError(
            f"{source}: line {row_number}: column {column} = {text!r} is not a positive "
            "voltage [V] (leave the cell empty when unknown)"
        )
    return value


def load_csv(path: Path) -> FlightLog:
    """Read a CSV flight log (see module docstring for the columns).

    Raises
    ------
    InputError
        When a required column is missing, a cell is not a number, a row is short
        (truncated file), a battery voltage is not a positive number or a signal has fewer
        than two samples.
    """
    source = str(path)
    try:
        with path.open(newline="", encoding="utf-8") as handle:
            rows = list(csv.reader(handle))
    except UnicodeDecodeError:
        raise InputError(f"{source}: not a text CSV file") from None
    if not rows:
        raise InputError(
            f"{source}: empty file (expected a header row with {', '.join(REQUIRED_COLUMNS)})"
        )
    header = [name.strip() for name in rows[0]]
    missing = [name for name in REQUIRED_COLUMNS if name not in header]
    if missing:
        raise InputError(
            f"{source}: missing column(s) {', '.join(missing)}; found {', '.join(header)}"
        )
    index = {name: header.index(name) for name in header}
    optional = [name for name in OPTIONAL_COLUMNS if name in index]
    wanted = list(REQUIRED_COLUMNS) + optional
    table = np.empty((len(rows) - 1, len(wanted)))
    for i, row in enumerate(rows[1:]):
        line = i + 2
        if len(row) < len(header):
            raise InputError(
                f"{source}: line {line} has {len(row)} fields, the header {len(header)} "
                "(truncated file?)"
            )
        for j, name in enumerate(wanted):
            table[i, j] = _parse(source, line, name, row[index[name]], name in REQUIRED_COLUMNS)
    column = {name: table[:, j] for j, name in enumerate(wanted)}
    time_s = column[TIME_COLUMN]

    def series(name: str, names: tuple[str, ...]) -> Series:
        return make_series(
            source, name, time_s, np.column_stack([column[c] for c in names]), len(names)
        )

    def optional_series(name: str) -> Series | None:
        if name not in column:
            return None
        return make_series(source, name, time_s, column[name], 1)

    return FlightLog(
        source=source,
        pwm_us=series("PWM", PWM_COLUMNS),
        specific_force_body_mps2=series("accelerometer", ACCEL_COLUMNS),
        euler_rad=series("attitude", EULER_COLUMNS),
        height_m=optional_series(HEIGHT_COLUMN),
        tension_n=optional_series(TENSION_COLUMN),
        battery_voltage_v=optional_series(BATTERY_COLUMN),
    )
