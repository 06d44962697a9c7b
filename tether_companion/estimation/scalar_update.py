"""The EKF's gated Joseph-form measurement update as straight-line scalar code, for small filters.

For the paper's 3- and 4-state filters (3 accelerometer components, 1 altimeter) numpy's
per-call overhead (~1 us a call, a dozen calls an update) costs more than the arithmetic, and
Python loops or generator expressions cost more again. So the update for a given state size
``n`` and measurement size ``m`` is *generated* here as one straight-line Python function per
stage (every product written out, no loop, no array), compiled once per ``(n, m)`` and cached.
The algebra is :meth:`~tether_companion.estimation.ekf.ExtendedKalmanFilter.update`'s, step
for step:

* :func:`innovate`: ``P H^T``, ``S = H P H^T + r I`` (noise ``r`` [measurement units^2] on
  each axis), its Cholesky factor (a non-positive or NaN pivot means "not positive definite",
  as LAPACK's dpotrf) and ``NIS = y^T S^-1 y``;
* :func:`fuse`: ``K = P H^T S^-1``, ``x + K y`` and the Joseph form
  ``(I - K H) P (I - K H)^T + r K K^T``, symmetrised as ``(P + P^T) / 2``;
* :func:`is_positive_definite`: the Cholesky test of the updated covariance.

Only the summation order differs from the BLAS path, so states agree to rounding (~1e-15
relative; the tests hold them to 1e-9). Gating, counting and repairs stay in the filter.
Matrices travel as flat row-major tuples/lists of floats (``P`` n*n, ``H`` m*n).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable


def _compile(name: str, source: str) -> Callable:
    namespace: dict = {"sqrt": math.sqrt}
    exec(compile(source, f"<scalar_update {name}>", "exec"), namespace)  # noqa: S102
    return namespace[name]


def _cholesky_lines(size: int, entry: Callable[[int, int], str], low: str) -> list[str]:
    """Statements computing the lower Cholesky factor ``{low}{i}_{j}`` of the symmetric matrix
    whose lower-triangle entries ``entry(i, j)`` name; ``return None`` on a failed pivot."""
    lines = []
    for j in range(size):
        diag = " - ".join([entry(j, j)] + [f"{low}{j}_{k} * {low}{j}_{k}" for k in range(j)])
        lines += [f"d = {diag}", "if not d > 0.0:", "    return None", f"{low}{j}_{j} = sqrt(d)"]
        for i in range(j + 1, size):
            terms = " - ".join([entry(i, j)] + [f"{low}{i}_{k} * {low}{j}_{k}" for k in range(j)])
            lines.append(f"{low}{i}_{j} = ({terms}) / {low}{j}_{j}")
    return lines


def _solve_lines(size: int, low: str, rhs: list[str], out: str) -> list[str]:
    """Statements solving ``L L^T {out} = rhs`` with the factor ``{low}{i}_{j}``."""
    lines = []
    for i in range(size):
        terms = " - ".join([rhs[i]] + [f"{low}{i}_{k} * {out}f{k}" for k in range(i)])
        lines.append(f"{out}f{i} = ({terms}) / {low}{i}_{i}")
    for i in range(size - 1, -1, -1):
        terms = " - ".join(
            [f"{out}f{i}"] + [f"{low}{k}_{i} * {out}{k}" for k in range(i + 1, size)]
        )
        lines.append(f"{out}{i} = ({terms}) / {low}{i}_{i}")
    return lines


def _unpack(names: list[str], source: str) -> str:
    return f"({', '.join(names)},) = {source}"


@functools.cache
def _innovate(n: int, m: int) -> Callable:
    p = [f"p{i}_{j}" for i in range(n) for j in range(n)]
    h = [f"h{a}_{j}" for a in range(m) for j in range(n)]
    y = [f"y{a}" for a in range(m)]
    body = [_unpack(p, "p"), _unpack(h, "h"), _unpack(y, "y")]
    for i in range(n):  # t = P H^T
        for a in range(m):
            body.append(f"t{i}_{a} = " + " + ".join(f"p{i}_{k} * h{a}_{k}" for k in range(n)))
    for a in range(m):  # S, lower triangle
        for b in range(a + 1):
            expr = " + ".join(f"h{a}_{k} * t{k}_{b}" for k in range(n))
            body.append(f"s{a}_{b} = {expr}" + (" + r" if a == b else ""))
    t = ", ".join(f"t{i}_{a}" for i in range(n) for a in range(m))
    if m == 1:
        body += [
            "if not s0_0 > 0.0:",
            "    return None",
            f"return y0 * y0 / s0_0, ({t},), (s0_0,)",
        ]
    else:
        body += _cholesky_lines(m, lambda i, j: f"s{i}_{j}", "l")
        body += _solve_lines(m, "l", y, "w")
        nis = " + ".join(f"y{a} * w{a}" for a in range(m))
        factor = ", ".join(f"l{i}_{j}" for i in range(m) for j in range(i + 1))
        body.append(f"return {nis}, ({t},), ({factor},)")
    source = "def innovate(p, h, y, r):\n" + "".join(f"    {line}\n" for line in body)
    return _compile("innovate", source)


def innovate(
    p: list[float], h: list[float], y: list[float], r: float
) -> tuple[float, tuple, tuple] | None:
    """``(NIS, P H^T, factor)`` of one measurement, or None when ``S`` is not positive definite
    (or not finite). ``factor`` is ``(S,)`` for m = 1, else the Cholesky factor's lower
    triangle row by row."""
    return _innovate(len(h) // len(y), len(y))(p, h, y, r)


@functools.cache
def _fuse(n: int, m: int) -> Callable:
    x = [f"x{i}" for i in range(n)]
    p = [f"p{i}_{j}" for i in range(n) for j in range(n)]
    h = [f"h{a}_{j}" for a in range(m) for j in range(n)]
    y = [f"y{a}" for a in range(m)]
    t = [f"t{i}_{a}" for i in range(n) for a in range(m)]
    body = [_unpack(x, "x"), _unpack(p, "p"), _unpack(h, "h"), _unpack(y, "y"), _unpack(t, "t")]
    if m == 1:
        body.append("(s,) = factor")
        body += [f"k{i}_0 = t{i}_0 / s" for i in range(n)]
    else:
        low = [f"l{i}_{j}" for i in range(m) for j in range(i + 1)]
        body.append(_unpack(low, "factor"))
        for i in range(n):
            body += _solve_lines(m, "l", [f"t{i}_{a}" for a in range(m)], f"k{i}_")
    for i in range(n):
        body.append(f"u{i} = x{i} + " + " + ".join(f"k{i}_{a} * y{a}" for a in range(m)))
    for i in range(n):  # A = I - K H
        for j in range(n):
            kh = " + ".join(f"k{i}_{c} * h{c}_{j}" for c in range(m))
            body.append(f"a{i}_{j} = {'1.0' if i == j else '0.0'} - ({kh})")
    for i in range(n):  # A P
        for j in range(n):
            body.append(f"b{i}_{j} = " + " + ".join(f"a{i}_{k} * p{k}_{j}" for k in range(n)))
    for i in range(n):  # A P A^T + r K K^T, both triangles (then averaged like (P + P^T)/2)
        for j in range(n):
            apa = " + ".join(f"b{i}_{k} * a{j}_{k}" for k in range(n))
            kk = " + ".join(f"k{i}_{c} * k{j}_{c}" for c in range(m))
            body.append(f"q{i}_{j} = {apa} + r * ({kk})")
    entries = [f"(q{i}_{j} + q{j}_{i}) * 0.5" for i in range(n) for j in range(n)]
    body.append(f"return [{', '.join(f'u{i}' for i in range(n))}], [{', '.join(entries)}]")
    source = "def fuse(x, p, h, y, r, t, factor):\n" + "".join(f"    {line}\n" for line in body)
    return _compile("fuse", source)


def fuse(
    x: list[float],
    p: list[float],
    h: list[float],
    y: list[float],
    r: float,
    pht: tuple,
    factor: tuple,
) -> tuple[list[float], list[float]]:
    """The updated state (n values) and covariance (n*n values, row-major), from
    :func:`innovate`'s ``pht`` and ``factor``."""
    return _fuse(len(x), len(y))(x, p, h, y, r, pht, factor)


@functools.cache
def _positive_definite(n: int) -> Callable:
    p = [f"p{i}_{j}" for i in range(n) for j in range(n)]
    body = [_unpack(p, "p")]
    body += _cholesky_lines(n, lambda i, j: f"p{i}_{j}", "l")
    body.append("return True")
    source = "def positive_definite(p):\n" + "".join(f"    {line}\n" for line in body)
    return _compile("positive_definite", source)


def is_positive_definite(p: list[float], n: int) -> bool:
    """Whether the symmetric n x n matrix ``p`` (flat, row-major) has a Cholesky factor."""
    return _positive_definite(n)(p) is True
