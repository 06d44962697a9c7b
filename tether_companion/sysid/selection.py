"""Which identified model to write: the one that predicts thrust from PWM best where the
estimator needs it.

The estimator runs the thrust model from PWM alone, and most of a tethered flight is a hover:
a model wrong at steady state is wrong all the time. k-step-ahead Fit% feeds the measured
thrust back into the prediction and rewards fitting the noise of the thrust derived from the
accelerometer; an ARX model can score 88 % on it while its steady-state gain is far off. So:

1. **Admission.** A dynamic model is admitted only if it is stable (it settles after a step)
   and its steady-state thrust matches the static fit's within :data:`DC_TOLERANCE_PCT` at the
   operating point: the median PWM of the steady validation samples, where the flight spends
   its time and the static fit is pinned by the data. (Away from it the static fit bends
   with the transients it cannot model: on the emulated identification flight it is 3.7 % off
   the true curve at the 5 % quantile of PWM and 0.3 % at the median, where the dynamic
   structures are within 0.4 % everywhere.) The static model is always admitted.
2. **Choice.** Among the admitted models, the one with the smallest validation error of its
   *simulated* thrust (from PWM alone), taken as the root mean square of two RMS errors: over
   the steady samples (the mean command moving less than :data:`STEADY_RATE_PER_S` of full
   scale per second) and over the transient ones, so that neither dominates by sample count.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from tether_companion.sysid.identify import StructureResult
from tether_companion.sysid.processing import IdData
from tether_companion.sysid.structures.base import FittedModel

FloatArray = NDArray[np.float64]

DC_TOLERANCE_PCT = 3.0
"""Largest admitted difference between a dynamic model's and the static fit's steady-state
thrust, relative to the static fit's, over the PWM levels flown [%]."""
STEADY_RATE_PER_S = 0.05
"""A validation sample is steady when the mean normalised command changes slower than this
[1/s] (5 % of full scale per second)."""
SETTLE_S = 20.0
"""Constant-input simulation length for the steady-state thrust [s]."""
OPERATING_QUANTILE = 0.5
"""The steady-state gain is compared at this quantile of the steady samples' mean PWM."""
WARMUP_SAMPLES = 50


@dataclass(frozen=True)
class SelectionScore:
    """How one structure serves the estimator (see module docstring)."""

    structure: str
    dc_error_pct: float
    stable: bool
    steady_rmse_n: float
    transient_rmse_n: float

    @property
    def score_n(self) -> float:
        """RMS of the steady and transient RMS errors [N] (lower is better)."""
        return math.sqrt(0.5 * (self.steady_rmse_n**2 + self.transient_rmse_n**2))

    def admitted(self, tolerance_pct: float = DC_TOLERANCE_PCT) -> bool:
        """Static, or stable with a steady-state thrust within ``tolerance_pct`` of static."""
        if self.structure == "static":
            return True
        return self.stable and self.dc_error_pct <= tolerance_pct


