"""The bank's batch prediction, mixture and health test over its members, each in one C call
(``_member_core.predict_batch``, bank_predict.c; ``bank_mixture``, bank_mixture.c;
``bank_healthy_members``, bank_health.c), against their Python references (the
member-by-member loop of :meth:`FilterBank.predict_batch` with the extension's step functions;
:meth:`FilterBank.mixture`'s cache test, weights and the extension's ``mixture``;
:meth:`FilterBank.drop_unhealthy`'s loop): on random banks (members holding arrays or lists,
transitions, batch sums, process noises, log weights, spoiled states) every member's state,
covariance and repair counts, every mixture, the cache and the members kept equal bit for bit;
where a call does not take the members it returns None and changes nothing the Python would
not, and the Python then decides as it always did; on a flight all three take nearly every
call and the flight's estimates equal the Python's.

The extension is optional; its absence fails this file where it could have been built
(:mod:`optional_extension`).
"""

from __future__ import annotations

import math
import os
import struct
from collections.abc import Callable

import numpy as np
import pytest
from bank_core_flight import fly_with_and_without_c
from optional_extension import import_extension

from tether_companion.estimation.dynamic import bank as bank_module
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.imu_batch import ImuBatch
from tether_companion.estimation.dynamic.member import MemberFilter

core, pytestmark = import_extension("tether_companion.estimation.dynamic._member_core")

_N = state.N_STATES


def _bits(value: object) -> object:
    """Floats by their bit patterns, arrays by their dtype, shape and bytes."""
    if isinstance(value, np.ndarray):
        return (value.dtype.str, value.shape, value.flags.c_contiguous, value.tobytes())
    if isinstance(value, list):
        return [_bits(v) for v in value]
    if isinstance(value, float):
        return struct.pack("<d", value)
    return (type(value).__name__, value)


def _member_bits(kf: MemberFilter) -> object:
    return (_bits(kf._xa), _bits(kf._pa), _bits(kf._xl), _bits(kf._pl), kf.resets, kf.pd_repairs)


def _value_bits(kf: MemberFilter) -> object:
    """A member's values and counts whichever form holds them (a list-held member's x / P
    property converts it, as the loop's kf.x and kf.P do)."""
    return (_bits(kf.values()[0]), _bits(kf.values()[1]), kf.resets, kf.pd_repairs)


def _skip_pure() -> None:
    if os.environ.get("TETHER_PURE_PYTHON"):
        pytest.skip("TETHER_PURE_PYTHON is set: the package runs the Python alone")


def _bank(rng: np.random.Generator) -> FilterBank:
    """1-6 members of random scales; some hold their values as lists (the scalar path's)."""
    filters = []
    for _ in range(int(rng.integers(1, 7))):
        a = rng.normal(size=(_N, _N)) * 10.0 ** rng.uniform(-3, 1, _N)
        kf = MemberFilter(
            rng.normal(size=_N) * 10.0 ** rng.uniform(-2, 3), a @ a.T + 1e-6 * np.eye(_N),
            np.full(_N, 1e-3), None, None,  # type: ignore[arg-type]
        )  # fmt: skip
        if rng.uniform() < 0.3:
            kf._xl, kf._xa = kf._xa.tolist(), None
        if rng.uniform() < 0.3:
            kf._pl, kf._pa = kf._pa.ravel().tolist(), None
        filters.append(kf)
    return FilterBank(filters, 0.0, 6.0)


def _batch(rng: np.random.Generator) -> ImuBatch:
    """A batch of random sums (duration, D_p, D_v, B_p, B_v) as ImuBatch.add leaves them."""
    batch = ImuBatch()
    batch.ticks = int(rng.integers(1, 5))
    batch.duration_s = float(rng.uniform(0.0, 0.05))
    scale = 10.0 ** rng.uniform(-4, 1)
    batch.d_p, batch.d_v = (rng.normal(size=3) * scale).tolist(), (rng.normal(size=3)).tolist()
    batch.b_p, batch.b_v = (rng.normal(size=9) * 1e-3).tolist(), rng.normal(size=9).tolist()
    if rng.uniform() < 0.2:  # exact zeros in the bias columns (their entries skipped)
        batch.b_p = [0.0] * 9
    return batch


def _noise(rng: np.random.Generator) -> np.ndarray:
    b = rng.normal(size=(_N, _N)) * 1e-2
    return b @ b.T


