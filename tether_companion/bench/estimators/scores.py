"""Scores of one flight and their pooling over seeds: RMSE, NEES, chi-square band, CRLB.

Everything is computed over the *scored window*: IMU ticks at or after ``settle_s``, where the
kind has an estimate (a finite position). Definitions:

* horizontal / vertical RMSE: ``sqrt(mean(e_n^2 + e_e^2))``, ``sqrt(mean(e_d^2))``;
* max error: largest 3-D error norm;
* NEES (3 dof): ``e^T P^{-1} e`` with the kind's position covariance ``P``;
* 95 % band (Bar-Shalom, Li & Kirubarajan 2001, sec. 5.4): with ``M`` seeds, the seed-averaged
  NEES of a consistent filter times ``M`` is chi-square with ``3 M`` dof, so it lies in
  ``[chi2(0.025, 3M) / M, chi2(0.975, 3M) / M]`` 95 % of the time; we report the share of
  ticks where it does (0.95 for a consistent filter);
* time to converge: the first time after which the 3-D error stays below ``converged_m``
  until the end of the flight (``inf`` when it ends above);
* share published: ticks the service would send / ticks in the window;
* published after taut: from the first tick with the drone off the ground and the cable's
  true tension above ``TAUT_TENSION_N`` to the first published tick at or after it, over the
  whole flight (not only the window: the issue asks for a position within 5 s of the cable
  becoming taut); ``inf`` when nothing is published after it, ``nan`` when it never is taut;
* beyond 3 sigma: share of the estimated ticks with some axis's error beyond 3 standard
  deviations of the kind's own covariance (``|e_i| > 3 sqrt(P_ii)``; a consistent Gaussian
  3-D error does so 0.8 % of the time), and the same share of the published ticks (what the
  autopilot is told);
* CRLB: ``sqrt(mean(bound variance))`` over the same ticks (see ``estimation/crlb.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from tether_companion.bench.estimators.flight import FlightRecord, KindTrace

FloatArray = NDArray[np.float64]

POSITION_DOF = 3
BAND_PROBABILITY = 0.95
TAUT_TENSION_N = 0.2
"""True tension above which an airborne drone's cable counts as taut [N] (the dynamic
filter's default ``slack_tension_n``)."""
SERIES_RATE_HZ = 10.0
"""Rate of the time series kept for plots [Hz]."""


def nees(error: FloatArray, covariance: FloatArray) -> FloatArray:
    """Normalised estimation error squared ``e^T P^{-1} e`` per row, shape (N,).

    ``error`` (N, d), ``covariance`` (N, d, d); ``nan`` where either is not finite or ``P`` is
    singular.
    """
    out = np.full(error.shape[0], math.nan)
    good = np.isfinite(error).all(axis=1) & np.isfinite(covariance).all(axis=(1, 2))
    if good.any():
        try:
            solved = np.linalg.solve(covariance[good], error[good][..., None])[..., 0]
            out[good] = np.einsum("ij,ij->i", error[good], solved)
        except np.linalg.LinAlgError:
            for i in np.flatnonzero(good):
                try:
                    out[i] = float(error[i] @ np.linalg.solve(covariance[i], error[i]))
                except np.linalg.LinAlgError:
                    out[i] = math.nan
    return out


def nees_band(runs: int | NDArray[np.int_], dof: int = POSITION_DOF) -> tuple:
    """Two-sided ``BAND_PROBABILITY`` band of the NEES averaged over ``runs`` runs."""
    runs = np.asarray(runs)
    tail = 0.5 * (1.0 - BAND_PROBABILITY)
    return chi2.ppf(tail, dof * runs) / runs, chi2.ppf(1.0 - tail, dof * runs) / runs


def share_in_band(nees_per_run: FloatArray, dof: int = POSITION_DOF) -> float:
    """Share of ticks where the run-averaged NEES lies in its 95 % band.

    ``nees_per_run`` (M, N): M runs of the same schedule; a tick's average is over the runs
    with a finite NEES there (its band uses that count). ``nan`` without any finite value.
    """
    values = np.atleast_2d(nees_per_run)
    finite = np.isfinite(values)
    count = finite.sum(axis=0)
    has = count > 0
    if not has.any():
        return math.nan
    mean = np.where(finite, values, 0.0).sum(axis=0)[has] / count[has]
    low, high = nees_band(count[has], dof)
    return float(np.mean((mean >= low) & (mean <= high)))


def published_after_taut_s(
    time_s: FloatArray,
    landed: NDArray[np.bool_],
    tension_n: FloatArray,
    published: NDArray[np.bool_],
) -> float:
    """Seconds from the first tick with the drone off the ground and the true tension above
    TAUT_TENSION_N to the first published tick at or after it; ``inf`` when none is
    published after it, ``nan`` when the cable is never taut."""
    taut = np.flatnonzero(~landed & (tension_n > TAUT_TENSION_N))
    if taut.size == 0:
        return math.nan
    start = taut[0]
    after = np.flatnonzero(published[start:])
    if after.size == 0:
        return math.inf
    return float(time_s[start + after[0]] - time_s[start])


