"""The published covariance's added terms in C (``_status_core.added_position_terms``) against
their Python reference ``published_terms.added_position_terms``: the same floats bit for bit on
seeded random arguments (every term on and off, positions over many decades, signed zeros,
NaNs, infinities, negative and zero variances and tensions), on a real flight's arguments, and
the Python function's result or exception wherever C could differ.

The extension is optional (no compiler: the Python function runs). Its absence fails this file
where it could have been built or with ``TETHER_REQUIRE_CORE=1``, as
``test_generated_core.py`` does.
"""

from __future__ import annotations

import math
import struct
from dataclasses import replace

import numpy as np
import pytest
from optional_extension import import_extension, recording_c_calls

from tether_companion.bench.dynamic import record
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import observability, published, published_terms, state
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.published_terms import StatusSettings
from tether_companion.estimation.feed import imu_ticks
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.scenario import load_scenario

core, pytestmark = import_extension("tether_companion.estimation.dynamic._status_core")

PY = published_terms.added_position_terms
SPECIAL = [0.0, -0.0, math.nan, math.inf, -math.inf]


def _c(*args: object) -> tuple:
    return core.added_position_terms(PY, *args)


def _bits(values: object) -> object:
    """Nested lists/tuples of floats by their bit patterns (-0.0 != 0.0, NaNs compare), and
    the containers' types."""
    if isinstance(values, (list, tuple)):
        return [type(values).__name__, [_bits(v) for v in values]]
    if isinstance(values, float):
        return struct.pack("<d", values)
    return (type(values).__name__, values)


def _floats(rng: np.random.Generator, count: int, special: bool, decades: float = 6.0) -> list:
    values = [
        float(v) for v in rng.normal(0.0, 1.0, count) * 10.0 ** rng.uniform(-decades, 3, count)
    ]
    if special:  # now and then a signed zero, a NaN or an infinity
        for i in rng.integers(0, count, rng.integers(0, 3)):
            values[i] = SPECIAL[rng.integers(0, len(SPECIAL))]
    return values


def _variance(rng: np.random.Generator, special: bool) -> float:
    """Zero (often: the term off), positive, and with ``special`` negative or not a number."""
    choices = [0.0, abs(_floats(rng, 1, False)[0])]
    if special:
        choices += [-abs(_floats(rng, 1, False)[0]), -0.0, math.nan, math.inf]
    return choices[rng.integers(0, len(choices))]


def _settings(rng: np.random.Generator, special: bool) -> StatusSettings:
    slack, bound, noise, pull, wind, drag = (abs(v) for v in _floats(rng, 6, special, 2.0))
    if rng.uniform() < 0.3:
        drag = [0.0, -1.0][rng.integers(0, 2)]  # the ring off
    return StatusSettings(slack, bound, noise, pull, wind, drag)


def _args(rng: np.random.Generator, special: bool) -> tuple:
    x = _floats(rng, int(rng.integers(13, 18)), special)
    if rng.uniform() < 0.3:  # the tension around and below MIN_TENSION_N
        x[state.TENSION] = float(rng.uniform(-1.0, 0.05))
    if rng.uniform() < 0.05:  # at the anchor, or right above it
        x[0] = x[1] = [0.0, -0.0][rng.integers(0, 2)]
        if rng.uniform() < 0.5:
            x[2] = [0.0, -0.0][rng.integers(0, 2)]
    if rng.uniform() < 0.1:  # a height below a tenth of the range: the floor
        x[2] = 1e-3 * x[0]
    information = None
    if rng.uniform() < 0.5:
        information = tuple(_floats(rng, 13, special))
        if rng.uniform() < 0.5:  # the weight kept, within [0, 1]
            information = (*information[:6], float(rng.uniform()), *information[7:])
    weight = [0.0, abs(_floats(rng, 1, special)[0])][rng.integers(0, 2)]
    return (
        x,
        weight,
        _settings(rng, special),
        abs(_floats(rng, 1, special)[0]),
        information,
        _variance(rng, special),
        bool(rng.integers(0, 2)),
        _variance(rng, special),
        _variance(rng, special),
    )


def _same(args: tuple) -> None:
    try:
        expected = PY(*args)
    except (OverflowError, ZeroDivisionError, ValueError) as error:
        with pytest.raises(type(error)):
            _c(*args)
        return
    assert _bits(_c(*args)) == _bits(expected), args


@pytest.mark.parametrize("special", [False, True])
def test_c_equals_the_python_function_bit_for_bit_on_random_arguments(special, rng):
    """Random arguments (every term on and off) and, with ``special``, signed zeros, NaNs,
    infinities and negative variances: the same floats in a tuple, or the same exception (a
    change of one operation's order in status_core.c fails this)."""
    for _ in range(40000):
        _same(_args(rng, special))