def _predict(bank: FilterBank, batch: ImuBatch, q: np.ndarray, c_path: bool) -> None:
    """The bank's batch prediction with its one C call on (``c_path``) or off (the loop)."""
    saved = bank_module.PREDICT_BATCH
    bank_module.PREDICT_BATCH = core.predict_batch if c_path else None
    try:
        bank.predict_batch(batch, q)
    finally:
        bank_module.PREDICT_BATCH = saved


def _same_draw(rng: np.random.Generator, change: Callable[..., None], *banks: FilterBank) -> None:
    """``change(rng, bank)`` on each of ``banks`` from the same generator state (the generator
    ends where the last call left it): equal banks stay equal."""
    state_now = rng.bit_generator.state
    for bank in banks:
        rng.bit_generator.state = state_now
        change(rng, bank)


def _copies(rng: np.random.Generator) -> tuple[FilterBank, FilterBank]:
    state_now = rng.bit_generator.state
    mine = _bank(rng)
    rng.bit_generator.state = state_now
    return mine, _bank(rng)


def test_bit_for_bit_on_random_banks() -> None:
    _skip_pure()
    rng = np.random.default_rng(2525)
    members = 0
    for _ in range(150):
        mine, reference = _copies(rng)
        batch, q = _batch(rng), _noise(rng)
        for _step in range(3):  # chained: each step from the last one's kept arrays
            _predict(mine, batch, q, True)
            _predict(reference, batch, q, False)
            for a, b in zip(mine.filters, reference.filters, strict=True):
                assert _member_bits(a) == _member_bits(b)
        members += len(mine.filters)
    assert members > 300


def test_a_list_held_member_is_converted_as_the_loop_converts_it() -> None:
    _skip_pure()
    rng = np.random.default_rng(7)
    bank = _bank(rng)
    kf = bank.filters[0]
    kf._xl, kf._xa = kf.x.tolist(), None
    kf._pl, kf._pa = kf.P.ravel().tolist(), None
    batch, q = _batch(rng), _noise(rng)
    step = batch.step()
    expected_x = step.step_state(np.array(kf._xl))
    expected_p, _ = step.step_member_covariance(np.array(kf._pl).reshape(_N, _N), q)
    assert core.predict_batch(
        bank.filters, step.phi, step.d_p, step.d_v, q, step.duration_s, np.empty
    )
    assert kf._xl is None and kf._pl is None
    assert _bits(kf._xa) == _bits(expected_x) and _bits(kf._pa) == _bits(expected_p)


def _spoiled(spoil: str, rng: np.random.Generator) -> tuple[FilterBank, ImuBatch, np.ndarray]:
    bank, batch, q = _bank(rng), _batch(rng), _noise(rng)
    last = bank.filters[-1]  # the last member: the earlier ones are computed before it fails
    if spoil == "state nan":
        last.x[4] = np.nan
    elif spoil == "covariance inf":
        last.P[2, 9] = np.inf
    elif spoil == "state near overflow":  # finite, but numpy's sum of the stepped state is not
        last.x[:] = 1.5e307
    elif spoil == "state entry past the bound":  # the sum finite: the loop keeps it
        last.x[:] = 0.0
        last.x[10] = np.finfo(float).max / _N * 1.01
    elif spoil == "covariance overflows":
        last.P[0, 0] = last.P[3, 3] = 1.7e308
        batch.duration_s = 1e3
    elif spoil == "noise asymmetric":
        q[1, 3] += 1e-9
    elif spoil == "noise nan":
        q[5, 5] = np.nan
    elif spoil == "sums nan":
        batch.d_v[1] = np.nan
    elif spoil == "sums short":
        batch.d_p = batch.d_p[:2]
    elif spoil == "duration int":
        batch.duration_s = 0  # type: ignore[assignment]
    elif spoil == "float32 state":
        last._xa = last.x.astype(np.float32)
    elif spoil == "strided covariance":
        last._pa = np.asfortranarray(last.P + np.eye(_N) * 1e-9)
    return bank, batch, q


