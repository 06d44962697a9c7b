"""The dynamic filter's scorecard kinds: registered, and riding a short flight."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("distributed", reason="bench estimators needs dask.distributed (test extra)")

from tether_companion.bench.estimators.flight import fly  # noqa: E402
from tether_companion.bench.estimators.registry import kinds  # noqa: E402
from tether_companion.sim.scenario import load_scenario  # noqa: E402


def test_dynamic_kinds_are_registered_and_score_a_flight() -> None:
    registry = kinds()
    assert {"dynamic", "dynamic-winch"} <= set(registry)
    scenario = dataclasses.replace(load_scenario("paper-circle"), duration_s=8.0)
    record = fly(scenario, [registry["dynamic"], registry["dynamic-winch"]])
    for name in ("dynamic", "dynamic-winch"):
        trace = record.traces[name]
        published = trace.published
        error = trace.position_ned_m - record.position_ned_m
        assert np.isfinite(error[-1]).all(), name
        # the last estimate inside 3 sigma of its own covariance, published or not
        nees = error[-1] @ np.linalg.solve(trace.position_covariance_m2[-1], error[-1])
        assert nees < 14.2, (name, nees)  # chi-square 3 dof, 99.7 %
        if published.any():
            assert np.sqrt(np.mean(error[published] ** 2)) < 0.3, name
    # with the paid-out length the position is observable at once: published at the end (the
    # defaults, sized for real flights, withhold the IMU-only kind for longer than 8 s here)
    assert record.traces["dynamic-winch"].published[-1]