def converge_time_s(time_s: FloatArray, error_norm_m: FloatArray, converged_m: float) -> float:
    """First time after which ``error_norm_m`` stays below ``converged_m`` (ticks with an
    estimate only); ``inf`` when the last one is not below, ``nan`` when there is none."""
    finite = np.isfinite(error_norm_m)
    if not finite.any():
        return math.nan
    t, e = time_s[finite], error_norm_m[finite]
    above = np.flatnonzero(e >= converged_m)
    if above.size == 0:
        return float(t[0])
    last = above[-1]
    return math.inf if last == e.size - 1 else float(t[last + 1])


@dataclass
class KindRunScore:
    """One kind's scores on one flight (sums, so that seeds pool exactly)."""

    ticks: int
    estimated: int
    published: int
    beyond_3_sigma: int
    """Estimated ticks with some axis beyond 3 sigma of the kind's covariance."""
    published_beyond_3_sigma: int
    """Published ticks with some axis beyond 3 sigma."""
    sq_horizontal_m2: float
    sq_vertical_m2: float
    max_error_m: float
    sq_tension_n2: float
    tension_count: int
    sq_velocity_m2ps2: float
    velocity_count: int
    converge_s: float
    published_after_taut_s: float
    """Seconds from the cable becoming taut to the first published tick (inf: never)."""
    crlb_horizontal_m2: float
    crlb_vertical_m2: float
    own_bound_horizontal_m2: float
    """Sum of the kind's own-model bound (horizontal variance) over the scored ticks [m^2];
    ``nan`` for a kind without one."""
    own_bound_vertical_m2: float
    nees: NDArray[np.float32]
    """Per tick of the window, nan where none."""
    series: dict[str, NDArray[np.float32]] = field(default_factory=dict)
    """Decimated time series for plots: time_s, horizontal/vertical error [m], 3-sigma [m],
    CRLB sigma [m]."""


def score_kind(
    record: FlightRecord,
    trace: KindTrace,
    crlb_diagonal: FloatArray,
    settle_s: float,
    converged_m: float,
    own_bound_diagonal: FloatArray | None = None,
) -> KindRunScore:
    """Score ``trace`` against ``record``'s truth over ticks at or after ``settle_s``;
    ``crlb_diagonal`` and ``own_bound_diagonal`` (the kind's own model's bound, optional) are
    bounds' diagonals per tick, position [m^2] first."""
    window = record.time_s >= settle_s
    error = trace.position_ned_m - record.position_ned_m
    error_norm = np.linalg.norm(error, axis=1)
    estimated = window & np.isfinite(error).all(axis=1)
    e = error[estimated]
    tension_error = (trace.tension_n - record.tension_n)[window]
    tension_error = tension_error[np.isfinite(tension_error)]
    velocity_error = (trace.velocity_ned_mps - record.velocity_ned_mps)[window]
    velocity_error = velocity_error[np.isfinite(velocity_error).all(axis=1)]
    nees_all = nees(error, trace.position_covariance_m2)
    crlb = crlb_diagonal[estimated]
    own = own_bound_diagonal[estimated] if own_bound_diagonal is not None else None
    step = max(1, int(round(1.0 / (SERIES_RATE_HZ * np.median(np.diff(record.time_s))))))
    var = np.diagonal(trace.position_covariance_m2, axis1=1, axis2=2)
    with np.errstate(invalid="ignore"):
        beyond = estimated & np.any(np.abs(error) > 3.0 * np.sqrt(var), axis=1)
    series = {
        "time_s": record.time_s,
        "horizontal_error_m": np.hypot(error[:, 0], error[:, 1]),
        "vertical_error_m": np.abs(error[:, 2]),
        "horizontal_3sigma_m": 3.0 * np.sqrt(var[:, 0] + var[:, 1]),
        "vertical_3sigma_m": 3.0 * np.sqrt(var[:, 2]),
        "crlb_horizontal_m": np.sqrt(crlb_diagonal[:, 0] + crlb_diagonal[:, 1]),
        "crlb_vertical_m": np.sqrt(crlb_diagonal[:, 2]),
    }
    return KindRunScore(
        ticks=int(window.sum()),
        estimated=int(estimated.sum()),
        published=int((trace.published & window).sum()),
        beyond_3_sigma=int(beyond.sum()),
        published_beyond_3_sigma=int((beyond & trace.published).sum()),
        sq_horizontal_m2=float(np.sum(e[:, 0] ** 2 + e[:, 1] ** 2)),
        sq_vertical_m2=float(np.sum(e[:, 2] ** 2)),
        max_error_m=float(error_norm[estimated].max()) if e.size else math.nan,
        sq_tension_n2=float(np.sum(tension_error**2)),
        tension_count=int(tension_error.size),
        sq_velocity_m2ps2=float(np.sum(velocity_error**2)),
        velocity_count=int(velocity_error.shape[0]),
        converge_s=converge_time_s(record.time_s, error_norm, converged_m),
        published_after_taut_s=published_after_taut_s(
            record.time_s, record.landed, record.tension_n, trace.published
        ),
        crlb_horizontal_m2=float(np.sum(crlb[:, 0] + crlb[:, 1])),
        crlb_vertical_m2=float(np.sum(crlb[:, 2])),
        own_bound_horizontal_m2=float(np.sum(own[:, 0] + own[:, 1]))
        if own is not None
        else math.nan,
        own_bound_vertical_m2=float(np.sum(own[:, 2])) if own is not None else math.nan,
        nees=nees_all[window].astype(np.float32),
        series={k: v[::step].astype(np.float32) for k, v in series.items()},
    )


