"""The bound approximation's step and the straight cable's unmodelled-force rows in C
(``_bound_core``) against their Python references ``published_bound.stepped_terms`` and
``observability.unmodelled_position_rows``: the same floats bit for bit on random and on a
real flight's arguments, and the Python function's result or exception wherever C could differ.

The extension is optional (no compiler: the Python function runs). Its absence fails this file
where it could have been built or with ``TETHER_REQUIRE_CORE=1``, as
``test_generated_core.py`` does.
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from optional_extension import float_bits as _bits
from optional_extension import import_extension, recording_c_calls

from tether_companion.bench.dynamic import record
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import (
    mixture,
    observability,
    offset_term,
    published,
    published_bound,
    published_terms,
)
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.feed import imu_ticks
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.scenario import load_scenario

core, pytestmark = import_extension("tether_companion.estimation.dynamic._bound_core")

PY = published_bound.stepped_terms


def _c(*args: object) -> tuple:
    return core.stepped_terms(PY, *args)


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


# ---------------------------------------------------------------- the straight cable's rows

ROWS_PY = observability.unmodelled_position_rows


def _rows_c(*args: object) -> list:
    return core.unmodelled_rows(ROWS_PY, *args)


def test_the_straight_rows_equal_the_python_function_bit_for_bit(rng):
    """``unmodelled_rows`` against ``observability.unmodelled_position_rows`` on random
    positions over 12 decades, tensions around and below ``MIN_TENSION_N`` (its clamp), zero
    positions and, now and then, signed zeros, NaNs and infinities: the same floats in new
    lists (a change of one operation's order in bound_core.c fails this)."""
    assert core_min_tension() == observability.MIN_TENSION_N
    for special in (False, True):
        for _ in range(20000):
            n, e, d = _floats(rng, 3, special)
            if rng.uniform() < 0.02:
                n = e = d = [0.0, -0.0][rng.integers(0, 2)]
            tension = [
                float(rng.uniform(-1.0, 0.02)),
                _floats(rng, 1, special)[0],
                observability.MIN_TENSION_N,
            ][rng.integers(0, 3)]
            force, length = _floats(rng, 2, special)
            args = (n, e, d, tension, force, length)
            expected = ROWS_PY(*args)
            got = _rows_c(*args)
            assert _bits(got) == _bits(expected), args
            assert got is not _rows_c(*args)


def core_min_tension() -> float:
    """The ``MIN_TENSION_N`` bound_core.c compiles in, read through its clamp: at a tension of
    zero the gain's square over the term's ``r^2 sigma^2`` is ``1 / MIN_TENSION_N^2``."""
    rows = _rows_c(1.0, 0.0, 0.0, 0.0, 1.0, 0.0)  # north: the east row's east entry is g
    return 1.0 / math.sqrt(rows[1][1])


def test_where_c_could_differ_the_straight_rows_return_what_python_returns():
    """Ints and numpy floats go to the Python function (its result, bit for bit); a wrong
    argument count raises."""
    args = (3.0, 2.0, -2.5, 4.0, 0.2, 0.05)
    for position, bad in [(0, 3), (3, 4), (5, 0), (1, np.float64(2.0)), (4, np.float64(0.2))]:
        changed = list(args)
        changed[position] = bad
        assert _bits(_rows_c(*changed)) == _bits(ROWS_PY(*changed))
    with pytest.raises(TypeError):
        core.unmodelled_rows(ROWS_PY, *args[:5])


def test_a_flight_runs_the_straight_rows_in_c_with_the_python_floats(monkeypatch):
    """The take-off flight: every straight-cable term the status read adds goes through C (no
    fallback) and gives the Python function's floats (the added terms' Python reference run,
    which calls them: their C twin has the rows written in, ``straight_rows.h``)."""
    monkeypatch.setattr(published, "ADDED_POSITION_TERMS", published_terms.added_position_terms)
    vehicle = load_vehicle(load_scenario("realistic-takeoff-figure8").vehicle)
    estimator = DynamicTetherEstimator(EstimatorConfig(), vehicle)
    with recording_c_calls(offset_term, "STRAIGHT_ROWS", core.unmodelled_rows, ROWS_PY) as (
        calls,
        fallbacks,
    ):
        for imu in imu_ticks(record("realistic-takeoff-figure8", 6.0), estimator):
            estimate = estimator.on_imu(imu)
            if estimate is not None:
                estimate.status  # noqa: B018 (the status read adds the term)
    assert len(calls) > 200
    assert not fallbacks
    for args in calls:
        assert _bits(_rows_c(*args)) == _bits(ROWS_PY(*args))


# ---------------------------------------------------------------- the mixture's bounds

SD_PY = mixture.sd_bounds


def test_the_sd_bounds_equal_the_python_function_bit_for_bit(rng):
    """``sd_bounds`` against ``mixture.sd_bounds`` on random variances over 12 decades and
    states (ties of the largest, signed zeros; now and then a negative variance, NaN or
    infinity, which are Python's): the same floats, a new list (a largest taken from the
    wrong rows fails this)."""
    for special in (False, True):
        for _ in range(20000):
            n = int(rng.integers(6, 18))
            diagonal = [abs(v) for v in _floats(rng, n, False)]
            x = _floats(rng, n, special)
            if rng.uniform() < 0.2:  # ties: the first of equal values is max's
                diagonal[int(rng.integers(0, n))] = diagonal[int(rng.integers(0, n))]
                x[int(rng.integers(0, n))] = -x[int(rng.integers(0, n))]
            if rng.uniform() < 0.1:
                x[int(rng.integers(0, n))] = [0.0, -0.0][rng.integers(0, 2)]
                x[int(rng.integers(0, n))] = [0.0, -0.0][rng.integers(0, 2)]
            if special and rng.uniform() < 0.3:
                diagonal[int(rng.integers(0, n))] = [-1.0, -0.0, math.nan, math.inf][
                    rng.integers(0, 4)
                ]
            expected = SD_PY(diagonal, x)
            got = core.sd_bounds(SD_PY, diagonal, x)
            assert _bits(got) == _bits(expected), (diagonal, x)


def test_the_sd_bounds_keep_max_s_first_of_equal_values():
    """Signed-zero ties: ``max``/``min`` keep the first of equal values, so the largest
    ``|x_i|`` of ``(-0.0, 0.0)`` is -0.0 (``>=`` for ``>`` in C gives 0.0)."""
    diagonal = [1.0, 4.0, 9.0, 0.25, 0.5, 2.0]
    for x in ([-0.0, 0.0], [0.0, -0.0], [-0.0, -0.0, 0.0]):
        assert _bits(core.sd_bounds(SD_PY, diagonal, x)) == _bits(SD_PY(diagonal, x))
    assert struct.pack("<d", core.sd_bounds(SD_PY, diagonal, [-0.0, 0.0])[4]) == struct.pack(
        "<d", -0.0
    )


def test_where_c_could_differ_the_sd_bounds_are_python_s():
    """Ints, numpy floats, tuples and fewer than six variances: the Python function's result
    or its exception."""
    diagonal, x = [1.0, 4.0, 9.0, 0.25, 0.5, 2.0, 3.0], [1.0, -2.0, 0.5]
    for args in [
        ([1, 4, 9, 1, 1, 1], x),
        (diagonal, [1, -2, 0]),
        ([np.float64(v) for v in diagonal], x),
        (tuple(diagonal), tuple(x)),
    ]:
        assert _bits(core.sd_bounds(SD_PY, *args)) == _bits(SD_PY(*args))
    with pytest.raises(IndexError):
        core.sd_bounds(SD_PY, diagonal[:5], x)
    with pytest.raises(ValueError):
        core.sd_bounds(SD_PY, diagonal, [])


def test_a_flight_s_mixture_bounds_run_in_c_with_the_python_floats():
    """The take-off flight: every mixture's bounds the status read makes go through C (no
    fallback) and give the Python function's floats."""
    vehicle = load_vehicle(load_scenario("realistic-takeoff-figure8").vehicle)
    estimator = DynamicTetherEstimator(EstimatorConfig(), vehicle)
    with recording_c_calls(mixture, "SD_BOUNDS", core.sd_bounds, SD_PY) as (calls, fallbacks):
        for imu in imu_ticks(record("realistic-takeoff-figure8", 6.0), estimator):
            estimate = estimator.on_imu(imu)
            if estimate is not None:
                estimate.status  # noqa: B018 (the status read makes the bounds)
    assert len(calls) > 50
    assert not fallbacks
    for args in calls:
        assert _bits(core.sd_bounds(SD_PY, *args)) == _bits(SD_PY(*args))
