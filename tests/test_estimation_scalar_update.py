"""The generated scalar EKF update against the numpy reference update (issue 12).

Same filter, same inputs: states and covariances equal to 1e-9 (only the summation order
differs), the same verdicts (fused, gated, forced, nonfinite, singular) and counts.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.bench.speed import _ours, _record
from tether_companion.estimation.config import load_estimator_config
from tether_companion.estimation.ekf import ExtendedKalmanFilter
from tether_companion.estimation.tether_models import FourStateModel
from tether_companion.sim.scenario import load_scenario
from tether_companion.sim.simulator import Simulator


def _pair(rng: np.random.Generator, n: int, gate: float = 1.0, forced: int = 0):
    a = rng.normal(size=(n, n))
    p0 = a @ a.T + n * np.eye(n)
    x0 = rng.normal(size=n) * 3.0
    q = np.eye(n) * 0.01
    make = lambda: ExtendedKalmanFilter(  # noqa: E731
        x0, p0, q, gate_probability=gate, max_consecutive_rejections=forced
    )
    return make(), make()


def _step(ref, fast, rng, m, scale=1.0):
    n = ref.n
    h = rng.normal(size=(m, n))
    z = rng.normal(size=m) * scale
    r = float(rng.uniform(0.01, 1.0))
    a = ref.update("s", z, lambda x, h=h: (h @ x, h), np.eye(m) * r)
    b = fast.update_rows("s", (z - h @ fast.x).tolist(), h.tolist(), r)
    return a, b


@pytest.mark.parametrize(("n", "m"), [(4, 3), (3, 3), (4, 1), (3, 1)])
def test_scalar_update_equals_the_numpy_update(n: int, m: int, rng) -> None:
    ref, fast = _pair(rng, n)
    for _ in range(200):
        ref.predict(0.005)
        fast.predict(0.005)
        a, b = _step(ref, fast, rng, m)
        assert a.status == b.status
        assert math.isclose(a.nis, b.nis, rel_tol=1e-9)
        np.testing.assert_allclose(fast.x, ref.x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(fast.P, ref.P, rtol=0, atol=1e-9)
        assert np.array_equal(fast.P, fast.P.T)


def test_gate_and_forced_fusion_agree(rng) -> None:
    ref, fast = _pair(rng, 4, gate=0.99, forced=3)
    statuses = []
    for k in range(120):
        a, b = _step(ref, fast, rng, 3, scale=30.0 if k % 4 else 1.0)  # mostly outliers
        assert a.status == b.status
        statuses.append(a.status)
        np.testing.assert_allclose(fast.x, ref.x, rtol=0, atol=1e-9)
    assert {"gated", "fused"} <= set(statuses)
    for key in ("fused", "gated", "forced", "nonfinite", "singular"):
        assert getattr(ref.sensors["s"], key) == getattr(fast.sensors["s"], key), key
    assert fast.sensors["s"].forced > 0


def test_nonfinite_and_singular_are_refused_like_the_reference(rng) -> None:
    ref, fast = _pair(rng, 4)
    h = rng.normal(size=(3, 4))
    bad = h.copy()
    bad[1, 2] = math.nan
    z = np.ones(3)
    a = ref.update("s", z, lambda x: (bad @ x, bad), np.eye(3) * 0.1)
    b = fast.update_rows("s", (z - bad @ fast.x).tolist(), bad.tolist(), 0.1)
    assert a.status == b.status == "nonfinite"
    zero = np.zeros((1, 4))  # S = r = 0: singular
    a = ref.update("t", np.ones(1), lambda x: (zero @ x, zero), np.zeros((1, 1)))
    b = fast.update_rows("t", [1.0], zero.tolist(), 0.0)
    assert a.status == b.status == "singular"
    np.testing.assert_array_equal(fast.x, ref.x)


def test_paper_filter_on_the_simulator_equals_the_numpy_path() -> None:
    """The 4-state filter over 2 s of the paper circle: scalar vs numpy path within 1e-9."""
    scenario = load_scenario("paper-circle")
    config = load_estimator_config(None)
    config = dataclasses.replace(config, gate=dataclasses.replace(config.gate, probability=1.0))
    rows = _record(scenario, 400)
    model = FourStateModel(Simulator(scenario).vehicle.mass_kg)
    _, scalar_x = _ours(rows, config, model)
    _, numpy_x = _ours(rows, config, model, scalar=False)
    assert np.max(np.abs(scalar_x - numpy_x)) < 1e-9


@pytest.mark.parametrize("n", [3, 4])
def test_a_constant_jacobian_gives_the_general_update_exactly(n: int, rng) -> None:
    """The altimeter's update compiled with its Jacobian as literals (zeros left out) equals
    the general update bit for bit (products by 0 and -1 are exact), gated or fused."""
    from tether_companion.estimation import scalar_update

    h = tuple([0.0, 0.0, -1.0, 0.0][:n])
    general = scalar_update.updater(n, 1)
    constant = scalar_update.updater(n, 1, h)
    for threshold in (math.inf, 0.5):
        for _ in range(50):
            a = rng.normal(size=(n, n))
            p = (a @ a.T + 0.1 * np.eye(n)).ravel().tolist()
            x = rng.normal(size=n).tolist()
            y = [float(rng.normal())]
            r = float(rng.uniform(0.01, 1.0))
            assert constant(x, p, None, y, r, threshold) == general(x, p, list(h), y, r, threshold)