def _share(part: int, whole: int) -> float:
    return part / whole if whole > 0 else math.nan


def _root_mean(total: float, count: int) -> float:
    return math.sqrt(total / count) if count > 0 else math.nan


def pool(runs: list[KindRunScore], has_tension: bool, has_velocity: bool) -> dict:
    """One kind's scores pooled over seeds (RMSE over all scored ticks of all seeds)."""
    estimated = sum(r.estimated for r in runs)
    ticks = sum(r.ticks for r in runs)
    horizontal = _root_mean(sum(r.sq_horizontal_m2 for r in runs), estimated)
    vertical = _root_mean(sum(r.sq_vertical_m2 for r in runs), estimated)
    crlb_h = _root_mean(sum(r.crlb_horizontal_m2 for r in runs), estimated)
    crlb_v = _root_mean(sum(r.crlb_vertical_m2 for r in runs), estimated)
    own_h = _root_mean(sum(r.own_bound_horizontal_m2 for r in runs), estimated)
    own_v = _root_mean(sum(r.own_bound_vertical_m2 for r in runs), estimated)
    lengths = {r.nees.size for r in runs}
    nees_matrix = np.vstack([r.nees for r in runs]).astype(float) if len(lengths) == 1 else None
    all_nees = np.concatenate([r.nees for r in runs]).astype(float)
    all_nees = all_nees[np.isfinite(all_nees)]
    converge = [r.converge_s for r in runs]
    finite_converge = [c for c in converge if math.isfinite(c)]
    seed_h = [_root_mean(r.sq_horizontal_m2, r.estimated) for r in runs]
    per_seed_h = [h for h in seed_h if math.isfinite(h)]
    return {
        "seeds": len(runs),
        "horizontal_rmse_m": horizontal,
        "horizontal_rmse_seed_std_m": float(np.std(per_seed_h, ddof=1))
        if len(per_seed_h) > 1
        else 0.0,
        "horizontal_rmse_per_seed_m": seed_h,
        "vertical_rmse_m": vertical,
        "max_error_m": max(
            (r.max_error_m for r in runs if math.isfinite(r.max_error_m)), default=math.nan
        ),
        "tension_rmse_n": _root_mean(
            sum(r.sq_tension_n2 for r in runs), sum(r.tension_count for r in runs)
        )
        if has_tension
        else None,
        "velocity_rmse_mps": _root_mean(
            sum(r.sq_velocity_m2ps2 for r in runs), sum(r.velocity_count for r in runs)
        )
        if has_velocity
        else None,
        "nees_mean": float(all_nees.mean()) if all_nees.size else math.nan,
        "nees_in_band": share_in_band(nees_matrix) if nees_matrix is not None else math.nan,
        "converge_s_median": float(np.median(finite_converge)) if finite_converge else math.inf,
        "converge_s_per_seed": converge,
        "never_converged": sum(1 for c in converge if not math.isfinite(c)),
        "published_after_taut_s_per_seed": [r.published_after_taut_s for r in runs],
        "share_estimated": estimated / ticks if ticks else math.nan,
        "share_published": sum(r.published for r in runs) / ticks if ticks else math.nan,
        "beyond_3_sigma": _share(sum(r.beyond_3_sigma for r in runs), estimated),
        "published_beyond_3_sigma": _share(
            sum(r.published_beyond_3_sigma for r in runs), sum(r.published for r in runs)
        ),
        "crlb_horizontal_m": crlb_h,
        "crlb_vertical_m": crlb_v,
        "horizontal_rmse_over_crlb": horizontal / crlb_h if crlb_h > 0 else math.nan,
        "vertical_rmse_over_crlb": vertical / crlb_v if crlb_v > 0 else math.nan,
        "own_bound_horizontal_m": own_h,
        "own_bound_vertical_m": own_v,
        "horizontal_rmse_over_own_bound": horizontal / own_h if own_h > 0 else math.nan,
        "vertical_rmse_over_own_bound": vertical / own_v if own_v > 0 else math.nan,
    }
