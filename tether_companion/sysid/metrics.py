"""Model quality as in the paper's Table 1: Fit%, Akaike's FPE and MSE.

- Fit% (NRMSE fit, MATLAB ``compare``): ``100 (1 - |y - y_hat| / |y - mean(y)|)`` on the
  validation data, for the k-step-ahead prediction and for pure simulation.
- MSE: mean squared one-step prediction error on the estimation data [N^2].
- FPE: Akaike's final prediction error ``MSE (1 + d/N) / (1 - d/N)`` with ``d`` parameters
  and ``N`` estimation samples [N^2].

The first ``warmup`` samples of every experiment are left out of all metrics: predictors
start from a steady state that the data need not be in.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.sysid.processing import IdData
from tether_companion.sysid.structures.base import FittedModel

FloatArray = NDArray[np.float64]

DEFAULT_K_STEPS = 5
DEFAULT_WARMUP_SAMPLES = 50


def fit_percent(measured: FloatArray, predicted: FloatArray) -> float:
    """NRMSE fit [%]: 100 for a perfect match, 0 for the mean, negative when worse."""
    spread = np.linalg.norm(measured - np.mean(measured))
    if spread == 0.0:
        return float("nan")
    return float(100.0 * (1.0 - np.linalg.norm(measured - predicted) / spread))


def final_prediction_error(mse: float, n_params: int, n_samples: int) -> float:
    """Akaike's FPE [N^2]; infinite when there are no more samples than parameters."""
    if n_samples <= n_params:
        return float("inf")
    ratio = n_params / n_samples
    return mse * (1.0 + ratio) / (1.0 - ratio)


@dataclass(frozen=True)
class Metrics:
    """Table-1 figures of one fitted model (see module docstring for definitions)."""

    fit_prediction_pct: float
    fit_simulation_pct: float
    fpe_n2: float
    mse_n2: float
    k_steps: int


def _pooled(
    model: FittedModel, experiments: Sequence[IdData], k: int | None, warmup: int
) -> tuple[FloatArray, FloatArray]:
    """Measured and predicted (k steps; None = simulation) thrust over all experiments."""
    measured, predicted = [], []
    for e in experiments:
        out = model.simulate(e) if k is None else model.predict(e, k)
        measured.append(e.thrust_n[warmup:])
        predicted.append(out[warmup:])
    return np.concatenate(measured), np.concatenate(predicted)


def evaluate(
    model: FittedModel,
    estimation: Sequence[IdData],
    validation: Sequence[IdData],
    k_steps: int = DEFAULT_K_STEPS,
    warmup: int = DEFAULT_WARMUP_SAMPLES,
) -> Metrics:
    """Table-1 metrics of ``model`` (see module docstring).

    Raises
    ------
    ArithmeticError
        When a prediction is not finite (an unstable or diverging model).
    """
    measured, one_step = _pooled(model, estimation, 1, warmup)
    val_measured, val_k = _pooled(model, validation, k_steps, warmup)
    _, val_sim = _pooled(model, validation, None, warmup)
    for name, values in (
        ("one-step prediction", one_step),
        ("prediction", val_k),
        ("simulation", val_sim),
    ):
        if not np.all(np.isfinite(values)):
            raise ArithmeticError(f"{name} is not finite (unstable model)")
    mse = float(np.mean((measured - one_step) ** 2))
    return Metrics(
        fit_prediction_pct=fit_percent(val_measured, val_k),
        fit_simulation_pct=fit_percent(val_measured, val_sim),
        fpe_n2=final_prediction_error(mse, model.n_params, measured.shape[0]),
        mse_n2=mse,
        k_steps=k_steps,
    )
