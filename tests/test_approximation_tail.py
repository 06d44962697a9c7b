"""The status read's approximation tail in C (``_bound_core.approximation_tail``) against its
Python reference ``published_bound.approximation_tail``: the same floats bit for bit and the
same :class:`Approximation` on random and on a real flight's arguments, and the Python
function's result or exception wherever C could differ.

The extension is optional (no compiler: the Python function runs); its absence fails this file
where it could have been built (``optional_extension.import_extension``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from optional_extension import float_bits as _bits
from optional_extension import import_extension, recording_c_calls

from tether_companion.bench.dynamic import record
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import published_bound
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.output import Approximation
from tether_companion.estimation.feed import imu_ticks
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.scenario import load_scenario

core, pytestmark = import_extension("tether_companion.estimation.dynamic._bound_core")

PY = published_bound.approximation_tail
BOUND = (Approximation, published_bound.ROUNDING, published_bound.FINITE_BOUND)


def _c(*args: object) -> object:
    return core.approximation_tail(PY, *BOUND, *args)


def _outcome(function: object, args: tuple) -> object:
    """The result as bits (the approximation's slots in order, its state's identity), or the
    exception's type."""
    try:
        approx, spread, largest = function(*args)  # type: ignore[operator]
    except Exception as exc:  # noqa: BLE001 - compared, not handled
        return type(exc)
    assert type(approx) is Approximation and approx.state is args[0]
    return _bits([[getattr(approx, name) for name in Approximation.__slots__], spread, largest])


def _float(rng: np.random.Generator, special: bool, decades: float = 8.0) -> float:
    if special and rng.uniform() < 0.08:
        return [0.0, -0.0, math.nan, math.inf, -math.inf][rng.integers(0, 5)]
    return float(rng.normal() * 10.0 ** rng.uniform(-decades, decades))


def _jac(rng: np.random.Generator, special: bool) -> object:
    """None, or a Jacobian row as the generated model gives it (floats and int zeros), now and
    then with ints C takes (small) and does not (huge, bool), as a tuple or a list."""
    if rng.uniform() < 0.25:
        return None
    n = int(rng.integers(0, 18))
    row: list[object] = [
        0 if rng.uniform() < 0.3 else _float(rng, special, 4.0) for _ in range(n)
    ]
    if special and n and rng.uniform() < 0.3:
        row[int(rng.integers(0, n))] = [-3, 7, 2**40, 2**70, True][
            rng.integers(0, 5)
        ]
    return (tuple, list)[rng.integers(0, 2)](row)


def _args(rng: np.random.Generator, special: bool) -> tuple:
    decades = [8.0, 80.0, 170.0][rng.integers(0, 3)]  # 1e170: the `** 2` overflows
    x = [_float(rng, False) for _ in range(int(rng.integers(11, 18)))]
    floats = [_float(rng, special, decades) for _ in range(13)]
    t = abs(floats[0])
    added = tuple(_float(rng, special, decades) for _ in range(6))
    return (x, t, *floats[1:], _jac(rng, special), added)


@pytest.mark.parametrize("special", [False, True])
def test_c_equals_the_python_function_bit_for_bit_on_random_arguments(special, rng):
    """60k random argument sets over up to 340 decades, signed zeros, NaN and infinities, int
    and huge-int Jacobian entries: the same floats, flag and objects, or the same exception
    (the `** 2`'s OverflowError). A swapped term, `<` for `<=` or a sum in another order fails
    this."""
    for _ in range(30000):
        args = _args(rng, special)
        assert _outcome(_c, args) == _outcome(PY, args), args


def test_the_finite_flag_at_its_bound():
    """Each of the four bounds (the covariance's scale, the tension's variance, the position's
    scale, the tension) alone just below, at and just beyond ``FINITE_BOUND``: the same flag
    and tolerances (a `<=` for a `<` fails this)."""
    bound = published_bound.FINITE_BOUND
    x = [1.0] * 13
    zeros = (0.0,) * 6
    for value in (math.nextafter(bound, 0.0), bound, math.nextafter(bound, math.inf)):
        for args in [  # t, block, spread, moved, row_sum, offset, sd, |x|, q, T, jac, added
            (x, 1.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, value, 1.0, (0.5,), zeros),
            (x, 1.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, value / 4, 1.0, (2.0, 0),
             zeros),
            (x, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0, value, 0.0, 1.0, None, zeros),
            (x, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, -value, None, zeros),
        ]:  # fmt: skip
            expected = _outcome(PY, args)
            assert _outcome(_c, args) == expected
            assert PY(*args)[0].finite is (value < bound)


def test_where_c_could_differ_it_returns_what_python_returns():
    """Ints and numpy floats for the floats, a numpy Jacobian, added terms of another length or
    type: the Python function's result or its exception; a wrong argument count raises."""
    good = ([1.0] * 13, 0.01, 1.0, 0.1, 2.0, 3.0, 0.5, 0.2, 1.5, 0.3, 0.7, 9.0, 0.02, 4.0,
            (0.5, 0, -0.25), (0.1, 0.0, 0.0, 0.2, 0.0, 0.3))  # fmt: skip
    for position, bad in [
        (1, 1),
        (5, np.float64(3.0)),
        (13, 4),
        (14, np.array([0.5, 0.0])),
        (15, [0.1, 0.0, 0.0, 0.2, 0.0, 0.3]),
        (15, (0.1, 0.0, 0.0, 0.2, 0.0)),
        (15, np.zeros(6)),
    ]:
        args = list(good)
        args[position] = bad
        assert _outcome(_c, tuple(args)) == _outcome(PY, tuple(args)), position
    assert _outcome(_c, good) == _outcome(PY, good)
    with pytest.raises(TypeError):
        core.approximation_tail(PY, *BOUND, *good[:15])


def test_a_flight_runs_c_on_every_tick_with_the_python_floats():
    """The take-off flight: every approximation the status read makes goes through C (no
    fallback) and gives the Python function's floats and object."""
    vehicle = load_vehicle(load_scenario("realistic-takeoff-figure8").vehicle)
    estimator = DynamicTetherEstimator(EstimatorConfig(), vehicle)
    ticks = imu_ticks(record("realistic-takeoff-figure8", 6.0), estimator)
    tail = (published_bound, "APPROXIMATION_TAIL", core.approximation_tail, PY, BOUND)
    with recording_c_calls(*tail) as (calls, fallbacks):
        for imu in ticks:
            estimate = estimator.on_imu(imu)
            if estimate is not None:
                estimate.status  # noqa: B018 (the status read makes the approximation)
    assert len(calls) > 200
    assert any(args[14] is not None for args in calls)
    assert not fallbacks
    for args in calls:
        assert _outcome(_c, args) == _outcome(PY, args)
