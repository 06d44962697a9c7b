"""What the published position covariance adds to the filter's own at one tick: one
function, :func:`added_position_terms`, read by both the exact values and the approximation of
:class:`~tether_companion.estimation.dynamic.published.TickSource` (so the two add the same
terms).

* the unmodelled force's term, narrowed by the cable angles
  (:func:`~tether_companion.estimation.dynamic.offset_term.offset_rows`,
  :func:`~tether_companion.estimation.dynamic.position_information.reduce_added_rows`);
* the rangefinder innovations' excess and the ground's unevenness the height carries (which
  the readings' white noise model averages away:
  :mod:`~tether_companion.estimation.dynamic.terrain`), along the line from the anchor
  without a winch length
  (:func:`~tether_companion.estimation.dynamic.position_information.height_excess`);
* a sagging cable's range over the tensions the filter cannot rule out, along the range
  (:mod:`~tether_companion.estimation.dynamic.sag_range`);
* on a tick the pull rule withholds, the bearing's ambiguity
  (:mod:`~tether_companion.estimation.dynamic.bearing_ambiguity`).

:data:`ADDED_POSITION_TERMS` is what the status read calls: :func:`added_position_terms`, or
its C twin (``status_core.c``). Pure.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

from tether_companion.estimation import optional_core
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.bearing_ambiguity import bearing_ambiguity
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.observability import (
    horizontal_pull_n,
    min_horizontal_pull_n,
)
from tether_companion.estimation.dynamic.offset_term import offset_rows
from tether_companion.estimation.dynamic.position_information import (
    height_excess,
    reduce_added_rows,
)


@dataclass(frozen=True, slots=True)
class StatusSettings:
    """The dynamic filter's settings the published estimate needs (SI units)."""

    slack_tension_n: float
    max_horizontal_std_m: float
    winch_length_noise_std_m: float
    pull_per_wind_n_s_per_m: float
    wind_std_mps: float
    drag_per_wind_n_s_per_m: float = 0.0
    """The rotor drag per unit airspeed ``m mu`` [N s/m]: with it a tick the pull rule
    withholds carries the bearing's ambiguity (:mod:`.bearing_ambiguity`); 0: it does not."""

    @classmethod
    def of_filter(
        cls, dynamic: DynamicFilterConfig, mass_kg: float, drag_per_s: float
    ) -> StatusSettings:
        """The settings of a filter with ``dynamic``'s settings on a drone of ``mass_kg`` [kg]
        with rotor drag ``drag_per_s`` [1/s]."""
        drag_n_s_per_m = mass_kg * drag_per_s
        return cls(
            slack_tension_n=dynamic.slack_tension_n,
            max_horizontal_std_m=dynamic.max_horizontal_std_m,
            winch_length_noise_std_m=dynamic.winch_length_noise_std_m,
            pull_per_wind_n_s_per_m=dynamic.min_pull_over_wind_drag * drag_n_s_per_m,
            wind_std_mps=dynamic.initial.wind_std_mps,
            drag_per_wind_n_s_per_m=drag_n_s_per_m,
        )


def added_position_terms(
    x: list[float],
    weight_n_per_m: float,
    settings: StatusSettings,
    force_std_n: float,
    information: tuple[float, ...] | None,
    height_excess_m2: float,
    winch_fused: bool,
    sag_m2: float,
    terrain_m2: float = 0.0,
) -> tuple[float, float, float, float, float, float]:
    """The position covariance (nn, ne, nd, ee, ed, dd) [m^2] added to the filter's own at
    the state's values ``x`` (Python floats) on a cable of ``weight_n_per_m`` [N/m] (the
    module docstring's terms; the arguments as :class:`TickSource`'s of those names)."""
    n, e, d = x[0], x[1], x[2]
    (u00, u01, u02), (_, u11, u12), (_, _, u22) = reduce_added_rows(
        offset_rows(
            x,
            weight_n_per_m,
            force_std_n,
            settings.winch_length_noise_std_m if winch_fused else 0.0,
            winch_fused,
        ),
        information,
    )
    h00, h01, h02, h11, h12, h22 = height_excess(
        (n, e, d), height_excess_m2 + terrain_m2, winch_fused
    )
    s00, s01, s11 = _along_range(n, e, sag_m2) if sag_m2 else (0.0, 0.0, 0.0)
    r00, r01, r11 = _ring(x, settings)
    return (
        u00 + h00 + s00 + r00,
        u01 + h01 + s01 + r01,
        u02 + h02,
        u11 + h11 + s11 + r11,
        u12 + h12,
        u22 + h22,
    )


ADDED_POSITION_TERMS: Callable[..., tuple[float, ...]] = added_position_terms
""":func:`added_position_terms`, or where the optional C extension ``_status_core`` is built (and
``TETHER_PURE_PYTHON`` is not set) its twin: the same floats, :func:`added_position_terms`
called where C could differ (``status_core.c``; it runs at every IMU tick's status read)."""
_CORE = optional_core.load("tether_companion.estimation.dynamic._status_core")
if _CORE is not None:
    ADDED_POSITION_TERMS = functools.partial(_CORE.added_position_terms, added_position_terms)

HORIZONTAL_PULL: Callable[[list[float]], float] = horizontal_pull_n
MIN_HORIZONTAL_PULL: Callable[[float, float, float, float], float] = min_horizontal_pull_n
""":func:`~.observability.horizontal_pull_n` and :func:`~.observability.min_horizontal_pull_n`,
or where ``_status_core`` is built with them (and ``TETHER_PURE_PYTHON`` is not set) their
twins: the same floats, the Python function called where C could differ (``status_core.c``;
the approximate status read calls both at every IMU tick)."""
if _CORE is not None and hasattr(_CORE, "horizontal_pull"):
    HORIZONTAL_PULL = functools.partial(_CORE.horizontal_pull, horizontal_pull_n)
    MIN_HORIZONTAL_PULL = functools.partial(_CORE.min_horizontal_pull, min_horizontal_pull_n)


def _ring(x: list[float], settings: StatusSettings) -> tuple[float, float, float]:
    """The bearing's ambiguity (nn, ne, ee) [m^2] at the state's values ``x`` when the pull
    rule withholds the tick (:mod:`.bearing_ambiguity`), else zeros."""
    drag_per_wind = settings.drag_per_wind_n_s_per_m
    if not drag_per_wind > 0.0:
        return 0.0, 0.0, 0.0
    pull = horizontal_pull_n(x)
    wind_n, wind_e = x[state.WIND.start], x[state.WIND.start + 1]
    min_pull = min_horizontal_pull_n(
        settings.pull_per_wind_n_s_per_m, settings.wind_std_mps, wind_n, wind_e
    )
    if not pull < min_pull:
        return 0.0, 0.0, 0.0
    drag = min_horizontal_pull_n(drag_per_wind, settings.wind_std_mps, wind_n, wind_e)
    return bearing_ambiguity(x[0], x[1], pull, drag)


def _along_range(n: float, e: float, variance_m2: float) -> tuple[float, float, float]:
    """``variance_m2`` [m^2] along the horizontal range direction of ``(n, e)`` [m] as the
    (nn, ne, ee) entries it adds [m^2] (none right above the anchor)."""
    span = math.hypot(n, e)
    if span == 0.0:
        return 0.0, 0.0, 0.0
    h0, h1 = n / span, e / span
    return variance_m2 * h0 * h0, variance_m2 * h0 * h1, variance_m2 * h1 * h1
