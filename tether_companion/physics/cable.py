"""Tether (cable) models: the force the cable exerts on the drone, NED, anchor at the origin.

Every model follows one protocol (:class:`CableModel`):

- ``force_on_drone_ned_n(position_ned_m, velocity_ned_m_s) -> ndarray(3)``: the force on the
  drone [N] in the NED frame for the drone's position relative to the anchor and its NED
  velocity; it also sets ``tension_n``, the tension magnitude at the drone end [N] of that
  evaluation;
- ``force_components(pn, pe, pd, vn, ve, vd) -> (fn, fe, fd)``: the same with plain floats, the
  allocation-free path the simulator's RK4 derivative calls;
- winch state: ``paid_out_m`` (cable length between the winch and the drone), advanced by
  ``advance(dt_s)`` at the winch rate set by ``set_winch_rate_mps``; ``set_tension_n`` for a
  tension-controlled winch; ``release()`` lets the cable go (zero force from then on).

Models
------
(a) :class:`ConstantTensionCable`: the paper's winch (Al-Radaideh & Sun 2021, section 3.1,
    eq. 21-22): a straight cable pulling toward the anchor with a set magnitude ``f_c``,
    ``F = -f_c p / |p|``. At ``|p| = 0`` the direction is undefined and the force is zero.
(b) :class:`ElasticCable`: a straight elastic line of paid-out length ``L`` (like ArduPilot
    SITL's SIM_TETH_*): when ``|p| > L`` a spring ``k (|p| - L)`` plus a damper ``c d|p|/dt``
    (never pushing); always the weight of the lifted cable ``rho g min(|p|, L)`` along the line
    toward the anchor.
(c) :class:`CatenaryCable`: a heavy elastic cable of unstretched length ``L`` hanging as a
    catenary (Martins 2019, section 3, case 2: known length) between the anchor and the drone,
    quasi-static. The drone feels the catenary's end force: ``w a`` horizontally toward the
    anchor and ``w s2`` down (eqs. 11-13), solved by
    :func:`tether_companion.physics.catenary.solve_known_length` and ``end_tensions``. The
    cable stretches by ``T / k`` under its drone-end tension ``T`` (solved as a fixed point), so
    as the drone pulls the cable straight the force goes over smoothly into the taut elastic
    line of (b). A cable long enough to reach the ground lies on it from the anchor to a
    touchdown point and rises as a catenary whose lowest point is that touchdown point
    (Martins case 1 over the remaining span).
(d) :class:`~tether_companion.physics.cable_winch.WinchCatenaryCable`: a real tethered drone's
    ground station, a winch holding the tension at its outlet on a heavy cable hanging as a
    catenary (or resting on the ground up to a touchdown point); it pays out what that takes
    (:mod:`tether_companion.physics.cable_winch`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tether_companion.config import ConfigError, spec
from tether_companion.constants import GRAVITY_MPS2
from tether_companion.physics.cable_base import MIN_DISTANCE_M, CableBase, CableModel
from tether_companion.physics.cable_winch import WinchCatenaryCable
from tether_companion.physics.catenary import (
    CatenaryCurve,
    lowest_point_at_anchor,
    solve_known_length,
    solve_lowest_point_at_anchor,
)
from tether_companion.physics.catenary_forces import end_tensions
from tether_companion.physics.roots import bracketed_root

CABLE_MODELS: tuple[str, ...] = (
    "constant_tension",
    "elastic",
    "catenary",
    "none",
    "winch_catenary",
)
"""Values of ``cable.model`` in a scenario (the emulator's TETH_MODEL is the index)."""
HEAVY_CABLE_MODELS: tuple[str, ...] = ("elastic", "catenary", "winch_catenary")
"""The models with the cable's weight (``linear_density_kg_per_m``); the constant-tension line
is the paper's weightless one whatever that key says."""
TENSION_CONTROLLED_MODELS: tuple[str, ...] = ("constant_tension", "winch_catenary")
"""The models whose winch holds a tension set-point (``tension_n``, ``set_tension`` events)."""


@dataclass(frozen=True)
class CableConfig:
    """The ``cable`` section of a scenario (SI units)."""

    model: str = spec("constant_tension", choices=CABLE_MODELS, doc="cable model")
    tension_n: float = spec(
        4.0,
        minimum=0.0,
        doc="winch tension set-point (constant_tension; winch_catenary: at the anchor) [N]",
    )
    length_m: float = spec(
        10.0, exclusive_minimum=0.0, doc="initial paid-out length (elastic, catenary) [m]"
    )
    min_length_m: float = spec(
        0.0, minimum=0.0, doc="shortest paid-out length the winch reels to [m]"
    )
    spool_length_m: float = spec(
        100.0, exclusive_minimum=0.0, doc="longest paid-out length (cable on the spool) [m]"
    )
    stiffness_n_per_m: float = spec(
        100.0, exclusive_minimum=0.0, doc="axial spring constant of the taut line [N/m]"
    )
    damping_n_s_per_m: float = spec(5.0, minimum=0.0, doc="axial damping of the taut line [N s/m]")
    linear_density_kg_per_m: float = spec(
        0.0167, minimum=0.0, doc="cable mass per length (elastic, catenary, winch_catenary) [kg/m]"
    )
    diameter_m: float = spec(
        0.0,
        minimum=0.0,
        maximum=0.05,
        doc="cable diameter for the wind's drag on it (physics/cable_drag.py); 0 = no drag [m]",
    )
    winch_rate_mps: float = spec(
        0.0, minimum=-10.0, maximum=10.0, doc="initial winch rate, + pays out, - reels in [m/s]"
    )

    def validate(self) -> None:
        """The paid-out length must lie within the winch's range."""
        if self.spool_length_m < self.min_length_m:
            raise ConfigError(
                "",
                "spool_length_m",
                self.spool_length_m,
                f"must be >= min_length_m ({self.min_length_m})",
            )
        if not self.min_length_m <= self.length_m <= self.spool_length_m:
            raise ConfigError(
                "",
                "length_m",
                self.length_m,
                f"must lie within [min_length_m, spool_length_m] = "
                f"[{self.min_length_m}, {self.spool_length_m}]",
            )


class ConstantTensionCable(CableBase):
    """The paper's constant-tension winch: ``F = -f_c p/|p|`` (eq. 21-22), zero when released.

    The winch pays out and reels in whatever is needed to keep the tension, so ``paid_out_m``
    follows the anchor-to-drone distance; a winch rate has no effect on the force.
    """

    def __init__(self, tension_n: float, spool_length_m: float = math.inf) -> None:
        super().__init__(0.0, 0.0, 0.0, spool_length_m)
        self.set_tension_n(tension_n)

    def set_tension_n(self, tension_n: float) -> None:
        """Set the winch tension ``f_c`` [N] (>= 0)."""
        if not (math.isfinite(tension_n) and tension_n >= 0.0):
            raise ValueError(f"tension must be a finite number >= 0 N, got {tension_n!r}")
        self.set_point_n = float(tension_n)

    def force_components(
        self, pn: float, pe: float, pd: float, vn: float, ve: float, vd: float
    ) -> tuple[float, float, float]:
        """Force (north, east, down) [N] on the drone at position (pn, pe, pd) [m]."""
        distance = math.sqrt(pn * pn + pe * pe + pd * pd)
        self.paid_out_m = distance
        if self.released or distance < MIN_DISTANCE_M:
            self.tension_n = 0.0
            return 0.0, 0.0, 0.0
        self.tension_n = tension = self.set_point_n
        scale = -tension / distance
        return scale * pn, scale * pe, scale * pd


class ElasticCable(CableBase):
    """A straight elastic line of paid-out length ``L`` with a lifted-cable weight.

    With ``d = |p|`` and ``u = p/d`` (anchor to drone)::

        spring_n = max(k (d - L) + c (p . v)/d, 0)   if d > L else 0
        weight_n = rho g min(d, L)
        F = -(spring_n + weight_n) u,   tension_n = spring_n + weight_n

    The weight of the lifted cable pulls along the line toward the anchor, as in ArduPilot
    SITL's tether (SIM_TETH_*); it grows with the paid-out length until the line is taut.
    The damper acts on the rate of change of ``d`` and never makes the line push.
    """

    def __init__(
        self,
        length_m: float,
        stiffness_n_per_m: float,
        damping_n_s_per_m: float,
        linear_density_kg_per_m: float,
        *,
        winch_rate_mps: float = 0.0,
        min_length_m: float = 0.0,
        spool_length_m: float = math.inf,
        gravity_mps2: float = GRAVITY_MPS2,
    ) -> None:
        super().__init__(length_m, winch_rate_mps, min_length_m, spool_length_m)
        self.stiffness_n_per_m = float(stiffness_n_per_m)
        self.damping_n_s_per_m = float(damping_n_s_per_m)
        self.weight_per_length_n_per_m = float(linear_density_kg_per_m) * gravity_mps2

    def taut_tension_n(self, distance_m: float, radial_rate_mps: float) -> float:
        """Tension [N] of the line at chord ``distance_m`` and chord rate ``radial_rate_mps``."""
        length = self.paid_out_m
        spring = 0.0
        if distance_m > length:
            spring = (
                self.stiffness_n_per_m * (distance_m - length)
                + self.damping_n_s_per_m * radial_rate_mps
            )
            spring = max(spring, 0.0)
        return spring + self.weight_per_length_n_per_m * min(distance_m, length)

    def force_components(
        self, pn: float, pe: float, pd: float, vn: float, ve: float, vd: float
    ) -> tuple[float, float, float]:
        """Force (north, east, down) [N] at (pn, pe, pd) [m] moving at (vn, ve, vd) [m/s]."""
        distance = math.sqrt(pn * pn + pe * pe + pd * pd)
        if self.released or distance < MIN_DISTANCE_M:
            self.tension_n = 0.0
            return 0.0, 0.0, 0.0
        inv = 1.0 / distance
        radial_rate = (pn * vn + pe * ve + pd * vd) * inv
        self.tension_n = tension = self.taut_tension_n(distance, radial_rate)
        scale = -tension * inv
        return scale * pn, scale * pe, scale * pd


class CatenaryCable(CableBase):
    """A heavy elastic cable hanging as a catenary (see the module docstring, model (c)).

    Quasi-static: the cable's shape follows the drone instantly. With horizontal distance
    ``X``, height ``H`` and chord ``d``:

    - ``H <= 0`` (drone on the ground): the cable lies on the ground; only a line stretched
      past its length pulls (the elastic line's spring and damper).
    - cable long enough to touch the ground (``L`` at least the length of the catenary whose
      lowest point is the anchor, Martins case 1): the part from the anchor to a touchdown
      point ``x_t`` lies on the ground; the rest is a case-1 catenary over ``X - x_t`` with
      length ``L - x_t``; ``L >= X + H`` hangs straight down (force ``w H`` down). The stretch
      of such a lightly loaded cable (``T/k``, below a millimetre for the defaults) is ignored.
    - otherwise: the stretch ``e`` solves ``k e = T_cat(L + e)``, with ``T_cat(L')`` the drone
      end tension of the inextensible catenary of length ``L'`` (case 2); for ``d > L`` the
      axial damper of the elastic line is added along the chord (``tension_n`` is then the
      magnitude of the resulting force).

    The ``d`` component of the force is ``w s2`` (downward pull of the cable beyond the lowest
    point); the horizontal component ``w a`` points toward the anchor.
    """

    history_free = False  # the stretch's root search starts from the last call's

    def __init__(self, elastic: ElasticCable, linear_density_kg_per_m: float) -> None:
        if not linear_density_kg_per_m > 0.0:
            raise ValueError(
                f"a catenary needs a linear density > 0 kg/m, got {linear_density_kg_per_m!r}"
            )
        super().__init__(
            elastic.paid_out_m, elastic.winch_rate_mps, elastic.min_length_m, elastic.spool_length_m
        )
        self.elastic = elastic
        self.weight_per_length_n_per_m = elastic.weight_per_length_n_per_m
        self.stretch_m = 0.0
        self._grounded_key: tuple[float, ...] = ()
        self._grounded_value = (0.0, 0.0, 0.0)

    def advance(self, dt_s: float) -> None:
        """Reel the winch (see :meth:`CableBase.advance`); the line follows."""
        super().advance(dt_s)
        self.elastic.paid_out_m = self.paid_out_m

    def release(self) -> None:
        """Let the cable go."""
        super().release()
        self.elastic.release()

    def _free_force(
        self, horizontal_m: float, height_m: float, length_m: float
    ) -> tuple[float, float, float]:
        """(horizontal force toward the anchor, down force, tension) [N] of a free catenary."""
        curve = solve_known_length(horizontal_m, height_m, length_m)
        ends = end_tensions(curve, self.weight_per_length_n_per_m)
        return ends.horizontal_n, -ends.on_drone_vertical_n, ends.drone_n

    def _grounded_force(
        self, horizontal_m: float, height_m: float, anchor_curve: CatenaryCurve
    ) -> tuple[float, float, float]:
        """As :meth:`_free_force` for a cable partly lying on the ground; ``anchor_curve`` is
        the case-1 catenary from the anchor to the drone (touchdown at the anchor), no longer
        than the cable. The same position and length give the same force: the last one is
        kept and given again (the IMU's specific force, the truth's tension and the next RK4
        step's first stage all ask at the same state)."""
        w = self.weight_per_length_n_per_m
        length = self.paid_out_m
        key = (horizontal_m, height_m, length, w)
        if key == self._grounded_key:
            return self._grounded_value
        curves = {0.0: anchor_curve}  # touchdown -> case-1 curve beyond it, as evaluated

        def excess(touchdown_m: float) -> float:
            rise = lowest_point_at_anchor(horizontal_m - touchdown_m, height_m)
            curves[touchdown_m] = rise
            return touchdown_m + rise.length_m - length

        touchdown = bracketed_root(
            excess, 0.0, horizontal_m, 1e-10, f_low=0.0 + anchor_curve.length_m - length
        )
        ends = end_tensions(curves[touchdown], w)
        value = (ends.horizontal_n, -ends.on_drone_vertical_n, ends.drone_n)
        self._grounded_key, self._grounded_value = key, value
        return value

    def _stretched_force(
        self, horizontal_m: float, height_m: float, chord_m: float
    ) -> tuple[float, float, float]:
        """As :meth:`_free_force` with the cable stretched by its own tension.

        Each stretch's free catenary is solved once per call (the warm start's bracket, the
        root search's end points and the answer are points already evaluated)."""
        k = self.elastic.stiffness_n_per_m
        length = self.paid_out_m
        low = max(0.0, chord_m - length) + 1e-9 * max(chord_m, 1.0)
        forces: dict[float, tuple[float, float, float]] = {}

        def free(stretch_m: float) -> tuple[float, float, float]:
            force = forces.get(stretch_m)
            if force is None:
                force = forces[stretch_m] = self._free_force(
                    horizontal_m, height_m, length + stretch_m
                )
            return force

        def balance(stretch_m: float) -> float:
            return k * stretch_m - free(stretch_m)[2]

        previous = self.stretch_m
        near = (max(low, 0.99 * previous), 1.01 * previous)
        if previous > low and balance(near[0]) <= 0.0 <= balance(near[1]):
            low, high = near  # warm start: the stretch changes little between calls
        else:
            high = max(2.0 * previous, 2.0 * low, 1e-6)
            while balance(high) < 0.0:
                low, high = high, 2.0 * high
        self.stretch_m = bracketed_root(balance, low, high, 1e-12)
        return free(self.stretch_m)

    def force_components(
        self, pn: float, pe: float, pd: float, vn: float, ve: float, vd: float
    ) -> tuple[float, float, float]:
        """Force (north, east, down) [N] at (pn, pe, pd) [m] moving at (vn, ve, vd) [m/s]."""
        horizontal = math.hypot(pn, pe)
        height = -pd
        chord = math.hypot(horizontal, height)
        if self.released or chord < MIN_DISTANCE_M:
            self.tension_n = 0.0
            return 0.0, 0.0, 0.0
        length = self.paid_out_m
        if height <= 0.0:
            spring = 0.0
            if chord > length:
                spring = self.elastic.taut_tension_n(chord, (pn * vn + pe * ve + pd * vd) / chord)
                spring -= self.elastic.weight_per_length_n_per_m * length
            self.tension_n = spring
            scale = -spring / chord
            return scale * pn, scale * pe, scale * pd
        if length >= horizontal + height:  # hangs straight down from the touchdown point
            pull_n, down_n = 0.0, self.weight_per_length_n_per_m * height
            tension = down_n
        elif length >= (anchor_curve := solve_lowest_point_at_anchor(horizontal, height)).length_m:
            # (a case-1 catenary is shorter than horizontal + height: the test above first)
            pull_n, down_n, tension = self._grounded_force(horizontal, height, anchor_curve)
        else:
            pull_n, down_n, tension = self._stretched_force(horizontal, height, chord)
        fn = fe = 0.0
        if horizontal > 0.0:
            fn = -pull_n * pn / horizontal
            fe = -pull_n * pe / horizontal
        fd = down_n
        if chord > length and self.elastic.damping_n_s_per_m > 0.0:
            damper = self.elastic.damping_n_s_per_m * (pn * vn + pe * ve + pd * vd) / chord
            damper = max(damper, -tension)
            fn -= damper * pn / chord
            fe -= damper * pe / chord
            fd -= damper * pd / chord
            tension = math.sqrt(fn * fn + fe * fe + fd * fd)
        self.tension_n = tension
        return fn, fe, fd


class NoCable(CableBase):
    """No tether at all (free flight): zero force, zero tension."""

    def __init__(self) -> None:
        super().__init__(0.0, 0.0, 0.0, 0.0)
        self.released = True

    def force_components(
        self, pn: float, pe: float, pd: float, vn: float, ve: float, vd: float
    ) -> tuple[float, float, float]:
        """Always (0, 0, 0) [N]."""
        return 0.0, 0.0, 0.0


def cable_weight_n_per_m(config: CableConfig, gravity_mps2: float = GRAVITY_MPS2) -> float:
    """The weight per length [N/m] of the cable ``config`` simulates: ``linear_density g`` for
    :data:`HEAVY_CABLE_MODELS`, 0 for the weightless ones."""
    if config.model not in HEAVY_CABLE_MODELS:
        return 0.0
    return config.linear_density_kg_per_m * gravity_mps2


def make_cable(config: CableConfig, gravity_mps2: float = GRAVITY_MPS2) -> CableModel:
    """Build the cable model a scenario's ``cable`` section asks for."""
    if config.model == "constant_tension":
        return ConstantTensionCable(config.tension_n, spool_length_m=config.spool_length_m)
    if config.model == "none":
        return NoCable()
    if config.model == "winch_catenary":
        return WinchCatenaryCable(
            config.tension_n,
            config.linear_density_kg_per_m,
            gravity_mps2,
            spool_length_m=config.spool_length_m,
        )
    kwargs = {
        "winch_rate_mps": config.winch_rate_mps,
        "min_length_m": config.min_length_m,
        "spool_length_m": config.spool_length_m,
        "gravity_mps2": gravity_mps2,
    }
    elastic = ElasticCable(
        config.length_m,
        config.stiffness_n_per_m,
        config.damping_n_s_per_m,
        config.linear_density_kg_per_m,
        **kwargs,
    )
    if config.model == "elastic":
        return elastic
    return CatenaryCable(elastic, config.linear_density_kg_per_m)
