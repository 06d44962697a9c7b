"""What the last seconds of flight could tell about the bearing: the published covariance kept
at least as wide as the window's information allows (:class:`BearingWindow`).

The accelerometer reads the cable's horizontal pull ``-H u`` (``u`` the horizontal unit
vector from the anchor to the drone) plus the rotor drag ``m mu (w - v)`` of the wind ``w``.
A constant error ``d`` of the position across the cable turns the pull by ``H d / rho``
(``rho`` the horizontal range), which a constant cross wind ``m mu dw = H d / rho`` hides
exactly: at a hover's equilibrium the pair is a null direction of the linearised model (rank
11 of 13, ``tests/test_dynamic_hover_observability.py``). It is told apart only when the
bearing turns (the pull turns with the drone, the wind's drag does not), so what the data
say about the bearing is set by how far the drone swept round the anchor within the time the
wind stays the same, and by the wind's prior. The EKF, linearised at its own moving
estimate, gains information along that direction that the data do not carry (its
covariance shrinks in a steady hover where the bearing is as unknown as the cross wind:
gusty hover with the winch, 37-46 % of the published ticks beyond 3 sigma).

:class:`BearingWindow` computes that information apart from the filter: the constant offsets
``theta = (d_n, d_e, dH, dw_n, dw_e)`` (position [m], horizontal pull [N], wind [m/s]) seen
through the horizontal force at the estimated positions of the last seconds (the INS keeps
their relative positions), each sample worth ``dt / correlation_s`` of an independent
force sample of ``force_std_n`` (the unmodelled force is correlated over about a second),
with exponential forgetting over ``memory_s`` (the wind changes), the wind's prior
standard deviation, and the filter's own radial variance (the range is not this module's
question); the bearing starts unknown (:data:`BEARING_PRIOR_RAD`). The variance across the
cable it leaves, less what the published covariance already holds there, is returned as a
horizontal force standard deviation, which the published estimate adds through
:func:`~tether_companion.estimation.dynamic.observability.unmodelled_position_covariance`
(the same ``|p| (I - u u^T) dF / T`` the unmodelled force already uses). The filter's state
and covariance are untouched. Pure.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state

FloatArray = NDArray[np.float64]

_PARAMETERS = 5
"""Offsets of (north, east) position [m], horizontal pull [N], (north, east) wind [m/s]."""
LOW_PULL_SIGMAS = 2.0
"""The window's rows are taken at the pull this many of its standard deviations below the
filter's (at least half of it)."""
STEADY_SPEED_MPS = 0.3
"""Estimated horizontal speed [m/s] below which the drone holds still: its bearing does not
turn (:class:`BearingWindow`) and its force balance's innovations show the gusts
(:class:`GustWalk`)."""
_PULL_PRIOR_N2 = 100.0
"""Prior variance of the horizontal pull's offset [N^2] (left to the data)."""
BEARING_PRIOR_RAD = 1.0
"""Prior standard deviation of the bearing at the window's first sample [rad]: the offset
across the cable starts as unknown as this times the horizontal range, so what the window
then holds is what its own samples and the wind's prior tell (not the filter's covariance,
which a hover's thrust-scale bank makes confident before the data tell the bearing:
docs/estimation-history.md, "The ground a moving drone averages, and the bearing before the data
tell it (terrain12)")."""


