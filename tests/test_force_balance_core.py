"""The force-balance test's scalars in C (``_member_core.force_balance``) against their Python
reference ``member.solve_force_balance``: the same floats bit for bit on random arguments and
on a real flight's, and the Python function's result or exception wherever C could differ.

The extension is optional (no compiler: the Python function runs); its absence fails this file
where it could have been built, as ``test_member_core.py``.
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from optional_extension import import_extension, recording_c_calls

from tether_companion.bench.dynamic import record
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import bank_updates, member
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.feed import imu_ticks
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.scenario import load_scenario

core, pytestmark = import_extension("tether_companion.estimation.dynamic._member_core")

PY = member.solve_force_balance


def _c(*args: object) -> tuple:
    return core.force_balance(PY, *args)


def _bits(values: object) -> object:
    """Nested tuples of floats by their bit patterns (-0.0 != 0.0, NaNs compare)."""
    if isinstance(values, tuple):
        return [_bits(v) for v in values]
    if isinstance(values, float):
        return (type(values).__name__, struct.pack("<d", values))
    return (type(values).__name__, values)


def _args(rng: np.random.Generator, special: bool) -> tuple:
    a = rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-6, 4, 3)
    s = a @ a.T
    if rng.uniform() < 0.3:  # indefinite, singular or barely definite
        s = s - rng.uniform(0.0, 2.0) * np.trace(s) / 3.0 * np.eye(3)
    values = [float(v) for v in s.ravel()]
    y = [float(v) for v in rng.normal(size=3) * 10.0 ** rng.uniform(-6, 3)]
    r = float(10.0 ** rng.uniform(-8, 2)) if rng.uniform() < 0.9 else 0.0
    if special:
        for _ in range(int(rng.integers(1, 3))):
            which = [values, y][int(rng.integers(0, 2))]
            which[int(rng.integers(0, len(which)))] = [0.0, -0.0, math.nan, math.inf, -math.inf][
                int(rng.integers(0, 5))
            ]
    return values if rng.uniform() < 0.5 else tuple(values), tuple(y), r


@pytest.mark.parametrize("special", [False, True])
def test_bit_for_bit_on_random_arguments(special: bool) -> None:
    rng = np.random.default_rng(1919 + special)
    rejected = accepted = 0
    for _ in range(20000):
        args = _args(rng, special)
        mine, reference = _c(*args), PY(*args)
        assert _bits(mine) == _bits(reference), args
        if math.isnan(reference[0]):
            rejected += 1
        else:
            accepted += 1
    assert rejected > 1000 and accepted > 1000


def test_other_arguments_go_to_python_with_its_result_or_error() -> None:
    s = [4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0]
    y = (0.1, -0.2, 0.3)
    numpy_floats = [np.float64(v) for v in s]  # Python's arithmetic then gives numpy floats
    assert _bits(_c(numpy_floats, y, 0.01)) == _bits(PY(numpy_floats, y, 0.01))
    assert type(_c(numpy_floats, y, 0.01)[1][0]) is np.float64
    assert _bits(_c(s, y, 1)) == _bits(PY(s, y, 1))  # an int variance
    for bad in (s[:8], [*s, 0.0]):
        with pytest.raises(ValueError):
            _c(bad, y, 0.01)
    with pytest.raises(ValueError):
        _c(s, y[:2], 0.01)


def test_the_member_test_uses_c_on_a_flight_and_equals_python(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # the bank's one-call fusion (bank_fusion.c) off: the member's own test runs
    monkeypatch.setattr(bank_updates, "FUSE_FORCE_BALANCE", None)
    vehicle = load_vehicle(load_scenario("realistic-circle").vehicle)
    estimator = DynamicTetherEstimator(EstimatorConfig(), vehicle)
    with recording_c_calls(member, "SOLVE_FORCE_BALANCE", core.force_balance, PY) as (
        calls,
        fallbacks,
    ):
        for imu in imu_ticks(record("realistic-circle", 6.0), estimator):
            estimator.on_imu(imu)
    assert len(calls) > 100
    assert not fallbacks
    for args in calls:
        assert _bits(core.force_balance(PY, *args)) == _bits(PY(*args))
