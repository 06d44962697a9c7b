"""Discrete-time multi-input single-output linear models in polynomial form (paper eq. 38).

Every linear structure (ARX, output error, Box-Jenkins, state space, transfer function,
process model) is held as

    y(t) = sum_i B_i(q) / F(q) u_i(t) + C(q) / D(q) e(t)

with ``q`` the backward shift, one common denominator ``F`` for all inputs, and signals taken
relative to an operating point (``u - u0``, ``y - y0``). ARX is ``F = D = A, C = 1``; output
error is ``C = D = 1``; a state-space innovations model has ``F = D = det(I - A q)``.
Polynomials are coefficient arrays in powers of ``q^-1`` starting at ``q^0``; ``F``, ``C``,
``D`` are monic.

The k-step-ahead predictor is ``y_hat(t|t-k) = y(t) + W_k(q) (G(q) u(t) - y(t))`` with
``W_k = H_k_bar / H`` and ``H_k_bar`` the first ``k`` impulse-response terms of ``H = C/D``
(Ljung, System Identification, eq. 3.31); ``k = 1`` gives the one-step predictor and
``k -> inf`` pure simulation.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter, lfilter_zi

from tether_companion.sysid.input_map import InputMap
from tether_companion.sysid.processing import IdData

FloatArray = NDArray[np.float64]


def steady_filter(b: FloatArray, a: FloatArray, x: FloatArray) -> FloatArray:
    """``lfilter(b, a, x)`` started in steady state for the constant input ``x[0]``.

    Parameters
    ----------
    b, a
        Numerator and denominator in powers of ``q^-1``.
    x
        Input, shape (n,).
    """
    n = max(len(a), len(b))
    if n == 1:
        return lfilter(b, a, x)
    try:
        zi = lfilter_zi(b, a) * x[0]
    except (np.linalg.LinAlgError, ValueError):
        zi = np.zeros(n - 1)
    if not np.all(np.isfinite(zi)):
        zi = np.zeros(n - 1)
    return lfilter(b, a, x, zi=zi)[0]


def impulse_response(num: FloatArray, den: FloatArray, n: int) -> FloatArray:
    """First ``n`` impulse-response coefficients of ``num / den``."""
    pulse = np.zeros(n)
    pulse[0] = 1.0
    return lfilter(num, den, pulse)


@dataclass(frozen=True)
class PolynomialModel:
    """A MISO model ``y = sum_i B_i/F u_i + C/D e`` about an operating point.

    Attributes
    ----------
    f
        Common denominator of the input paths, monic, shape (nf + 1,).
    b
        Numerators, shape (n_inputs, nb + 1), leading zeros for input delay.
    c, d
        Noise numerator and denominator, monic.
    u0
        Input operating point, shape (n_inputs,), in the input map's unit.
    y0_n
        Output operating point [N].
    dt_s
        Sample time [s].
    input_map
        Static map from PWM [us] to the model inputs (identity by default).
    """

    f: FloatArray
    b: FloatArray
    c: FloatArray = field(default_factory=lambda: np.ones(1))
    d: FloatArray = field(default_factory=lambda: np.ones(1))
    u0: FloatArray = field(default_factory=lambda: np.zeros(4))
    y0_n: float = 0.0
    dt_s: float = 0.01
    input_map: InputMap = field(default_factory=InputMap)

    def response(self, du: FloatArray) -> FloatArray:
        """``G(q) du`` [N], shape (n,), for input deviations ``du = u - u0``, shape (n, m),
        started in steady state."""
        return sum(steady_filter(self.b[i], self.f, du[:, i]) for i in range(self.b.shape[0]))

    def simulate(self, data: IdData) -> FloatArray:
        """Pure simulation: thrust [N], shape (n,), from the inputs alone."""
        return self.y0_n + self.response(self.input_map.inputs(data) - self.u0)

    def predict(self, data: IdData, k: int) -> FloatArray:
        """k-step-ahead prediction [N], shape (n,), from inputs and measured thrust.

        ``y_hat(t)`` uses measured thrust up to ``t - k`` and inputs up to ``t``.
        """
        du = self.input_map.inputs(data) - self.u0
        return self.y0_n + self.predict_deviation(du, data.thrust_n - self.y0_n, k)

    def predict_deviation(self, du: FloatArray, dy: FloatArray, k: int) -> FloatArray:
        """k-step-ahead prediction of ``y - y0`` from ``du = u - u0`` (n, m) and ``dy`` (n,)."""
        error = self.response(du) - dy
        h_bar = impulse_response(self.c, self.d, k)
        return dy + steady_filter(np.convolve(h_bar, self.d), self.c, error)

    @property
    def n_params(self) -> int:
        """Free parameters: denominator and noise coefficients plus non-delay numerator terms.

        A noise denominator equal to ``F`` (ARX, state space) is shared, counted once.
        """
        free_b = int(np.count_nonzero(np.any(self.b != 0.0, axis=0))) * self.b.shape[0]
        shared_d = len(self.d) == len(self.f) and bool(np.array_equal(self.d, self.f))
        noise_d = 0 if shared_d else len(self.d) - 1
        return len(self.f) - 1 + free_b + len(self.c) - 1 + noise_d

    def is_stable(self) -> bool:
        """All poles of ``1/F`` inside the unit circle."""
        return bool(np.all(np.abs(np.roots(self.f)) < 1.0)) if len(self.f) > 1 else True

    def state_space(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Observer canonical form of the input paths: ``(A, B, C, D)`` with shapes
        (n, n), (n, m), (1, n), (1, m); ``x(t+1) = A x + B du``, ``dy = C x + D du``."""
        n = max(len(self.f), self.b.shape[1]) - 1
        f = np.zeros(n + 1)
        f[: len(self.f)] = self.f
        b = np.zeros((self.b.shape[0], n + 1))
        b[:, : self.b.shape[1]] = self.b
        a_matrix = np.zeros((n, n))
        a_matrix[:, 0] = -f[1:]
        a_matrix[:-1, 1:] = np.eye(n - 1)
        b_matrix = (b[:, 1:] - np.outer(b[:, 0], f[1:])).T
        c_matrix = np.zeros((1, n))
        c_matrix[0, 0] = 1.0
        d_matrix = b[:, :1].T.copy()
        return a_matrix, b_matrix, c_matrix, d_matrix