class BearingWindow:
    """A small Kalman filter of the constant offsets ``theta`` seen through the horizontal
    force: what the recent flight tells about the bearing.

    Parameters
    ----------
    drag_n_s_per_m
        Rotor drag per unit airspeed ``m mu`` [N s/m] (0: the wind does not move the pull,
        nothing is added).
    wind_std_mps
        The wind's prior standard deviation [m/s].
    force_std_n
        Standard deviation of one independent sample of the unmodelled horizontal force [N].
    correlation_s
        Time over which that force stays correlated [s] (samples this far apart count as
        independent).
    position_walk_m2ps
        Random walk of the position offset [m^2/s]: how far the estimate's positions a few
        seconds apart may be off relative to each other (the INS's drift between them); a
        turn of the bearing tells the wind only when it is larger than that (0 or below: the
        window is off and nothing is added).
    wind_walk_m2ps3
        Random walk of the wind [m^2/s^3].
    sample_interval_s
        Least time between two samples taken into the window [s].
    """

    def __init__(
        self,
        drag_n_s_per_m: float,
        wind_std_mps: float,
        force_std_n: float,
        correlation_s: float,
        position_walk_m2ps: float,
        wind_walk_m2ps3: float,
        sample_interval_s: float = 0.25,
    ) -> None:
        self._drag = drag_n_s_per_m
        self._wind_variance = wind_std_mps * wind_std_mps
        self._force_variance = force_std_n * force_std_n
        self._correlation_s = correlation_s
        self._walk = np.array(
            [position_walk_m2ps, position_walk_m2ps, 0.0, wind_walk_m2ps3, wind_walk_m2ps3]
        )
        self._interval_s = sample_interval_s
        self._least_wind_walk = wind_walk_m2ps3
        self.enabled = position_walk_m2ps > 0.0 and drag_n_s_per_m > 0.0 and force_std_n > 0.0
        self._covariance = np.zeros((_PARAMETERS, _PARAMETERS))
        self._last_s = math.nan
        self._bearing = (1.0, 0.0)
        self._base_std_n = force_std_n
        self._window_m2 = 0.0
        """The window's variance across the cable at its last sample [m^2]."""
        self.force_std_n = force_std_n
        """The unmodelled horizontal force standard deviation [N] the published covariance
        takes: ``force_std_n``, widened until it holds the window's variance across the
        cable."""

    def clear(self) -> None:
        """Forget every sample (a restart)."""
        self._last_s = math.nan
        self.force_std_n = self._base_std_n
        self.set_wind_walk(0.0)

    def set_wind_walk(self, measured_m2ps3: float) -> None:
        """The wind's random walk from now on [m^2/s^3]: the larger of ``wind_walk_m2ps3``
        and ``measured_m2ps3`` (what the flight's own gusts show: :class:`GustWalk`)."""
        walk = max(self._least_wind_walk, measured_m2ps3)
        self._walk[3] = self._walk[4] = walk if math.isfinite(walk) else self._least_wind_walk

    def add_bearing(self, across_std_m: float) -> None:
        """A measurement of the position across the cable of standard deviation
        ``across_std_m`` [m] (a ground-station cable angle's azimuth times the horizontal
        range) at the last sample's bearing; ignored before the first sample."""
        if not self.enabled or math.isnan(self._last_s) or not across_std_m > 0.0:
            return
        un, ue = self._bearing
        row = np.array([-ue, un, 0.0, 0.0, 0.0])
        p = self._covariance
        ph = p @ row
        p -= np.outer(ph, ph) / (row @ ph + across_std_m * across_std_m)
        p[:] = 0.5 * (p + p.T)
        self._window_m2 = float(row @ p @ row)

    def add(
        self,
        time_s: float,
        position_ned_m: list[float],
        tension_n: float,
        filter_horizontal_m2: tuple[float, float, float],
        pull_known: bool = True,
    ) -> None:
        """One sample of the estimate at ``time_s`` [s]: its position from the anchor (NED
        [m]), tension at the drone [N] and the filter's horizontal position covariance
        ``(nn, ne, ee)`` [m^2]; ``pull_known`` False while several thrust-scale hypotheses
        run in a hover (the pull trades against the thrust scale and the bearing does not
        turn, so the force tells nothing of the bearing yet: the window keeps its prior, a
        cable angle's bearing and the walk; realistic gusty hover with the winch, seeds 2,
        17, 41-49: published 1.2-4.4 s after the start, the estimate 1-2 m off at 0.3-0.5 m).
        Updates :attr:`force_std_n`; samples closer than
        ``sample_interval_s`` to the last only update it against the filter's covariance now
        (the thrust-scale bank's collapse narrows it at once: the window's floor then
        applies at once, not at the next sample)."""
        if not self.enabled:
            return
        north, east, down = position_ned_m
        rho = math.hypot(north, east)
        distance = math.sqrt(rho * rho + down * down)
        if not (rho > 0.0 and tension_n > 0.0 and math.isfinite(distance)):
            self.force_std_n = self._base_std_n
            return
        nn, ne, ee = filter_horizontal_m2
        last = self._last_s
        if not math.isnan(last) and time_s - last < self._interval_s:
            self._widen(self._window_m2, north / rho, east / rho, distance / tension_n, nn, ne, ee)
            return
        un, ue = north / rho, east / rho
        self._bearing = (un, ue)
        radial = max(un * un * nn + 2.0 * un * ue * ne + ue * ue * ee, 1e-12)
        p = self._covariance
        if math.isnan(last):  # the prior: the filter's range, any bearing, the wind's prior
            dt = self._interval_s
            p[:] = 0.0
            across = (BEARING_PRIOR_RAD * rho) ** 2  # along (-ue, un)
            p[:2, :2] = (
                (nn + across * ue * ue, ne - across * un * ue),
                (ne - across * un * ue, ee + across * un * un),
            )
            p[2, 2] = _PULL_PRIOR_N2
            p[3, 3] = p[4, 4] = self._wind_variance
        else:
            dt = time_s - last
            p[np.diag_indices(_PARAMETERS)] += self._walk * dt
        self._last_s = time_s
        across_axis = np.array([-ue, un, 0.0, 0.0, 0.0])
        if math.isnan(last):  # no floor before a second sample: a cable angle tells the
            self._window_m2 = 0.0  # bearing within it (the prior would stay in the angles'
            self.force_std_n = self._base_std_n  # position information for a second)
            return
        if not pull_known:
            self._window_m2 = float(across_axis @ p @ across_axis)
            self._widen(self._window_m2, un, ue, distance / tension_n, nn, ne, ee)
            return
        # the horizontal pull over the horizontal range, at the least pull the window does
        # not exclude (the bearing's turn per unit of force is larger at a smaller pull)
        least = max(
            tension_n - LOW_PULL_SIGMAS * math.sqrt(p[2, 2]) * distance / rho, 0.5 * tension_n
        )
        k = least / distance
        # rows of d(horizontal force)/d(theta): -(H / rho)(I - u u^T), -u, m mu I; and the
        # filter's range (the radial offset)
        rows = np.array(
            [
                [-k * (1.0 - un * un), k * un * ue, -un, self._drag, 0.0],
                [k * ue * un, -k * (1.0 - ue * ue), -ue, 0.0, self._drag],
                [un, ue, 0.0, 0.0, 0.0],
            ]
        )
        force = self._force_variance * self._correlation_s / dt
        noise = np.diag((force, force, radial))
        ph = p @ rows.T
        gain = np.linalg.solve(rows @ ph + noise, ph.T).T
        p -= gain @ ph.T
        p[:] = 0.5 * (p + p.T)
        self._window_m2 = float(across_axis @ p @ across_axis)
        self._widen(self._window_m2, un, ue, distance / tension_n, nn, ne, ee)

    def _widen(
        self,
        window_m2: float,
        un: float,
        ue: float,
        gain_m_per_n: float,
        nn: float,
        ne: float,
        ee: float,
    ) -> None:
        """:attr:`force_std_n` from the window's variance across the cable ``window_m2``
        [m^2] at the bearing ``(un, ue)``, the published term's ``|p| / T`` [m/N] and the
        filter's horizontal covariance ``(nn, ne, ee)`` [m^2]: across the cable the published
        covariance holds the filter's and the unmodelled force's ``|p| sigma / T``."""
        base = self._base_std_n
        across = ue * ue * nn - 2.0 * un * ue * ne + un * un * ee + (gain_m_per_n * base) ** 2
        missing = window_m2 - across
        extra2 = missing / (gain_m_per_n * gain_m_per_n) if missing > 0.0 else 0.0
        self.force_std_n = math.sqrt(base * base + extra2)


