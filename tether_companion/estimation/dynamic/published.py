"""One IMU tick's published estimate, computed when it is read: :class:`TickSource`.

The dynamic filter's members step and fuse once per IMU batch (``imu_ticks_per_fusion``
ticks), but the estimate is per tick: the bank's mixture stepped over the ticks the members
have not stepped yet (a 13x13 ``Phi P Phi^T``), the tension at the drone with its variance,
the unmodelled-force position covariance, the observability status. The service reads the
status at every tick and the numbers at its publication rate (30 Hz of 200), replay the same,
``bench dynamic`` nothing. So each tick keeps only what it is computed from (references to the
mixture's arrays, which the members replace and never change in place, and to the batch's
fixed step), and computes

* the **exact values** (:meth:`TickSource.values`: every field, with the same arithmetic as
  when they were computed at every tick, so bit for bit the same) only when a field is read;
* the **status** (:meth:`TickSource.status`) from approximate scalars: the position and the
  tension at the stepped state in Python floats, the published position block from the
  mixture's own (:class:`~tether_companion.estimation.dynamic.mixture.MixtureValues`, made
  once per member step) with a bound on how far the batch's step moves it
  (:meth:`Approximation.covariance_tol`: ``|(Phi P Phi^T - P)_ij| <= e_i sd_j + e_j sd_i +
  e_i e_j``, ``e_i = sum_k |Phi_ik - I_ik| sd_k``, plus the rounding); each comparison with a
  threshold (slack tension, the pull against the wind's drag, the horizontal standard
  deviation, the thrust scale and wind's share of it:
  :meth:`~tether_companion.estimation.dynamic.mixture.HoverAnchor.explains`) is decided on
  them only when it is clearly on one side (:data:`MARGIN` relative, and the bound); when it
  is not, the exact values decide. So the status is always the exact values' status, and
  between two member steps a tick costs no matrix product;
* the same approximation for the publisher's checks (:meth:`TickSource.approximate`: finite,
  variances within the bound, tension above slack; ``service.health`` decides with the same
  margins and reads the exact values when unsure).

Pure.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.imu_batch import BatchStep
from tether_companion.estimation.dynamic.mixture import (
    HOVER_UNKNOWNS,
    MixtureValues,
    ProcessNoise,
)
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.estimation.dynamic.observability import (
    DECIDE,
    HoverUnknowns,
    assess,
)
from tether_companion.estimation.dynamic.output import Approximation, ExactValues
from tether_companion.estimation.dynamic.published_bound import approximation
from tether_companion.estimation.dynamic.published_terms import (
    ADDED_POSITION_TERMS,
    HORIZONTAL_PULL,
    MIN_HORIZONTAL_PULL,
    StatusSettings,
)

FloatArray = NDArray[np.float64]

MARGIN = 1e-9
"""Relative margin within which an approximate value is too close to its threshold to
decide (their rounding differs from the exact values' by ~1e-16 relative)."""
UNKNOWN_VARIANCE = 1e6
"""Variance reported for every component while there is no state [SI units^2]."""
_HOVER_LIST = list(HOVER_UNKNOWNS)


class TickSource:
    """What one tick's estimate is computed from, and the computations (cached).

    Parameters
    ----------
    mixture
        The bank's mixture at the tick (None: no state yet).
    step
        The batch's step of the ticks the members have not stepped over (None or no ticks:
        the mixture is the estimate).
    noise
        The process noise.
    constants
        The cable models' constants.
    settings
        The filter's status settings.
    height_excess_m2
        The rangefinder innovations' excess variance at the tick [m^2]: down, and without a
        fused winch length along the line from the anchor too
        (:func:`~tether_companion.estimation.dynamic.position_information.height_excess`).
    winch_fused
        Whether a winch length was fused so far (its noise then stays along the cable, and
        it holds the range a height error would otherwise move).
    force_std_n
        The unmodelled horizontal force's standard deviation at the tick [N]
        (:class:`~tether_companion.estimation.dynamic.consistency.BearingWindow`).
    position_information
        The information about the position of the cable angles fused within the
        unmodelled force's correlation time, (nn, ne, nd, ee, ed, dd) [1/m^2], which narrows
        the unmodelled term (:mod:`~tether_companion.estimation.dynamic.position_information`);
        None: none was fused, the term is left as it is.
    hypotheses
        Members of the thrust-scale bank running.
    initialised_reason, reset_reason, on_ground, inputs_stale
        As for :func:`~tether_companion.estimation.dynamic.observability.assess`.
    sag_std_m
        The range's standard deviation over the tensions the filter cannot rule out at a
        fused winch length on a sagging cable [m]; beyond ``max_horizontal_std_m`` the
        withheld estimate's reason says so (never ``learning``: the thrust scale and the
        wind do not explain it); ``inf``: no winch length and the cable may rest on the
        ground, withheld.
    sag_m2
        The variance added along the horizontal range ``(n, e)/|(n, e)|`` for the tensions
        the filter cannot rule out at a fused winch length on a sagging cable [m^2]
        (:func:`~tether_companion.estimation.dynamic.sag_range.sag_range_variance_m2`).
    terrain_m2
        The ground's variance the height carries at the tick [m^2]
        (:class:`~tether_companion.estimation.dynamic.terrain.GroundFootprint`), published
        with the rangefinder innovations' excess.
    """

    __slots__ = (
        "_approximation",
        "_assess_inputs",
        "_exact",
        "_row_scale",
        "_spread",
        "_status",
        "constants",
        "force_std_n",
        "height_excess_m2",
        "hypotheses",
        "initialised_reason",
        "inputs_stale",
        "mixture",
        "on_ground",
        "noise",
        "position_information",
        "reset_reason",
        "sag_m2",
        "sag_std_m",
        "settings",
        "step",
        "terrain_m2",
        "winch_fused",
    )

    def __init__(
        self,
        mixture: MixtureValues | None,
        step: BatchStep | None,
        noise: ProcessNoise,
        constants: ModelConstants,
        settings: StatusSettings,
        height_excess_m2: float,
        winch_fused: bool,
        force_std_n: float,
        position_information: tuple[float, float, float, float, float, float] | None,
        hypotheses: int,
        initialised_reason: str | None,
        reset_reason: str | None,
        on_ground: str,
        inputs_stale: bool,
        sag_std_m: float = 0.0,
        sag_m2: float = 0.0,
        terrain_m2: float = 0.0,
    ) -> None:
        self.mixture = mixture
        self.step = step if step is not None and step.ticks else None
        self.noise = noise
        self.constants = constants
        self.settings = settings
        self.height_excess_m2 = height_excess_m2
        self.winch_fused = winch_fused
        self.force_std_n = force_std_n
        self.position_information = position_information
        self.hypotheses = hypotheses
        self.initialised_reason = initialised_reason
        self.reset_reason = reset_reason
        self.on_ground = on_ground
        self.inputs_stale = inputs_stale
        self.sag_std_m = sag_std_m
        self.sag_m2 = sag_m2
        self.terrain_m2 = terrain_m2
        self._exact: ExactValues | None = None
        self._status: str | None = None
        self._assess_inputs: tuple | None = None
        """What the exact status and reason are assessed from, kept while they wait."""
        self._approximation: Approximation | None = None
        self._spread = 0.0
        """``max_i sum_k |E_ik| sd_k`` over the horizontal position rows of ``E = Phi - I``
        [m]."""
        self._row_scale = 0.0
        """A bound of ``sum_k |Phi_ik| sd_k`` over the rows ``i`` of ``Phi`` [SI units]."""

    # ------------------------------------------------------------------ exact
    def values(self) -> ExactValues:
        """Every field, exactly (computed on the first call; the status and its reason only
        when the status is not known yet: else the reason when it is read, :meth:`reason`)."""
        exact = self._exact
        if exact is None:
            exact = self._exact = self._compute()
            self._status = exact.status
        return exact

    def reason(self) -> str:
        """The exact values' reason (computed with their status when first read)."""
        exact = self.values()
        if exact.reason is None:
            exact.status, exact.reason = self._assess(*self._assess_inputs)
            self._assess_inputs = None
        return exact.reason

    def _compute(self) -> ExactValues:
        mixture = self.mixture
        values = None
        if mixture is None:  # no state: zeros with a covariance that says "unknown"
            x = np.zeros(state.N_STATES)
            p = np.eye(state.N_STATES) * UNKNOWN_VARIANCE
            tension, tension_var = 0.0, UNKNOWN_VARIANCE
        else:
            x, p = mixture.x, mixture.p
            if self.step is not None:
                x, p = self.step.step_state(x), self.step.step_covariance(p, self.noise.matrix)
            values = x.tolist()
            tension, tension_var = self.constants.tension_at_drone(values, p)
        published = p[state.POSITION_VELOCITY, state.POSITION_VELOCITY].copy()
        if values is None:
            published[2, 2] += self.height_excess_m2
        else:
            nn, ne, nd, ee, ed, dd = self._added(values)
            published[:3, :3] += ((nn, ne, nd), (ne, ee, ed), (nd, ed, dd))
        status = self._status
        reason = None
        if status is None:
            status, reason = self._assess(x, p, values, tension, published)
        else:  # decided already: the reason waits until it is read
            self._assess_inputs = (x, p, values, tension, published)
        return ExactValues(
            x[state.POSITION].copy(),
            x[state.VELOCITY].copy(),
            published,
            float(tension),
            tension_var,
            status,
            reason,
            float(x[state.SCALE]),
            x[state.BIAS].copy(),
            x[state.WIND].copy(),
        )

    def _assess(
        self,
        x: FloatArray,
        p: FloatArray,
        values: list[float] | None,
        tension: float,
        published: FloatArray,
    ) -> tuple[str, str]:
        """The exact values' ``(status, reason)`` (``values``: ``x`` as floats, None without
        a state)."""
        settings = self.settings
        return assess(
            initialised_reason=self.initialised_reason,
            reset_reason=self.reset_reason,
            on_ground=self.on_ground,
            inputs_stale=self.inputs_stale,
            tension_n=tension,
            slack_tension_n=settings.slack_tension_n,
            position_covariance_m2=published[:3, :3],
            max_horizontal_std_m=settings.max_horizontal_std_m,
            horizontal_pull_n=0.0 if values is None else HORIZONTAL_PULL(values),
            min_horizontal_pull_n=MIN_HORIZONTAL_PULL(
                settings.pull_per_wind_n_s_per_m,
                settings.wind_std_mps,
                float(x[state.WIND][0]),
                float(x[state.WIND][1]),
            ),
            sag_std_m=self.sag_std_m,
            hover_unknowns=None
            if values is None or self._sag_withholds()
            else HoverUnknowns(
                float(x[state.SCALE]),
                x[state.WIND].copy(),
                p[_HOVER_LIST][:, _HOVER_LIST],
                p[:2][:, _HOVER_LIST],
                self.hypotheses,
            ),
        )

    def _added(self, x: list[float]) -> tuple[float, ...]:
        """What the published position covariance adds at the state's values ``x``
        (:func:`.published_terms.added_position_terms`, or its C twin)."""
        return ADDED_POSITION_TERMS(
            x,
            self.constants.weight_n_per_m,
            self.settings,
            self.force_std_n,
            self.position_information,
            self.height_excess_m2,
            self.winch_fused,
            self.sag_m2,
            self.terrain_m2,
        )

    # ------------------------------------------------------------------ status
    def status(self) -> str:
        """The exact values' status, from the approximation where it is clear."""
        status = self._status
        if status is None:
            status = self._quick_status()
            if status is None:
                status = self.values().status
            self._status = status
        return status

    def _quick_status(self) -> str | None:
        settings = self.settings
        decided_early = (
            self.reset_reason is not None
            or self.initialised_reason is not None
            or self.on_ground
            or self.inputs_stale
        )
        tension = pull = min_pull = tol = 0.0
        horizontal = (0.0, 0.0, 0.0)
        if not decided_early:  # the numbers are needed
            approx = self.approximate()
            if approx is None:
                return None
            x = approx.state
            tension, tol = approx.tension_n, approx.covariance_tol
            horizontal = approx.horizontal
            pull = HORIZONTAL_PULL(x)
            min_pull = MIN_HORIZONTAL_PULL(
                settings.pull_per_wind_n_s_per_m, settings.wind_std_mps, x[11], x[12]
            )
        return DECIDE(
            initialised=self.initialised_reason is None,
            reset=self.reset_reason is not None,
            on_ground=self.on_ground,
            inputs_stale=self.inputs_stale,
            tension_n=tension,
            slack_tension_n=settings.slack_tension_n,
            horizontal_m2=horizontal,
            max_horizontal_std_m=settings.max_horizontal_std_m,
            horizontal_pull_n=pull,
            min_horizontal_pull_n=min_pull,
            explained=self._explained,
            margin=MARGIN,
            variance_tol=tol,
            range_unknown=self.sag_std_m == math.inf,
        )

    def _explained(self) -> bool | None:
        """Whether the thrust scale and the wind explain the horizontal covariance
        (:meth:`~tether_companion.estimation.dynamic.observability.HoverUnknowns.explains`):
        without numbers while several thrust-scale hypotheses run, else from the mixture's
        (None: only the exact values tell)."""
        if self._sag_withholds():
            return False
        if self.hypotheses > 1:
            return True
        approx = self._approximation
        mixture = self.mixture
        assert approx is not None and mixture is not None
        hover = mixture.hover()
        if hover is None:
            return None
        return hover.explains(
            approx.horizontal,
            approx.covariance_tol,
            self._spread,
            approx.duration_s,
            self.noise,
            self._row_scale,
            self.settings.max_horizontal_std_m,
            MARGIN,
        )

    def _sag_withholds(self) -> bool:
        """Whether the range's spread over the plausible tensions alone is beyond the bound
        (then the thrust scale and the wind do not explain the covariance)."""
        return self.sag_std_m > self.settings.max_horizontal_std_m

    # ------------------------------------------------------------------ approximation
    def approximate(self) -> Approximation | None:
        """The published position, its covariance and the tension in Python floats, with
        bounds of their error (:mod:`~tether_companion.estimation.dynamic.published_bound`);
        None without a state or with non-finite arrays (then only the exact values tell)."""
        approx = self._approximation
        if approx is not None:
            return approx
        mixture = self.mixture
        if mixture is None:
            return None
        bounded = approximation(mixture, self.step, self.noise, self.constants, self._added)
        if bounded is None:
            return None
        approx, self._spread, self._row_scale = bounded
        self._approximation = approx
        return approx
