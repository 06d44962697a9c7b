"""The generated models' C extension against their Python reference: the same objects out,
floats bit for bit, and the Python function's behaviour wherever the C one could differ.

The extension is optional (no compiler: the Python functions run). Its absence fails this file
where it could have been built (a C compiler and the Python headers here: ``pip install -e .``
builds it, as CI's install does) or with ``TETHER_REQUIRE_CORE=1``; it is skipped, with the
reason, only where it could not.
"""

from __future__ import annotations

import math
import os
import struct
import subprocess
import sys

import numpy as np
import pytest
from optional_extension import import_extension

from tether_companion.estimation.dynamic import generated, state

core, pytestmark = import_extension("tether_companion.estimation.dynamic._generated_core")

from test_dynamic_derivation import ALL_MODELS, _random_case  # noqa: E402


def _bits(value: object) -> object:
    """A float by its bit pattern (so -0.0 != 0.0 and NaNs compare), anything else itself."""
    if isinstance(value, float):
        return struct.pack("<d", value)
    return value


def _same(expected: object, got: object) -> None:
    """The same nested tuples of the same types and the same bits."""
    assert type(got) is type(expected)
    if isinstance(expected, tuple):
        assert len(got) == len(expected)  # type: ignore[arg-type]
        for e, g in zip(expected, got, strict=True):  # type: ignore[call-overload]
            _same(e, g)
    else:
        assert _bits(got) == _bits(expected)


def _outcome(function, *args) -> object:
    """What the call returns, or the type of what it raises."""
    try:
        return function(*args)
    except ArithmeticError as error:  # e.g. sinh overflowing on the scaled cases
        return type(error)


def _python(name: str):
    return generated.PYTHON[list(core.NAMES).index(name)]


def test_the_module_has_every_model_in_the_reference_order() -> None:
    assert list(core.NAMES) == ALL_MODELS
    assert [f.__name__ for f in generated.PYTHON] == ALL_MODELS
    assert generated.COMPILED
    for name in ALL_MODELS:
        assert getattr(generated, name) is getattr(core, name)


@pytest.mark.parametrize("name", ALL_MODELS)
def test_c_gives_the_python_floats_bit_for_bit(name: str) -> None:
    rng = np.random.default_rng(1000 + sum(map(ord, name)))
    python, c_function = _python(name), getattr(core, name)
    for i in range(400):
        x, u, c = _random_case(rng, name)
        x, u, c = [float(v) for v in x], [float(v) for v in u], [float(v) for v in c]
        if i % 4 == 1:  # far from the unit scale and through zero (exact cancellations)
            x = [v * 10.0 ** int(rng.integers(-6, 7)) for v in x]
        elif i % 4 == 2:
            x[state.VELOCITY] = [0.0, -0.0, 0.0]
            x, u = tuple(x), tuple(u)
        expected = _outcome(python, x, u, c)
        if isinstance(expected, type):
            assert _outcome(c_function, x, u, c) is expected
        else:
            _same(expected, c_function(x, u, c))


@pytest.mark.parametrize("name", ["tension_catenary", "force_balance_grounded", "inertial"])
def test_c_returns_the_input_objects_and_int_constants_python_returns(name: str) -> None:
    x, u, c = _random_case(np.random.default_rng(5), name)
    x, u, c = [float(v) for v in x], [float(v) for v in u], [float(v) for v in c]
    expected, got = _python(name)(x, u, c), getattr(core, name)(x, u, c)
    for e_part, g_part in zip(expected, got, strict=True):
        for e, g in zip(e_part, g_part, strict=True):
            if any(e is item for item in (*x, *u, *c)):
                assert g is e  # `v_n` returned as the very input object
    assert any(type(v) is int for v in expected[1])  # the test sees the int constants
    _same(expected, got)


