"""Posterior Cramer-Rao bound of the dynamic filter's own 13-state model along a true flight.

Tichavsky, Muravchik & Nehorai (1998): for ``x_{k+1} = f_k(x_k) + w_k``, ``w_k ~ N(0, Q_k)``,
and measurements ``z = h(x) + v``, ``v ~ N(0, R)``, the Fisher information of the state obeys

    J_{k+1} = D22 - D21 (J_k + D11)^-1 D12,
    D11 = F^T Q^-1 F,  D12 = D21^T = -F^T Q^-1,  D22 = Q^-1 + sum H^T R^-1 H,

with ``F``, ``H`` the Jacobians at the true state (the "along the true trajectory" bound: the
expectations replaced by one flight's values). With the noise additive and Gaussian the matrix
inversion lemma turns ``Q^-1 - Q^-1 F (J_k + F^T Q^-1 F)^-1 F^T Q^-1`` into
``(F J_k^-1 F^T + Q)^-1``, so

    J_{k+1} = (F J_k^-1 F^T + Q)^-1 + sum H^T R^-1 H,

the information form of the EKF's covariance recursion evaluated at the truth. That form is what
:func:`information_step` computes: it needs no ``Q^-1`` (the thrust scale's and the bias's
``Q`` per step are 1e-7..1e-6, whose inverses the ``D`` form would subtract from each other).

The model is the filter's (``state.py``; inertial formulation): ``p' = v``,
``v' = R^T (f_meas - b) + g``, tension, thrust scale, bias and wind random walks; the
force balance ``f_meas = f(x, u) + b`` fused once every ``imu_ticks_per_fusion`` IMU ticks, the
rangefinder's height, and, by measurement set, the winch's paid-out length and the
ground-station cable angle, every Jacobian from the filter's own generated code
(``generated.py`` through :class:`~tether_companion.estimation.dynamic.models.CableModels`, the
straight, catenary or grounded variant the true state calls for). Units SI, NED from the
anchor, FRD body. The noise is mapped from the simulated error sources in :mod:`.crlb_noise`.

Nuisance states (:mod:`.crlb_nuisance`): the ground station's calibration errors
(:class:`CalibrationPrior`), and since crlb14 (:class:`HeadingError`, :class:`TerrainNoise`)
errors of the simulated flight the filter's model has no state for, whose leaving out made the
bound claim more than the data can tell: the flight controller's heading error, a
first-order Gauss-Markov angle added to the yaw the filter is given (the force balance's and
the INS's horizontal directions turn with it, so it limits what the flight tells of the cable
angle's azimuth zero); and the ground's undulation under the rangefinder, correlated over
``correlation_m`` along the drone's path (a first-order Gauss-Markov process in the distance
flown: constant under a hovering drone, where taken as white it was averaged away).

Timing: the prediction steps every IMU tick; the information of every sample (rangefinder at
20 Hz, winch every tick and the cable angle at its reports while the true chord tension is
positive, force balance at the fusion ticks) is added at the
next fusion tick (at most ``imu_ticks_per_fusion - 1`` ticks, 15 ms, late), each with its
Jacobian at its own tick's truth.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import generated, state
from tether_companion.estimation.dynamic.crlb_nuisance import (
    AZIMUTH_BIAS,
    ELEVATION_BIAS,
    OFFSET,
    SCALE,
    CalibrationPrior,
    HeadingError,
    TerrainNoise,
    gauss_markov_step,
    yaw_column_of_model,
    yaw_column_of_specific_force,
)
from tether_companion.estimation.dynamic.models import UNDEFINED, Generated, ModelConstants
from tether_companion.frames import rotation_ned_to_body_rows

FloatArray = NDArray[np.float64]

_N = state.CALIBRATION.start
"""The bound's state: the filter's without the ground station's calibration, which
:class:`CalibrationPrior` adds when the flight has it (the generated Jacobians' calibration
columns are left out; :func:`_add` writes them at the augmented state's columns)."""
_CALIBRATION_AT_TRUTH = (0.0,) * (state.N_STATES - _N)
"""The calibration states at which the generated models are evaluated (no Jacobian depends
on their values but the scale's ``1 + scale`` factor, taken as 1)."""
_NO_CONSTANTS = (0.0, 0.0, 0.0)
_ANCHOR_LEVEL = (0.0,)
"""The height model's input (the anchor's height: its Jacobian does not depend on it)."""


@dataclass(frozen=True)
class TrueTrack:
    """A flight's truth at its IMU ticks (SI, NED from the anchor).

    Attributes
    ----------
    time_s
        Tick times, shape (N,) [s].
    position_ned_m, velocity_ned_mps, euler_rad
        Shapes (N, 3) [m], [m/s], (roll, pitch, yaw) [rad].
    thrust_n
        Total rotor thrust, shape (N,) [N].
    cable_force_ned_n
        The cable's force on the drone, shape (N, 3) [N].
    wind_ned_mps
        Wind at the drone, shape (N, 3) [m/s].
    range_seen
        A rangefinder sample since the previous tick, shape (N,).
    specific_force_body_mps2
        The accelerometer's true specific force without noise or bias, FRD, shape (N, 3)
        [m/s^2].
    angle_seen
        A ground-station cable-angle report at the tick, shape (N,); ``None``: none in the
        flight.
    winch_seen
        A winch length report at the tick, shape (N,); ``None``: one every tick.
    """

    time_s: FloatArray
    position_ned_m: FloatArray
    velocity_ned_mps: FloatArray
    euler_rad: FloatArray
    thrust_n: FloatArray
    cable_force_ned_n: FloatArray
    wind_ned_mps: FloatArray
    range_seen: NDArray[np.bool_]
    specific_force_body_mps2: FloatArray
    angle_seen: NDArray[np.bool_] | None = None
    winch_seen: NDArray[np.bool_] | None = None

    def state_at(self, k: int) -> list[float]:
        """The model's state at tick ``k``: position, velocity, chord tension
        ``|F_ne| |p| / |p_ne|`` (the cable's horizontal pull is ``T_ch p_ne / |p|`` in every
        cable variant; ``|F|`` right above the anchor), thrust scale 1 (the true thrust is the
        input), bias 0 (the Jacobians do not depend on it), the horizontal wind."""
        p = self.position_ned_m[k]
        force = self.cable_force_ned_n[k]
        span = math.hypot(p[0], p[1])
        distance = math.sqrt(span * span + p[2] * p[2])
        pull = math.hypot(force[0], force[1])
        tension = pull * distance / span if span > 1e-6 else math.sqrt(float(force @ force))
        wind = self.wind_ned_mps[k]
        v = self.velocity_ned_mps[k]
        return [
            *map(float, p),
            *map(float, v),
            tension,
            1.0,
            0.0,
            0.0,
            0.0,
            *map(float, wind[:2]),
            *_CALIBRATION_AT_TRUTH,
        ]


@dataclass(frozen=True)
class BoundNoise:
    """What the bound assumes about the noise (SI units).

    Attributes
    ----------
    process_density
        Diagonal of the process noise spectral density, shape (13,) [state units^2 / s].
    prior_std
        Standard deviation of the prior at the flight's start, shape (13,) [state units].
    force_balance_var_mps2
        Variance of one fused force-balance sample, body x, y, z [(m/s^2)^2].
    range_var_m2
        Variance of one tilt-corrected height [m^2] (the sensor's white noise; with
        ``terrain`` the ground's undulation is that state, else it is counted here as white).
    winch_var_m2
        Variance of one paid-out length [m^2]; ``None``: not measured.
    cable_angle_var_rad2
        Variance of the cable direction's turn per axis in one angle report [rad^2]: the
        elevation's, the azimuth's over ``cos^2(elevation)``; ``None``: not measured.
    calibration
        The ground station's calibration errors estimated beside the state; ``None``: the
        winch and the angle sensor have none.
    heading
        The flight controller's heading error, estimated beside the state; ``None``: none.
    terrain
        The ground's undulation under the rangefinder as a state of the height; ``None``:
        none (or counted as white in ``range_var_m2``).
    """

    process_density: FloatArray
    prior_std: FloatArray
    force_balance_var_mps2: tuple[float, float, float]
    range_var_m2: float
    winch_var_m2: float | None = None
    cable_angle_var_rad2: float | None = None
    calibration: CalibrationPrior | None = None
    heading: HeadingError | None = None
    terrain: TerrainNoise | None = None


@dataclass(frozen=True)
class Gating:
    """When the force balance is fused (the filter's rules, applied to the truth). The winch
    length and the cable angle count wherever the true chord tension is positive: the filter
    skips them below its ``slack_tension_n`` by its own tension estimate, which may be above the
    truth's (the sagging hovers' cables rest on the ground at 0.13 N of chord tension), and a
    bound must not leave out samples the filter may use.

    Attributes
    ----------
    ticks_per_fusion
        IMU ticks per prediction batch and force-balance sample.
    min_distance_m
        No force balance closer to the anchor [m].
    min_thrust_n
        No force balance below this thrust (on the ground) [N].
    """

    ticks_per_fusion: int
    min_distance_m: float
    min_thrust_n: float


def information_step(
    covariance: FloatArray,
    transition: FloatArray,
    process_noise: FloatArray,
    measurement_information: FloatArray | None,
) -> FloatArray:
    """One step of the posterior-CRLB recursion in covariance form: ``J_k^-1`` (n, n) to
    ``J_{k+1}^-1`` with ``J_{k+1} = (F J_k^-1 F^T + Q)^-1 + M``, ``M = sum H^T R^-1 H`` of the
    samples at ``k+1`` (``None``: no sample, the prediction alone)."""
    predicted = transition @ covariance @ transition.T + process_noise
    if measurement_information is None:
        return 0.5 * (predicted + predicted.T)
    information = np.linalg.inv(predicted) + measurement_information
    bound = np.linalg.inv(information)
    return 0.5 * (bound + bound.T)


@dataclass(frozen=True)
class ForceBalanceAtTruth:
    """The force-balance samples the filter would fuse, evaluated at the truth.

    Attributes
    ----------
    ticks
        Tick indices of the samples, shape (M,).
    jacobians
        ``H`` of the generated ``accel_*`` model, shape (M, 3, 13).
    residuals_mps2
        True specific force minus the model's value at the true state, FRD body, shape (M, 3)
        [m/s^2]: what the model leaves out (quadratic body drag, vertical gusts, the cable's
        drag, rotor-drag model error), without the sensor's noise.
    yaw_columns
        ``d h / d yaw`` of each sample (:func:`yaw_column_of_model`), shape (M, 3)
        [m/s^2/rad]: the heading error's column.
    """

    ticks: NDArray[np.int64]
    jacobians: FloatArray
    residuals_mps2: FloatArray
    yaw_columns: FloatArray


def force_balance_at_truth(
    track: TrueTrack, constants: ModelConstants, gating: Gating
) -> ForceBalanceAtTruth:
    """The force balance at every ``gating.ticks_per_fusion``-th tick, skipped as the filter
    skips it (thrust below ``min_thrust_n``: on the ground; closer than ``min_distance_m`` to
    the anchor) and where the model is undefined."""
    model = constants.models.accel
    c = constants.values()
    ticks, jacobians, residuals, yaw_columns = [], [], [], []
    step = gating.ticks_per_fusion
    for k in range(step - 1, len(track.time_s), step):
        x = track.state_at(k)
        thrust_n = float(track.thrust_n[k])
        if thrust_n < gating.min_thrust_n or math.dist(x[0:3], (0, 0, 0)) < gating.min_distance_m:
            continue
        rows = rotation_ned_to_body_rows(*track.euler_rad[k])
        try:
            value, jac = model(x, (*rows[0], *rows[1], *rows[2], thrust_n), c)
        except UNDEFINED:
            continue
        if not (math.isfinite(sum(jac)) and math.isfinite(sum(value))):
            continue
        ticks.append(k)
        jacobian = np.reshape(np.array(jac, dtype=float), (3, state.N_STATES))
        jacobians.append(jacobian[:, :_N])
        yaw_columns.append(yaw_column_of_model(jacobian, x))
        residuals.append(track.specific_force_body_mps2[k] - np.array(value))
    return ForceBalanceAtTruth(
        np.array(ticks, dtype=np.int64),
        np.reshape(np.array(jacobians, dtype=float), (len(ticks), 3, _N)),
        np.reshape(np.array(residuals, dtype=float), (len(ticks), 3)),
        np.reshape(np.array(yaw_columns, dtype=float), (len(ticks), 3)),
    )


def posterior_bound(
    track: TrueTrack,
    constants: ModelConstants,
    noise: BoundNoise,
    gating: Gating,
    force_balance: ForceBalanceAtTruth | None = None,
    *,
    held: Mapping[int, int | None] | None = None,
    start_tick: int = 0,
) -> FloatArray:
    """Diagonal of the bound ``J_k^-1`` at every tick, shape (N, 13), in the state's units
    squared (position [m^2] first). The prior ``diag(prior_std^2)`` holds before
    ``start_tick`` (the rows before it are ``nan``). ``force_balance``: the samples of
    :func:`force_balance_at_truth` when already made. With ``noise.calibration`` the recursion
    runs on the state and the four calibration errors (constants: identity transition, no
    process noise), with ``noise.heading`` and ``noise.terrain`` on their Gauss-Markov states
    too, and returns the state's part.

    ``held``: calibration errors (:data:`OFFSET`...) an estimator holds as consider (Schmidt)
    states, each to the tick from which it learns them (``None``: never): then this is not a
    bound but the covariance of the best estimator that does not correct them meanwhile (the
    optimal gain with their rows zeroed, :func:`consider_step`), what not learning them costs
    (the dynamic filter holds the azimuth zero for the whole flight, the others until it has
    settled: ``calibration_release.py``)."""
    if force_balance is None:
        force_balance = force_balance_at_truth(track, constants, gating)
    calibration = noise.calibration
    prior_std = noise.prior_std
    density = noise.process_density
    column: dict[int, int] = {}
    """Calibration error (:data:`OFFSET`...) -> its column in the augmented state."""
    if calibration is not None:
        stds = calibration.std()
        unknown = [i for i in range(len(stds)) if stds[i] > 0.0]
        column = {error: _N + j for j, error in enumerate(unknown)}
        prior_std = np.concatenate([prior_std, stds[unknown]])
        density = np.concatenate([density, np.zeros(len(unknown))])
    heading, terrain = noise.heading, noise.terrain
    heading_column = terrain_column = None
    if heading is not None and heading.std_rad > 0.0:
        heading_column = len(prior_std)
        prior_std = np.append(prior_std, heading.std_rad)
        density = np.append(density, 0.0)
    if terrain is not None and terrain.std_m > 0.0:
        terrain_column = len(prior_std)
        prior_std = np.append(prior_std, terrain.std_m)
        density = np.append(density, 0.0)
    held_until = [
        (column[error], until) for error, until in (held or {}).items() if error in column
    ]
    winch_columns = ((column.get(OFFSET), column.get(SCALE)),)
    angle_columns = ((column.get(ELEVATION_BIAS),), (column.get(AZIMUTH_BIAS),))
    height_columns = ((terrain_column,),)
    n = len(prior_std)
    accel_weight = 1.0 / np.asarray(noise.force_balance_var_mps2, dtype=float)
    accel_rows = {}
    for k, jac, yaw in zip(
        force_balance.ticks, force_balance.jacobians, force_balance.yaw_columns, strict=True
    ):
        h = np.zeros((3, n))
        h[:, :_N] = jac
        if heading_column is not None:
            h[:, heading_column] = yaw
        accel_rows[int(k)] = (h, accel_weight)
    n_ticks = len(track.time_s)
    out = np.full((n_ticks, _N), np.nan)
    covariance = np.diag(prior_std**2)
    models = constants.models
    c = constants.values()
    transition = np.eye(n)
    gathered: list[tuple[FloatArray, FloatArray]] = []
    previous_s = track.time_s[start_tick] if n_ticks else 0.0
    zero_force = (0.0, 0.0, 0.0)
    for k in range(start_tick, n_ticks):
        x = track.state_at(k)
        rows = rotation_ned_to_body_rows(*track.euler_rad[k])
        dt = float(track.time_s[k] - previous_s)
        previous_s = track.time_s[k]
        _, dv = generated.inertial(x, (*rows[0], *rows[1], *rows[2], *zero_force), c)
        transition[0:3, 3:6] = dt * np.eye(3)
        transition[3:6, :_N] = dt * np.reshape(dv, (3, state.N_STATES))[:, :_N]
        transition[3:6, 3:6] += np.eye(3)
        process = density * dt
        if heading_column is not None:
            assert heading is not None
            transition[3:6, heading_column] = dt * yaw_column_of_specific_force(
                track.euler_rad[k], track.specific_force_body_mps2[k]
            )
            gauss_markov_step(
                transition,
                process,
                heading_column,
                dt / heading.time_constant_s,
                heading.std_rad,
            )
        if terrain_column is not None:
            assert terrain is not None
            flown_m = dt * math.hypot(*track.velocity_ned_mps[k][:2])
            gauss_markov_step(
                transition,
                process,
                terrain_column,
                flown_m / terrain.correlation_m,
                terrain.std_m,
            )
        if k in accel_rows:
            gathered.append(accel_rows[k])
        if track.range_seen[k]:
            _add(
                gathered,
                n,
                generated.height_above_ground,
                x,
                _NO_CONSTANTS,
                1,
                noise.range_var_m2,
                height_columns,
                u=_ANCHOR_LEVEL,
            )
        taut = x[state.TENSION] > 0.0
        winch_seen = track.winch_seen is None or track.winch_seen[k]
        if noise.winch_var_m2 is not None and taut and winch_seen:
            _add(gathered, n, models.winch_length, x, c, 1, noise.winch_var_m2, winch_columns)
        angle_var = noise.cable_angle_var_rad2
        if angle_var is not None and taut and track.angle_seen is not None and track.angle_seen[k]:
            _add(gathered, n, models.cable_angle, x, c, 2, angle_var, angle_columns, per_cos=True)
        apply = (k + 1) % gating.ticks_per_fusion == 0 and len(gathered) > 0
        held_columns = [col for col, until in held_until if until is None or k < until]
        if not apply:
            covariance = information_step(covariance, transition, np.diag(process), None)
        elif held_columns:
            covariance = consider_step(
                covariance, transition, np.diag(process), gathered, held_columns
            )
        else:
            information = np.zeros((n, n))
            for h, weight in gathered:
                information += h.T @ (weight[:, None] * h)
            covariance = information_step(covariance, transition, np.diag(process), information)
        if apply:
            gathered = []
        out[k] = np.diag(covariance)[:_N]
    return out


def consider_step(
    covariance: FloatArray,
    transition: FloatArray,
    process_noise: FloatArray,
    samples: list[tuple[FloatArray, FloatArray]],
    held_columns: list[int],
) -> FloatArray:
    """One step of a Schmidt (consider) Kalman filter's covariance: the prediction, then the
    ``samples`` (``H`` (m, n), weights ``1 / variance`` (m,)) fused at once with the optimal
    gain whose ``held_columns`` rows are zeroed (those states are not corrected), in Joseph
    form ``(I - K H) P (I - K H)^T + K R K^T``. With nothing held it equals
    :func:`information_step`."""
    predicted = transition @ covariance @ transition.T + process_noise
    h = np.vstack([rows for rows, _ in samples])
    r = np.concatenate([1.0 / weight for _, weight in samples])
    innovation = h @ predicted @ h.T + np.diag(r)
    gain = np.linalg.solve(innovation, h @ predicted).T
    gain[held_columns, :] = 0.0
    joseph = np.eye(len(predicted)) - gain @ h
    updated = joseph @ predicted @ joseph.T + (gain * r) @ gain.T
    return 0.5 * (updated + updated.T)


def _add(
    gathered: list[tuple[FloatArray, FloatArray]],
    width: int,
    model: Generated,
    x: list[float],
    c: tuple[float, float, float],
    rows: int,
    variance: float,
    calibration_columns: tuple[tuple[int | None, ...], ...] = (),
    u: tuple[float, ...] = (),
    *,
    per_cos: bool = False,
) -> None:
    """Append ``(H, 1 / variance per row)`` of the generated ``model`` at ``x`` to
    ``gathered`` (``per_cos``, the cable angle: the second row's, the azimuth's, variance over
    the cosine squared of the first, the elevation); nothing where the model is undefined there
    (at the anchor, zero tension). ``calibration_columns``: per row, the augmented state's
    columns of the nuisance parameters in the reading, ``None`` where it has none: an additive
    error (coefficient 1), then a scale error (coefficient the model's value); ``H`` is
    ``width`` wide."""
    try:
        value, jac = model(x, u, c)
    except UNDEFINED:
        return
    jacobian = np.zeros((rows, width))
    jacobian[:, :_N] = np.reshape(jac, (rows, state.N_STATES))[:, :_N]
    if not np.isfinite(jacobian).all():
        return
    for row, columns in enumerate(calibration_columns):
        for column, coefficient in zip(columns, (1.0, value[row]), strict=False):
            if column is not None:
                jacobian[row, column] = coefficient
    weight = np.full(rows, 1.0 / variance)
    if per_cos:
        weight[1] *= math.cos(value[0]) ** 2
    gathered.append((jacobian, weight))
