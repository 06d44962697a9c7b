"""The status read's C twins (``_status_core``) against their Python references: the published
covariance's added terms (``added_position_terms``, ``published_terms.added_position_terms``)
and the status decision (``decide``, ``observability.decide``): the same floats bit for bit on
seeded random arguments (every term on and off, positions over many decades, signed zeros,
NaNs, infinities, negative and zero variances and tensions), on a real flight's arguments, and
the Python function's result or exception wherever C could differ.

The extension is optional (no compiler: the Python function runs). Its absence fails this file
where it could have been built or with ``TETHER_REQUIRE_CORE=1``, as
``test_generated_core.py`` does.
"""

from __future__ import annotations

import math
import os
from dataclasses import replace

import numpy as np
import pytest
from optional_extension import float_bits as _bits
from optional_extension import import_extension, recording_c_calls

from tether_companion.bench.dynamic import record
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import (
    observability,
    output,
    published,
    published_terms,
    state,
)
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
    """Ints, numpy floats, other containers, a truthy non-bool, a settings value that is an int:
    the Python function's result, bit for bit (and the catenary's plane rows, a fused length
    on a cable with weight, in C); too short a state or information: its exception."""
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


# ---------------------------------------------------------------- the status decision

DECIDE_PY = observability.decide
STATUS_NAMES = ["OK", "INITIALISING", "WEAK_PULL", "LEARNING", "SLACK", "ON_GROUND"]
STATUSES = [None, *(getattr(output, name) for name in (*STATUS_NAMES, "STALE_INPUTS", "RESET"))]


def _decide_c(**keywords: object) -> str | None:
    return core.decide(DECIDE_PY, **keywords)


def _near(rng: np.random.Generator, value: float) -> float:
    """``value``, or within a few relative 1e-9 of it (the margin's edge), or far off."""
    return [
        value,
        value * (1.0 + float(rng.uniform(-3e-9, 3e-9))),
        abs(_floats(rng, 1, False, 2.0)[0]),
    ][rng.integers(0, 3)]


def _keywords(rng: np.random.Generator, special: bool) -> dict:
    slack, max_std, min_pull = (abs(v) for v in _floats(rng, 3, False, 2.0))
    a, c = (_near(rng, max_std * max_std) for _ in range(2))
    keywords = {
        "initialised": bool(rng.uniform() < 0.95),
        "reset": bool(rng.uniform() < 0.05),
        "on_ground": ["", "", "", "", "landed"][rng.integers(0, 5)],
        "inputs_stale": bool(rng.uniform() < 0.05),
        "tension_n": _near(rng, slack),
        "slack_tension_n": slack,
        "horizontal_m2": (a, float(rng.uniform(-0.5, 0.5)) * math.sqrt(a * c), c),
        "max_horizontal_std_m": max_std,
        "horizontal_pull_n": _near(rng, min_pull),
        "min_horizontal_pull_n": min_pull,
        "explained": [None, lambda: True, lambda: False, lambda: None][rng.integers(0, 4)],
    }
    for name, value in [
        ("margin", [0.0, 1e-9][rng.integers(0, 2)]),
        ("variance_tol", [0.0, float(rng.uniform(0.0, 1e-9))][rng.integers(0, 2)]),
        ("range_unknown", bool(rng.uniform() < 0.1)),
    ]:
        if rng.uniform() < 0.8:  # else the default
            keywords[name] = value
    if rng.uniform() < 0.3:  # the larger variance within a few variance_tol of the bound's
        tol = 1e-6 * max_std * max_std
        keywords["variance_tol"] = tol
        largest = max_std * max_std + float(rng.uniform(-8.0, 8.0)) * tol
        keywords["horizontal_m2"] = (largest, 0.0, 0.5 * largest)
    if special:
        names = ["tension_n", "slack_tension_n", "max_horizontal_std_m", "horizontal_pull_n"]
        names += ["min_horizontal_pull_n", "horizontal_m2", "margin", "variance_tol"]
        for name in rng.choice(names, int(rng.integers(1, 3)), replace=False):
            pick = SPECIAL[rng.integers(0, len(SPECIAL))]
            if name == "horizontal_m2":
                entries = list(keywords[name])
                entries[rng.integers(0, 3)] = [pick, -1.0, 1e300][rng.integers(0, 3)]
                keywords[name] = tuple(entries)
            else:
                keywords[name] = pick
    return keywords