SPOILS = [
    "state nan", "covariance inf", "state near overflow", "state entry past the bound",
    "covariance overflows", "noise asymmetric", "noise nan", "sums nan", "sums short",
    "duration int", "float32 state", "strided covariance",
]  # fmt: skip


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the loop's numpy on non-finite values
@pytest.mark.parametrize("spoil", SPOILS)
def test_not_taken_changes_nothing_and_the_loop_decides(spoil: str) -> None:
    _skip_pure()
    rng = np.random.default_rng(SPOILS.index(spoil))
    bank, batch, q = _spoiled(spoil, rng)
    before = [_value_bits(kf) for kf in bank.filters]
    step = batch.step()
    taken = core.predict_batch(
        bank.filters, step.phi, step.d_p, step.d_v, q, step.duration_s, np.empty
    )
    assert taken is None
    assert [_value_bits(kf) for kf in bank.filters] == before
    rng = np.random.default_rng(SPOILS.index(spoil))
    reference, batch, q = _spoiled(spoil, rng)
    if spoil == "sums short":  # not a batch: the loop's numpy refuses it, on both paths
        for c_path in (True, False):
            with pytest.raises(ValueError):
                _predict(bank, batch, q, c_path)
        return
    _predict(bank, batch, q, True)
    _predict(reference, batch, q, False)
    for a, b in zip(bank.filters, reference.filters, strict=True):
        assert _member_bits(a) == _member_bits(b)


def _mixture(bank: FilterBank, c_path: bool) -> tuple[np.ndarray, np.ndarray]:
    """The bank's mixture with its one C call on (``c_path``) or off (the Python)."""
    saved = bank_module.BANK_MIXTURE
    bank_module.BANK_MIXTURE = core.bank_mixture if c_path else None
    try:
        return bank.mixture()
    finally:
        bank_module.BANK_MIXTURE = saved


def _cache_bits(bank: FilterBank) -> object:
    arrays, ll, (mean, cov) = bank._mixture_cache
    held = [a for kf in bank.filters for a in (kf._xa, kf._pa)]
    return [a is b for a, b in zip(arrays, held, strict=True)], _bits(ll), _bits(mean), _bits(cov)


def _weighted(rng: np.random.Generator, bank: FilterBank) -> None:
    """Log weights of random spreads (ties, a dominant member, underflowing exponentials)."""
    spread = float(10.0 ** rng.uniform(-3, 3))
    ll = (rng.normal(size=len(bank.filters)) * spread).tolist()
    if rng.uniform() < 0.2:
        ll[-1] = ll[0]
    bank.log_weight = ll


def test_mixture_bit_for_bit_on_random_banks() -> None:
    _skip_pure()
    rng = np.random.default_rng(2526)
    mixed = 0
    for _ in range(200):
        mine, reference = _copies(rng)
        if len(mine.filters) < 2:
            continue
        _same_draw(rng, _weighted, mine, reference)
        got, expected = _mixture(mine, True), _mixture(reference, False)
        assert _bits(list(got)) == _bits(list(expected))
        assert _cache_bits(mine) == _cache_bits(reference)
        for a, b in zip(mine.filters, reference.filters, strict=True):
            assert _member_bits(a) == _member_bits(b)
        mixed += 1
    assert mixed > 120


@pytest.mark.parametrize("c_path", [True, False])
def test_the_cache_holds_until_a_weight_or_an_array_changes(c_path: bool) -> None:
    _skip_pure()
    rng = np.random.default_rng(31)
    bank = _bank(rng)
    while len(bank.filters) < 3:
        bank = _bank(rng)
    _weighted(rng, bank)
    first = _mixture(bank, c_path)
    again = _mixture(bank, c_path)
    assert again[0] is first[0] and again[1] is first[1]
    bank.log_weight[-1] += 1e-12  # in place, as the evidence is added
    moved = _mixture(bank, c_path)
    assert moved[0] is not first[0]
    bank.filters[1]._pa = bank.filters[1].P.copy()  # the same values, another array
    assert _mixture(bank, c_path)[1] is not moved[1]


MIXTURE_SPOILS = ["one member", "log weight nan", "log weight inf", "log weight int",
                  "state nan", "covariance inf", "float32 covariance"]  # fmt: skip


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the numpy reference on non-finite values
@pytest.mark.parametrize("spoil", MIXTURE_SPOILS)
def test_mixture_not_taken_and_the_python_decides(spoil: str) -> None:
    _skip_pure()
    banks = []
    for _ in range(2):
        rng = np.random.default_rng(40 + MIXTURE_SPOILS.index(spoil))
        bank = _bank(rng)
        while len(bank.filters) < 3:
            bank = _bank(rng)
        _weighted(rng, bank)
        last = bank.filters[-1]
        if spoil == "one member":
            bank.keep([0])
        elif spoil.startswith("log weight"):
            value = {"nan": math.nan, "inf": math.inf, "int": 3}[spoil.split()[-1]]
            bank.log_weight[1] = value
        elif spoil == "state nan":
            last.x[2] = np.nan
        elif spoil == "covariance inf":
            last.P[4, 4] = np.inf
        elif spoil == "float32 covariance":
            last._pa = last.P.astype(np.float32)
        banks.append(bank)
    mine, reference = banks
    cache = mine._mixture_cache
    assert core.bank_mixture(mine.filters, mine.log_weight, cache, np.empty) is None
    assert mine._mixture_cache is cache
    got, expected = _mixture(mine, True), _mixture(reference, False)
    assert _bits(list(got)) == _bits(list(expected))


