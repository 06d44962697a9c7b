"""The bound approximation's step in C (``_bound_core``) against its Python reference
``published_bound.stepped_terms``: the same floats bit for bit on random and on a real
flight's arguments, and the Python function's result or exception wherever C could differ.

The extension is optional (no compiler: the Python function runs). Its absence fails this file
where it could have been built or with ``TETHER_REQUIRE_CORE=1``, as
``test_generated_core.py`` does.
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from optional_extension import import_extension, recording_c_calls

from tether_companion.bench.dynamic import record
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import published_bound
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.feed import imu_ticks
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.scenario import load_scenario

core, pytestmark = import_extension("tether_companion.estimation.dynamic._bound_core")

PY = published_bound.stepped_terms


def _c(*args: object) -> tuple:
    return core.stepped_terms(PY, *args)


def _bits(values: object) -> object:
    """Nested lists/tuples of floats by their bit patterns (-0.0 != 0.0, NaNs compare), and
    the containers' types."""
    if isinstance(values, (list, tuple)):
        return [type(values).__name__, [_bits(v) for v in values]]
    if isinstance(values, float):
        return struct.pack("<d", values)
    return (type(values).__name__, values)


def _floats(rng: np.random.Generator, count: int, special: bool) -> list[float]:
    values = [float(v) for v in rng.normal(0.0, 1.0, count) * 10.0 ** rng.uniform(-8, 4, count)]
    if special:  # zeros of both signs, and now and then a NaN or an infinity
        for i in rng.integers(0, count, rng.integers(0, 4)):
            values[i] = [0.0, -0.0, math.nan, math.inf, -math.inf][rng.integers(0, 5)]
    return values


def _args(rng: np.random.Generator, special: bool) -> tuple:
    n = int(rng.integers(11, 18))
    lists = [list, tuple][rng.integers(0, 2)]
    return (
        _floats(rng, n, special),
        _floats(rng, 1, special)[0],
        lists(_floats(rng, 3, special)),
        lists(_floats(rng, 3, special)),
        _floats(rng, 9, special),
        _floats(rng, 9, special),
        _floats(rng, n, special),
        _floats(rng, 1, special)[0],
        _floats(rng, 1, special)[0],
        _floats(rng, n, special),
        tuple(_floats(rng, 4, special)),
        tuple(_floats(rng, 4, special)),
        tuple(_floats(rng, 4, special)),
    )


@pytest.mark.parametrize("special", [False, True])
def test_c_equals_the_python_function_bit_for_bit_on_random_arguments(special, rng):
    """Random arguments over 12 decades (and zeros of both signs, NaNs and infinities): the
    same floats and the same containers (a change of one operation's order in bound_core.c
    fails this)."""
    for _ in range(3000):
        args = _args(rng, special)
        expected = PY(*args)
        got = _c(*args)
        assert _bits(got) == _bits(expected)
        assert got[0] is not args[0]  # a new list, as list(x)
        assert all(a is b for a, b in zip(got[0][6:], args[0][6:], strict=True))


def test_where_c_could_differ_it_returns_what_python_returns(rng):
    """Ints, numpy floats, other containers and wrong lengths go to the Python function: its
    result, or its exception."""
    args = _args(rng, False)
    for position, bad in [
        (1, [int(v) for v in args[0]]),  # ints in x
        (1, np.array(args[0])),
        (2, np.float64(args[1])),
        (2, 1),
        (5, [np.float64(v) for v in args[4]]),
        (7, np.array(args[6])),
        (10, np.array(args[9])),
        (11, list(args[10])),  # a list is fine for Python and C alike
    ]:
        changed = list(args)
        changed[position - 1] = bad
        assert _bits(_c(*changed)) == _bits(PY(*changed))
    for position, bad in [(3, args[2][:2]), (5, args[4][:8]), (11, args[10][:3]), (1, args[0][:9])]:
        changed = list(args)
        changed[position - 1] = bad
        with pytest.raises((ValueError, IndexError)) as python_error:
            PY(*changed)
        with pytest.raises(python_error.type):
            _c(*changed)


def test_a_flight_runs_c_on_every_tick_with_the_python_floats():
    """The take-off flight (ground, initialising, the bank): every approximation the estimator
    steps goes through C (no fallback: the filter's arguments are exact floats) and gives the
    Python function's floats."""
    vehicle = load_vehicle(load_scenario("realistic-takeoff-figure8").vehicle)
    estimator = DynamicTetherEstimator(EstimatorConfig(), vehicle)
    with recording_c_calls(published_bound, "STEPPED_TERMS", core.stepped_terms, PY) as (
        calls,
        fallbacks,
    ):
        for imu in imu_ticks(record("realistic-takeoff-figure8", 6.0), estimator):
            estimate = estimator.on_imu(imu)
            if estimate is not None:
                estimate.status  # noqa: B018 (the status read runs the approximation)
    assert len(calls) > 200
    assert not fallbacks
    for args in calls:
        assert _bits(core.stepped_terms(PY, *args)) == _bits(PY(*args))
