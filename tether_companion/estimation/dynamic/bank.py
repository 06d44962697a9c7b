"""A bank of filters that differ in their thrust-scale hypothesis, until the data pick one.

Why: the thrust scale ``s`` (thrust map error, battery sag) trades against the cable's
vertical pull, so a 10 % error moves the first position fix by metres; one EKF started with
``s = 1 +- 0.1`` linearises far from the truth and can converge to a wrong, over-confident
state. Each member starts from the same window with a narrow prior around its own ``s``
(spaced so that the truth is within about one prior standard deviation of one member), the
members run side by side on the same measurements, and each accumulates the log-likelihood
``-NIS/2`` of its innovations (tempered: :data:`LIKELIHOOD_TEMPERING`). The published state
is the mixture's mean and covariance (weights from the log-likelihoods; the covariance
includes the spread between members, so it stays honest while they disagree). When one
member's weight passes ``SELECT_WEIGHT`` after ``MIN_BANK_S`` the others are dropped; after
``max_bank_s`` (the config's ``initial.thrust_scale_bank_max_s``) without a decision (a steady
hover gives the thrust scale no information) the bank collapses into one filter holding the
mixture's moments.

Pure and synchronous.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic.member import MemberFilter
from tether_companion.estimation.ekf import MeasurementFunction

FloatArray = NDArray[np.float64]

SELECT_WEIGHT = 0.99
"""Posterior weight at which one member is kept and the others dropped."""
MIN_BANK_S = 3.0
"""Shortest time the members run side by side [s]."""
LIKELIHOOD_TEMPERING = 20.0
"""Each sample's ``-NIS/2`` is divided by this: the innovations of consecutive IMU ticks are
not independent (motor lag, unmodelled forces and the FC's attitude error last tens of
milliseconds to seconds), and counting 200 of them per second as independent evidence made
the bank pick a member within seconds in a steady hover, where the thrust scale is not
observable at all (a member 1.6-2 m off published at 3.2 sigma in the service's closed loop)."""


class FilterBank:
    """Members (``MemberFilter``) with log-likelihood weights.

    Parameters
    ----------
    filters
        The members, one per hypothesis (at least one).
    start_s
        Time the bank started [s].
    """

    def __init__(self, filters: list[MemberFilter], start_s: float, max_bank_s: float) -> None:
        self.filters = filters
        self.log_likelihood = [0.0] * len(filters)
        """Each member's tempered log-likelihood so far (Python floats: read every tick)."""
        self.start_s = start_s
        self.max_bank_s = max_bank_s

    @property
    def decided(self) -> bool:
        """Whether one member is left."""
        return len(self.filters) == 1

    @property
    def best(self) -> MemberFilter:
        """The member with the largest weight."""
        filters = self.filters
        if len(filters) == 1:
            return filters[0]
        return filters[self._best_index()]

    def _best_index(self) -> int:
        ll = self.log_likelihood
        return ll.index(max(ll))

    def weights(self) -> FloatArray:
        """Normalised posterior weights, shape (members,)."""
        ll = self.log_likelihood
        top = max(ll)
        w = [math.exp(v - top) for v in ll]
        total = sum(w)
        return np.array([v / total for v in w])

    def keep(self, indices: list[int]) -> None:
        """Keep only the members at ``indices`` (with their log-likelihoods)."""
        self.filters = [self.filters[i] for i in indices]
        self.log_likelihood = [self.log_likelihood[i] for i in indices]

    def predict(self, dt_s: float, u: list[float], covariance: bool = True) -> None:
        """Predict every member (``u`` the inputs as floats; the covariance too when
        ``covariance``, see :meth:`MemberFilter.predict`)."""
        for kf in self.filters:
            kf.predict(dt_s, u, covariance=covariance)

    def update_others(
        self, name: str, z: FloatArray, measure: MeasurementFunction, r: FloatArray
    ) -> None:
        """Fuse into every member but the best (the caller fuses the best with its status
        record) and add each member's ``-NIS/2``."""
        best = self.best
        for i, kf in enumerate(self.filters):
            if kf is not best:
                result = kf.update(name, z, measure, r)
                if math.isfinite(result.nis):
                    self.log_likelihood[i] -= 0.5 * result.nis / LIKELIHOOD_TEMPERING

    def add_best_nis(self, nis: float) -> None:
        """The best member's NIS of the sample just fused."""
        if math.isfinite(nis):
            self.log_likelihood[self._best_index()] -= 0.5 * nis / LIKELIHOOD_TEMPERING

    def drop_unhealthy(self, max_distance_m: float) -> None:
        """Drop members whose state is not finite or farther than ``max_distance_m``."""
        if len(self.filters) == 1:  # nothing to choose between: the caller restarts
            return
        limit = max_distance_m**2
        keep = []
        for i, kf in enumerate(self.filters):
            x = kf.x_values()
            distance_sq = x[0] * x[0] + x[1] * x[1] + x[2] * x[2]
            if math.isfinite(sum(x)) and distance_sq <= limit:
                keep.append(i)
        if keep and len(keep) < len(self.filters):
            self.keep(keep)

    def mixture(self) -> tuple[FloatArray, FloatArray]:
        """Mean (n,) and covariance (n, n) of the weighted mixture (with one member left,
        that member's own arrays: the caller copies what it keeps)."""
        if self.decided:  # the member's own arrays: read them, do not change them
            kf = self.filters[0]
            return kf.x, kf.P
        w = self.weights()
        xs = np.array([kf.x for kf in self.filters])
        n = xs.shape[1]
        mean = w @ xs
        spread = xs - mean
        cov = (w @ np.array([kf.P.ravel() for kf in self.filters])).reshape(n, n)
        cov += (spread.T * w) @ spread
        cov += cov.T
        cov *= 0.5
        return mean, cov

    def maybe_decide(self, time_s: float) -> None:
        """Keep one member when its weight passes :data:`SELECT_WEIGHT` (after
        :data:`MIN_BANK_S`), or collapse to the moments after ``max_bank_s``."""
        if self.decided:
            return
        elapsed = time_s - self.start_s
        if elapsed < MIN_BANK_S:
            return
        w = self.weights()
        best = int(np.argmax(w))
        if w[best] >= SELECT_WEIGHT:
            self.keep([best])
        elif elapsed >= self.max_bank_s:
            mean, cov = self.mixture()
            kf = self.filters[best]
            resets = kf.resets
            kf.reset(mean, cov)
            kf.resets = resets  # a collapse is not a restart
            self.filters = [kf]
            self.log_likelihood = [0.0]
