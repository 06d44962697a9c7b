"""The dynamic filter's observability status: may the position be published, and if not why.

Checked in this order (the first that applies wins): restarted this tick, not initialised,
on the ground, inputs stale, cable slack, horizontal position standard deviation beyond the
bound (the pull is too weak for the data to fix the position: low tension, short cable, or
a steady hover where thrust scale and wind trade against the cable's pull). The covariance
itself grows in those cases (nothing pins the position); the status names the cause.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic.output import (
    INITIALISING,
    OK,
    ON_GROUND,
    RESET,
    SLACK,
    STALE_INPUTS,
    WEAK_PULL,
)

FloatArray = NDArray[np.float64]


def assess(
    *,
    initialised_reason: str | None,
    reset_reason: str | None,
    on_ground: bool,
    inputs_stale: bool,
    tension_n: float,
    slack_tension_n: float,
    position_covariance_m2: FloatArray,
    max_horizontal_std_m: float,
) -> tuple[str, str]:
    """``(status, reason)`` of one tick (reason empty when ``ok``).

    Parameters
    ----------
    initialised_reason
        Why there is no state yet (None once initialised).
    reset_reason
        Why the filter restarted this tick (None if it did not).
    on_ground, inputs_stale
        This tick's thrust far below the weight; attitude or PWM stale.
    tension_n, slack_tension_n
        Estimated tension at the drone and the slack threshold [N].
    position_covariance_m2
        Position block of the covariance, shape (3, 3) [m^2].
    max_horizontal_std_m
        Bound on the larger horizontal standard deviation [m].
    """
    if reset_reason is not None:
        return RESET, reset_reason
    if initialised_reason is not None:
        return INITIALISING, initialised_reason
    if on_ground:
        return ON_GROUND, "thrust far below the weight: on the ground"
    if inputs_stale:
        return STALE_INPUTS, "attitude or motor outputs stale: prediction only"
    if tension_n < slack_tension_n:
        return SLACK, f"cable slack ({tension_n:.2f} N < {slack_tension_n:g} N)"
    (a, b), (_, c) = position_covariance_m2[:2, :2].tolist()
    largest = 0.5 * (a + c) + math.sqrt(0.25 * (a - c) ** 2 + b * b)  # 2x2 eigenvalue
    std = math.sqrt(max(largest, 0.0))
    if std > max_horizontal_std_m:
        return WEAK_PULL, (
            f"horizontal std {std:.2f} m > {max_horizontal_std_m:g} m: pull too weak "
            f"({tension_n:.1f} N)"
        )
    return OK, ""
