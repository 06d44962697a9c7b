"""The bank's force-balance and scalar fusions over its members in one C call
(``_member_core.fuse_force_balance`` / ``fuse_scalar``, bank_fusion.c) against their Python
reference (:meth:`FilterBank.update_force_balance` / ``update_scalar`` with the extension's
member functions): on random
banks (members, covariances, models, gates, consider states, counters) every outcome, state,
covariance, ``log det S`` and sensor count equal bit for bit after every fusion; where it does
not take the members it returns None and changes nothing; on a flight it takes nearly every
fusion and the flight's states and counts equal the Python's.

The extension is optional; its absence fails this file where it could have been built
(:mod:`optional_extension`).
"""

from __future__ import annotations

import copy
import math
import os
import struct

import numpy as np
import pytest
from bank_core_flight import fly_with_and_without_c
from optional_extension import import_extension

from tether_companion.estimation.dynamic import bank_updates as bank_module
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.member import MemberFilter
from tether_companion.estimation.ekf import UpdateResult

core, pytestmark = import_extension("tether_companion.estimation.dynamic._member_core")

_N = state.N_STATES
SENSOR = "accel"


def _bits(value: object) -> object:
    """Floats by their bit patterns, arrays by their bytes, containers item by item."""
    if isinstance(value, np.ndarray):
        return (value.dtype.str, value.shape, value.tobytes())
    if isinstance(value, (list, tuple)):
        return [type(value).__name__, *(_bits(v) for v in value)]
    if isinstance(value, float):
        return ("float", struct.pack("<d", value))
    if isinstance(value, UpdateResult):
        return ("UpdateResult", value.status, _bits(value.nis))
    return (type(value).__name__, value)


def _status_bits(kf: MemberFilter) -> object:
    return sorted(
        (name, s.fused, s.gated, s.nonfinite, s.singular, s.forced, s.consecutive_rejections,
         _bits(s.last_nis), _bits(s.innovation))
        for name, s in kf.sensors.items()
    )  # fmt: skip


def _member_bits(kf: MemberFilter) -> object:
    return (
        _bits(kf._xa), _bits(kf._pa), kf._xl, kf._pl, _bits(kf.last_log_det_s),
        _status_bits(kf), kf.resets, kf.pd_repairs,
    )  # fmt: skip


def _measure_for(rng: np.random.Generator):  # noqa: ANN202 (a model closure)
    """A pure random 3-axis model ``(h(x) (3 floats), H (51 floats and ints, a list or tuple))``:
    linear plus a small quadratic term, with some Jacobian entries the ints 0 and 1, as the
    generated models give."""
    h = rng.normal(size=(3, _N)) * 10.0 ** rng.uniform(-2, 1, (3, 1))
    h[rng.uniform(size=h.shape) < 0.3] = 0.0
    ones = rng.uniform(size=h.shape) < 0.05
    h[ones] = 1.0
    entries = [
        int(v) if (v == 0.0 or one) else float(v)
        for v, one in zip(h.ravel(), ones.ravel(), strict=True)
    ]
    curvature = [float(v) for v in rng.normal(size=3) * 0.1]
    as_tuple = bool(rng.uniform() < 0.5)

    def measure(x: list[float]) -> tuple[tuple[float, ...], object]:
        value = tuple(
            float(sum(a * b for a, b in zip(h[k], x, strict=True)) + curvature[k] * x[k] * x[k])
            for k in range(3)
        )
        return value, (tuple(entries) if as_tuple else list(entries))

    return measure


def _bank(rng: np.random.Generator) -> FilterBank:
    members = int(rng.integers(1, 7))
    filters = []
    for _ in range(members):
        a = rng.normal(size=(_N, _N)) * 10.0 ** rng.uniform(-3, 0, _N)
        p0 = a @ a.T + 1e-6 * np.eye(_N)
        x0 = rng.normal(size=_N)
        kf = MemberFilter(
            x0, p0, np.full(_N, 1e-3), None, None,  # type: ignore[arg-type]
            gate_probability=float(rng.choice([1.0, 0.9, 0.999])),
            max_consecutive_rejections=int(rng.choice([0, 2, 5])),
        )  # fmt: skip
        filters.append(kf)
    consider = [None, state.CALIBRATION, slice(3, 6)][int(rng.integers(0, 3))]
    return FilterBank(filters, 0.0, 6.0, consider=consider)


