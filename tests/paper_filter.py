"""The paper's 4-state EKF for tests of the service's plumbing (not collected: no ``test_``
prefix).

The service's default estimator, the dynamic filter, withholds its position in a steady hover
and for the first seconds of any flight (the thrust scale and the wind are not yet known:
docs/estimation.md, "In the service"). Tests of the link, the recording, replay, ingest,
signing, trust and scheduling need positions from the first second of a short synthetic
hover; they name the paper's 4-state filter, which publishes from its fixed initial guess.
"""

from __future__ import annotations

PAPER_FILTER = {"kind": "four_state"}
"""The ``estimator`` section that selects the paper's 4-state EKF."""


def with_paper_filter(overrides: dict) -> dict:
    """``overrides`` (service config sections) with ``estimator.kind: four_state`` added."""
    estimator = {**overrides.get("estimator", {}), **PAPER_FILTER}
    return {**overrides, "estimator": estimator}
