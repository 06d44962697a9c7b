"""The inertial formulation's prediction over several IMU ticks at once (a delta-velocity batch).

The inertial process (formulation (b), ``generated.inertial``) is affine in the state, with
coefficients that depend only on the inputs ``u`` (attitude, specific force): ``p' = v``,
``v' = c(u) + J(u) b`` (``c`` the specific force rotated into NED plus gravity, ``J = -R^T``
the Jacobian's bias columns: both taken from the generated function at the zero state), and
the other states are random walks but the wind, a first-order Gauss-Markov process
(``w' = -w / tau``, ``noise.wind_decay_per_s``) stepped exactly over the batch
(``w_N = exp(-T / tau) w_0``: no input enters it). The Euler steps of consecutive ticks
(``p += dt v``, then ``v += dt v'``) therefore compose into one step over the batch,

    p_N = p_0 + T v_0 + D_p + B_p b,        v_N = v_0 + D_v + B_v b,

with ``T = sum dt_k``, ``D_v = sum dt_k c(u_k)``, ``B_v = sum dt_k J(u_k)``, and for the
position the velocity sums as they were before each tick: ``D_p = sum dt_k D_v(<k)``,
``B_p = sum dt_k B_v(<k)``. None of these depends on the state, so they are accumulated once
per tick and shared by every bank member and by the published mean; a member then steps once
per batch, with the state the tick-by-tick Euler gives (to rounding). The covariance goes
through the same step's transition ``Phi = I + E`` (``E``: position rows ``T`` on the velocity
and ``B_p`` on the bias columns; velocity rows ``B_v`` on the bias columns; the wind's diagonal
``exp(-T / tau) - 1``), ``Phi P Phi^T +
T Q``: the tick-by-tick covariance's Euler steps composed, with the second-order terms kept
(``E P E^T``) and the process noise added once for the whole batch (not carried through the
batch's own transition: second order in ``T``). PX4 EKF2 predicts over summed IMU deltas the
same way.

Pure.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation import optional_core
from tether_companion.estimation.dynamic import generated, state

FloatArray = NDArray[np.float64]

_N = state.N_STATES
_ZERO_STATE = (0.0,) * _N
_BIAS_OF = operator.itemgetter(
    *(row * _N + state.BIAS.start + col for row in range(3) for col in range(3))
)
"""``dv'/db`` (3x3, row-major) of the generated ``dv'/dx`` (3x13, row-major)."""
_TRANSITION_ENTRIES = np.array(
    [0 * _N + 3, 1 * _N + 4, 2 * _N + 5]
    + [row * _N + col for row in range(3) for col in range(8, 11)]
    + [row * _N + col for row in range(3, 6) for col in range(8, 11)]
)
"""Flat positions in ``Phi`` of ``T`` (position rows, velocity columns), ``B_p`` and ``B_v``
(position and velocity rows, bias columns)."""
_WIND_NORTH, _WIND_EAST = range(state.WIND.start, state.WIND.stop)
"""The wind's rows (and columns) in ``Phi``: its decay over the batch on the diagonal."""