def _fuse_through(entry: str, bank: FilterBank, c_path: bool, *args: object) -> object:
    """The bank's fusion ``entry`` ("FUSE_FORCE_BALANCE" or "FUSE_SCALAR") with its one C call
    on (``c_path``) or off (the Python reference)."""
    saved = getattr(bank_module, entry)
    setattr(bank_module, entry, getattr(core, entry.lower()) if c_path else None)
    try:
        method = bank.update_force_balance if entry == "FUSE_FORCE_BALANCE" else bank.update_scalar
        return method(*args)  # type: ignore[arg-type]
    finally:
        setattr(bank_module, entry, saved)


def _fuse(bank: FilterBank, c_path: bool, *args: object) -> object:
    return _fuse_through("FUSE_FORCE_BALANCE", bank, c_path, *args)


def _core_call(
    function: object, bank: FilterBank, z: object, measure: object, r: object, tempering: object
) -> object:
    """One C fusion called directly on ``bank``'s members (None: not taken)."""
    return function(  # type: ignore[operator]
        bank.filters, SENSOR, z, measure, r, *_hold(bank), np.empty, bank_module.UpdateResult,
        bank_module.FUSED, bank_module.GATED, bank.log_weight, tempering,
    )  # fmt: skip


def _same_fusion(
    mine: FilterBank, reference: FilterBank, got: object, expected: object
) -> tuple[int, int]:
    """Assert one fusion's C and Python results equal bit for bit (outcomes, Jacobians, priors,
    log weights, every member's arrays and counts); return its (fused, gated) member counts."""
    assert _bits(mine.log_weight) == _bits(reference.log_weight)
    assert _bits(got[0]) == _bits(expected[0])  # type: ignore[index]
    assert _bits(got[1]) == _bits(expected[1])  # type: ignore[index]
    assert _bits(got[2]) == _bits(expected[2])  # type: ignore[index]
    for a, b in zip(mine.filters, reference.filters, strict=True):
        assert _member_bits(a) == _member_bits(b)
    statuses = [result.status for result in got[0]]  # type: ignore[index]
    return statuses.count("fused"), statuses.count("gated")


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the numpy reference on non-finite states
def test_bit_for_bit_on_random_banks() -> None:
    if os.environ.get("TETHER_PURE_PYTHON"):
        pytest.skip("TETHER_PURE_PYTHON is set: the package runs the Python alone")
    rng = np.random.default_rng(2121)
    taken = fused = gated = forced = 0
    for _ in range(60):
        reference = _bank(rng)
        mine = copy.deepcopy(reference)
        measure = _measure_for(rng)
        r = float(10.0 ** rng.uniform(-3, 0))
        tempering = None if rng.uniform() < 0.3 else float(rng.uniform(1.0, 20.0))
        for _ in range(25):
            z = [float(v) for v in rng.normal(size=3) * 10.0 ** rng.uniform(-2, 1.5)]
            if rng.uniform() < 0.1:  # an innovation exactly zero: its sign is +0.0
                z = list(measure(mine.filters[0].x_values())[0])
            z = z if rng.uniform() < 0.5 else tuple(z)
            expected = _fuse(reference, False, SENSOR, z, measure, r, tempering)
            took = _took(mine, z, measure, r, tempering)
            got = _fuse(mine, True, SENSOR, z, measure, r, tempering)
            taken += took
            counts = _same_fusion(mine, reference, got, expected)
            fused, gated = fused + counts[0], gated + counts[1]
        forced += sum(s.forced for kf in mine.filters for s in kf.sensors.values())
    assert taken > 1000 and fused > 1000 and gated > 100 and forced > 10, (
        taken, fused, gated, forced,
    )  # fmt: skip


