"""Is the running filter lost? Its position tested against the last window's own fix.

The filter's position carries its whole history: a start that was wrong, a bank that
collapsed onto a wrong thrust-scale hypothesis, a linearisation that ran away. Once lost
this way the filter can be consistent with its measurements (a far, nearly horizontal cable
with a low thrust scale explains the accelerometer as well as the true one: the thrust scale
trades against the cable's vertical pull) while its covariance claims metres, so the
accelerometer's innovations do not show it.

The initialiser's fix from the last ``initial.window_s`` of data
(:class:`~tether_companion.estimation.dynamic.initialise.Initialiser`, with the config's
priors of the thrust scale, bias and wind, not the filter's) does not depend on that history.
Both estimate the same position; while the filter is right their difference ``d`` has a
covariance no larger than ``P_filter + P_window`` (the two share only the window's data,
which makes them agree more, not less), so ``NIS = d^T (P_filter + P_window)^-1 d`` exceeds
the chi-square quantile (3 degrees of freedom) of :data:`LOST_PROBABILITY` rarely, and
:data:`LOST_WINDOWS` windows in a row above it say the filter is lost: it restarts
(``reset_counter``, with this test's reason). A window that gives no fix (slack cable, on
the ground, no height) tests nothing and leaves the count as it was.

Pure and synchronous.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic.initialise import Initialiser
from tether_companion.estimation.ekf import chi2_threshold

FloatArray = NDArray[np.float64]

LOST_PROBABILITY = 0.9999
"""Chi-square probability of the per-window test (3 dof: NIS above ~21.1)."""
LOST_WINDOWS = 3
"""Windows in a row beyond the threshold that make the filter lost."""
LOST_THRESHOLD = chi2_threshold(LOST_PROBABILITY, 3)


class LostCheck:
    """Collects a window of ticks and heights beside the running filter and tests it.

    Parameters
    ----------
    make_initialiser
        A fresh :class:`Initialiser` (the same settings as the filter's start).
    """

    def __init__(self, make_initialiser: Callable[[], Initialiser]) -> None:
        self._make = make_initialiser
        self._window = make_initialiser()
        self.failures = 0
        """Windows in a row whose fix was beyond the threshold."""
        self.last_nis = math.nan
        """NIS of the last window that gave a fix."""

    def add_tick(
        self,
        time_s: float,
        specific_force_body: FloatArray,
        rotation_ned_to_body: FloatArray,
        thrust_n: float,
    ) -> None:
        """One aligned IMU tick (as :meth:`Initialiser.add_tick`)."""
        self._window.add_tick(time_s, specific_force_body, rotation_ned_to_body, thrust_n)

    def add_height(self, height_above_anchor_m: float) -> None:
        """One rangefinder height above the anchor [m] (as :meth:`Initialiser.add_height`)."""
        self._window.add_height(height_above_anchor_m)

    def test(
        self,
        time_s: float,
        moments: Callable[[], tuple[FloatArray, FloatArray]],
        length_m: float,
    ) -> str | None:
        """Once the window is full: its fix against the filter's ``moments()`` (state (13,),
        covariance (13, 13)) at ``time_s`` [s], and a new window; why the filter is lost, or
        ``None``. ``length_m``: the winch's paid-out length [m] (``nan``: unknown)."""
        window = self._window
        if not window.window_full(time_s):
            return None
        fix = window.solve(time_s, length_m)
        self._window = self._make()
        if fix.x is None or fix.p is None:
            return None
        x, p = moments()
        d = x[:3] - fix.x[:3]
        total = p[:3, :3] + fix.p[:3, :3]
        if not (np.all(np.isfinite(d)) and np.all(np.isfinite(total))):
            return None
        nis = float(d @ np.linalg.solve(total, d))
        self.last_nis = nis
        if nis <= LOST_THRESHOLD:
            self.failures = 0
            return None
        self.failures += 1
        if self.failures < LOST_WINDOWS:
            return None
        return (
            f"lost: {float(np.linalg.norm(d)):.1f} m from the last {LOST_WINDOWS} windows' own"
            f" fixes (NIS {nis:.0f} > {LOST_THRESHOLD:.0f})"
        )