def product(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a @ b``, through ``np.dot`` when neither is stacked (at most 2-D: one member's arrays):
    the same BLAS call without the ``matmul`` gufunc's iterator, ~1-2 us less a product at 17
    states, bit for bit the same numbers (tests/test_dynamic_bank_exact.py)."""
    if a.ndim <= 2 and b.ndim <= 2:
        return _DOT(a, b)  # type: ignore[no-any-return]
    return a @ b


_DOT = np.dot
_EMPTY = np.empty

MEMBER_CORE = optional_core.load("tether_companion.estimation.dynamic._member_core")
"""The C extension ``_member_core`` (``member_core.c``) when it runs: one member's transition
step, projection and gain update in C loops over the arrays' buffers, to 1e-12 relative of the
numpy code here and in ``bank.py`` (the reference and the fallback; BLAS sums in its own order
with its own fused multiply-adds, so not bit for bit). Built by setup.py where a compiler is;
``TETHER_PURE_PYTHON=1`` keeps numpy."""


def batch_sums(
    d_p: list[float],
    d_v: list[float],
    b_p: list[float],
    b_v: list[float],
    dt_s: float,
    u: Sequence[float],
    c: Sequence[float],
) -> tuple[list[float], list[float], list[float], list[float]] | bool:
    """The sums ``D_p, D_v, B_p, B_v`` (new lists) with one IMU tick of ``dt_s`` [s] and
    inputs ``u`` added (:meth:`ImuBatch.add`), or ``False`` when ``dt_s`` is negative or
    anything is not finite. The reference of the C extension's ``batch_sums`` (the same
    operations in the same order; it returns ``None`` where this function must decide)."""
    if not (dt_s >= 0.0 and math.isfinite(dt_s) and math.isfinite(sum(u))):
        return False
    xdot, jac = generated.inertial(_ZERO_STATE, u, c)
    v0, v1, v2 = d_v
    c0, c1, c2, c3, c4, c5, c6, c7, c8 = b_v
    j0, j1, j2, j3, j4, j5, j6, j7, j8 = _BIAS_OF(jac)
    # written out (this runs at every IMU tick where the C extension is not built)
    return (
        [d_p[0] + dt_s * v0, d_p[1] + dt_s * v1, d_p[2] + dt_s * v2],
        [v0 + dt_s * xdot[3], v1 + dt_s * xdot[4], v2 + dt_s * xdot[5]],
        [
            b_p[0] + dt_s * c0,
            b_p[1] + dt_s * c1,
            b_p[2] + dt_s * c2,
            b_p[3] + dt_s * c3,
            b_p[4] + dt_s * c4,
            b_p[5] + dt_s * c5,
            b_p[6] + dt_s * c6,
            b_p[7] + dt_s * c7,
            b_p[8] + dt_s * c8,
        ],
        [
            c0 + dt_s * j0,
            c1 + dt_s * j1,
            c2 + dt_s * j2,
            c3 + dt_s * j3,
            c4 + dt_s * j4,
            c5 + dt_s * j5,
            c6 + dt_s * j6,
            c7 + dt_s * j7,
            c8 + dt_s * j8,
        ],
    )


_CORE_SUMS = generated.CORE.batch_sums if generated.CORE is not None else None
""":func:`batch_sums` in C where the extension runs (``generated.CORE``)."""


class BatchStep:
    """The step of one batch, fixed: its sums as they were when it was taken, with the
    transition built from them on first use (an estimate read later steps with the batch of
    its own tick). Read-only."""

    __slots__ = (
        "_phi",
        "_q",
        "_q_step",
        "b_p",
        "b_v",
        "d_p",
        "d_v",
        "duration_s",
        "ticks",
        "wind_decay_per_s",
    )

    def __init__(
        self,
        ticks: int,
        duration_s: float,
        d_p: list[float],
        d_v: list[float],
        b_p: list[float],
        b_v: list[float],
        wind_decay_per_s: float = 0.0,
    ) -> None:
        self.ticks = ticks
        self.wind_decay_per_s = wind_decay_per_s
        """The wind's reversion rate ``1 / tau`` [1/s] (0: a random walk)."""
        self.duration_s = duration_s
        """``T`` [s]."""
        self.d_p = d_p
        """``D_p`` [m]."""
        self.d_v = d_v
        """``D_v`` [m/s]."""
        self.b_p = b_p
        """``B_p`` [s^2], 3x3 row-major (NED position row, body bias column)."""
        self.b_v = b_v
        """``B_v`` [s], 3x3 row-major."""
        self._phi: FloatArray | None = None
        self._q: FloatArray | None = None
        self._q_step = _NO_ARRAY

    @property
    def phi(self) -> FloatArray:
        """``Phi`` (13, 13) (made once; do not change it)."""
        phi = self._phi
        if phi is None:
            t = self.duration_s
            phi = _IDENTITY.copy()
            phi.flat[_TRANSITION_ENTRIES] = (t, t, t, *self.b_p, *self.b_v)
            if self.wind_decay_per_s > 0.0:
                phi[_WIND_NORTH, _WIND_NORTH] = phi[_WIND_EAST, _WIND_EAST] = math.exp(
                    -t * self.wind_decay_per_s
                )
            self._phi = phi
        return phi

    def noise(self, q: FloatArray) -> FloatArray:
        """``T q`` (13, 13) for the process noise spectral density ``q`` (do not change it)."""
        if self._q is not q:
            self._q_step = q * self.duration_s
            self._q = q
        return self._q_step

    def step_state(self, x: FloatArray) -> FloatArray:
        """States (..., 17) stepped over the batch (new array): ``Phi x + (D_p, D_v, 0...)``
        (one state (17,): in C where :data:`MEMBER_CORE` runs and takes it)."""
        if MEMBER_CORE is not None and x.ndim == 1:
            out = _EMPTY(x.shape)
            if MEMBER_CORE.step(self.phi, x, self.d_p, self.d_v, out) is not None:
                return out
        out = product(x, self.phi.T)
        out += np.array((*self.d_p, *self.d_v, *_ZERO_STATE[6:]))
        return out

    def step_covariance(self, p: FloatArray, q: FloatArray) -> FloatArray:
        """``Phi P Phi^T + T Q`` (new array, exactly symmetric) for covariances ``p`` (..., 17,
        17) and the process noise spectral density ``q`` (17, 17)."""
        return self._covariance(p, q)[0]

    def step_member_covariance(self, p: FloatArray, q: FloatArray) -> tuple[FloatArray, bool]:
        """:meth:`step_covariance` of one covariance (17, 17) and whether it is finite."""
        out, finite = self._covariance(p, q)
        return out, math.isfinite(_ADD_REDUCE(out, None)) if finite is None else finite

    def _covariance(self, p: FloatArray, q: FloatArray) -> tuple[FloatArray, bool | None]:
        """:meth:`step_covariance`, in C where :data:`MEMBER_CORE` runs and takes one
        covariance (the C product skips ``Phi``'s zeros and says whether the result is
        finite), else numpy (finiteness not checked: ``None``)."""
        phi = self.phi
        if MEMBER_CORE is not None and p.ndim == 2:
            out = _EMPTY(p.shape)
            finite = MEMBER_CORE.step_covariance(phi, p, q, self.duration_s, out)
            if finite is not None:
                return out, finite
        out = product(product(phi, p), phi.T)
        out = out + out.swapaxes(-1, -2)  # a new array: no copy of the overlapping operand
        out *= 0.5
        out += self.noise(q)
        return out, None


_ADD_REDUCE = np.add.reduce
_NO_ARRAY = np.zeros((0, 0))
_IDENTITY = np.eye(_N)
"""Copied for each ``Phi`` (cheaper than making it)."""


class ImuBatch:
    """The summed inertial step of the IMU ticks since the last :meth:`clear`; the wind
    reverts toward calm at ``wind_decay_per_s`` [1/s] (``noise.wind_decay_per_s``; 0: a random
    walk)."""

    __slots__ = ("_step", "b_p", "b_v", "d_p", "d_v", "duration_s", "ticks", "wind_decay_per_s")

    def __init__(self, wind_decay_per_s: float = 0.0) -> None:
        self.wind_decay_per_s = wind_decay_per_s
        self.clear()

    def clear(self) -> None:
        """Start an empty batch."""
        self.ticks = 0
        self.duration_s = 0.0
        """``T`` [s]."""
        self.d_p = [0.0, 0.0, 0.0]
        """``D_p`` [m]."""
        self.d_v = [0.0, 0.0, 0.0]
        """``D_v`` [m/s]."""
        self.b_p = [0.0] * 9
        """``B_p`` [s^2], 3x3 row-major (NED position row, body bias column)."""
        self.b_v = [0.0] * 9
        """``B_v`` [s], 3x3 row-major."""
        self._step: BatchStep | None = None

    def add(self, dt_s: float, u: Sequence[float], c: Sequence[float]) -> bool:
        """One IMU tick of ``dt_s`` [s] with the inputs ``u = (R_v^b row-major, f_x, f_y,
        f_z)`` (floats; specific force [m/s^2], FRD body) and constants ``c``. ``False`` (the
        batch unchanged) when ``dt_s`` is negative or anything is not finite."""
        sums = None
        if _CORE_SUMS is not None:
            sums = _CORE_SUMS(self.d_p, self.d_v, self.b_p, self.b_v, dt_s, u, c)
        if sums is None:
            sums = batch_sums(self.d_p, self.d_v, self.b_p, self.b_v, dt_s, u, c)
        if sums is False:
            return False
        # new lists every tick (never changed in place): a BatchStep keeps them as they were
        self.d_p, self.d_v, self.b_p, self.b_v = sums
        self.duration_s += dt_s
        self.ticks += 1
        self._step = None
        return True

    def step(self) -> BatchStep:
        """The batch's step as it is now (the same object until a tick is added or the batch
        cleared)."""
        step = self._step
        if step is None:
            step = self._step = BatchStep(
                self.ticks,
                self.duration_s,
                self.d_p,
                self.d_v,
                self.b_p,
                self.b_v,
                self.wind_decay_per_s,
            )
        return step

    def step_state(self, x: FloatArray, q: FloatArray) -> FloatArray:
        """States (..., 13) stepped over the batch (new array): ``Phi x + (D_p, D_v, 0...)``
        (``q`` unused: the state's step has no noise; kept for symmetry with
        :meth:`step_covariance`)."""
        return self.step().step_state(x)

    def step_covariance(self, p: FloatArray, q: FloatArray) -> FloatArray:
        """``Phi P Phi^T + T Q`` (new array, exactly symmetric) for covariances ``p`` (..., 13,
        13) and the process noise spectral density ``q`` (13, 13)."""
        return self.step().step_covariance(p, q)
