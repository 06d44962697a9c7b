"""Fit every requested structure to a processed flight and measure each (paper Table 1).

One structure failing numerically (an unstable fit, an optimiser giving up) is recorded as a
failure for that structure; the others are still fitted and reported.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from tether_companion.sysid.input_map import InputMap
from tether_companion.sysid.metrics import DEFAULT_K_STEPS, Metrics, evaluate
from tether_companion.sysid.processing import IdData
from tether_companion.sysid.structures.arx import ArxOrders, fit_arx
from tether_companion.sysid.structures.base import FitContext, FittedModel
from tether_companion.sysid.structures.prediction_error import fit_box_jenkins, fit_output_error
from tether_companion.sysid.structures.process import fit_process, fit_transfer_function
from tether_companion.sysid.structures.static import fit_static
from tether_companion.sysid.structures.subspace import fit_state_space

Fitter = Callable[[Sequence[IdData], FitContext, ArxOrders], FittedModel]

STRUCTURES: dict[str, Fitter] = {
    "static": lambda e, c, o: fit_static(e, c),
    "tf": lambda e, c, o: fit_transfer_function(e, c),
    "process": lambda e, c, o: fit_process(e, c),
    "arx": lambda e, c, o: fit_arx(e, c, o),
    "oe": lambda e, c, o: fit_output_error(e, c, o),
    "bj": lambda e, c, o: fit_box_jenkins(e, c, o),
    "ss": lambda e, c, o: fit_state_space(e, c),
}
"""Structure name -> fitter given the data, context and the ARX-selected orders."""

DYNAMIC_STRUCTURES = ("tf", "process", "arx", "oe", "bj", "ss")
FALLBACK_ORDERS = ArxOrders(na=2, nb=2, nk=1)
"""Orders for output error and Box-Jenkins when no stable ARX model is found (Appendix A's)."""


@dataclass(frozen=True)
class StructureResult:
    """One structure's outcome: the model and its metrics, or why it failed."""

    structure: str
    model: FittedModel | None
    metrics: Metrics | None
    error: str | None = None

    @property
    def ok(self) -> bool:
        """True when the structure was fitted and measured."""
        return self.model is not None and self.metrics is not None


def identify(
    estimation: Sequence[IdData],
    validation: Sequence[IdData],
    pwm_range_us: tuple[float, float],
    structures: Sequence[str] = tuple(STRUCTURES),
    k_steps: int = DEFAULT_K_STEPS,
    input_kind: str = "quadratic",
) -> list[StructureResult]:
    """Fit and evaluate each structure in ``structures`` (names of :data:`STRUCTURES`).

    The ARX orders are selected first (minimum description length) and reused as the
    ``nb``/``nf``/``nk`` of output error and Box-Jenkins. ``input_kind`` is the input map
    of the linear structures (:mod:`tether_companion.sysid.input_map`): ``"quadratic"``
    (Hammerstein: ``cmd`` and ``cmd^2`` of every motor) or ``"pwm"`` (PWM as is, as in the paper).
    """
    input_map = InputMap(input_kind, *pwm_range_us)
    context = FitContext.from_data(estimation, pwm_range_us, input_map)
    try:
        with np.errstate(all="ignore"):
            orders = selected_orders(estimation, context)
    except (ArithmeticError, np.linalg.LinAlgError, ValueError):
        orders = FALLBACK_ORDERS  # the ARX row itself reports the failure
    results = []
    for name in structures:
        try:
            with np.errstate(all="ignore"):
                model = STRUCTURES[name](estimation, context, orders)
                metrics = evaluate(model, estimation, validation, k_steps)
        except (ArithmeticError, np.linalg.LinAlgError, ValueError) as exc:
            results.append(StructureResult(name, None, None, f"{type(exc).__name__}: {exc}"))
            continue
        results.append(StructureResult(name, model, metrics))
    return results


def selected_orders(estimation: Sequence[IdData], context: FitContext) -> ArxOrders:
    """The ARX orders chosen by minimum description length (na, nb, nk)."""
    model = fit_arx(estimation, context).model
    na = len(model.f) - 1
    nk = int(np.argmax(np.any(model.b != 0.0, axis=0)))
    return ArxOrders(na=na, nb=model.b.shape[1] - nk, nk=nk)


def best_result(results: Sequence[StructureResult], by: str) -> StructureResult | None:
    """The successful result with the highest validation Fit% of ``by``: ``"prediction"``
    (k steps ahead, the paper's Table 1) or ``"simulation"`` (from inputs alone)."""
    attribute = "fit_prediction_pct" if by == "prediction" else "fit_simulation_pct"
    ok = [r for r in results if r.ok and np.isfinite(getattr(r.metrics, attribute))]
    return max(ok, key=lambda r: getattr(r.metrics, attribute)) if ok else None
