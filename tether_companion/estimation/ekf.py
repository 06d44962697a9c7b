"""A generic continuous-discrete extended Kalman filter (Al-Radaideh & Sun 2021, Algorithm 1).

The filter owns the state ``x`` (shape ``(n,)``) and its covariance ``P`` (shape ``(n, n)``)
and knows nothing about tethers: a process model supplies ``f(x, u)`` and its Jacobian, each
sensor's fusion supplies a measurement function returning the predicted measurement and its
Jacobian at the filter's current state.

Prediction (Algorithm 1, lines 3-8) integrates ``x_dot = f(x, u)`` and the covariance
equation ``P_dot = F P + P F^T + Q_c`` with ``N`` Euler sub-steps, ``Q_c`` being the process
noise *spectral density* (units of state^2 per second). For a random-walk model (``f = 0``,
``F = 0``) the covariance equation is integrated exactly as ``P += Q_c dt``, which is also the
paper's discrete eq. 31 with ``Q_k = Q_c dt``; :mod:`tether_companion.estimation.config`
converts the paper's per-step ``Q`` into ``Q_c``.

Correction (lines 9-14) is done once per sensor sample with

* rejection of non-finite inputs (never let NaN/inf into the state; counted),
* a chi-square innovation gate on the normalised innovation squared (NIS),
* the Joseph form ``P = (I - K H) P (I - K H)^T + K R K^T``, which stays symmetric positive
  semi-definite under rounding where the paper's ``(I - K H) P`` (eq. 34) does not,
* symmetrisation and a positive-definiteness check (Cholesky); a covariance that lost
  definiteness is repaired by clipping its eigenvalues, and a state or covariance that is no
  longer finite makes the filter reset to its initial condition (counted in ``resets``).

Each sensor's counts (:class:`~tether_companion.estimation.aid_status.SensorStatus`) and the
gate's decision live in :mod:`~tether_companion.estimation.aid_status` (imported here too).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation import scalar_update
from tether_companion.estimation.aid_status import (  # noqa: F401 (also imported from here)
    FUSED,
    GATED,
    NONFINITE,
    SINGULAR,
    SensorStatus,
    UpdateResult,
    chi2_threshold,
    gate_rejects,
)
from tether_companion.estimation.lapack import dpotrf, dpotrs

FloatArray = NDArray[np.float64]

MeasurementFunction = Callable[[FloatArray], tuple[FloatArray, FloatArray]]
"""``measure(x) -> (z_pred (m,), H (m, n))``: predicted measurement and its Jacobian at ``x``."""

EIGENVALUE_FLOOR = 1e-12
"""Smallest eigenvalue a repaired covariance keeps [state units^2]."""


class ProcessModel(Protocol):
    """Continuous process model ``x_dot = f(x, u)`` with its Jacobian ``F = df/dx``."""

    def derivative(self, x: FloatArray, u: FloatArray | None) -> FloatArray:
        """``f(x, u)``, shape (n,)."""
        ...

    def jacobian(self, x: FloatArray, u: FloatArray | None) -> FloatArray:
        """``df/dx`` at ``(x, u)``, shape (n, n)."""
        ...


class RandomWalk:
    """The paper's process model (eq. 26): ``x_dot = 0``; all motion enters through ``Q``."""

    is_random_walk = True

    def derivative(self, x: FloatArray, u: FloatArray | None) -> FloatArray:
        """Zero derivative, shape (n,)."""
        return np.zeros_like(x)

    def jacobian(self, x: FloatArray, u: FloatArray | None) -> FloatArray:
        """Zero Jacobian, shape (n, n)."""
        return np.zeros((x.size, x.size))


