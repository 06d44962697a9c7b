"""One member of the dynamic filter's bank: the EKF with its per-IMU-tick arithmetic made lean.

Every IMU tick predicts and fuses the 3-axis force balance in every member, so those two steps
decide the filter's cost. :class:`MemberFilter` is an
:class:`~tether_companion.estimation.ekf.ExtendedKalmanFilter` (same state, covariance, status
records, gate, repairs and resets) whose two hot steps do the same algebra with fewer and
cheaper operations:

* prediction (one Euler step, ``x + h f``, ``P + h (F P + (F P)^T + Q)``): ``F`` is known in
  structure: the position rows are ``p' = v`` (so ``(F P)`` there is ``P``'s velocity rows,
  copied, not multiplied), the velocity rows are the generated ``dv'/dx`` (one 3xn by nxn
  product; ``n`` = 17 states), the wind's ``-1 / tau`` on its own columns (a Gauss-Markov
  process, ``noise.wind_decay_per_s``), the other rows are zero (random walks and constants);
  ``Q`` diagonal. No nxnxn product.
* the force-balance update with ``R = r I``: ``P H^T``, the 3x3 ``S`` tested for definiteness
  (Sylvester's leading minors) and inverted in scalars, ``NIS = y^T S^-1 y``, the gate,
  ``K = P H^T S^-1``, ``x + K y`` and ``P - K (P H^T)^T`` made exactly symmetric. That is the
  Joseph form's value for the optimal gain (the Joseph form guards against a gain that is not
  optimal; here ``K`` is computed from the same ``S``), as PX4 EKF2's updates; the covariance
  then gets the same finite check and Cholesky test as before (a repair is counted); a scalar
  measurement (rangefinder, winch, load cell) likewise, ``K = P h / s``;
* the bank runs the linear algebra of these steps for all its members at once (stacked
  arrays: :mod:`~tether_companion.estimation.dynamic.bank`; one member left, on its own 2-D
  arrays through ``np.dot``, the same numbers without ``matmul``'s gufunc machinery), the
  member its scalar part
  (:meth:`MemberFilter.test_force_balance`: the 3x3 ``S`` and the gate;
  :meth:`MemberFilter.test_scalar`, :meth:`MemberFilter.accept_update`,
  :meth:`MemberFilter.set_predicted`); the
  inertial formulation is predicted over several IMU ticks at once
  (:mod:`~tether_companion.estimation.dynamic.imu_batch`).

Numbers: the generic EKF spent most of a member's tick in numpy calls on 13x13 arrays
(Joseph form: four 13x13 products; LAPACK Cholesky of S and of P twice); see
docs/estimation-history.md ("Cost per IMU tick") for the measured costs. The results equal the
generic EKF's to rounding (tests: 1e-9).

Straight-line scalar Python for the same algebra (generated with the Jacobians' sparsity, as
the paper filters do for 3-4 states) was measured too and was slower at 13 states: ~1500
multiplications a tick in bytecode cost more than a dozen numpy calls of ~1 us each.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.imu_batch import MEMBER_CORE
from tether_companion.estimation.dynamic.models import Generated, ModelConstants
from tether_companion.estimation.ekf import (
    FUSED,
    GATED,
    NONFINITE,
    SINGULAR,
    ExtendedKalmanFilter,
    SensorStatus,
    UpdateResult,
)

FloatArray = NDArray[np.float64]

_N = state.N_STATES
_P = state.POSITION
_V = state.VELOCITY
_W = range(state.WIND.start, state.WIND.stop)


class MemberFilter(ExtendedKalmanFilter):
    """The EKF of one thrust-scale hypothesis (see the module docstring).

    Parameters
    ----------
    x0, p0
        Initial state (n,) and covariance (n, n).
    q_diagonal
        Process noise spectral density, diagonal (n,) [state units^2 / s].
    constants
        The models' constants (mass, drag, cable weight).
    process
        The generated process function ``(x, u, c) -> (x' (n,), dv'/dx (3n,))``
        (``generated.inertial`` or a ``force_balance_*``).
    gate_probability, max_consecutive_rejections
        As for :class:`~tether_companion.estimation.ekf.ExtendedKalmanFilter`.
    wind_decay_per_s
        The wind's reversion rate toward calm, ``1 / tau`` [1/s], in :meth:`predict` (the
        generated process leaves the wind's rate at 0; 0: a random walk).
    """

    def __init__(
        self,
        x0: FloatArray,
        p0: FloatArray,
        q_diagonal: FloatArray,
        constants: ModelConstants,
        process: Generated,
        *,
        gate_probability: float = 1.0,
        max_consecutive_rejections: int = 0,
        wind_decay_per_s: float = 0.0,
    ) -> None:
        super().__init__(
            x0,
            p0,
            np.diag(q_diagonal),
            None,
            gate_probability=gate_probability,
            max_consecutive_rejections=max_consecutive_rejections,
        )
        self._random_walk = False  # the prediction below runs the process, not a random walk
        self.constants = constants
        self.process_function = process
        self.wind_decay_per_s = wind_decay_per_s
        self._q = np.diag(q_diagonal).copy()
        self._fp = np.zeros((_N, _N))
        """``F P``, rows 0-5 and the wind's rewritten each prediction, the rest stay zero."""
        self.last_log_det_s = math.nan
        """``log det S`` of the last sample :meth:`test_force_balance` or :meth:`test_scalar`
        tested (the Gaussian likelihood's normalisation, for the bank's weights)."""
        self.consider: slice | None = None
        """The states held as consider (Schmidt) states, or None: every update keeps their
        mean and their own covariance block as they were (:func:`hold_consider`); set by the
        bank (:attr:`~tether_companion.estimation.dynamic.bank.FilterBank.consider`)."""

    def set_process_noise(self, q_diagonal: FloatArray) -> None:
        """Predict with the process noise spectral density ``q_diagonal`` (n,) from now on
        (the estimator's tension walk: a winch's tension fused or not)."""
        self._q = np.diag(q_diagonal)
        self._q_density = self._q.copy()

    def predict(self, dt_s: float, u: Sequence[float] | None = None) -> bool:  # type: ignore[override]
        """One Euler step of the state and the covariance over ``dt_s`` [s] with the inputs
        ``u`` (floats). ``False`` (and ``rejected_predictions``) when ``dt_s`` or ``u`` is not
        finite or ``dt_s < 0``."""
        if not (dt_s >= 0.0 and math.isfinite(dt_s)) or (
            u is not None and not math.isfinite(sum(u))
        ):
            self.rejected_predictions += 1
            return False
        if dt_s == 0.0:
            return True
        x = self.x_values()
        xdot, dv = self.process_function(x, u, self.constants.values())  # type: ignore[arg-type]
        x = [a + dt_s * b for a, b in zip(x, xdot, strict=True)]
        decay = self.wind_decay_per_s
        for i in _W:
            x[i] -= dt_s * decay * x[i]  # w' = -w / tau (the generated rate is 0)
        self.x = np.array(x)
        if not math.isfinite(sum(x)):
            self.reset()
            return True
        p = self.P
        fp = self._fp
        fp[_P] = p[_V]
        fp[_V] = np.array(dv).reshape(3, _N) @ p
        fp[state.WIND] = -decay * p[state.WIND]
        rate = fp + fp.T
        rate += self._q
        rate *= dt_s
        rate += p
        self.P = rate
        self._check_health()
        return True

    def set_predicted(self, x: FloatArray, p: FloatArray, *, healthy: bool) -> None:
        """Keep a state (n,) and covariance (n, n) predicted for the whole bank at once
        (:meth:`~tether_companion.estimation.dynamic.bank.FilterBank.predict_batch`); unless
        known ``healthy`` (finite and positive definite) they are checked as after
        :meth:`predict`: reset when not finite, repaired when not positive definite."""
        self._keep(x, p)
        if not healthy:
            self._check_health()

    def _keep(self, x: FloatArray, p: FloatArray) -> None:
        """Keep a state (n,) and covariance (n, n), float arrays the bank made (the ``x`` and
        ``P`` setters' conversion skipped: they are float arrays already)."""
        self._xa, self._xl, self._pa, self._pl = x, None, p, None

    def test_scalar(self, sensor: str, innovation: float, s_value: float) -> UpdateResult | None:
        """The scalar part of a 1-D update: ``s_value`` is ``H P H^T + R``; tested, the NIS
        ``y^2 / s`` gated (counted as :meth:`test_force_balance` counts). The outcome when the
        sample is rejected, ``None`` to fuse with :meth:`accept_update`."""
        status = self.sensors.get(sensor)
        if status is None:
            status = self.sensors[sensor] = SensorStatus()
        if not s_value > 0.0:
            self.last_log_det_s = math.nan
            return self._rejected(status, s_value)
        self.last_log_det_s = math.log(s_value)
        nis = innovation * innovation / s_value
        status.last_nis = nis
        status.innovation = (innovation,)
        threshold, in_force = self._gate(status, 1)
        if self._gated(status, nis, threshold, in_force):
            return UpdateResult(GATED, nis)
        return None

    def test_force_balance(
        self, sensor: str, innovation: Sequence[float], s_values: Sequence[float], r_variance: float
    ) -> tuple[UpdateResult | None, tuple[float, ...]]:
        """The scalar part of a 3-axis update with ``R = r_variance I``: ``s_values`` is
        ``H P H^T`` (9, row-major), ``innovation`` ``z - h(x)`` (3). ``S`` is tested for
        definiteness (Sylvester's leading minors) and inverted in scalars, the NIS gated
        (counted as :meth:`~tether_companion.estimation.ekf.ExtendedKalmanFilter.update`
        counts). Returns the outcome when the sample is rejected (non-finite, singular,
        gated) and ``()``, or ``None`` and ``(nis, S^-1 row-major (9), S^-1 y (3))`` to fuse
        with :meth:`accept_update`."""
        status = self.sensors.get(sensor)
        if status is None:
            status = self.sensors[sensor] = SensorStatus()
        log_det, solved = SOLVE_FORCE_BALANCE(s_values, innovation, r_variance)
        self.last_log_det_s = log_det
        if log_det != log_det:  # nan: S is not positive definite, ``solved`` its entries' sum
            return self._rejected(status, solved), ()
        nis = solved[0]
        status.last_nis = nis
        status.innovation = innovation
        threshold, in_force = self._gate(status, 3)
        if self._gated(status, nis, threshold, in_force):
            return UpdateResult(GATED, nis), ()
        return None, solved

    def accept_update(
        self, sensor: str, nis: float, x: FloatArray, p: FloatArray, *, checked: bool
    ) -> UpdateResult:
        """Keep the updated state (n,) and covariance (n, n) of a sample that
        :meth:`test_force_balance` or :meth:`test_scalar` let through: when ``checked``
        (finite, exactly symmetric and positive definite, tested for the whole bank at once)
        counted and stored, otherwise through the generic EKF's finite check, symmetrisation and
        Cholesky test (and repair)."""
        status = self.sensors[sensor]
        if not checked:
            return self._accept(status, nis, x, p)
        self._keep(x, p)
        status.fused += 1
        status.consecutive_rejections = 0
        return UpdateResult(FUSED, nis)

    def _accept(
        self, status: SensorStatus, nis: float, x: FloatArray, p: FloatArray
    ) -> UpdateResult:
        """The generic EKF's update (:meth:`update`: a 2-D cable angle) with the consider
        states held (:func:`hold_consider`) before it is kept."""
        if self.consider is not None:
            hold_consider(x[None], p[None], self.x[None], self.P[None], self.consider)
        return super()._accept(status, nis, x, p)

    @staticmethod
    def _rejected(status: SensorStatus, s_sum: float) -> UpdateResult:
        """Count an innovation covariance that is not positive definite."""
        if not math.isfinite(s_sum):
            status.nonfinite += 1
            return UpdateResult(NONFINITE, math.nan)
        status.singular += 1
        return UpdateResult(SINGULAR, math.nan)