def _step_input(
    template: IdData, pwm_us: float, n_samples: int, pwm_range_us: tuple[float, float]
) -> IdData:
    """Every motor stepping to ``pwm_us`` a tenth into ``n_samples`` (from another level, so
    an unstable model is excited and shows), no measured thrust."""
    low, high = pwm_range_us
    start = low + (0.3 if abs(pwm_us - (low + 0.5 * (high - low))) < 1.0 else 0.5) * (high - low)
    pwm = np.full(n_samples, pwm_us)
    pwm[: n_samples // 10] = start
    cmd = np.clip((pwm - low) / (high - low), 0.0, 1.0)
    n_motors = template.pwm_us.shape[1]
    return replace(
        template,
        time_s=np.arange(n_samples) * template.dt_s,
        pwm_us=np.repeat(pwm[:, None], n_motors, axis=1),
        command=np.repeat(cmd[:, None], n_motors, axis=1),
        command_sq=np.repeat((cmd * cmd)[:, None], n_motors, axis=1),
        thrust_n=np.zeros(n_samples),
    )


def steady_state_thrust_n(
    model: FittedModel, template: IdData, pwm_us: float, pwm_range_us: tuple[float, float]
) -> tuple[float, bool]:
    """Thrust [N] the model settles to after every motor steps to ``pwm_us``, and whether it
    settled (finite, and the last tenth of the run within 0.1 % of its end value)."""
    n = max(int(SETTLE_S / template.dt_s), 20)
    with np.errstate(all="ignore"):
        out = model.simulate(_step_input(template, pwm_us, n, pwm_range_us))
    end = float(out[-1])
    tail = out[-max(n // 10, 2) :]
    settled = bool(np.all(np.isfinite(tail))) and float(np.ptp(tail)) <= 1e-3 * max(abs(end), 1e-9)
    return end, settled


def steady_mask(data: IdData) -> FloatArray:
    """True where the mean normalised command moves slower than :data:`STEADY_RATE_PER_S`."""
    mean_cmd = data.command.mean(axis=1)
    rate = np.abs(np.gradient(mean_cmd, data.dt_s))
    return rate < STEADY_RATE_PER_S


def score(
    result: StructureResult,
    static: StructureResult,
    validation: Sequence[IdData],
    pwm_range_us: tuple[float, float],
) -> SelectionScore:
    """Steady-state agreement with the static fit and split simulation errors of ``result``."""
    steady_pwm = np.concatenate([v.pwm_us.mean(axis=1)[steady_mask(v)] for v in validation])
    if steady_pwm.size == 0:
        steady_pwm = np.concatenate([v.pwm_us.mean(axis=1) for v in validation])
    levels = [float(np.quantile(steady_pwm, OPERATING_QUANTILE))]
    template = validation[0]
    worst, stable = 0.0, True
    for level in levels:
        own, settled = steady_state_thrust_n(result.model, template, float(level), pwm_range_us)
        reference, _ = steady_state_thrust_n(static.model, template, float(level), pwm_range_us)
        stable = stable and settled
        if reference > 0.0 and math.isfinite(own):
            worst = max(worst, 100.0 * abs(own - reference) / reference)
        else:
            worst = math.inf
    steady_errors, transient_errors = [], []
    for data in validation:
        with np.errstate(all="ignore"):
            error = result.model.simulate(data) - data.thrust_n
        mask = steady_mask(data)
        steady_errors.append(error[WARMUP_SAMPLES:][mask[WARMUP_SAMPLES:]])
        transient_errors.append(error[WARMUP_SAMPLES:][~mask[WARMUP_SAMPLES:]])
    return SelectionScore(
        structure=result.structure,
        dc_error_pct=worst,
        stable=stable,
        steady_rmse_n=_rms(np.concatenate(steady_errors)),
        transient_rmse_n=_rms(np.concatenate(transient_errors)),
    )


def _rms(values: FloatArray) -> float:
    with np.errstate(all="ignore"):
        return float(np.sqrt(np.mean(values**2))) if values.size else 0.0


def select(
    results: Sequence[StructureResult],
    validation: Sequence[IdData],
    pwm_range_us: tuple[float, float],
    tolerance_pct: float = DC_TOLERANCE_PCT,
) -> tuple[StructureResult | None, dict[str, SelectionScore]]:
    """The result to write (admitted, lowest :attr:`SelectionScore.score_n`) and every
    successful structure's score. Needs a successful ``static`` result as the reference; with
    none, nothing is chosen."""
    static = next((r for r in results if r.structure == "static" and r.ok), None)
    if static is None:
        return None, {}
    scores = {r.structure: score(r, static, validation, pwm_range_us) for r in results if r.ok}
    admitted = [r for r in results if r.ok and scores[r.structure].admitted(tolerance_pct)]
    chosen = min(admitted, key=lambda r: scores[r.structure].score_n)
    return chosen, scores
