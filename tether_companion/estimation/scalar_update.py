"""The EKF's gated Joseph-form measurement update as straight-line scalar code, for small filters.

For the paper's 3- and 4-state filters (3 accelerometer components, 1 altimeter) numpy's
per-call overhead (~1 us a call, a dozen calls an update) costs more than the arithmetic, and
Python loops or generator expressions cost more again. So the update for a given state size
``n`` and measurement size ``m`` is *generated* here as one straight-line Python function
(every product written out, no loop, no array), compiled once per ``(n, m)`` and cached. The
algebra is :meth:`~tether_companion.estimation.ekf.ExtendedKalmanFilter.update`'s, step for
step, with noise ``R = r I`` (``r`` [measurement units^2] on each axis):

* ``T = P H^T``, ``S = H T + r I``, its Cholesky factor (a non-positive or NaN pivot means
  "not positive definite", as LAPACK's dpotrf) and ``NIS = y^T S^-1 y``;
* the gate: ``NIS > threshold`` rejects (a NaN NIS passes, as in the numpy path, and is then
  caught by the finite check);
* ``K = T S^-1``, ``x + K y``;
* the Joseph form ``(I - K H) P (I - K H)^T + r K K^T``, associated to save products:
  ``B = (I - K H) P = P - K T^T``, ``B (I - K H)^T = B - (B H^T) K^T``, so the result is
  ``B - D K^T`` with ``D = B H^T - r K``, which is ``T - K S`` (``H T = H P H^T = S - r I``):
  it vanishes for the exact optimal gain, the Joseph form's first-order correction of
  rounding in ``K``, and the identity holds for any ``K``. Only the lower triangles of ``B``
  and of the result are computed, the result mirrored, so it is exactly symmetric;
* a finite check of the new state and covariance, and the Cholesky test of the covariance.

Only the summation order differs from the BLAS path, so states agree to rounding (~1e-15
relative; the tests hold them to 1e-9). Counting, forced fusion and repairs stay in the
filter. Matrices travel as flat row-major lists of floats (``P`` n*n, ``H`` m*n).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

UpdateOutcome = tuple[float, list[float] | None, list[float] | None, bool] | None
"""What an :func:`updater` function returns (see there)."""


def compile_function(name: str, body: list[str], arguments: str) -> Callable:
    """Compile the generated statements ``body`` as ``def {name}({arguments})`` (``sqrt`` and
    ``isfinite`` in scope) and return the function."""
    source = f"def {name}({arguments}):\n" + "".join(f"    {line}\n" for line in body)
    namespace: dict = {"sqrt": math.sqrt, "isfinite": math.isfinite}
    exec(compile(source, f"<generated {name}>", "exec"), namespace)  # noqa: S102
    return namespace[name]


def sum_of(terms: list[str | None]) -> str:
    """The generated expression adding ``terms``, leaving out ``None`` (``0.0`` for none)."""
    kept = [t for t in terms if t is not None]
    return " + ".join(kept) if kept else "0.0"


def times(coefficient: float | str, name: str) -> str | None:
    """``coefficient * name`` as generated code: ``coefficient`` is the name of a variable, or
    a constant written in as a literal (exact: ``repr`` of a float round-trips); ``None`` for a
    zero constant, the bare (or negated) name for +-1."""
    if isinstance(coefficient, str):
        return f"{coefficient} * {name}"
    if coefficient == 0.0:
        return None
    if coefficient == 1.0:
        return name
    if coefficient == -1.0:
        return f"-{name}"
    return f"{coefficient!r} * {name}"


def _cholesky_lines(size: int, entry: Callable[[int, int], str], low: str, fail: str) -> list[str]:
    """Statements computing the lower Cholesky factor ``{low}{i}_{j}`` of the symmetric matrix
    whose lower-triangle entries ``entry(i, j)`` name; ``fail`` (a statement) on a bad pivot."""
    lines = []
    for j in range(size):
        diag = " - ".join([entry(j, j)] + [f"{low}{j}_{k} * {low}{j}_{k}" for k in range(j)])
        lines += [f"d = {diag}", "if not d > 0.0:", f"    {fail}", f"{low}{j}_{j} = sqrt(d)"]
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
def updater(
    n: int, m: int, constant_h: tuple[float, ...] | None = None
) -> Callable[..., UpdateOutcome]:
    """The update of an n-state filter by an m-dimensional measurement, compiled once:
    ``update(x, p, h, y, r, threshold)`` with the state ``x`` (n values), covariance ``p`` (n*n,
    row-major), Jacobian ``h`` (m*n, row-major), innovation ``y = z - h(x)`` (m values), noise
    ``r`` on each axis and the gate's NIS ``threshold``.

    With ``constant_h`` (the m*n entries of a Jacobian that never changes, such as the
    altimeter's ``[0, 0, -1, 0]``) its entries are written in as literals and the products with
    its zeros left out; the function then ignores its ``h`` argument. Multiplying by 0 or +-1
    is exact, so the result is the same as the general function's for finite inputs.

    The function returns

    * ``None`` when ``S`` is not positive definite (singular, or NaN/inf somewhere);
    * ``(nis, None, None, False)`` when gated (``nis > threshold``; nothing more computed);
    * ``(nis, x_new, None, False)`` when the updated state or covariance is not finite;
    * ``(nis, x_new, p_new, positive_definite)`` when fused: the new state (list of n), the
      new covariance (list of n*n, exactly symmetric) and whether it passed the Cholesky test.
    """
    x = [f"x{i}" for i in range(n)]
    p = [f"p{i}_{j}" for i in range(n) for j in range(n)]
    y = [f"y{a}" for a in range(m)]
    body = [_unpack(p, "p"), _unpack(y, "y")]
    if constant_h is None:
        h: list[float | str] = [f"h{a}_{j}" for a in range(m) for j in range(n)]
        body.append(_unpack(h, "h"))  # type: ignore[arg-type]
    else:
        if len(constant_h) != m * n:
            raise ValueError(f"constant_h needs {m * n} entries, got {len(constant_h)}")
        h = [float(v) for v in constant_h]
    for i in range(n):  # T = P H^T
        for a in range(m):
            terms = [times(h[a * n + k], f"p{i}_{k}") for k in range(n)]
            body.append(f"t{i}_{a} = " + sum_of(terms))
    for a in range(m):  # S, lower triangle
        for b in range(a + 1):
            expr = sum_of([times(h[a * n + k], f"t{k}_{b}") for k in range(n)])
            body.append(f"s{a}_{b} = {expr}" + (" + r" if a == b else ""))
    if m == 1:
        body += ["if not s0_0 > 0.0:", "    return None", "nis = y0 * y0 / s0_0"]
    else:
        body += _cholesky_lines(m, lambda i, j: f"s{i}_{j}", "l", "return None")
        body += _solve_lines(m, "l", y, "w")
        body.append("nis = " + sum_of([f"y{a} * w{a}" for a in range(m)]))
    body += ["if nis > threshold:", "    return nis, None, None, False"]
    if m == 1:
        body += [f"k{i}_0 = t{i}_0 / s0_0" for i in range(n)]
    else:
        for i in range(n):
            body += _solve_lines(m, "l", [f"t{i}_{a}" for a in range(m)], f"k{i}_")
    body.append(_unpack(x, "x"))
    for i in range(n):
        body.append(f"u{i} = x{i} + " + sum_of([f"k{i}_{a} * y{a}" for a in range(m)]))
    for i in range(n):  # B = (I - K H) P = P - K T^T, lower triangle
        for j in range(i + 1):
            kt = sum_of([f"k{i}_{c} * t{j}_{c}" for c in range(m)])
            body.append(f"b{i}_{j} = p{i}_{j} - ({kt})")
    for i in range(n):  # D = B H^T - r K = T - K S
        for a in range(m):
            ks = sum_of([f"k{i}_{c} * s{max(c, a)}_{min(c, a)}" for c in range(m)])
            body.append(f"e{i}_{a} = t{i}_{a} - ({ks})")
    for i in range(n):  # B - D K^T, lower triangle
        for j in range(i + 1):
            dk = sum_of([f"e{i}_{c} * k{j}_{c}" for c in range(m)])
            body.append(f"q{i}_{j} = b{i}_{j} - ({dk})")
    lower = [f"q{max(i, j)}_{min(i, j)}" for i in range(n) for j in range(n)]
    new_x = [f"u{i}" for i in range(n)]
    new_lower = [f"q{i}_{j}" for i in range(n) for j in range(i + 1)]
    body += [
        f"if not isfinite({sum_of(new_x + new_lower)}):",
        f"    return nis, [{', '.join(new_x)}], None, False",
    ]
    fused = f"nis, [{', '.join(new_x)}], [{', '.join(lower)}]"
    body += _cholesky_lines(n, lambda i, j: f"q{i}_{j}", "c", f"return {fused}, False")
    body.append(f"return {fused}, True")
    return compile_function("update", body, "x, p, h, y, r, threshold")