def test_where_c_could_differ_the_python_function_runs() -> None:
    """Non-finite inputs or intermediates, numpy scalars or arrays, ints, wrong lengths: the
    Python function's results or exceptions exactly."""
    x, u, c = _random_case(np.random.default_rng(9), "accel_catenary")
    x, u, c = [float(v) for v in x], [float(v) for v in u], [float(v) for v in c]
    at_anchor = [0.0, 0.0, 0.0, *x[3:]]  # |p| = 0: Python divides by zero
    for name in ("accel_catenary", "cable_angle_straight", "tension_grounded"):
        args = (at_anchor, u if "accel" in name else [], c)
        with pytest.raises(ZeroDivisionError):
            _python(name)(*args)
        with pytest.raises(ZeroDivisionError):
            getattr(core, name)(*args)
    cases = [
        ([*x[:6], math.nan, *x[7:]], u, c),  # a NaN tension: NaN results, no exception
        ([*x[:11], math.inf, *x[12:]], u, c),  # an infinite wind
        (np.array(x), u, c),  # numpy array (items are numpy scalars)
        ([np.float64(v) for v in x], u, c),  # numpy scalars are floats: computed in C
        ([int(round(v)) or 1 for v in x], u, c),  # ints: Python's int arithmetic
    ]
    for args in cases:
        expected = _python("accel_catenary")(*args)
        got = core.accel_catenary(*args)
        assert len(got) == len(expected) == 2
        for e_part, g_part in zip(expected, got, strict=True):
            np.testing.assert_array_equal(np.array(g_part, float), np.array(e_part, float))
    for args in ((x[:-1], u, c), (x, u), (x, u, c, c)):
        with pytest.raises((ValueError, TypeError)) as python_error:
            _python("accel_catenary")(*args)
        with pytest.raises(python_error.type):
            core.accel_catenary(*args)


def test_pure_python_is_kept_when_asked() -> None:
    code = (
        "from tether_companion.estimation.dynamic import generated as g;"
        "print(g.COMPILED, g.inertial is g.PYTHON[-5])"
    )
    for env, expected in (({"TETHER_PURE_PYTHON": "1"}, "False True"), ({}, "True False")):
        out = subprocess.run(
            [sys.executable, "-c", code],
            env={k: v for k, v in os.environ.items() if k != "TETHER_PURE_PYTHON"} | env,
            capture_output=True,
            text=True,
            check=True,
        )
        assert out.stdout.split() == expected.split()


def test_the_batch_sums_are_the_python_sums_bit_for_bit() -> None:
    """``imu_batch.batch_sums`` and its C twin over random ticks, and their verdicts on a
    negative or non-finite tick; where C leaves it to Python it says None."""
    from tether_companion.estimation.dynamic import imu_batch

    rng = np.random.default_rng(44)
    sums = ([0.0] * 3, [0.0] * 3, [0.0] * 9, [0.0] * 9)
    c = [1.5, 0.3, 0.1]
    for i in range(2000):
        x, u, _ = _random_case(rng, "inertial")
        u = [float(v) for v in u]
        dt_s = float(rng.uniform(0.0, 0.02)) if i % 50 else 0.0
        expected = imu_batch.batch_sums(*sums, dt_s, u, c)
        got = core.batch_sums(*sums, dt_s, u, c)
        _same(tuple(map(tuple, expected)), tuple(map(tuple, got)))
        assert all(type(part) is list for part in got)
        sums = got
    for dt_s, u_bad in ((-1e-3, u), (math.inf, u), (math.nan, u), (0.01, [*u[:-1], math.nan])):
        assert imu_batch.batch_sums(*sums, dt_s, u_bad, c) is False
        assert core.batch_sums(*sums, dt_s, u_bad, c) is False
    for args in (
        (*sums, 1, u, c),  # an int dt_s
        (*sums, 0.01, np.array(u), c),  # an array of inputs
        (*sums, 0.01, u, [1.5, 0.3]),  # short constants
        (sums[0][:2], *sums[1:], 0.01, u, c),  # short sums
    ):
        assert core.batch_sums(*args) is None