def test_c_equals_the_python_function_over_the_whole_float_range(rng):
    """Positions and variances from subnormal to 1e300 (math.hypot's scaling, the ring's
    ``(drag / pull) ** 2`` overflow and underflow): the same floats or exception."""
    for _ in range(20000):
        args = list(_args(rng, False))
        x = list(args[0])
        scale = 10.0 ** float(rng.uniform(-320, 300))
        for i in (0, 1, 2, state.TENSION, state.WIND.start, state.WIND.start + 1):
            x[i] = x[i] * scale if rng.uniform() < 0.5 else x[i]
        args[0] = x
        args[7] = args[7] * 10.0 ** float(rng.uniform(-300, 300))
        _same(tuple(args))


def test_the_ring_s_overflow_raises_as_python_does():
    """A pull so weak that ``(drag / pull) ** 2`` overflows: OverflowError from both."""
    x = [3.0, 4.0, -2.0, 0.0, 0.0, 0.0, 1e-300, 1.0, 0.0, 0.0, 0.0, 1.0, 0.5]
    settings = StatusSettings(0.5, 1.0, 0.05, 3.0, 2.0, 0.8)
    args = (x, 0.0, settings, 0.3, None, 0.0, False, 0.0, 0.0)
    with pytest.raises(OverflowError):
        PY(*args)
    with pytest.raises(OverflowError):
        _c(*args)


def test_the_compiled_constants_are_the_python_ones():
    """MIN_TENSION_N (through the straight term's clamp at a zero tension) and the state's
    indices (through the ring: the tension and the wind moved)."""
    settings = StatusSettings(0.5, 1.0, 0.0, 0.0, 0.0, 0.0)
    x = [1.0, 0.0, 0.0] + [0.0] * 14
    added = _c(x, 0.0, settings, 1.0, None, 0.0, False, 0.0, 0.0)
    assert added[3] == (1.0 / observability.MIN_TENSION_N) ** 2  # east-east: the gain g
    assert (state.TENSION, state.WIND.start, state.WIND.stop) == (6, 11, 13)


def test_where_c_could_differ_it_returns_what_python_returns(rng):
    """Ints, numpy floats, other containers, a truthy non-bool, a settings value that is an int,
    the catenary's plane rows (a fused length on a cable with weight): the Python function's
    result, bit for bit; too short a state or information: its exception."""
    base = (
        [3.0, -4.0, -2.0, 0.1, 0.0, 0.2, 2.5, 1.0, 0.0, 0.0, 0.0, 0.3, -0.4, 0.0],
        0.0,
        StatusSettings(0.5, 1.0, 0.05, 3.0, 2.0, 0.8),
        0.3,
        tuple(float(v) for v in range(13)),
        0.01,
        False,
        0.02,
        0.005,
    )
    for position, bad in [
        (0, [int(v) for v in base[0]]),
        (0, np.array(base[0])),
        (1, 0),
        (1, np.float64(0.0)),
        (2, replace(base[2], drag_per_wind_n_s_per_m=1)),
        (3, np.float64(0.3)),
        (4, list(base[4])),
        (4, np.array(base[4])),
        (5, 0),
        (6, 1),
        (6, np.bool_(True)),
        (7, 2),
        (8, np.float64(0.005)),
    ]:
        changed = list(base)
        changed[position] = bad
        assert _bits(_c(*changed)) == _bits(PY(*changed)), position
    plane = list(base)
    plane[1], plane[6] = 0.05, True  # the drone above the anchor's level (d < 0)
    assert _bits(_c(*plane)) == _bits(PY(*plane))
    for position, bad in [(0, base[0][:12]), (4, base[4][:12])]:
        changed = list(base)
        changed[position] = bad
        with pytest.raises((IndexError, ValueError)) as python_error:
            PY(*changed)
        with pytest.raises(python_error.type):
            _c(*changed)
    with pytest.raises(TypeError):
        core.added_position_terms(PY, *base[:8])


def test_a_flight_runs_c_on_every_tick_with_the_python_floats():
    """The take-off flight (ground, initialising, the bank): every added term the status read
    asks for goes through C (no fallback: the filter's arguments are exact floats, no winch)
    and gives the Python function's floats."""
    vehicle = load_vehicle(load_scenario("realistic-takeoff-figure8").vehicle)
    estimator = DynamicTetherEstimator(EstimatorConfig(), vehicle)
    with recording_c_calls(published, "ADDED_POSITION_TERMS", core.added_position_terms, PY) as (
        calls,
        fallbacks,
    ):
        for imu in imu_ticks(record("realistic-takeoff-figure8", 6.0), estimator):
            estimate = estimator.on_imu(imu)
            if estimate is not None:
                estimate.status  # noqa: B018 (the status read adds the terms)
    assert len(calls) > 200
    assert not fallbacks
    for args in calls:
        assert _bits(_c(*args)) == _bits(PY(*args))