@pytest.mark.parametrize("special", [False, True])
def test_decide_equals_the_python_function_on_random_keywords(special, rng):
    """Random statuses' inputs at, near and far from their thresholds (the margin's edges),
    with and without the defaults, with NaNs, infinities, signed zeros, a negative variance
    and an overflowing ``(a - c) ** 2``: the same status object (or None) or exception, and
    ``explained`` asked exactly when the Python function asks it."""
    seen = set()
    for _ in range(40000):
        keywords = _keywords(rng, special)
        asked: list[str] = []
        explained = keywords["explained"]
        if explained is not None:
            keywords["explained"] = lambda e=explained: asked.append("py") or e()
        try:
            expected = DECIDE_PY(**keywords)
        except OverflowError:
            with pytest.raises(OverflowError):
                _decide_c(**keywords)
            continue
        if explained is not None:
            keywords["explained"] = lambda e=explained: asked.append("c") or e()
        got = _decide_c(**keywords)
        assert got is expected, keywords
        assert asked.count("c") == asked.count("py"), keywords
        seen.add(got)
    assert seen == set(STATUSES)  # every status and None decided


def test_decide_where_c_could_differ_is_python_s():
    """Ints, numpy floats, a list for the tuple, a truthy non-bool, a str subclass: the Python
    function's status; a missing or unknown keyword, a positional argument: its TypeError; an
    exception from ``explained`` propagates."""
    keywords = {
        "initialised": True,
        "reset": False,
        "on_ground": "",
        "inputs_stale": False,
        "tension_n": 4.0,
        "slack_tension_n": 0.5,
        "horizontal_m2": (0.04, 0.01, 0.09),
        "max_horizontal_std_m": 0.2,
        "horizontal_pull_n": 3.0,
        "min_horizontal_pull_n": 1.0,
        "explained": lambda: True,
    }
    assert _decide_c(**keywords) == DECIDE_PY(**keywords) == output.LEARNING
    for name, bad in [
        ("tension_n", 4),
        ("tension_n", np.float64(0.2)),
        ("horizontal_m2", [0.04, 0.01, 0.09]),
        ("horizontal_m2", (0.01, 0.0, 0.01)),
        ("initialised", 1),
        ("reset", np.bool_(True)),
        ("margin", 0),
        ("range_unknown", 1),
    ]:
        changed = dict(keywords, **{name: bad})
        assert _decide_c(**changed) is DECIDE_PY(**changed), name
    for changed in [
        {k: v for k, v in keywords.items() if k != "tension_n"},
        dict(keywords, unknown=1.0),
    ]:
        with pytest.raises(TypeError):
            DECIDE_PY(**changed)
        with pytest.raises(TypeError):
            _decide_c(**changed)
    with pytest.raises(TypeError):
        core.decide(DECIDE_PY, True, **keywords)

    def fails() -> bool:
        raise RuntimeError("explained")

    with pytest.raises(RuntimeError):
        _decide_c(**dict(keywords, explained=fails))


def test_a_flight_decides_every_tick_in_c_with_the_python_status():
    """The take-off flight: every approximate status goes through C (no fallback) and is the
    Python function's."""
    if os.environ.get("TETHER_PURE_PYTHON"):
        pytest.skip("TETHER_PURE_PYTHON is set: the package runs the Python alone")
    vehicle = load_vehicle(load_scenario("realistic-takeoff-figure8").vehicle)
    estimator = DynamicTetherEstimator(EstimatorConfig(), vehicle)
    calls: list[dict] = []
    fallbacks: list[dict] = []

    def fallback(**keywords: object) -> object:
        fallbacks.append(keywords)
        return DECIDE_PY(**keywords)

    def recorded(**keywords: object) -> object:
        calls.append(keywords)
        return core.decide(fallback, **keywords)

    saved = published.DECIDE
    published.DECIDE = recorded
    try:
        for imu in imu_ticks(record("realistic-takeoff-figure8", 6.0), estimator):
            estimate = estimator.on_imu(imu)
            if estimate is not None:
                estimate.status  # noqa: B018 (the status read decides)
    finally:
        published.DECIDE = saved
    assert saved.func is core.decide  # the package runs C
    assert len(calls) > 200
    assert not fallbacks
    for keywords in calls:
        assert _decide_c(**keywords) is DECIDE_PY(**keywords)


