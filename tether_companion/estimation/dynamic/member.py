"""One member of the dynamic filter's bank: the EKF with its per-IMU-tick arithmetic made lean.

Every IMU tick predicts and fuses the 3-axis force balance in every member, so those two steps
decide the filter's cost. :class:`MemberFilter` is an
:class:`~tether_companion.estimation.ekf.ExtendedKalmanFilter` (same state, covariance, status
records, gate, repairs and resets) whose two hot steps do the same algebra with fewer and
cheaper operations:

* prediction (one Euler step, ``x + h f``, ``P + h (F P + (F P)^T + Q)``): ``F`` is known in
  structure: the position rows are ``p' = v`` (so ``(F P)`` there is ``P``'s velocity rows,
  copied, not multiplied), the velocity rows are the generated ``dv'/dx`` (one 3x13 by 13x13
  product), the other rows are zero (random walks); ``Q`` diagonal. No 13x13x13 product.
* the force-balance update with ``R = r I``: ``P H^T``, the 3x3 ``S`` tested for definiteness
  (Sylvester's leading minors) and inverted in scalars, ``NIS = y^T S^-1 y``, the gate,
  ``K = P H^T S^-1``, ``x + K y`` and ``P - K (P H^T)^T`` made exactly symmetric. That is the
  Joseph form's value for the optimal gain (the Joseph form guards against a gain that is not
  optimal; here ``K`` is computed from the same ``S``), as PX4 EKF2's updates; the covariance
  then gets the same finite check and Cholesky test as before (a repair is counted).
* the covariance may lag the state (``predict(..., covariance=False)``, the
  ``imu_ticks_per_fusion`` option): the time is summed and one Euler step with the latest
  Jacobian is taken before the next update or covariance prediction.

Numbers: the generic EKF spent most of a member's tick in numpy calls on 13x13 arrays
(Joseph form: four 13x13 products; LAPACK Cholesky of S and of P twice); see
docs/estimation.md ("Cost per IMU tick") for the measured costs. The results equal the
generic EKF's to rounding (tests: 1e-9).

Straight-line scalar Python for the same algebra (generated with the Jacobians' sparsity, as
the paper filters do for 3-4 states) was measured too and was slower at 13 states: ~1500
multiplications a tick in bytecode cost more than a dozen numpy calls of ~1 us each.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.models import Generated, ModelConstants
from tether_companion.estimation.ekf import (
    GATED,
    NONFINITE,
    SINGULAR,
    ExtendedKalmanFilter,
    MeasurementFunction,
    SensorStatus,
    UpdateResult,
)

FloatArray = NDArray[np.float64]

_N = state.N_STATES
_P = state.POSITION
_V = state.VELOCITY


class MemberFilter(ExtendedKalmanFilter):
    """The EKF of one thrust-scale hypothesis (see the module docstring).

    Parameters
    ----------
    x0, p0
        Initial state (13,) and covariance (13, 13).
    q_diagonal
        Process noise spectral density, diagonal (13,) [state units^2 / s].
    constants
        The models' constants (mass, drag, cable weight).
    process
        The generated process function ``(x, u, c) -> (x' (13,), dv'/dx (39,))``
        (``generated.inertial`` or a ``force_balance_*``).
    gate_probability, max_consecutive_rejections
        As for :class:`~tether_companion.estimation.ekf.ExtendedKalmanFilter`.
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
        self._q = np.diag(q_diagonal).copy()
        self._fp = np.zeros((_N, _N))
        """``F P``, rows 0-5 rewritten each prediction, the rest stay zero."""
        self._pending_s = 0.0
        """Time the state has been predicted over and the covariance not yet [s]."""
        self._dv: Sequence[float] = ()
        """``dv'/dx`` of the latest state prediction (39, row-major)."""

    def predict(  # type: ignore[override]
        self, dt_s: float, u: Sequence[float] | None = None, *, covariance: bool = True
    ) -> bool:
        """One Euler step of the state over ``dt_s`` [s] with the inputs ``u`` (floats), and of
        the covariance over the time since its last step when ``covariance`` (otherwise that
        waits for the next prediction with ``covariance`` or the next update, with the
        latest Jacobian). ``False`` (and ``rejected_predictions``) when ``dt_s`` or ``u`` is
        not finite or ``dt_s < 0``."""
        if not (dt_s >= 0.0 and math.isfinite(dt_s)) or (
            u is not None and not math.isfinite(sum(u))
        ):
            self.rejected_predictions += 1
            return False
        if dt_s > 0.0:
            x = self.x_values()
            xdot, self._dv = self.process_function(x, u, self.constants.values())  # type: ignore[arg-type]
            x = [a + dt_s * b for a, b in zip(x, xdot, strict=True)]
            self.x = np.array(x)
            self._pending_s += dt_s
            if not math.isfinite(sum(x)):
                self.reset()
                return True
        if covariance:
            self.propagate_covariance()
        return True

    def propagate_covariance(self) -> None:
        """``P + h (F P + (F P)^T + Q)`` over the time the state has gone ahead of it."""
        h = self._pending_s
        if h == 0.0:
            return
        self._pending_s = 0.0
        p = self.P
        fp = self._fp
        fp[_P] = p[_V]
        fp[_V] = np.array(self._dv).reshape(3, _N) @ p
        rate = fp + fp.T
        rate += self._q
        rate *= h
        rate += p
        self.P = rate
        self._check_health()

    def update(
        self, sensor: str, z: FloatArray, measure: MeasurementFunction, r: FloatArray
    ) -> UpdateResult:
        """:meth:`ExtendedKalmanFilter.update` on the covariance brought up to the state's
        time first; a scalar measurement (rangefinder, winch, load cell) in the lean form:
        ``t = P h``, ``s = h t + r``, ``K = t / s``, ``P - K t^T`` made exactly symmetric
        (no 13x13x13 product), same checks, gate and counts."""
        self.propagate_covariance()
        if z.size != 1:
            return super().update(sensor, z, measure, r)
        status = self.sensors.get(sensor)
        if status is None:
            status = self.sensors[sensor] = SensorStatus()
        z_pred, h_jac = measure(self.x)
        p = self.P
        h_row = h_jac[0]
        pht = p @ h_row
        s = float(h_row @ pht) + float(r[0, 0])
        y = float(z[0]) - float(z_pred[0])
        if not s > 0.0:
            return self._rejected(status, s)
        nis = y * y / s
        status.last_nis = nis
        status.innovation = (y,)
        threshold, in_force = self._gate(status, 1)
        if self._gated(status, nis, threshold, in_force):
            return UpdateResult(GATED, nis)
        gain = pht / s
        x = self.x + gain * y
        p_new = p - np.outer(gain, pht)
        return self._accept(status, nis, x, p_new)

    def reset(self, x: FloatArray | None = None, p: FloatArray | None = None) -> None:
        """:meth:`ExtendedKalmanFilter.reset`; nothing pending."""
        self._pending_s = 0.0
        super().reset(x, p)

    def update_force_balance(
        self,
        sensor: str,
        innovation: Sequence[float],
        jacobian: Sequence[float],
        r_variance: float,
    ) -> UpdateResult:
        """Fuse a 3-axis measurement: ``innovation`` ``z - h(x)`` (3), ``jacobian`` (39,
        row-major 3x13), noise ``r_variance`` on each axis; same checks, gate and counts as
        :meth:`~tether_companion.estimation.ekf.ExtendedKalmanFilter.update`."""
        self.propagate_covariance()
        status = self.sensors.get(sensor)
        if status is None:
            status = self.sensors[sensor] = SensorStatus()
        h_jac = np.array(jacobian, dtype=float).reshape(3, _N)
        p = self.P
        pht = p @ h_jac.T
        s00, s01, s02, _, s11, s12, _, _, s22 = (h_jac @ pht).ravel().tolist()
        s00 += r_variance
        s11 += r_variance
        s22 += r_variance
        # Sylvester: S is positive definite iff its leading minors are (NaN fails each test)
        m01 = s00 * s11 - s01 * s01
        c0, c1, c2 = s11 * s22 - s12 * s12, s02 * s12 - s01 * s22, s01 * s12 - s02 * s11
        det = s00 * c0 + s01 * c1 + s02 * c2
        if not (s00 > 0.0 and m01 > 0.0 and det > 0.0):
            return self._rejected(status, s00 + s11 + s22 + s01 + s02 + s12)
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
        status.last_nis = nis
        status.innovation = innovation
        threshold, in_force = self._gate(status, 3)
        if self._gated(status, nis, threshold, in_force):
            return UpdateResult(GATED, nis)
        s_inv = np.array(((i00, i01, i02), (i01, i11, i12), (i02, i12, i22)))
        x = self.x + pht @ np.array((w0, w1, w2))
        p_new = p - (pht @ s_inv) @ pht.T
        return self._accept(status, nis, x, p_new)

    @staticmethod
    def _rejected(status: SensorStatus, s_sum: float) -> UpdateResult:
        """Count an innovation covariance that is not positive definite."""
        if not math.isfinite(s_sum):
            status.nonfinite += 1
            return UpdateResult(NONFINITE, math.nan)
        status.singular += 1
        return UpdateResult(SINGULAR, math.nan)
