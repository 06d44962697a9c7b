"""ARX, the polynomial model's predictors and Table-1 metrics against known systems."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter
from sysid_synthetic import ARX_A, ARX_B, arx_data

from tether_companion.sysid.linear_model import PolynomialModel
from tether_companion.sysid.metrics import final_prediction_error, fit_percent
from tether_companion.sysid.structures.arx import ArxOrders, fit_arx
from tether_companion.sysid.structures.base import FitContext

RANGE = (1000.0, 2000.0)


def test_known_arx_coefficients_recovered_within_two_percent(rng):
    data = arx_data(rng)
    context = FitContext.from_data([data], RANGE)
    fit = fit_arx([data], context, ArxOrders(na=2, nb=2, nk=1))
    np.testing.assert_allclose(fit.model.f, ARX_A, rtol=0.02)
    np.testing.assert_allclose(fit.model.b[:, 1:], ARX_B[:, 1:], rtol=0.02)
    assert np.all(fit.model.b[:, 0] == 0.0)  # the delay nk = 1


def test_order_selection_finds_the_true_orders(rng):
    data = arx_data(rng)
    fit = fit_arx([data], FitContext.from_data([data], RANGE))
    assert fit.orders == "na=2 nb=2 nk=1"


def test_one_step_prediction_of_arx_is_the_regression():
    """y_hat(t|t-1) = (1 - A) y + B u: check the general predictor against it directly."""
    rng = np.random.default_rng(4)
    u = rng.standard_normal((300, 4))
    y = rng.standard_normal(300)
    model = PolynomialModel(f=ARX_A, b=ARX_B, d=ARX_A, u0=np.zeros(4))
    predicted = model.predict_deviation(u, y, 1)
    direct = -ARX_A[1] * np.r_[0, y[:-1]] - ARX_A[2] * np.r_[0, 0, y[:-2]]
    direct += sum(lfilter(ARX_B[i], [1.0], u[:, i]) for i in range(4))
    # the predictor starts in steady state, the direct form from zero: compare after 2 samples
    np.testing.assert_allclose(predicted[2:], direct[2:], atol=1e-12)


def test_long_horizon_prediction_becomes_simulation():
    rng = np.random.default_rng(5)
    u = rng.standard_normal((400, 4))
    y = rng.standard_normal(400)
    model = PolynomialModel(f=ARX_A, b=ARX_B, d=ARX_A, u0=np.zeros(4))
    far = model.predict_deviation(u, y, 200)
    np.testing.assert_allclose(far[250:], model.response(u)[250:], atol=1e-9)


def test_state_space_form_simulates_like_the_polynomials():
    rng = np.random.default_rng(6)
    u = rng.standard_normal((200, 4))
    model = PolynomialModel(f=ARX_A, b=ARX_B, u0=np.zeros(4))
    a, b, c, d = model.state_space()
    x = np.zeros(a.shape[0])
    out = []
    for k in range(len(u)):
        out.append((c @ x + d @ u[k])[0])
        x = a @ x + b @ u[k]
    reference = sum(lfilter(ARX_B[i], ARX_A, u[:, i]) for i in range(4))
    np.testing.assert_allclose(out, reference, atol=1e-12)


def test_fit_percent_and_fpe_formulas():
    y = np.array([0.0, 1.0, 2.0, 3.0])
    assert fit_percent(y, y) == pytest.approx(100.0)
    assert fit_percent(y, np.full(4, y.mean())) == pytest.approx(0.0)
    assert np.isnan(fit_percent(np.ones(4), np.ones(4)))
    assert final_prediction_error(2.0, 10, 100) == pytest.approx(2.0 * 1.1 / 0.9)
    assert final_prediction_error(2.0, 100, 100) == float("inf")