def solve_force_balance(
    s_values: Sequence[float], innovation: Sequence[float], r_variance: float
) -> tuple[float, tuple[float, ...] | float]:
    """The scalars of :meth:`MemberFilter.test_force_balance`: ``S = H P H^T + r_variance I``
    from ``s_values`` (``H P H^T``, 9 row-major) tested for definiteness (Sylvester's leading
    minors; NaN fails each test) and inverted in scalars, with ``y`` = ``innovation`` (3).
    Returns ``(log det S, (nis, S^-1 row-major (9), S^-1 y (3)))``, or ``(nan, sum of S's
    upper entries)`` when ``S`` is not positive definite. The reference of ``_member_core``'s
    ``force_balance`` (:data:`SOLVE_FORCE_BALANCE`), which is bit for bit this."""
    s00, s01, s02, _, s11, s12, _, _, s22 = s_values
    s00 += r_variance
    s11 += r_variance
    s22 += r_variance
    # Sylvester: S is positive definite iff its leading minors are (NaN fails each test)
    m01 = s00 * s11 - s01 * s01
    c0, c1, c2 = s11 * s22 - s12 * s12, s02 * s12 - s01 * s22, s01 * s12 - s02 * s11
    det = s00 * c0 + s01 * c1 + s02 * c2
    if not (s00 > 0.0 and m01 > 0.0 and det > 0.0):
        return math.nan, s00 + s11 + s22 + s01 + s02 + s12
    inv = 1.0 / det
    i00, i01, i02 = c0 * inv, c1 * inv, c2 * inv
    i11 = (s00 * s22 - s02 * s02) * inv
    i12 = (s01 * s02 - s00 * s12) * inv
    i22 = m01 * inv
    y0, y1, y2 = innovation
    w0 = i00 * y0 + i01 * y1 + i02 * y2
    w1 = i01 * y0 + i11 * y1 + i12 * y2
    w2 = i02 * y0 + i12 * y1 + i22 * y2
    nis = y0 * w0 + y1 * w1 + y2 * w2
    return math.log(det), (nis, i00, i01, i02, i01, i11, i12, i02, i12, i22, w0, w1, w2)


