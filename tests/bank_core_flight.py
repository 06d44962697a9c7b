"""One realistic-circle flight flown twice, with the bank's C calls taken (each counted) and
with them off (the Python references), for the C twins' flight tests (test_bank_fusion_core,
test_bank_members_core): every output and the members' end state, as the caller's bit
patterns, and how often each C call ran or fell back to Python."""

from __future__ import annotations

import os
from collections.abc import Callable
from types import ModuleType

import pytest

from tether_companion.bench.dynamic import record
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.member import MemberFilter
from tether_companion.estimation.feed import imu_ticks
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.scenario import load_scenario

FlightRun = tuple[list[object], list[object], dict[str, list[int]]]
"""A flight's outputs, its members' end states and, per C call, ``[taken, fell back]``."""


def fly_with_and_without_c(
    owner: ModuleType,
    c_functions: dict[str, Callable[..., object]],
    bits: Callable[[object], object],
    member_bits: Callable[[MemberFilter], object],
    log_weights: bool = False,
    duration_s: float = 8.0,
) -> tuple[FlightRun, FlightRun]:
    """Fly ``duration_s`` [s] of realistic-circle with each ``owner.<name>`` of
    ``c_functions`` (``owner``: the module that binds the bank's C calls) bound to its C
    function (counted: taken, or None = fell back), then with every such name None (the
    Python runs). Outputs: each published estimate's status,
    position and covariance (and, with ``log_weights``, the bank's log weights each tick)
    through ``bits``; the members at the end through ``member_bits``. Skips where
    ``TETHER_PURE_PYTHON`` is set (the package then runs the Python alone, by request)."""
    if os.environ.get("TETHER_PURE_PYTHON"):
        pytest.skip("TETHER_PURE_PYTHON is set: the package runs the Python alone")
    vehicle = load_vehicle(load_scenario("realistic-circle").vehicle)
    flight = record("realistic-circle", duration_s)
    runs = []
    for c_path in (True, False):
        saved = {name: getattr(owner, name) for name in c_functions}
        calls = {name: [0, 0] for name in c_functions}
        for name, function in c_functions.items():

            def counted(
                *args: object,
                function: Callable[..., object] = function,
                count: list[int] = calls[name],
            ) -> object:
                out = function(*args)
                count[out is None] += 1
                return out

            setattr(owner, name, counted if c_path else None)
        try:
            estimator = DynamicTetherEstimator(EstimatorConfig(), vehicle)
            outputs: list[object] = []
            for imu in imu_ticks(flight, estimator):
                estimate = estimator.on_imu(imu)
                if estimate is not None:
                    outputs.append(
                        (estimate.status, bits(estimate.position_ned_m),
                         bits(estimate.position_velocity_covariance))
                    )  # fmt: skip
                if log_weights and estimator.bank is not None:
                    outputs.append(bits(list(estimator.bank.log_weight)))
        finally:
            for name, function in saved.items():
                setattr(owner, name, function)
        assert estimator.bank is not None
        runs.append((outputs, [member_bits(kf) for kf in estimator.bank.filters], calls))
    return runs[0], runs[1]
