"""The published estimate's approximation between two member steps
(estimation/dynamic/mixture.py, published.py): on random covariances and batch steps larger
than a filter's, every approximate value is within the bound it claims of the exact one, and
the status it decides is the exact values' status (or it leaves the tick to them)."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.imu_batch import BatchStep
from tether_companion.estimation.dynamic.mixture import MixtureValues, ProcessNoise
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.estimation.dynamic.observability import (
    HoverUnknowns,
    _explained_2x2,
    _largest_std_values,
)
from tether_companion.estimation.dynamic.output import LEARNING, OK, WEAK_PULL
from tether_companion.estimation.dynamic.published import StatusSettings, TickSource

_SCALES = np.array(
    [1.0, 1.0, 0.3, 0.5, 0.5, 0.2, 1.0, 0.05, 0.1, 0.1, 0.1, 2.0, 2.0, 0.1, 0.01, 0.007, 0.026]
)
"""Typical standard deviations of the states (position, velocity, tension, thrust scale,
bias, wind, the ground station's calibration) [SI units]."""


def _case(rng: np.random.Generator) -> tuple[TickSource, TickSource]:
    """Two sources of one random tick (one for the exact values, one for the approximation)."""
    n = state.N_STATES
    # correlated states: a few shared factors (the hover's trade-offs) and each its own part
    mixing = rng.normal(size=(n, 4)) * rng.uniform(0.2, 1.0, size=4)
    own = np.diag(rng.uniform(0.05, 0.6, size=n))
    a = (mixing @ rng.normal(size=(4, n)) + own) * _SCALES[:, None]
    p = a @ a.T / n
    p = 0.5 * (p + p.T)
    x = rng.normal(size=n) * _SCALES
    x[:3] = [rng.uniform(-20, 20), rng.uniform(-20, 20), rng.uniform(-30, -5)]
    x[state.TENSION] = rng.uniform(0.5, 20.0)
    x[state.SCALE] = 1.0 + 0.05 * rng.normal()
    ticks = int(rng.integers(1, 6))
    t = 0.005 * ticks * rng.uniform(0.5, 2.0)  # up to 5 ticks of a slow IMU
    b_v = (t * rng.normal(size=9)).tolist()
    b_p = (0.5 * t * t * rng.normal(size=9)).tolist()
    step = BatchStep(ticks, t, (t * rng.normal(size=3)).tolist(),
                     (rng.normal(size=3)).tolist(), b_p, b_v)  # fmt: skip
    noise = ProcessNoise(np.diag(rng.uniform(1e-5, 1e-2, size=n) * _SCALES**2))
    horizontal_sd = float(np.sqrt(max(p[0, 0], p[1, 1])))
    settings = StatusSettings(
        slack_tension_n=0.2,
        max_horizontal_std_m=horizontal_sd * float(rng.uniform(0.3, 1.3)),
        winch_length_noise_std_m=0.05,
        pull_per_wind_n_s_per_m=float(rng.uniform(0.0, 0.3)),
        wind_std_mps=1.0,
    )
    constants = ModelConstants(1.5, 0.3, 0.0)
    # half the ticks with a cable angle's information narrowing the unmodelled term
    h = rng.normal(size=(2, 3)) / 5.0
    excess = 0.01 * h.T @ h
    information = (
        None
        if rng.uniform() < 0.5
        else (*excess[np.triu_indices(3)], float(rng.uniform()), *excess[np.triu_indices(3)])
    )

    # half the ticks with a sagging cable's range variance (sag_range), some beyond the
    # bound, a tenth with the range unknown (no length, the cable may rest on the ground)
    sag_std = 0.0 if rng.uniform() < 0.5 else horizontal_sd * float(rng.uniform(0.0, 1.5))
    sag = (sag_std, sag_std * sag_std * float(rng.uniform()))
    if rng.uniform() < 0.1:
        sag = (math.inf, 0.0)

    def source() -> TickSource:
        return TickSource(MixtureValues(x, p), step, noise, constants, settings,
                          0.01, False, 0.2, information, 1, None, None, False, False,
                          *sag)  # fmt: skip

    return source(), source()


def test_the_approximation_between_member_steps_is_within_its_bound() -> None:
    rng = np.random.default_rng(12)
    outcomes: Counter = Counter()
    for _ in range(400):
        exact_source, source = _case(rng)
        exact = exact_source.values()
        approx = source.approximate()
        assert approx is not None and approx.finite
        covariance = exact.covariance
        tol = approx.covariance_tol
        north, north_east, east = approx.horizontal
        assert abs(north - covariance[0, 0]) <= tol
        assert abs(north_east - covariance[0, 1]) <= tol
        assert abs(east - covariance[1, 1]) <= tol
        assert abs(approx.down_variance - covariance[2, 2]) <= tol
        for a, b in zip(approx.position, exact.position.tolist(), strict=True):
            assert abs(a - b) <= approx.position_tol
        assert abs(approx.tension_n - exact.tension) <= 1e-12 * exact.tension
        quick = source._quick_status()
        if quick is not None:
            assert quick == exact.status
        outcomes[quick] += 1
    # the random thresholds put many ticks near them; most are still decided, each branch
    assert outcomes[None] < 0.05 * sum(outcomes.values())
    assert min(outcomes[OK], outcomes[WEAK_PULL], outcomes[LEARNING]) >= 20


@pytest.mark.parametrize(("bias_factor", "near", "least"), [(1.0, 0.02, 60), (100.0, 0.2, 40)])
def test_the_hover_bound_holds_near_its_threshold(
    bias_factor: float, near: float, least: int
) -> None:
    """:meth:`HoverAnchor.explains` on exact horizontal entries, the bound set within ``near``
    (relative) of the exact residual's standard deviation and bias terms ``bias_factor``
    times the random step's: the exact answer or none."""
    rng = np.random.default_rng(7)
    hover = [state.SCALE, state.WIND.start, state.WIND.start + 1]
    decided = 0
    for _ in range(300):
        source, _ = _case(rng)
        step, mixture, noise = source.step, source.mixture, source.noise
        assert step is not None and mixture is not None
        b_p = (np.array(step.b_p) * bias_factor).tolist()
        step = BatchStep(step.ticks, step.duration_s, step.d_p, step.d_v, b_p, step.b_v)
        p = step.step_covariance(mixture.p, noise.matrix)
        horizontal = p[:2, :2]
        exact = HoverUnknowns(1.0, np.zeros(2), p[hover][:, hover], p[:2][:, hover], 1)
        (a, b), (_, c) = horizontal.tolist()
        explained = _explained_2x2(p[hover][:, hover].tolist(), p[:2][:, hover].tolist())
        assert explained is not None
        residual = _largest_std_values(a - explained[0], b - explained[1], c - explained[2])
        max_std = residual * float(rng.uniform(1.0 - near, 1.0 + near))
        sd = mixture.sd
        spread = max(sum(abs(b_p[3 * i + m]) * sd[8 + m] for m in range(3)) for i in (0, 1))
        anchor = mixture.hover()
        if anchor is None:
            continue
        got = anchor.explains((a, b, c), 0.0, spread, step.duration_s, noise, 1e3, max_std, 1e-9)
        if got is not None:
            decided += 1
            assert got == exact.explains(horizontal, max_std)
    assert decided >= least