SOLVE_FORCE_BALANCE: Callable[..., tuple] = solve_force_balance
""":func:`solve_force_balance`, or where the optional C extension ``_member_core`` runs its
twin ``force_balance``: the same floats (the Python function called where C could differ).
An extension built before ``force_balance`` existed leaves the Python function (rebuild it:
tests/test_force_balance_core.py fails until then)."""
if getattr(MEMBER_CORE, "force_balance", None) is not None:
    SOLVE_FORCE_BALANCE = functools.partial(MEMBER_CORE.force_balance, solve_force_balance)


def hold_consider(
    xs: FloatArray, ps: FloatArray, prior_xs: FloatArray, prior_ps: FloatArray, consider: slice
) -> None:
    """Make optimal updates of stacked states (m, n) and covariances (m, n, n) (or one
    member's, (n,) and (n, n)) Schmidt updates, in place: the ``consider`` states' means and
    their own covariance block back to the priors ``prior_xs``, ``prior_ps``.

    With the optimal gain ``K = [K_s; K_c]`` the Schmidt gain is ``[K_s; 0]``: the other
    states and their covariance update exactly as with ``K`` (their gain is the optimal one),
    the cross block ``P_sc`` too (``P_sc - K_s H P_c``, the same in both), and ``P_cc`` keeps
    its prior; the result is the optimal covariance plus ``K_c S K_c^T`` in the consider
    block, so it stays positive definite."""
    xs[..., consider] = prior_xs[..., consider]
    ps[..., consider, consider] = prior_ps[..., consider, consider]
