"""The tension filter's predict/update in C (``_tension_core``) against the generated Python
functions of ``tension_filter.py``: the same floats bit for bit, and the Python function's
result or exception wherever C could differ.

The extension is optional (no compiler: the Python functions run). Its absence fails this file
where it could have been built (a C compiler and the Python headers here) or with
``TETHER_REQUIRE_CORE=1``, as ``test_generated_core.py`` does.
"""

from __future__ import annotations

import functools
import math
import os
import struct

import numpy as np
import pytest
from optional_extension import import_extension

from tether_companion.estimation import tension_filter
from tether_companion.estimation.tension_filter import TensionKalmanFilter
from tether_companion.estimation.tension_kf import TensionFilterConfig

core, pytestmark = import_extension("tether_companion.estimation._tension_core")


def _bits(values: object) -> object:
    """Nested lists/tuples of floats by their bit patterns (-0.0 != 0.0, NaNs compare)."""
    if isinstance(values, (list, tuple)):
        return [type(values).__name__, [_bits(v) for v in values]]
    if isinstance(values, float):
        return struct.pack("<d", values)
    return values


def _matrix(rng: np.random.Generator, n: int) -> tuple[tuple[float, ...], ...]:
    """A random n x n matrix with the generator's special entries: 0, -0, 1, -1 and others."""
    choices = [0.0, -0.0, 1.0, -1.0, 0.5, -2.0]
    rows = []
    for _ in range(n):
        row = []
        for _ in range(n):
            pick = rng.integers(0, len(choices) + 3)
            value = choices[pick] if pick < len(choices) else float(rng.normal(0.0, 3.0))
            row.append(value)
        rows.append(tuple(row))
    return tuple(rows)


def _floats(rng: np.random.Generator, count: int) -> list[float]:
    scale = 10.0 ** rng.uniform(-6, 6, count)
    values = [float(v) for v in rng.normal(0.0, 1.0, count) * scale]
    for i in rng.integers(0, count, rng.integers(0, 3)):  # zeros, now and then NaN or inf
        values[i] = [0.0, -0.0, 0.0, -0.0, math.nan, math.inf, -math.inf][rng.integers(0, 7)]
    return values


def _pair(a, q, r):
    """(Python predict, C predict, Python update, C update) for A = a, Q = q, R = r."""
    n = len(a)
    py_predict = tension_filter._predict(a, q)
    py_update = tension_filter._update(n, r)
    c_predict = functools.partial(core.predict, py_predict, sum(a, ()), sum(q, ()))
    c_update = functools.partial(core.update, py_update, r)
    return py_predict, c_predict, py_update, c_update


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_c_predict_and_update_equal_the_generated_functions_bit_for_bit(n, rng):
    """Random A (with 0, -0, +-1 entries, which the generator leaves out or writes bare), Q,
    R, states, covariances and observations (with zeros, NaNs, infinities): C's results are
    the generated function's floats (a mutation of one operation's order in tension_core.c
    fails this)."""
    for _ in range(300):
        a, q = _matrix(rng, n), _matrix(rng, n)
        r = float(10.0 ** rng.uniform(-4, 2))
        py_predict, c_predict, py_update, c_update = _pair(a, q, r)
        x, p, y = _floats(rng, 3 * n), _floats(rng, n * n), _floats(rng, 3)
        assert _bits(c_predict(x, p)) == _bits(py_predict(x, p))
        try:
            expected = _bits(py_update(x, p, *y))
        except ZeroDivisionError:
            with pytest.raises(ZeroDivisionError):
                c_update(x, p, *y)
        else:
            assert _bits(c_update(x, p, *y)) == expected


@pytest.mark.parametrize(
    "cfg",
    [
        TensionFilterConfig(model="constant", constant_process_noise_n2=0.01),
        TensionFilterConfig(model="derivative"),
        TensionFilterConfig(model="derivative", derivative_a=0.5, derivative_b=-0.3),
    ],
)
def test_a_filter_on_c_runs_the_same_floats_as_on_python(cfg, rng):
    """The configured filters, chained over 600 steps with restarts: every state, covariance
    and innovation the same bits with the extension as with the generated Python."""
    r, p0 = 0.37, 25.0
    fast = TensionKalmanFilter(cfg.transition(), cfg.process_noise(), r, p0)
    assert isinstance(fast._predict, functools.partial)
    ref = TensionKalmanFilter(cfg.transition(), cfg.process_noise(), r, p0)
    ref._predict, ref._update = fast._predict.args[0], fast._update.args[0]
    truth = np.array([-3.0, 1.0, 2.5])
    for k in range(600):
        y = [float(v) for v in truth + 0.5 * np.sin(0.02 * k) + rng.normal(0.0, 0.3, 3)]
        if k % 250 == 0:
            fast.restart(y)
            ref.restart(y)
            continue
        fast.predict()
        ref.predict()
        assert _bits(fast._p) == _bits(ref._p)
        assert _bits(fast.update(y)) == _bits(ref.update(y))
        assert _bits(fast._x) == _bits(ref._x)
        assert _bits(fast._p) == _bits(ref._p)


def test_where_c_could_differ_it_returns_what_python_returns():
    """Not exact floats (numpy scalars, ints), wrong lengths, non-finite values and a zero
    innovation variance go to the generated function: its result or its exception."""
    a, q, r = ((1.0, 0.5), (0.0, 1.0)), ((0.1, 0.0), (0.0, 0.2)), 0.5
    py_predict, c_predict, py_update, c_update = _pair(a, q, r)
    x, p = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0], [2.0, 0.5, 0.5, 1.0]
    for bad_x in ([1, 2, 3, 4, 5, 6], [np.float64(v) for v in x], tuple(x)):
        assert _bits(c_predict(bad_x, p)) == _bits(py_predict(bad_x, p))
        assert _bits(c_update(bad_x, p, 1.0, 2.0, 3.0)) == _bits(py_update(bad_x, p, 1.0, 2.0, 3.0))
    assert _bits(c_update(x, p, np.float64(1.0), 2.0, 3)) == _bits(
        py_update(x, p, np.float64(1.0), 2.0, 3)
    )
    nan_x = [float("nan"), float("inf")] + x[2:]
    assert _bits(c_predict(nan_x, p)) == _bits(py_predict(nan_x, p))
    for short in (x[:5], p[:3]):
        with pytest.raises(ValueError):
            py_predict(short, p) if len(short) == 5 else py_predict(x, short)
        with pytest.raises(ValueError):
            c_predict(short, p) if len(short) == 5 else c_predict(x, short)
    zero = [2.0, 0.5, 0.5, -r]  # P_cc + R = 0
    with pytest.raises(ZeroDivisionError):
        py_update(x, zero, 1.0, 2.0, 3.0)
    with pytest.raises(ZeroDivisionError):
        c_update(x, zero, 1.0, 2.0, 3.0)


def test_the_filter_uses_the_extension_unless_pure_python_is_asked():
    """``TETHER_PURE_PYTHON`` unset here: the module found and uses the extension."""
    if os.environ.get("TETHER_PURE_PYTHON"):
        pytest.skip("TETHER_PURE_PYTHON is set")
    assert tension_filter.CORE is core
    cfg = TensionFilterConfig(model="derivative")
    kf = TensionKalmanFilter(cfg.transition(), cfg.process_noise(), 0.3, 1.0)
    assert kf._predict.func is core.predict
    assert kf._update.func is core.update