# ---------------------------------------------------------------- the horizontal pulls

PULL_PY = observability.horizontal_pull_n
MIN_PULL_PY = observability.min_horizontal_pull_n


def _result(function: object, *args: object) -> object:
    try:
        return _bits(function(*args))  # type: ignore[operator]
    except Exception as exc:  # noqa: BLE001 - compared, not handled
        return type(exc)


def test_the_pulls_equal_the_python_functions_bit_for_bit(rng):
    """``horizontal_pull`` and ``min_horizontal_pull`` against ``observability``'s functions on
    40k random states and settings over up to 600 decades (the hypot's subnormal and overflow
    scaling), signed zeros, NaN and infinities, positions at the anchor, states too short and
    ints: the same floats, or the Python function's result or exception."""
    for special in (False, True):
        for _ in range(20000):
            decades = [6.0, 150.0, 300.0][rng.integers(0, 3)]
            x = _floats(rng, int(rng.integers(13, 18)), special, decades)
            if rng.uniform() < 0.1:  # at the anchor (nan tension or not)
                x[0], x[1], x[2] = [0.0, -0.0][rng.integers(0, 2)], 0.0, -0.0
            if special and rng.uniform() < 0.05:
                x = x[: int(rng.integers(0, 13))] if rng.uniform() < 0.5 else [*x[:6], 2, *x[7:]]
            assert _result(core.horizontal_pull, PULL_PY, x) == _result(PULL_PY, x), x
            settings = _floats(rng, 4, special, decades)
            if special and rng.uniform() < 0.05:
                settings[int(rng.integers(0, 4))] = 1
            assert _result(core.min_horizontal_pull, MIN_PULL_PY, *settings) == _result(
                MIN_PULL_PY, *settings
            ), settings


def test_the_least_pull_keeps_the_prior_at_a_tie():
    """``max(wind_std, speed)``: the prior unless the speed is greater (a `>=` changes the sign
    of a zero); a wrong argument count raises."""
    for args in [(2.0, 0.0, 0.0, -0.0), (2.0, -0.0, 0.0, 0.0), (1.5, 3.0, 3.0, 0.0)]:
        assert _bits(core.min_horizontal_pull(MIN_PULL_PY, *args)) == _bits(MIN_PULL_PY(*args))
    with pytest.raises(TypeError):
        core.min_horizontal_pull(MIN_PULL_PY, 1.0, 2.0, 3.0)
    with pytest.raises(TypeError):
        core.horizontal_pull(PULL_PY)


def test_a_flight_s_pulls_run_in_c_with_the_python_floats():
    """The take-off flight: every pull the approximate status read computes goes through C (no
    fallback) and gives the Python function's floats."""
    vehicle = load_vehicle(load_scenario("realistic-takeoff-figure8").vehicle)
    estimator = DynamicTetherEstimator(EstimatorConfig(), vehicle)
    with recording_c_calls(
        published, "HORIZONTAL_PULL", core.horizontal_pull, PULL_PY
    ) as (pulls, pull_fallbacks), recording_c_calls(
        published, "MIN_HORIZONTAL_PULL", core.min_horizontal_pull, MIN_PULL_PY
    ) as (least, least_fallbacks):
        for imu in imu_ticks(record("realistic-takeoff-figure8", 6.0), estimator):
            estimate = estimator.on_imu(imu)
            if estimate is not None:
                estimate.status  # noqa: B018 (the status read computes the pulls)
    assert len(pulls) > 200 and len(least) == len(pulls)
    assert not pull_fallbacks and not least_fallbacks
    for args in pulls:
        assert _bits(core.horizontal_pull(PULL_PY, *args)) == _bits(PULL_PY(*args))
    for args in least:
        assert _bits(core.min_horizontal_pull(MIN_PULL_PY, *args)) == _bits(MIN_PULL_PY(*args))