class ExtendedKalmanFilter:
    """Continuous-discrete EKF with gated Joseph-form updates and covariance health checks.

    Parameters
    ----------
    x0
        Initial state, shape (n,).
    p0
        Initial covariance, shape (n, n), symmetric positive definite.
    q_density
        Process noise spectral density ``Q_c``, shape (n, n) [state units^2 / s].
    process
        Process model; ``None`` means the paper's random walk.
    substeps
        Euler sub-steps per prediction for a non-random-walk model (Algorithm 1's ``N``).
    gate_probability
        Probability mass of the chi-square gate (e.g. 0.9999); 1.0 disables gating.
    max_consecutive_rejections
        After this many gate rejections in a row on one sensor, the next sample is fused
        regardless (counted as ``forced``); 0 means never force.
    """

    def __init__(
        self,
        x0: FloatArray,
        p0: FloatArray,
        q_density: FloatArray,
        process: ProcessModel | None = None,
        *,
        substeps: int = 1,
        gate_probability: float = 1.0,
        max_consecutive_rejections: int = 0,
    ) -> None:
        x0 = np.asarray(x0, dtype=float).reshape(-1)
        n = x0.size
        p0 = np.asarray(p0, dtype=float)
        q_density = np.asarray(q_density, dtype=float)
        if p0.shape != (n, n) or q_density.shape != (n, n):
            raise ValueError(f"P0 and Q must be ({n}, {n}); got {p0.shape} and {q_density.shape}")
        if not (
            np.all(np.isfinite(x0)) and np.all(np.isfinite(p0)) and np.all(np.isfinite(q_density))
        ):
            raise ValueError("x0, P0 and Q must be finite")
        if dpotrf(p0, lower=1, clean=0)[1] != 0:
            raise ValueError("P0 must be symmetric positive definite")
        if substeps < 1:
            raise ValueError(f"substeps must be >= 1, got {substeps}")
        self._x0 = x0.copy()
        self._p0 = p0.copy()
        self._q_density = q_density.copy()
        self.process: ProcessModel = process if process is not None else RandomWalk()
        self._random_walk = bool(getattr(self.process, "is_random_walk", False))
        self.substeps = substeps
        self.gate_probability = gate_probability
        self.max_consecutive_rejections = max_consecutive_rejections
        self._thresholds: dict[int, float] = {}
        self._updaters: dict[object, Callable[..., scalar_update.UpdateOutcome]] = {}
        self._eye = np.eye(n)
        self._n = n
        # The state and covariance live in one of two forms at a time: numpy arrays (the numpy
        # paths, and whoever reads ``x`` or ``P``) or flat Python lists (the scalar paths, see
        # update_rows). Each accessor converts on first use and the other form is dropped, so
        # a caller may change the arrays it was handed in place, as before.
        self._xa: FloatArray | None = x0.copy()
        self._xl: list[float] | None = None
        self._pa: FloatArray | None = p0.copy()
        self._pl: list[float] | None = None
        self._q_entries = [(int(k), float(q_density.flat[k])) for k in np.flatnonzero(q_density)]
        """``(flat index, Q_c entry)`` of the non-zero process noise (random walk on lists)."""
        self.sensors: dict[str, SensorStatus] = {}
        self.resets = 0
        self.pd_repairs = 0
        self.rejected_predictions = 0

    @property
    def n(self) -> int:
        """State dimension."""
        return self._n

    @property
    def q_density(self) -> FloatArray:
        """Process noise spectral density ``Q_c`` (a copy), shape (n, n) [state units^2 / s];
        fixed at construction (the scalar path keeps its non-zero entries)."""
        return self._q_density.copy()

    @property
    def x(self) -> FloatArray:
        """State, shape (n,)."""
        xa = self._xa
        if xa is None:
            xa = self._xa = np.array(self._xl)
            self._xl = None
        return xa

    @x.setter
    def x(self, value: FloatArray) -> None:
        self._xa = np.asarray(value, dtype=float)
        self._xl = None

    @property
    def P(self) -> FloatArray:  # noqa: N802 (the covariance's usual name)
        """State covariance, shape (n, n)."""
        pa = self._pa
        if pa is None:
            pa = self._pa = np.array(self._pl).reshape(self._n, self._n)
            self._pl = None
        return pa

    @P.setter
    def P(self, value: FloatArray) -> None:  # noqa: N802
        self._pa = np.asarray(value, dtype=float)
        self._pl = None

    def x_values(self) -> list[float]:
        """A new list of the n state values (no conversion on the scalar path)."""
        xl = self._xl
        return list(xl) if xl is not None else self._xa.tolist()  # type: ignore[union-attr]

    def values(self) -> tuple[list[float], list[float]]:
        """New lists of the n state values and the n*n covariance entries, row-major (no
        array on the scalar path)."""
        xl, pl = self._xl, self._pl
        x = list(xl) if xl is not None else self._xa.tolist()  # type: ignore[union-attr]
        p = list(pl) if pl is not None else self._pa.ravel().tolist()  # type: ignore[union-attr]
        return x, p

    def snapshot(self) -> tuple[FloatArray, FloatArray]:
        """New arrays of the state, shape (n,), and covariance, shape (n, n)."""
        xl, pl, xa, pa = self._xl, self._pl, self._xa, self._pa
        x = np.array(xl) if xa is None else xa.copy()
        p = np.array(pl).reshape(self._n, self._n) if pa is None else pa.copy()
        return x, p

    def _lists(self) -> tuple[list[float], list[float]]:
        """The state (n values) and covariance (n*n, row-major) as the current lists."""
        xl = self._xl
        if xl is None:
            xl = self._xl = self._xa.tolist()  # type: ignore[union-attr]
            self._xa = None
        pl = self._pl
        if pl is None:
            pl = self._pl = self._pa.ravel().tolist()  # type: ignore[union-attr]
            self._pa = None
        return xl, pl

    # ------------------------------------------------------------------ prediction
    def predict(self, dt_s: float, u: FloatArray | None = None) -> bool:
        """Propagate the state and covariance over ``dt_s`` seconds (Algorithm 1, lines 3-8).

        Returns ``False`` (and counts ``rejected_predictions``) when ``dt_s`` is negative or
        not finite, or ``u`` is not finite; the state is then left unchanged.
        """
        if not (dt_s >= 0.0 and math.isfinite(dt_s)) or (
            u is not None and not np.all(np.isfinite(u))
        ):
            self.rejected_predictions += 1
            return False
        if dt_s == 0.0:
            return True
        if self._random_walk:
            pl = self._pl
            if pl is None:
                self._pa += self._q_density * dt_s  # type: ignore[operator]
            else:
                for k, q in self._q_entries:
                    pl[k] += q * dt_s
            return True
        h = dt_s / self.substeps
        x, p = self.x, self.P
        for _ in range(self.substeps):
            f_jac = self.process.jacobian(x, u)
            x = x + h * self.process.derivative(x, u)
            fp = f_jac @ p
            p = p + h * (fp + fp.T + self._q_density)
        self.x, self.P = x, p
        self._check_health()
        return True

    # ------------------------------------------------------------------ correction
    def update(
        self, sensor: str, z: FloatArray, measure: MeasurementFunction, r: FloatArray
    ) -> UpdateResult:
        """Fuse one measurement ``z`` (shape (m,)) with noise covariance ``r`` (shape (m, m)).

        ``measure(x)`` returns the predicted measurement and its Jacobian at the current
        state. The sample is rejected (state untouched, counted in ``sensors[sensor]``) when
        any value is NaN/inf, when the innovation covariance is not positive definite, or
        when its NIS exceeds the chi-square gate.
        """
        status = self.sensors.get(sensor)
        if status is None:
            status = self.sensors[sensor] = SensorStatus()
        z_pred, h_jac = measure(self.x)
        innovation = z - z_pred
        pht = self.P @ h_jac.T
        s = h_jac @ pht + r
        m = innovation.size
        if m == 1:  # scalar measurement: no factorisation needed
            s_value = float(s[0, 0])
            positive_definite = s_value > 0.0
        else:
            s_chol, info = dpotrf(s, lower=1, clean=0)  # Cholesky: is S positive definite?
            positive_definite = info == 0
        if not positive_definite:
            if not math.isfinite(float(s.sum())):
                status.nonfinite += 1
                return UpdateResult(NONFINITE, math.nan)
            status.singular += 1
            return UpdateResult(SINGULAR, math.nan)
        if m == 1:
            nis = float(innovation[0]) ** 2 / s_value
        else:  # NIS = y^T S^-1 y with S^-1 y solved from the Cholesky factor
            nis = float(innovation @ dpotrs(s_chol, innovation, lower=1)[0])
        status.last_nis = nis
        status.innovation = innovation
        threshold, in_force = self._gate(status, m)
        if self._gated(status, nis, threshold, in_force):
            return UpdateResult(GATED, nis)
        # K = P H^T S^-1, i.e. K^T = S^-1 (P H^T)^T (S symmetric)
        gain = pht / s_value if m == 1 else dpotrs(s_chol, pht.T, lower=1)[0].T
        x = self.x + gain @ innovation
        # Joseph form: symmetric PSD by construction, unlike (I - K H) P under rounding
        a = self._eye - gain @ h_jac
        p = (a @ self.P) @ a.T
        p += (gain @ r) @ gain.T
        return self._accept(status, nis, x, p)

    def _accept(
        self, status: SensorStatus, nis: float, x: FloatArray, p: FloatArray
    ) -> UpdateResult:
        """Keep an updated state ``x`` and covariance ``p`` (made exactly symmetric, in place)
        unless they are not finite: NaN/inf anywhere in z, h(x), H or R reaches x or P, one
        reduction catches it and the state is left untouched. A covariance that fails the
        Cholesky test is repaired."""
        if not math.isfinite(float(x.sum()) + float(p.sum())):
            status.nonfinite += 1
            return UpdateResult(NONFINITE, math.nan)
        p += p.T
        p *= 0.5
        self.x = x
        self.P = p
        status.fused += 1
        status.consecutive_rejections = 0
        if dpotrf(p, lower=1, clean=0)[1] != 0:  # Cholesky failed: not PD
            self._repair_covariance()
        return UpdateResult(FUSED, nis)

    def update_rows(
        self,
        sensor: str,
        innovation: list[float],
        h_rows: list[list[float]],
        r_variance: float,
    ) -> UpdateResult:
        """:meth:`update_values` with the Jacobian given row by row (m rows of n)."""
        return self.update_values(
            sensor, innovation, [v for row in h_rows for v in row], r_variance
        )

    def update_values(
        self,
        sensor: str,
        innovation: list[float],
        h: Sequence[float],
        r_variance: float,
        *,
        constant: bool = False,
    ) -> UpdateResult:
        """:meth:`update` for a small filter, in scalar Python (same checks, counts, gate).

        ``innovation`` is ``z - h(x)`` (m values), ``h`` the Jacobian's m*n entries row by row,
        and the noise is ``r_variance`` on each axis (``R = r I``). With ``constant`` the
        Jacobian never changes (give it as a tuple): the update is compiled with its entries
        as literals, its zeros left out. See :mod:`~tether_companion.estimation.scalar_update`
        for the arithmetic; the result equals :meth:`update`'s to rounding. Give Python floats:
        numpy scalars give the same result several times slower (every product a numpy
        operation).
        """
        status = self.sensors.get(sensor)
        if status is None:
            status = self.sensors[sensor] = SensorStatus()
        m = len(innovation)
        threshold, in_force = self._gate(status, m)
        key = (m, h) if constant else m
        update = self._updaters.get(key)
        if update is None:
            update = self._updaters[key] = scalar_update.updater(
                self._n, m, tuple(h) if constant else None
            )
        x, p = self._xl, self._pl
        if x is None or p is None:
            x, p = self._lists()
        outcome = update(x, p, h, innovation, float(r_variance), in_force)
        if outcome is None:  # S not positive definite: NaN/inf somewhere, or singular
            if not math.isfinite(sum(p) + sum(h) + sum(innovation) + r_variance):
                status.nonfinite += 1
                return UpdateResult(NONFINITE, math.nan)
            status.singular += 1
            return UpdateResult(SINGULAR, math.nan)
        nis, x_new, p_new, positive_definite = outcome
        status.last_nis = nis
        status.innovation = innovation
        if self._gated(status, nis, threshold, in_force):  # x_new is None
            return UpdateResult(GATED, nis)
        if p_new is None:
            status.nonfinite += 1
            return UpdateResult(NONFINITE, math.nan)
        self._xl = x_new
        self._pl = p_new
        status.fused += 1
        status.consecutive_rejections = 0
        if not positive_definite:
            self._repair_covariance()
        return UpdateResult(FUSED, nis)

    def _gate(self, status: SensorStatus, m: int) -> tuple[float, float]:
        """The chi-square threshold of an m-dimensional NIS, and the threshold in force: the
        same, or ``inf`` when ``status``'s sensor was rejected ``max_consecutive_rejections``
        times in a row and its next sample is fused regardless."""
        threshold = self._thresholds.get(m)
        if threshold is None:
            threshold = self._thresholds[m] = chi2_threshold(self.gate_probability, m)
        limit = self.max_consecutive_rejections
        return threshold, (math.inf if 0 < limit <= status.consecutive_rejections else threshold)

    _gated = staticmethod(gate_rejects)

    # ------------------------------------------------------------------ diagnostics
    def nees(self, x_true: FloatArray) -> float:
        """Normalised estimation error squared ``e^T P^-1 e`` with ``e = x - x_true``."""
        error = self.x - np.asarray(x_true, dtype=float)
        return float(error @ np.linalg.solve(self.P, error))

    def reset(self, x: FloatArray | None = None, p: FloatArray | None = None) -> None:
        """Restart from ``(x, p)`` (default: the initial condition); counts in ``resets``."""
        self.x = (self._x0 if x is None else np.asarray(x, dtype=float)).copy()
        self.P = (self._p0 if p is None else np.asarray(p, dtype=float)).copy()
        for status in self.sensors.values():
            status.consecutive_rejections = 0
        self.resets += 1

    def _check_health(self) -> None:
        """Keep ``P`` symmetric positive definite; repair it or reset the filter."""
        if not math.isfinite(float(self.x.sum()) + float(self.P.sum())):
            self.reset()
            return
        if dpotrf(self.P, lower=1, clean=0)[1] != 0:  # Cholesky failed: not PD
            self._repair_covariance()

    def _repair_covariance(self) -> None:
        """Clip the eigenvalues of the symmetrised covariance to a small positive floor."""
        sym = 0.5 * (self.P + self.P.T)
        try:
            values, vectors = np.linalg.eigh(sym)
        except np.linalg.LinAlgError:
            self.reset()
            return
        floor = max(EIGENVALUE_FLOOR, EIGENVALUE_FLOOR * float(np.max(np.abs(values))))
        self.P = (vectors * np.maximum(values, floor)) @ vectors.T
        self.P = 0.5 * (self.P + self.P.T)
        self.pd_repairs += 1
