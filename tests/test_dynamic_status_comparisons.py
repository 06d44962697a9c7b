"""The status path's ``max``/``min`` written out as comparisons (perf15) give the builtins'
floats bit for bit, nan, infinities and signed zeros included (the builtin keeps the first
value unless a later one compares greater)."""

from __future__ import annotations

import itertools
import math
import struct

import numpy as np

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.mixture import HoverAnchor
from tether_companion.estimation.dynamic.observability import (
    MIN_TENSION_N,
    _largest_std_values,
    min_horizontal_pull_n,
    unmodelled_position_rows,
)
from tether_companion.estimation.dynamic.published_bound import _tension_and_jacobian

_VALUES = (0.0, -0.0, 1e-300, 0.3, 2.5, -1.5, 1e150, math.inf, -math.inf, math.nan)


def _bits(value: float) -> bytes:
    return struct.pack("<d", value)


def _same(a: float, b: float) -> bool:
    """Equal floats, bit for bit (any nan equals any nan)."""
    return (math.isnan(a) and math.isnan(b)) or _bits(a) == _bits(b)


def test_largest_std_is_the_builtin_max_of_the_eigenvalue_and_zero() -> None:
    for a, b, c in itertools.product(_VALUES, repeat=3):
        largest = 0.5 * (a + c) + math.sqrt(0.25 * (a - c) ** 2 + b * b)
        expected = math.sqrt(max(largest, 0.0))
        assert _same(_largest_std_values(a, b, c), expected), (a, b, c)


def test_min_pull_is_the_builtin_max_of_the_prior_and_the_wind() -> None:
    for std, wn, we in itertools.product(_VALUES, repeat=3):
        expected = 0.7 * max(std, math.hypot(wn, we))
        assert _same(min_horizontal_pull_n(0.7, std, wn, we), expected), (std, wn, we)


def test_unmodelled_rows_take_the_builtin_max_of_the_tension_and_its_floor() -> None:
    for tension in (*_VALUES, MIN_TENSION_N, 0.5 * MIN_TENSION_N):
        rows = unmodelled_position_rows(3.0, -2.0, -2.5, tension, 0.2, 0.05)
        floor = max(tension, MIN_TENSION_N)
        if math.isnan(floor):  # the builtin keeps a nan tension: every entry nan
            assert all(math.isnan(v) for row in rows for v in row)
            continue
        # else the rows at the tension the builtin gives (at or above the floor: taken as is)
        reference = unmodelled_position_rows(3.0, -2.0, -2.5, floor, 0.2, 0.05)
        assert rows == reference, tension


def test_tension_at_the_drone_clips_as_the_builtin_max() -> None:
    class _Models:
        @staticmethod
        def tension(x, u, c):
            return (x[state.TENSION] * 1.0,), (0.0,) * state.N_STATES

    class _Constants:
        models = _Models()

        @staticmethod
        def values():
            return (1.0, 0.1, 0.0)

    for tension in _VALUES:
        x = [1.0] * state.N_STATES
        x[state.TENSION] = tension
        value, _ = _tension_and_jacobian(_Constants(), x)  # type: ignore[arg-type]
        expected = max(tension, 0.0)
        assert _same(value, expected), tension


def test_hover_anchor_keeps_the_builtin_smallest_and_largest_sd() -> None:
    rng = np.random.default_rng(3)
    for _ in range(50):
        sd = tuple(float(v) for v in rng.uniform(0.01, 3.0, 3))
        sd = sd if rng.uniform() < 0.8 else (sd[0], sd[0], sd[1])  # ties
        anchor = HoverAnchor((0.0,) * 6, (0.0,) * 6, 0.5, sd)  # type: ignore[arg-type]
        assert _bits(anchor.smallest_sd) == _bits(min(sd))
        assert _bits(anchor.largest_sd) == _bits(max(sd))