def _hold(bank: FilterBank) -> tuple[int, int]:
    hold = bank.consider
    start, stop, _ = (slice(0, 0) if hold is None else hold).indices(_N)
    return start, stop


def _took(bank: FilterBank, z: object, measure: object, r: float, tempering: object) -> bool:
    """Whether the C takes this fusion (run on a copy: it changes what it takes)."""
    return _call(copy.deepcopy(bank), z, measure, r, tempering) is not None


def _ready_bank() -> tuple[FilterBank, object]:
    """A bank that has fused once (statuses and gate thresholds made), and its model."""
    rng = np.random.default_rng(7)
    bank = _bank(rng)
    while len(bank.filters) < 2:
        bank = _bank(rng)
    measure = _measure_for(rng)
    _fuse(bank, False, SENSOR, [0.1, 0.2, 0.3], measure, 0.5)
    return bank, measure


def _call(
    bank: FilterBank, z: object, measure: object, r: object, tempering: object = 5.0
) -> object:
    return _core_call(core.fuse_force_balance, bank, z, measure, r, tempering)


@pytest.mark.parametrize(
    "spoil",
    [
        "lists", "nan_p", "inf_x", "new_sensor", "no_threshold", "nan_model", "int_z",
        "np_float_r", "model_not_tuple", "indefinite", "int_log_weight", "int_tempering",
    ],
)  # fmt: skip
def test_not_taken_changes_nothing(spoil: str) -> None:
    bank, measure = _ready_bank()
    z: object = [0.1, 0.2, 0.3]
    r: object = 0.5
    kf = bank.filters[-1]
    if spoil == "lists":
        kf._lists()
    elif spoil == "nan_p":
        p = kf.P.copy()
        p[3, 4] = math.nan
        kf.P = p
    elif spoil == "inf_x":
        x = kf.x.copy()
        x[2] = math.inf
        kf.x = x
    elif spoil == "new_sensor":
        del kf.sensors[SENSOR]
    elif spoil == "no_threshold":
        kf._thresholds.clear()
    elif spoil == "nan_model":
        inner = measure

        def measure(x: list[float]) -> object:  # type: ignore[no-redef]
            value, jac = inner(x)  # type: ignore[operator]
            return (value[0], math.nan, value[2]), jac

    elif spoil == "int_z":
        z = [0.1, 2, 0.3]
    elif spoil == "np_float_r":
        r = np.float64(0.5)
    elif spoil == "model_not_tuple":
        inner = measure

        def measure(x: list[float]) -> object:  # type: ignore[no-redef]
            return list(inner(x))  # type: ignore[operator]

    elif spoil == "indefinite":
        kf.P = -np.eye(_N)
    elif spoil == "int_log_weight":
        bank.log_weight[0] = 0
    tempering = 5 if spoil == "int_tempering" else 5.0
    before = [_member_bits(m) for m in bank.filters], _bits(bank.log_weight)
    assert _call(bank, z, measure, r, tempering) is None
    assert ([_member_bits(m) for m in bank.filters], _bits(bank.log_weight)) == before


def _scalar_measure_for(rng: np.random.Generator):  # noqa: ANN202 (a model closure)
    """A pure random scalar model on the state array ``(h(x) (1,) array, H)``, ``H`` a (1, n)
    float array, a list or a tuple (floats and the ints 0 and 1)."""
    h = rng.normal(size=_N) * 10.0 ** rng.uniform(-2, 1)
    h[rng.uniform(size=_N) < 0.3] = 0.0
    form = int(rng.integers(0, 3))
    entries = [int(v) if v == 0.0 else float(v) for v in h]
    jacobian = h.reshape(1, _N).copy() if form == 0 else (entries if form == 1 else tuple(entries))
    curvature = float(rng.normal() * 0.1)

    def measure(x: np.ndarray) -> tuple[np.ndarray, object]:
        return np.array((float(h @ x) + curvature * float(x[0]) * float(x[0]),)), jacobian

    return measure


