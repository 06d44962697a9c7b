"""Start the dynamic filter from its first second of data: no initial guess needed.

Over a window of IMU ticks (``initial.window_s``), with the drone assumed near rest on
average, the cable's force per unit mass in NED is what the accelerometer reads beyond
thrust, drag and bias:

    c = mean(R^T f) - mean(R^T) b + s mean(R^T e_z T / m) - mu mean(R^T diag(1,1,0) R) w

(``f`` specific force, FRD body; ``T`` thrust from the map, ``s`` its scale; ``b`` bias;
``w`` wind). Its horizontal part points from the drone to the anchor; with the rangefinder's
height above the anchor the filter's own cable curve (straight, catenary, or resting on the
ground, :func:`~tether_companion.estimation.dynamic.start_placement.place`) gives the span
and the chord tension ``T_ch``; a cable resting on the ground pulls the same at every span
beyond its touchdown, so there only the winch length places the drone. The prior of
everything the window cannot measure (``s``, ``b``, ``w`` from the config; the
accelerometer's and the rangefinder's noise averaged over the window) is mapped through this
construction by central differences
(:mod:`~tether_companion.estimation.dynamic.start_covariance`), so the initial covariance
carries the correlations (position with thrust scale, bias and wind) that let later data
correct the position when those become known. In a steady hover they do not: the thrust
scale trades against the cable's vertical pull and the wind against its horizontal pull, and
the covariance says so.

With a ground-station cable angle read within the window (:meth:`Initialiser.add_angle`) the
anchor measures the drone's bearing itself: its azimuth is the bearing (a cable hangs in the
vertical plane through the anchor and the drone), and for a weightless cable its elevation
places the drone with the winch length ``L`` (along the direction ``(el, az)``: the ground
station alone fixes it) or, without one, with the height (span ``h / tan(el)``); the tension
is the window's force along the cable. The force
alone cannot do this near the anchor: there the cable's horizontal pull is not much larger
than the wind's drag, which turns the force's bearing (the realistic take-off, 1 m from the
anchor, 1.4 N of pull against 0.6-0.8 N of drag: started 1 m off, its first angles gated).
The angle's noise (averaged over the window's readings) enters the initial covariance as two
more parameters of the construction; its calibration errors (and, wherever the winch length
places the drone, the length's offset and scale error) as parameters too, which are also the
filter's calibration states (``state.CALIBRATION``): their prior enters here, correlated with
the position it moved, not again at the sensor's first reading. The motion fit places the
drone at each reading from the angle instead of from that tick's force
(:mod:`~tether_companion.estimation.dynamic.start_angle`). Only where the force cannot tell
the bearing (:meth:`Initialiser._pull_weak`). A heavy cable there (slack12) is placed on the
azimuth's bearing by its elevation, the winch length and the height (the free catenary they
fix, :func:`~tether_companion.estimation.dynamic.start_placement.heavy_by_elevation`), or,
where it leaves the anchor flat and may rest on the ground, by the force's pull along that
bearing; each tick of the motion fit by the reading nearest in time. On the light cable at
the winch's 1 N the force alone started the figure-8 up to 7 m off (tuning seeds).

The start's position and velocity are the window's motion at its end: a quadratic fit of
the positions each tick's force places (:func:`~.start_motion.fitted_motion`), or of the
cable angle's readings (:meth:`~.start_angle.AngleReadings.motion`).

Not possible yet (reported, and the window starts again): no height and no winch length,
thrust far below the weight (on the ground), cable slack, a cable that does not rise to the
drone, or one resting on the ground when only a height is known, as a heavy cable is while
a cable angle of the window reads it flat (:meth:`~.start_angle.AngleReadings.all_lifted`;
its pull on the free curve places the drone at the touchdown kink:
docs/estimation-history.md, angle21).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.config import DynamicFilterConfig, DynamicInitial
from tether_companion.estimation.dynamic.start_angle import AngleReadings
from tether_companion.estimation.dynamic.start_covariance import (
    T_ACCEL,
    T_AZIMUTH,
    T_BIAS,
    T_ELEVATION,
    T_HEIGHT,
    T_LENGTH,
    T_SCALE,
    T_WINCH_TENSION,
    T_WIND,
    THETA_SIZE,
    start_state,
    window_parameter_std,
)
from tether_companion.estimation.dynamic.start_motion import ForceSnapshot, fitted_motion
from tether_companion.estimation.dynamic.start_placement import place

FloatArray = NDArray[np.float64]

PLACEMENT_FAILED = (
    "the cable does not rise to the drone, or rests on the ground with no winch length:"
    " no position fix"
)
"""Why the window gave no state when the pull does not place the drone."""
NO_COVARIANCE = (
    "initial covariance not finite (degenerate): the pull does not place the drone nearby"
)
"""Why the window gave no state when a nearby pull would not place the drone."""
RESTING = "a cable angle reads the heavy cable flat (resting on the ground), no winch length"
"""Why the window gave no state on a heavy cable that may rest on the ground."""


@dataclass(frozen=True, slots=True)
class Hypothesis:
    """One bank member's start: state (n,), covariance (n, n), log prior weight, and
    whether it is a bearing hypothesis (a wind other than the prior's mean)."""

    x: FloatArray
    p: FloatArray
    log_prior: float
    bearing_rival: bool


@dataclass(frozen=True, slots=True)
class Initialisation:
    """A starting state and covariance, or why there is none yet (``x`` is None)."""

    x: FloatArray | None
    p: FloatArray | None
    reason: str


class Initialiser:
    """Accumulates the first window of aligned ticks and heights; :meth:`try_start` solves.

    Parameters
    ----------
    config
        The dynamic filter's settings (priors, window, slack and thrust thresholds).
    mass_kg
        Vehicle mass [kg].
    drag_per_s
        Rotor drag coefficient ``mu`` [1/s].
    accel_std_mps2
        Accelerometer noise per axis per tick [m/s^2].
    range_std_m
        Rangefinder noise per reading [m].
    """

    def __init__(
        self,
        config: DynamicFilterConfig,
        mass_kg: float,
        drag_per_s: float,
        accel_std_mps2: float,
        range_std_m: float,
    ) -> None:
        self.config = config
        self.mass_kg = mass_kg
        self.drag_per_s = drag_per_s
        self.accel_std_mps2 = accel_std_mps2
        self.range_std_m = range_std_m
        self.reason = self.reason_not_full
        self._restart(math.nan)

    def _restart(self, time_s: float) -> None:
        self._start_s = time_s
        self._n = 0
        self._sum_a = np.zeros(3)
        self._sum_r = np.zeros((3, 3))
        self._sum_e = np.zeros(3)
        self._sum_d = np.zeros((3, 3))
        self._sum_thrust = 0.0
        self._n_height = 0
        self._sum_height = 0.0
        self._latest_height = math.nan
        self._snapshots: list[ForceSnapshot] = []
        self._snapshot_readings: list[int] = []
        """Each snapshot's height reading (its count in the window)."""
        self._angles = AngleReadings()
        self._winch_tensions: list[float] = []

    def add_tick(
        self,
        time_s: float,
        specific_force_body: FloatArray,
        rotation_ned_to_body: FloatArray,
        thrust_n: float,
    ) -> None:
        """One aligned IMU tick (specific force [m/s^2] FRD, ``R_v^b``, thrust [N])."""
        if math.isnan(self._start_s):
            self._start_s = time_s
        rt = rotation_ned_to_body.T
        self._n += 1
        self._sum_a += rt @ specific_force_body
        self._sum_r += rt
        self._sum_e += rt[:, 2] * (thrust_n / self.mass_kg)
        horizontal = rt[:, :2] @ rotation_ned_to_body[:2, :]
        self._sum_d += horizontal
        self._sum_thrust += thrust_n
        if not math.isnan(self._latest_height):  # for the motion fit: (t, m R^T f, R^T e_z T, h)
            self._snapshots.append(
                (
                    time_s,
                    self.mass_kg * (rt @ specific_force_body),
                    rt[:, 2] * thrust_n,
                    self._latest_height,
                )
            )
            self._snapshot_readings.append(self._n_height)

    def add_height(self, height_above_anchor_m: float) -> None:
        """One rangefinder height above the anchor [m] (tilt-corrected, anchor height off)."""
        self._n_height += 1
        self._sum_height += height_above_anchor_m
        self._latest_height = height_above_anchor_m

    def add_angle(
        self,
        time_s: float,
        elevation_rad: float,
        azimuth_rad: float,
        noise_std_rad: float,
        calibration_std_rad: tuple[float, float],
        length_m: float = math.nan,
    ) -> None:
        """A ground-station cable angle taken at ``time_s`` [s] (its stamp less the sensor's
        latency): elevation up from horizontal and azimuth from north at the anchor [rad],
        the sensor's direction noise [rad] and its calibration errors (elevation, azimuth)
        [rad] (as :meth:`.DynamicTetherEstimator.on_cable_angle` is told), with the winch's
        latest paid-out length [m] (``nan``: none). Readings taken before the window
        started are not kept."""
        if math.isnan(self._start_s) or time_s < self._start_s:
            return
        self._angles.add(
            time_s,
            elevation_rad,
            azimuth_rad,
            noise_std_rad,
            calibration_std_rad,
            self._latest_height,
            length_m,
        )

    def add_winch_tension(self, time_s: float, tension_n: float) -> None:
        """The winch's tension [N] where the cable leaves it, taken at ``time_s`` [s]: with a
        cable angle it places a heavy cable that leaves the anchor flat
        (:func:`~.start_placement.place_heavy_by_angle`). Readings taken before the window
        started are not kept."""
        if not (math.isnan(self._start_s) or time_s < self._start_s):
            self._winch_tensions.append(tension_n)

    def try_start(
        self,
        time_s: float,
        length_m: float = math.nan,
        thrust_scale: float | None = None,
        thrust_scale_std: float | None = None,
    ) -> Initialisation:
        """The starting state once the window is full, else why not (``x`` None); a failed
        attempt starts the window again (see :meth:`solve`)."""
        start = self.solve(time_s, length_m, thrust_scale, thrust_scale_std)
        if start.x is None and self.window_full(time_s):
            self.restart(time_s, start.reason)
        return start

    reason_not_full = "waiting for the first second of data"

    def window_full(self, time_s: float) -> bool:
        """Whether the window holds ``initial.window_s`` of ticks at ``time_s`` [s]."""
        return self._n > 0 and time_s - self._start_s >= self.config.initial.window_s

    def solve(
        self,
        time_s: float,
        length_m: float = math.nan,
        thrust_scale: float | None = None,
        thrust_scale_std: float | None = None,
        wind_ne_mps: tuple[float, float] = (0.0, 0.0),
    ) -> Initialisation:
        """The starting state from the window, or why not (``x`` None); no side effect.

        Parameters
        ----------
        time_s
            Now [s] (the state is for this time).
        length_m
            The winch's paid-out length [m] when known (``nan`` otherwise).
        thrust_scale, thrust_scale_std
            Prior mean and standard deviation of the thrust scale (default: the config's).
        wind_ne_mps
            Prior mean of the wind, north and east [m/s] (its standard deviation is the
            config's): the window's force less that wind's drag is the cable's pull.
        """
        cfg = self.config
        scale = cfg.initial.thrust_scale if thrust_scale is None else thrust_scale
        scale_std = cfg.initial.thrust_scale_std if thrust_scale_std is None else thrust_scale_std
        if not self.window_full(time_s):
            return Initialisation(None, None, self.reason)
        n = self._n
        weight_n = self.mass_kg * GRAVITY_MPS2
        mean_thrust = self._sum_thrust / n
        height = self._sum_height / self._n_height if self._n_height else math.nan
        if mean_thrust < cfg.min_thrust_fraction * weight_n:
            return Initialisation(
                None,
                None,
                f"thrust {mean_thrust:.1f} N below {cfg.min_thrust_fraction:.0%} of the "
                f"weight: on the ground",
            )
        if math.isnan(height) and math.isnan(length_m):
            return Initialisation(None, None, "no rangefinder height and no winch length yet")
        if (  # a heavy cable's pull on the free curve: only where the cable hangs free
            cfg.cable_weight_n_per_m > 0.0
            and math.isnan(length_m)
            and len(self._angles)
            and not self._angles.all_lifted()
        ):
            return Initialisation(None, None, RESTING)
        theta = np.zeros(THETA_SIZE)
        theta[T_ACCEL] = self._sum_a / n
        theta[T_SCALE] = scale
        theta[T_WIND] = wind_ne_mps
        theta[T_HEIGHT] = height
        theta[T_LENGTH] = length_m
        theta[T_ELEVATION] = theta[T_AZIMUTH] = theta[T_WINCH_TENSION] = math.nan
        if self._pull_weak(theta):  # the force would not tell the bearing
            theta[T_ELEVATION], theta[T_AZIMUTH] = self._angles.mean()
            if self._winch_tensions:
                # readings near zero scatter below it (ground_station.tension_ok); a tension
                # does not
                theta[T_WINCH_TENSION] = max(
                    0.0, sum(self._winch_tensions) / len(self._winch_tensions)
                )
        y = self._solve(theta)
        if y is None or not np.all(np.isfinite(y)):
            return Initialisation(None, None, PLACEMENT_FAILED)
        if y[3] < cfg.slack_tension_n:
            return Initialisation(
                None, None, f"cable slack (chord tension {y[3]:.2f} N < {cfg.slack_tension_n} N)"
            )
        sigma, calibration_std = window_parameter_std(
            theta,
            cfg,
            scale_std,
            self.accel_std_mps2,
            n,
            self.range_std_m,
            self._n_height,
            len(self._winch_tensions),
            self._angles,
        )
        x, p = start_state(theta, y, sigma, calibration_std, self._solve, cfg.initial)
        if x is None or p is None:
            return Initialisation(None, None, NO_COVARIANCE)
        motion = None
        weightless = cfg.cable_weight_n_per_m == 0.0
        if (
            math.isfinite(theta[T_ELEVATION]) and weightless
        ):  # a weightless cable placed by the readings
            motion = self._angles.motion(time_s, self.range_std_m, cfg.winch_length_noise_std_m)
            if motion is not None:  # the end point as uncertain as the fit says, at least
                position_var = np.diag(p)[state.POSITION]
                p[state.POSITION, state.POSITION] += np.diag(
                    np.maximum(motion[3] ** 2 - position_var, 0.0)
                )
        if motion is None:
            by_azimuth = math.isfinite(theta[T_AZIMUTH]) and not weightless
            wind = theta[T_WIND]
            motion = fitted_motion(
                time_s,
                self._snapshots,
                self._snapshot_readings,
                scale,
                length_m,
                wind,
                self._wind_drag_n(wind),
                cfg.cable_weight_n_per_m,
                self._angles,
                by_azimuth,
                float(theta[T_WINCH_TENSION]),
            )
        if motion is not None:  # the window's motion: position now and velocity
            position, velocity, velocity_se, _ = motion
            x[state.POSITION] = position
            x[state.VELOCITY] = velocity
            p[state.VELOCITY, state.VELOCITY] = np.diag(
                np.maximum(velocity_se**2, cfg.initial.velocity_std_mps**2 * 0.25)
            )
        self.reason = ""
        return Initialisation(x, p, "")

    def hypotheses(
        self, time_s: float, initial: DynamicInitial, length_m: float
    ) -> list[Hypothesis]:
        """Starting states of the bank's members: the thrust-scale hypotheses, spaced over
        3 standard deviations of the thrust scale's prior, each with half the spacing as its
        own standard deviation (one member: the prior itself); then, when the rotor drag
        makes the wind's drag turn the cable's pull (``mu > 0``) and a winch length fixes the
        range, the bearing hypotheses: at the prior thrust scale, the window's force less the
        drag of ``initial.wind_hypotheses`` winds on a ring of
        ``initial.wind_hypothesis_radius_std`` standard deviations of the wind's prior (each
        with the prior density there as its weight, ``-r^2 / 2``). Empty while the window
        is not full or when no thrust-scale hypothesis places the drone (the reason kept, the
        window restarted).
        ``length_m``: the paid-out cable length [m] (nan: unknown)."""
        if not self.window_full(time_s):
            return []
        n = initial.thrust_scale_hypotheses
        if n == 1:
            scales, member_std = [initial.thrust_scale], initial.thrust_scale_std
        else:
            spacing = 3.0 * initial.thrust_scale_std / (n - 1)
            scales = [initial.thrust_scale + (i - (n - 1) / 2) * spacing for i in range(n)]
            member_std = 0.5 * spacing
        results = [self.solve(time_s, length_m, s, member_std) for s in scales]
        starts = [
            Hypothesis(r.x, r.p, 0.0, False) for r in results if r.x is not None and r.p is not None
        ]
        if not starts:
            self.restart(time_s, results[len(results) // 2].reason)
            return starts
        # without a length the range is as unknown as the bearing: ring members left
        # undecided by the bank's collapse only widen it (realistic 4 N circle, IMU only,
        # seeds 1-5: published 14.6 -> 7.6 %)
        known_range = math.isfinite(length_m)
        rivals = initial.wind_hypotheses if self.drag_per_s > 0.0 and known_range else 0
        radius = initial.wind_hypothesis_radius_std
        speed = radius * initial.wind_std_mps
        for k in range(rivals):
            angle = 2.0 * math.pi * k / rivals
            wind = (speed * math.cos(angle), speed * math.sin(angle))
            r = self.solve(time_s, length_m, wind_ne_mps=wind)
            if r.x is not None and r.p is not None:
                starts.append(Hypothesis(r.x, r.p, -0.5 * radius * radius, True))
        return starts

    def restart(self, time_s: float, reason: str) -> None:
        """Start the window again from ``time_s`` [s], remembering why."""
        self._restart(time_s)
        self.reason = reason

    # ------------------------------------------------------------------ internals
    def _solve(self, theta: FloatArray) -> FloatArray | None:
        """``(p_n, p_e, p_d, T_ch)`` from the parameters, or None (no rising cable)."""
        return place(
            self._window_force_n(theta),
            theta[T_HEIGHT],
            theta[T_LENGTH],
            self.config.cable_weight_n_per_m,
            theta[T_ELEVATION],
            theta[T_AZIMUTH],
            theta[T_WINCH_TENSION],
        )

    def _window_force_n(self, theta: FloatArray) -> FloatArray:
        """The cable's force on the drone over the window (NED [N]) for the parameters
        ``theta``: the module docstring's ``c`` times the mass."""
        n = self._n
        c = (
            theta[T_ACCEL]
            - (self._sum_r / n) @ theta[T_BIAS]
            + theta[T_SCALE] * (self._sum_e / n)
            - self.drag_per_s * ((self._sum_d / n)[:, :2] @ theta[T_WIND])
        )
        return self.mass_kg * c

    def _pull_weak(self, theta: FloatArray) -> bool:
        """Whether the window's horizontal force (less the drag of the prior's wind) is below
        the pull rule's least pull, ``min_pull_over_wind_drag`` times the drag of a wind of
        the prior's standard deviation: there the wind's drag could turn the bearing the
        force gives, and a cable angle places the start instead. Above it the force places
        it as without an angle (measured: the angle's start on the realistic gusty hover,
        4 N at 4 m, published 91 -> 60 % of the ticks, held-out seeds 31-35)."""
        cfg = self.config
        force = self._window_force_n(theta)
        pull = math.hypot(float(force[0]), float(force[1]))
        least = (
            cfg.min_pull_over_wind_drag * self.mass_kg * self.drag_per_s * cfg.initial.wind_std_mps
        )
        return len(self._angles) > 0 and pull < least

    def _wind_drag_n(self, wind_ne_mps: FloatArray) -> FloatArray:
        """The rotor drag's force (NED [N]) of the wind ``wind_ne_mps`` (north, east [m/s])
        at the window's mean attitude."""
        return -self.mass_kg * self.drag_per_s * ((self._sum_d / self._n)[:, :2] @ wind_ne_mps)
