"""Accuracy metrics of an offline run: RMSE per axis and of the tension (paper's Table 2)."""

from __future__ import annotations

import numpy as np

from tether_companion.estimation.runner import RunResult

AXES = ("north_m", "east_m", "down_m")


def rmse(result: RunResult, start_s: float = 0.0) -> dict[str, dict[str, float]]:
    """Root-mean-square errors of both filters over ticks at or after ``start_s`` [s].

    Returns ``{"3S": {"north_m", "east_m", "down_m"}, "4S": {... , "tension_n"}}``; NaN rows
    (ticks without an estimate) are left out.
    """
    keep = result.time_s >= start_s
    truth = result.truth_position_ned_m[keep]
    table: dict[str, dict[str, float]] = {}
    for name, estimate in (("3S", result.position_3s_ned_m), ("4S", result.position_4s_ned_m)):
        values = np.sqrt(np.nanmean(np.square(estimate[keep] - truth), axis=0))
        table[name] = {axis: float(v) for axis, v in zip(AXES, values, strict=True)}
    tension_error = result.tension_4s_n[keep] - result.truth_tension_n[keep]
    table["4S"]["tension_n"] = float(np.sqrt(np.nanmean(np.square(tension_error))))
    return table