def _fuse_scalar(bank: FilterBank, c_path: bool, *args: object) -> object:
    return _fuse_through("FUSE_SCALAR", bank, c_path, *args)


def _call_scalar(
    bank: FilterBank, z: object, measure: object, r: object, tempering: object = 20.0
) -> object:
    return _core_call(core.fuse_scalar, bank, z, measure, r, tempering)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the numpy reference on non-finite states
def test_scalar_bit_for_bit_on_random_banks() -> None:
    if os.environ.get("TETHER_PURE_PYTHON"):
        pytest.skip("TETHER_PURE_PYTHON is set: the package runs the Python alone")
    rng = np.random.default_rng(2122)
    taken = fused = gated = 0
    for _ in range(60):
        reference = _bank(rng)
        mine = copy.deepcopy(reference)
        measure = _scalar_measure_for(rng)
        r = float(10.0 ** rng.uniform(-3, 0))
        tempering = None if rng.uniform() < 0.3 else float(rng.uniform(1.0, 20.0))
        for _ in range(25):
            z = float(rng.normal() * 10.0 ** rng.uniform(-2, 1.5))
            if rng.uniform() < 0.1:  # an innovation exactly zero
                z = float(measure(mine.filters[0].x)[0][0])
            expected = _fuse_scalar(reference, False, SENSOR, z, measure, r, None, tempering)
            taken += _call_scalar(copy.deepcopy(mine), z, measure, r, tempering) is not None
            got = _fuse_scalar(mine, True, SENSOR, z, measure, r, None, tempering)
            counts = _same_fusion(mine, reference, got, expected)
            fused, gated = fused + counts[0], gated + counts[1]
    assert taken > 1000 and fused > 1000 and gated > 100, (taken, fused, gated)


@pytest.mark.parametrize(
    "spoil",
    ["lists", "nan_model", "new_sensor", "no_threshold", "int_z", "flat_jacobian", "zero_s"],
)
def test_scalar_not_taken_changes_nothing(spoil: str) -> None:
    rng = np.random.default_rng(8)
    bank = _bank(rng)
    while len(bank.filters) < 2:
        bank = _bank(rng)
    measure = _scalar_measure_for(rng)
    _fuse_scalar(bank, False, SENSOR, 0.1, measure, 0.5)
    z: object = 0.2
    r: object = 0.5
    kf = bank.filters[-1]
    if spoil == "lists":
        kf._lists()
    elif spoil == "nan_model":
        inner = measure

        def measure(x: np.ndarray) -> object:  # type: ignore[no-redef]
            return np.array((math.nan,)), inner(x)[1]  # type: ignore[operator]

    elif spoil == "new_sensor":
        del kf.sensors[SENSOR]
    elif spoil == "no_threshold":
        kf._thresholds.clear()
    elif spoil == "int_z":
        z = 2
    elif spoil == "flat_jacobian":
        inner = measure

        def measure(x: np.ndarray) -> object:  # type: ignore[no-redef]
            value, _ = inner(x)  # type: ignore[operator]
            return value, np.ones(_N)

    elif spoil == "zero_s":
        r = 0.0
        kf.P = np.zeros((_N, _N))
    before = [_member_bits(m) for m in bank.filters], _bits(bank.log_weight)
    assert _call_scalar(bank, z, measure, r) is None
    assert ([_member_bits(m) for m in bank.filters], _bits(bank.log_weight)) == before


def test_a_flight_takes_c_and_equals_python() -> None:
    (mine, mine_members, calls), (reference, reference_members, _) = fly_with_and_without_c(
        bank_module,
        {"FUSE_FORCE_BALANCE": core.fuse_force_balance, "FUSE_SCALAR": core.fuse_scalar},
        _bits,
        _member_bits,
        log_weights=True,
    )
    balance, scalar = calls["FUSE_FORCE_BALANCE"], calls["FUSE_SCALAR"]
    assert balance[0] > 300 and balance[1] < 10 and scalar[0] > 100 and scalar[1] < 10, calls
    assert mine == reference
    assert mine_members == reference_members
