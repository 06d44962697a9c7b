"""The catenary estimator's position as the publisher reads it (``position.source: catenary``):
:class:`CatenaryEstimate` and the publisher health for each reason it has no position."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tether_companion.estimation.catenary_position import (
    NO_TENSION,
    UNOBSERVABLE,
    CatenaryPosition,
)
from tether_companion.estimation.catenary_position import STALE_TENSION as CATENARY_STALE_TENSION
from tether_companion.estimation.catenary_position import WEAK_PULL as CATENARY_WEAK_PULL
from tether_companion.estimation.tension_kf import TensionEstimate
from tether_companion.service.health import SLACK, STALE, WEAK_PULL

CATENARY_UNAVAILABLE = {
    NO_TENSION: STALE,
    CATENARY_STALE_TENSION: STALE,
    UNOBSERVABLE: SLACK,
    CATENARY_WEAK_PULL: WEAK_PULL,
}
"""Publisher health for the catenary estimator's reasons to have no position (the others,
``inconsistent`` and ``no_length``, show as ``diverged``)."""


@dataclass(frozen=True, slots=True)
class CatenaryEstimate:
    """A catenary position with the tension it came from, as the publisher reads it.

    Attributes
    ----------
    time_s
        Flight-controller time [s].
    position_ned_m
        Position from the anchor, NED, shape (3,) [m] (``nan`` when invalid).
    tension_n
        Filtered tension magnitude [N].
    covariance
        Shape (4, 4): the catenary position covariance [m^2], then the variance of the
        filtered tension's magnitude, its error budget included [N^2].
    reset_counter
        Restarts of the tension filter (each one can step the position).
    """

    time_s: float
    position_ned_m: np.ndarray
    tension_n: float
    covariance: np.ndarray
    reset_counter: int

    @property
    def position_covariance_m2(self) -> np.ndarray:
        """Position block of the covariance, shape (3, 3) [m^2]."""
        return self.covariance[:3, :3]

    @classmethod
    def of(cls, position: CatenaryPosition, tension: TensionEstimate) -> CatenaryEstimate:
        """The estimate for ``position``, computed from ``tension``."""
        covariance = np.zeros((4, 4))
        covariance[:3, :3] = position.covariance_m2
        covariance[3, 3] = tension.magnitude_variance_n2
        return cls(
            position.time_s,
            position.position_ned_m,
            tension.magnitude_n,
            covariance,
            tension.health.restarts,
        )
