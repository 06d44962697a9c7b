"""The tension Kalman filter (Martins 2019 eqs. 43-47) over an ``(n, 3)`` state, as generated
scalar code.

``n`` history taps per NED axis (``n = 1`` for the constant model of eqs. 48-49, ``n = 3`` for
the derivative model of eqs. 51-53), one covariance shared by the three axes (same noise on
each, uncorrelated between them), ``C`` picking the newest tap. Per step:

* predict (eqs. 43-44): ``x <- A x``, ``P <- A P A^T + Q``;
* update (eqs. 45-47) with the observation ``y`` (3 values, NED [N]): innovation
  ``v = y - x_newest``, ``s = P_cc + R``, gain ``g = P e_c / s``, ``x <- x + g v^T``, and the
  Joseph form ``P <- (I - g e_c^T) P (I - g e_c^T)^T + R g g^T``, which keeps P symmetric
  positive semi-definite in floating point.

At this size numpy's per-call overhead is most of the cost, so both steps are generated as
straight-line Python per filter, with ``A``, ``Q`` and ``R`` written in as literals (exact:
``repr`` of a float round-trips) and the products with their zero entries left out (the
derivative model's ``A`` is a companion matrix, its ``Q`` one non-zero entry). The covariance
keeps its lower triangle, mirrored, so it is exactly symmetric. The state and covariance are
flat row-major lists (``x`` n*3, ``P`` n*n).

Where the optional C extension ``_tension_core`` is built (``setup.py``; not with
``TETHER_PURE_PYTHON=1``) its twins of the two generated functions run instead: the same
floats (``tension_core.c`` applies the generator's rules to ``A``, ``Q`` and ``R`` at run time,
in the same order), the generated function called wherever they could differ.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation import optional_core
from tether_companion.estimation.scalar_update import compile_function, sum_of, times

FloatArray = NDArray[np.float64]

CORE = optional_core.load("tether_companion.estimation._tension_core")
"""The C extension ``_tension_core`` when it runs (None: the generated Python functions)."""


def _lower(n: int, name: str) -> list[str]:
    """The n*n row-major entries of a symmetric matrix kept as its lower triangle."""
    return [f"{name}{max(i, j)}_{min(i, j)}" for i in range(n) for j in range(n)]


@functools.cache
def _predict(a: tuple[tuple[float, ...], ...], q: tuple[tuple[float, ...], ...]):
    n = len(a)
    x = [f"x{i}_{k}" for i in range(n) for k in range(3)]
    p = [f"p{i}_{j}" for i in range(n) for j in range(n)]
    body = [f"({', '.join(x)},) = x", f"({', '.join(p)},) = p"]
    new_x = []
    for i in range(n):
        for k in range(3):
            new_x.append(sum_of([times(a[i][j], f"x{j}_{k}") for j in range(n)]))
    for i in range(n):  # M = A P
        for j in range(n):
            body.append(f"m{i}_{j} = " + sum_of([times(a[i][k], f"p{k}_{j}") for k in range(n)]))
    for i in range(n):  # M A^T + Q, lower triangle
        for j in range(i + 1):
            terms = [times(a[j][k], f"m{i}_{k}") for k in range(n)]
            terms.append(repr(q[i][j]) if q[i][j] != 0.0 else None)
            body.append(f"q{i}_{j} = " + sum_of(terms))
    body.append(f"return [{', '.join(new_x)}], [{', '.join(_lower(n, 'q'))}]")
    return compile_function("predict", body, "x, p")


@functools.cache
def _update(n: int, r: float):
    c = n - 1
    x = [f"x{i}_{k}" for i in range(n) for k in range(3)]
    p = [f"p{i}_{j}" for i in range(n) for j in range(n)]
    body = [f"({', '.join(x)},) = x", f"({', '.join(p)},) = p"]
    body += [f"v{k} = y{k} - x{c}_{k}" for k in range(3)]
    body.append(f"s = p{c}_{c} + {r!r}")
    body += [f"g{i} = p{i}_{c} / s" for i in range(n)]
    new_x = [f"x{i}_{k} + g{i} * v{k}" for i in range(n) for k in range(3)]
    for i in range(n):  # B = (I - g e_c^T) P
        for j in range(n):
            body.append(f"b{i}_{j} = p{i}_{j} - g{i} * p{c}_{j}")
    for i in range(n):  # B (I - g e_c^T)^T + R g g^T, lower triangle
        for j in range(i + 1):
            body.append(f"q{i}_{j} = b{i}_{j} - b{i}_{c} * g{j} + {r!r} * g{i} * g{j}")
    body.append(f"return [{', '.join(new_x)}], [{', '.join(_lower(n, 'q'))}], [v0, v1, v2]")
    return compile_function("update", body, "x, p, y0, y1, y2")


def _as_tuple(matrix: FloatArray) -> tuple[tuple[float, ...], ...]:
    return tuple(tuple(float(v) for v in row) for row in matrix)


class TensionKalmanFilter:
    """Linear KF over an ``(n, 3)`` state: ``n`` history taps per NED axis, shared covariance.

    The newest tap (last row) is the tension estimate. Pure: no clocks, no I/O.

    Parameters
    ----------
    transition
        ``A``, shape (n, n).
    process_noise_n2
        ``Q`` per step, shape (n, n), symmetric [N^2].
    measurement_variance_n2
        ``R`` per axis [N^2] (``C`` picks the newest tap).
    initial_variance_n2
        ``P0 = initial_variance_n2 I`` at (re)start [N^2].
    """

    def __init__(
        self,
        transition: FloatArray,
        process_noise_n2: FloatArray,
        measurement_variance_n2: float,
        initial_variance_n2: float,
    ) -> None:
        self.A = np.asarray(transition, dtype=float)
        self.Q = np.asarray(process_noise_n2, dtype=float)
        self.R = float(measurement_variance_n2)
        self.n = self.A.shape[0]
        self._p0 = float(initial_variance_n2)
        a, q = _as_tuple(self.A), _as_tuple(self.Q)
        self._predict = _predict(a, q)
        self._update = _update(self.n, self.R)
        if CORE is not None:  # the same floats; the generated function where C could differ
            flat_a, flat_q = sum(a, ()), sum(q, ())
            self._predict = functools.partial(CORE.predict, self._predict, flat_a, flat_q)
            self._update = functools.partial(CORE.update, self._update, self.R)
        self._x = [0.0] * (3 * self.n)
        self._p = self._initial_covariance()
        self.started = False

    def _initial_covariance(self) -> list[float]:
        n = self.n
        return [self._p0 if i == j else 0.0 for i in range(n) for j in range(n)]

    @property
    def x(self) -> FloatArray:
        """A copy of the state, shape (n, 3): the taps, oldest first [N]."""
        return np.array(self._x).reshape(self.n, 3)

    @property
    def P(self) -> FloatArray:  # noqa: N802 (the covariance's usual name)
        """A copy of the covariance shared by the three axes, shape (n, n) [N^2]."""
        return np.array(self._p).reshape(self.n, self.n)

    @property
    def tension_ned_n(self) -> FloatArray:
        """Current tension estimate, NED [N], shape (3,)."""
        return np.array(self._x[-3:])

    def tension_values(self) -> list[float]:
        """Current tension estimate, NED [N], as a new list of 3 floats (no array)."""
        return self._x[-3:]

    @property
    def variance_n2(self) -> float:
        """Variance of the current estimate on each axis [N^2]."""
        return self._p[-1]

    def restart(self, observation_ned_n: FloatArray | list[float]) -> None:
        """Start from one observation (3 values, NED [N]): every tap equals it, ``P = P0``."""
        n0, e0, d0 = (float(v) for v in observation_ned_n)
        self._x = [n0, e0, d0] * self.n
        self._p = self._initial_covariance()
        self.started = True

    def predict(self) -> None:
        """One step of the model (eqs. 43-44)."""
        self._x, self._p = self._predict(self._x, self._p)

    def update(self, observation_ned_n: FloatArray | list[float]) -> list[float]:
        """Correct with one observation (3 values, NED [N]; eqs. 45-47, Joseph form); returns
        the innovation (3 values [N])."""
        y0, y1, y2 = observation_ned_n
        self._x, self._p, innovation = self._update(self._x, self._p, y0, y1, y2)
        return innovation