def _drop(bank: FilterBank, c_path: bool, max_distance_m: float) -> None:
    """The bank's drop_unhealthy with its one C call on (``c_path``) or off (the loop)."""
    saved = bank_module.HEALTHY_MEMBERS
    bank_module.HEALTHY_MEMBERS = core.bank_healthy_members if c_path else None
    try:
        bank.drop_unhealthy(max_distance_m)
    finally:
        bank_module.HEALTHY_MEMBERS = saved


def _sicken(rng: np.random.Generator, bank: FilterBank) -> None:
    """Some members' states spoiled: nan, inf, far from the anchor, at the limit, or summing
    past the largest float (finite entries whose in-order sum overflows)."""
    for kf in bank.filters:
        x = kf.x
        kind = int(rng.integers(0, 8))
        if kind == 0:
            x[int(rng.integers(0, _N))] = np.nan
        elif kind == 1:
            x[int(rng.integers(0, _N))] = -np.inf
        elif kind == 2:
            x[:3] = rng.normal(size=3) * 800.0
        elif kind == 3:
            x[:3] = (600.0, 800.0, 0.0)  # exactly 1000 m: kept (<=)
        elif kind == 4:
            x[5:9] = 1.7e308  # overflows in order
        elif kind == 5:
            x[5:9] = (1.7e308, -1.7e308, 1.7e308, -1.7e308)  # finite in order
        elif kind == 6:
            x[5:7] = (1.0e308, 0.9e308)  # just past the largest float
        if rng.uniform() < 0.3:
            kf._xl, kf._xa = kf._xa.tolist(), None


def test_healthy_members_bit_for_bit_on_random_banks() -> None:
    _skip_pure()
    rng = np.random.default_rng(2527)
    dropped = 0
    for _ in range(300):
        mine, reference = _copies(rng)
        _same_draw(rng, _sicken, mine, reference)
        listed = [kf._xl is not None for kf in mine.filters]
        assert core.bank_healthy_members(mine.filters, 1e6) is not None
        assert [kf._xl is not None for kf in mine.filters] == listed  # read, not converted
        before = len(mine.filters)
        _drop(mine, True, 1000.0)
        _drop(reference, False, 1000.0)
        assert [kf.resets for kf in mine.filters] == [kf.resets for kf in reference.filters]
        assert [_bits(kf.x_values()) for kf in mine.filters] == [
            _bits(kf.x_values()) for kf in reference.filters
        ]
        assert _bits(mine.log_weight) == _bits(reference.log_weight)
        dropped += before - len(mine.filters)
    assert dropped > 100


HEALTH_SPOILS = ["limit int", "list with an int", "float32 state", "2-D state", "short state"]


@pytest.mark.parametrize("spoil", HEALTH_SPOILS)
def test_healthy_members_not_taken(spoil: str) -> None:
    _skip_pure()
    rng = np.random.default_rng(50)
    bank = _bank(rng)
    last = bank.filters[-1]
    limit: object = 1e6
    if spoil == "limit int":
        limit = 10**6
    elif spoil == "list with an int":
        last._xl, last._xa = [0, *last.x[1:].tolist()], None
    elif spoil == "float32 state":
        last._xa = last.x.astype(np.float32)
    elif spoil == "2-D state":
        last._xa = last.x.reshape(1, _N)
    elif spoil == "short state":
        last._xa = last.x[:2].copy()
    assert core.bank_healthy_members(bank.filters, limit) is None


def test_a_flight_takes_c_and_equals_the_python() -> None:
    (mine, mine_members, calls), (reference, reference_members, _) = fly_with_and_without_c(
        bank_module,
        {
            "PREDICT_BATCH": core.predict_batch,
            "BANK_MIXTURE": core.bank_mixture,
            "HEALTHY_MEMBERS": core.bank_healthy_members,
        },
        _bits,
        _member_bits,
    )
    predicted, mixed = calls["PREDICT_BATCH"], calls["BANK_MIXTURE"]
    tested = calls["HEALTHY_MEMBERS"]
    assert predicted[0] > 300 and predicted[1] < 5 and mixed[0] > 300 and mixed[1] < 5, calls
    assert tested[0] > 200 and tested[1] < 5, calls
    assert mine == reference
    assert mine_members == reference_members
