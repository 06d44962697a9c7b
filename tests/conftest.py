"""Shared test fixtures."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "tether",
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.load_profile("tether")
"""Property tests draw the same examples on every run (seeded by the test's name, as the rest of
the suite seeds its randomness), and a slow, busy machine's slower data generation is not a
failure (HealthCheck.too_slow measures the machine, not the code)."""


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator: every test that draws random numbers is reproducible."""
    return np.random.default_rng(20211117)