def sample_bearing(
    window: BearingWindow,
    gusts: GustWalk,
    time_s: float,
    mixture: tuple[FloatArray, FloatArray],
    decided: bool,
    innovation_body: list[float],
    rows: list[list[float]],
) -> None:
    """The bank's mixture ``(x, P)`` after a force-balance fusion at ``time_s`` [s] into the
    bearing window, and that fusion's innovation (body, [m/s^2]; ``R_v^b``'s ``rows``) into
    the gusts' walk, which the window then takes; ``decided``: one thrust-scale hypothesis
    left (else the force tells the window nothing while the drone holds still)."""
    x, p = mixture
    speed_mps = math.hypot(float(x[3]), float(x[4]))
    gusts.add_body(time_s, innovation_body, rows, speed_mps)
    window.set_wind_walk(gusts.walk_m2ps3)
    pull_known = decided or speed_mps >= STEADY_SPEED_MPS
    horizontal = (p[0, 0], p[0, 1], p[1, 1])
    window.add(time_s, x[:3].tolist(), float(x[state.TENSION]), horizontal, pull_known)


class GustWalk:
    """The wind's random walk [m^2/s^3] the flight's own gusts show, from the force balance's
    horizontal innovations: what :class:`BearingWindow` takes as the wind's walk when it is
    larger than its configured one.

    A wind ``w`` that walks with density ``q`` [m^2/s^3] moves the rotor drag per unit mass
    ``mu (w - v)`` [m/s^2] by ``mu^2 q D`` in variance over ``D`` seconds; the innovations
    carry the part of a gust the filter's own wind does not follow (since gust25 its wind is a
    Gauss-Markov process driven by 1.2 m^2/s^3 that follows much of it: the gusty hover's
    tuning seed 1 reads 0.42 where the 0.05 walk before read 1.18). The
    horizontal innovations (NED) are smoothed over ``smoothing_s`` (the accelerometer's
    vibration averages out), and the mean square of the smoothed value's change over
    ``lag_s``, less what white innovations of their own measured variance would give, is
    ``mu^2 q lag_s`` times the share of the walk's change the smoothing keeps (averaged over
    ``memory_s``). Measured on the realistic flights (tuning
    seeds 1-3, winch): 0.4-0.55 m^2/s^3 in the gusty hover, whose true wind walks by 0.42-0.55;
    0.03-0.08 on the 4 N circle (true 0.04-0.05).

    Counted only while the drone holds still (estimated horizontal speed below
    ``steady_speed_mps``): in flight the unmodelled body drag changes with the drone's own
    air speed, and the residuals' change is then the manoeuvre's, not the wind's (the
    take-off's figure-eight shows the gusty hover's 0.02 (m/s^2)^2 per second in a wind that
    walks by 0.04). Pure.

    Parameters
    ----------
    drag_per_s
        Rotor drag per unit mass ``mu`` [1/s] (0: nothing is measured).
    smoothing_s, lag_s, memory_s
        The innovations' smoothing, the change's lag and the mean square's memory [s].
    steady_speed_mps
        Horizontal speed [m/s] below which the drone holds still.
    """

    def __init__(
        self,
        drag_per_s: float,
        smoothing_s: float = 0.5,
        lag_s: float = 1.0,
        memory_s: float = 10.0,
        steady_speed_mps: float = STEADY_SPEED_MPS,
    ) -> None:
        self._mu_sq = drag_per_s * drag_per_s
        self._smoothing_s = smoothing_s
        self._lag_s = lag_s
        self._memory_s = memory_s
        self._steady_speed_mps = steady_speed_mps
        self._kept = 1.0 - smoothing_s / lag_s * (1.0 - math.exp(-lag_s / smoothing_s))
        """The share of a random walk's change over ``lag_s`` its smoothed value keeps
        (``1 - (tau / D)(1 - exp(-D / tau))``: 0.57 for 0.5 s over 1 s)."""
        self.clear()

    def clear(self) -> None:
        """Forget every innovation (a restart)."""
        self._last_s = math.nan
        self._smoothed = (0.0, 0.0)
        self._history: deque[tuple[float, float, float]] = deque()
        self._raw_sq = 0.0
        self._raw_weight = 0.0
        self._change_sq = 0.0
        self._floor_sq = 0.0
        self._weight = 0.0
        self.walk_m2ps3 = 0.0
        """The wind's random walk the innovations show [m^2/s^3] (0 until measured)."""

    def add_body(
        self,
        time_s: float,
        innovation_frd_mps2: list[float],
        rotation_rows: list[list[float]],
        speed_mps: float,
    ) -> None:
        """:meth:`add` of a force balance's innovation in the body (FRD [m/s^2]; anything but
        3 values is ignored), turned to NED with the attitude's ``R_v^b`` (its rows)."""
        if len(innovation_frd_mps2) != 3:
            return
        f, r, d = innovation_frd_mps2
        (a0, a1, _), (b0, b1, _), (c0, c1, _) = rotation_rows
        self.add(time_s, (a0 * f + b0 * r + c0 * d, a1 * f + b1 * r + c1 * d), speed_mps)

    def add(self, time_s: float, innovation_ne_mps2: tuple[float, float], speed_mps: float) -> None:
        """One fused force balance's horizontal innovation, NED north and east [m/s^2], at
        ``time_s`` [s] with the estimated horizontal speed [m/s]."""
        north, east = innovation_ne_mps2
        if not (math.isfinite(north + east + time_s + speed_mps) and self._mu_sq > 0.0):
            return
        last = self._last_s
        dt = time_s - last if math.isfinite(last) else 0.0
        if dt < 0.0:
            return
        self._last_s = time_s
        if speed_mps > self._steady_speed_mps:
            self._history.clear()
            return
        alpha = 1.0 - math.exp(-dt / self._smoothing_s) if dt > 0.0 else 1.0
        sn, se = self._smoothed
        dn, de = north - sn, east - se
        sn += alpha * dn
        se += alpha * de
        self._smoothed = (sn, se)
        history = self._history
        history.append((time_s, sn, se))
        keep = 1.0 - math.exp(-dt / self._memory_s)
        # white innovations of variance s^2 stand off the smoothed value by 2 s^2 / (2 - alpha)
        white_sq = 0.25 * (dn * dn + de * de) * (2.0 - alpha)
        self._raw_sq += keep * (white_sq - self._raw_sq)
        self._raw_weight += keep * (1.0 - self._raw_weight)
        if time_s - history[0][0] < self._lag_s:
            return
        while time_s - history[1][0] >= self._lag_s:
            history.popleft()
        t0, n0, e0 = history[0]
        lag = time_s - t0
        change_sq = 0.5 * ((sn - n0) ** 2 + (se - e0) ** 2) / lag
        # two smoothed values lag apart, of white innovations: 2 alpha / (2 - alpha) of their
        # variance, per second of lag
        floor_sq = 2.0 * self._raw_sq / max(self._raw_weight, 1e-12) * alpha / (2.0 - alpha) / lag
        self._change_sq += keep * (change_sq - self._change_sq)
        self._floor_sq += keep * (floor_sq - self._floor_sq)
        self._weight += keep * (1.0 - self._weight)
        if self._weight > 0.0:
            excess = (self._change_sq - self._floor_sq) / self._weight
            self.walk_m2ps3 = max(excess, 0.0) / (self._mu_sq * self._kept)
