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
        assert published[-1], name
        error = trace.position_ned_m[published] - record.position_ned_m[published]
        assert np.sqrt(np.mean(error**2)) < 0.3, name
