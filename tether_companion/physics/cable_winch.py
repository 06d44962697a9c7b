"""A constant-tension winch on a heavy cable: the ground station of a real tethered drone.

The winch (Elistair's, Hoverfly's) holds the tension ``T_a`` at its outlet, the anchor, and pays
out or reels in whatever length that takes; the cable of weight ``w`` per length hangs from the
anchor to the drone as a catenary. Quasi-static (the shape follows the drone at once) and
inextensible (the stretch ``T / EA`` is below 1e-4 at these tensions). The ground is at the
anchor's level.

Geometry (the vertical plane through the anchor and the drone, ``x`` toward the drone, ``y``
up, anchor at the origin, drone at ``(X, h)``): ``y = c cosh((x - x0)/c) + k``, horizontal
tension ``H = w c`` all along the cable, tension ``T = w c cosh((x - x0)/c) = w (y - k)``: the
tension is ``w`` times the height above the directrix ``y = k``. So, with ``A = T_a / w``:

- the drone feels ``T_d = T_a + w h`` whatever the shape;
- the cable leaves the anchor at an angle ``phi`` above the horizontal with ``c = A cos(phi)``
  and arc ``s1 = A sin(phi)`` from the lowest point (``x0 <= 0``) to the anchor; at the drone
  ``c cosh(u2) = A + h``, so ``s2 = sqrt(s1^2 + h (2A + h))``; the arc between them is
  ``L = s2 - s1 = h (2A + h) / (s1 + s2)`` and the span
  ``X(phi) = c asinh(h (2A + h) / (A s2 + (A + h) s1))`` (``sinh(u2 - u1)`` written without
  cancellation). ``X(phi)`` falls from ``X0 = A asinh(sqrt(h (2A + h)) / A)`` at ``phi = 0`` to
  0 at ``phi = pi/2``; the cable is convex, so ``phi`` is below the chord's elevation. A span
  ``X < X0`` has one root ``phi`` in ``(0, atan2(h, X)]``: the taut (stable) one; the other
  catenaries through both ends with the same anchor tension dip below the anchor (the deep
  branch of the same family).
- ``X >= X0``: the free catenary would have its lowest point between the anchor and the drone,
  below the anchor's level, i.e. under ground. The cable lies on the ground from the winch to a
  touchdown point instead; without friction the tension along the ground part is ``T_a``, so
  ``H = T_a``, ``c = A``, and the cable rises from the touchdown, its lowest point, at
  ``x_t = X - X0``, with arc ``sqrt(h (2A + h))``.

The drone feels ``H`` horizontally toward the anchor and ``w s`` down (``s`` the arc from the
lowest point to the drone); the winch has paid out the arc plus the ground part.

Limits: ``T_a -> 0`` (the winch too slack to lift the cable to the drone): ``X0 -> 0``, the cable
rests on the ground up to below the drone and hangs straight up to it: the drone carries
``w h`` and no horizontal pull. ``w -> 0``: the straight line at ``T_a`` of the paper's winch
(``w = 0`` is that line exactly). A drone straight above the anchor: the vertical cable,
``T_a + w h`` down. A drone at or below the anchor's level: the cable runs along the chord at
``T_a`` (lying on the ground, or over the winch's edge); there is no cable below the ground in
this model.

Pure; SI units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tether_companion.physics.cable_base import MIN_DISTANCE_M, CableBase
from tether_companion.physics.roots import bracketed_root

ANGLE_TOLERANCE_RAD = 1e-13
"""Width of the bracket [rad] on the anchor angle at which the root search stops."""


@dataclass(frozen=True, slots=True)
class WinchCatenary:
    """The cable of a constant-tension winch for one drone position (module docstring).

    Attributes
    ----------
    pull_n
        Horizontal force on the drone toward the anchor [N] (``>= 0``).
    down_n
        Downward force on the drone [N] (negative: the drone is below the anchor's level).
    drone_tension_n
        Tension at the drone [N].
    paid_out_m
        Cable between the winch and the drone [m]: the arc plus the part on the ground.
    on_ground_m
        The part lying on the ground, winch to touchdown [m].
    anchor_elevation_rad
        The cable's angle above the horizontal where it leaves the anchor [rad] (0 where it
        rests on the ground).
    """

    pull_n: float
    down_n: float
    drone_tension_n: float
    paid_out_m: float
    on_ground_m: float
    anchor_elevation_rad: float


def tension_at_drone_n(
    winch_tension_n: float, weight_per_length_n_per_m: float, height_m: float
) -> float:
    """The tension at a drone ``height_m`` [m] above the anchor [N] of a cable leaving the winch
    with ``winch_tension_n`` [N]: ``T_a + w max(h, 0)`` (the catenary's tension grows by ``w h``
    whatever its shape, the part on the ground included); nan for a heavy cable without a
    finite height."""
    if weight_per_length_n_per_m <= 0.0:
        return winch_tension_n
    return (
        winch_tension_n + weight_per_length_n_per_m * max(0.0, height_m)
        if math.isfinite(height_m)
        else math.nan
    )


def _span_m(phi: float, big_a: float, height: float, rise_sq: float) -> float:
    """``X(phi)`` [m] for ``A = big_a`` [m], drone height [m] and ``rise_sq = h (2A + h)``."""
    s1 = big_a * math.sin(phi)
    s2 = math.sqrt(s1 * s1 + rise_sq)
    return big_a * math.cos(phi) * math.asinh(rise_sq / (big_a * s2 + (big_a + height) * s1))


def winch_catenary(
    horizontal_m: float,
    height_m: float,
    anchor_tension_n: float,
    weight_per_length_n_per_m: float,
) -> WinchCatenary:
    """The cable of a winch holding ``anchor_tension_n`` [N] at the anchor, weighing
    ``weight_per_length_n_per_m`` [N/m], to a drone ``horizontal_m`` [m] out and ``height_m``
    [m] above the anchor (module docstring).

    Raises
    ------
    ValueError
        A non-finite input, a negative horizontal distance, tension or weight.
    """
    x, h, t_a, w = (
        float(v) for v in (horizontal_m, height_m, anchor_tension_n, weight_per_length_n_per_m)
    )
    if not all(math.isfinite(v) for v in (x, h, t_a, w)):
        raise ValueError(f"winch cable inputs must be finite, got {(x, h, t_a, w)!r}")
    if x < 0.0 or t_a < 0.0 or w < 0.0:
        raise ValueError(
            f"horizontal distance, tension and weight must be >= 0, got {(x, t_a, w)!r}"
        )
    chord = math.hypot(x, h)
    if chord < MIN_DISTANCE_M:
        return WinchCatenary(0.0, 0.0, 0.0, chord, 0.0, 0.0)
    if w == 0.0 or h <= 0.0:
        return WinchCatenary(t_a * x / chord, t_a * h / chord, t_a, chord, 0.0, math.atan2(h, x))
    drone_tension = t_a + w * h
    if x == 0.0:
        return WinchCatenary(0.0, drone_tension, drone_tension, h, 0.0, 0.5 * math.pi)
    big_a = t_a / w
    rise_sq = h * (2.0 * big_a + h)
    rise = math.sqrt(rise_sq)
    touchdown_span = big_a * math.asinh(rise / big_a) if big_a > 0.0 else 0.0
    if x >= touchdown_span:
        on_ground = x - touchdown_span
        return WinchCatenary(t_a, w * rise, drone_tension, on_ground + rise, on_ground, 0.0)
    phi = bracketed_root(
        lambda angle: x - _span_m(angle, big_a, h, rise_sq),
        0.0,
        math.atan2(h, x),
        ANGLE_TOLERANCE_RAD,
        f_low=x - touchdown_span,
    )
    s1 = big_a * math.sin(phi)
    s2 = math.sqrt(s1 * s1 + rise_sq)
    return WinchCatenary(t_a * math.cos(phi), w * s2, drone_tension, rise_sq / (s1 + s2), 0.0, phi)


class WinchCatenaryCable(CableBase):
    """A constant-tension winch on a heavy cable (:func:`winch_catenary`), zero when released.

    ``tension_n`` is the tension at the drone, ``T_a + w h``; ``paid_out_m`` the length the
    winch has paid out for the last evaluated position (the arc plus the part on the ground);
    a winch rate has no effect (the winch pays out what the tension needs).
    """

    def __init__(
        self,
        tension_n: float,
        linear_density_kg_per_m: float,
        gravity_mps2: float,
        spool_length_m: float = math.inf,
    ) -> None:
        super().__init__(0.0, 0.0, 0.0, spool_length_m)
        weight = float(linear_density_kg_per_m) * float(gravity_mps2)
        if not (math.isfinite(weight) and weight >= 0.0):
            raise ValueError(f"cable weight per length must be finite and >= 0, got {weight!r}")
        self.weight_per_length_n_per_m = weight
        self.set_tension_n(tension_n)

    def set_tension_n(self, tension_n: float) -> None:
        """Set the winch's tension at the anchor ``T_a`` [N] (>= 0)."""
        if not (math.isfinite(tension_n) and tension_n >= 0.0):
            raise ValueError(f"tension must be a finite number >= 0 N, got {tension_n!r}")
        self.set_point_n = float(tension_n)

    def advance(self, dt_s: float) -> None:
        """Nothing to reel: the length follows the drone at each force evaluation."""

    def force_components(
        self, pn: float, pe: float, pd: float, vn: float, ve: float, vd: float
    ) -> tuple[float, float, float]:
        """Force (north, east, down) [N] on the drone at (pn, pe, pd) [m]."""
        if self.released:
            return 0.0, 0.0, 0.0
        horizontal = math.hypot(pn, pe)
        cable = winch_catenary(horizontal, -pd, self.set_point_n, self.weight_per_length_n_per_m)
        self.paid_out_m = cable.paid_out_m
        self.tension_n = cable.drone_tension_n
        if horizontal <= 0.0:
            return 0.0, 0.0, cable.down_n
        scale = -cable.pull_n / horizontal
        return scale * pn, scale * pe, cable.down_n
