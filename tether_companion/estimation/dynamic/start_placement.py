"""Where a cable force puts the drone: the geometry the dynamic filter's start
(:mod:`~tether_companion.estimation.dynamic.initialise`) maps its window's data through.

From the cable's force on the drone (NED [N]) and the drone's height above the anchor, a
winch's paid-out length or a ground-station cable angle, the position relative to the anchor
(NED [m]) and the chord tension [N] on the filter's own cable curve (derive.py): the straight
line, the catenary, or a catenary resting on the ground to a touchdown. Pure.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic.start_angle import MIN_RISE, angle_position

FloatArray = NDArray[np.float64]


def place(
    force: FloatArray,
    height: float,
    length: float,
    weight: float,
    elevation: float = math.nan,
    azimuth: float = math.nan,
    winch_tension: float = math.nan,
) -> FloatArray | None:
    """``(p_n, p_e, p_d, T_ch)`` of a cable force on the drone ``force`` (NED [N]) with
    the drone ``height`` [m] above the anchor and/or a cable ``length`` [m] (``nan``:
    unknown), on a cable of ``weight`` per length [N/m]; None when the cable does not rise to
    the drone or the data cannot place it.

    With a height the curve is the filter's own (derive.py): the straight line for a
    weightless cable; for a heavy one the catenary of parameter ``c = H/w`` (``H`` the
    force's horizontal part, ``V`` its down part) whose slope at the drone is ``V/H``: the
    anchor sits where ``cosh(x_a/c) = sqrt(1 + (V/H)^2) - b/c``, so the span is
    ``a = c (asinh(V/H) - acosh(that))``. A cable resting on the ground has that at
    exactly 1 (its lowest point, the touchdown, is at the anchor's level) whatever the
    span beyond the touchdown, so only the winch length places it: a length at least the
    rise ``sqrt(b^2 + 2 b c)`` (longer than any free curve reaching the height) lies on
    the ground over ``L - rise`` and ``a = L - rise + c acosh(1 + b/c)``; without a
    length a pull with ``cosh`` at or below 1 places nothing. A free curve with a winch
    length has the length's span (:func:`free_span`; the straight line's ``sqrt(L^2 - b^2)``),
    the force giving the bearing and ``T_ch`` as on its own curve (the straight line's
    ``|F|``; from the length's geometry a weak pull turned by a wind hypothesis read slack and
    that member did not start): the slope's span moves metres for a few percent of thrust
    scale, and started that way the bank's members were scored by the length's first readings
    for their placements (docs/estimation-history.md, winch22). Without a height, the chord
    of a winch length ``L`` along the force (the weight's pull taken as half the cable's, a
    first guess the filter refines).

    With a cable angle at the anchor (``elevation``, ``azimuth`` [rad]; ``nan``: none;
    given where the wind could turn the pull, :meth:`.initialise.Initialiser._pull_weak`)
    the angle places the drone: a weightless cable along it (:func:`place_by_angle`), a
    heavy one by :func:`place_heavy_by_angle` (with the winch's ``winch_tension`` [N] where
    it is known, ``nan`` otherwise)."""
    if math.isfinite(azimuth):  # a pull the wind could turn
        if weight > 0.0:
            return place_heavy_by_angle(
                force, height, length, weight, elevation, azimuth, winch_tension
            )
        return place_by_angle(force, height, length, elevation, azimuth)
    if math.isnan(height):
        chord = force - np.array((0.0, 0.0, 0.5 * weight * length))
        tension = float(np.linalg.norm(chord))
        if not tension > 0.0:
            return None
        return np.array((*(-chord / tension * length), tension))
    pull = math.hypot(float(force[0]), float(force[1]))
    down = float(force[2])
    if not (pull > 0.0 and down > 0.0 and height > 0.0):
        return None
    if weight > 0.0:
        parameter = pull / weight
        rise = math.sqrt(height * height + 2.0 * height * parameter)
        anchor = math.hypot(1.0, down / pull) - height / parameter
        if length >= rise:  # longer than any free curve to this height: on the ground
            span = length - rise + parameter * math.acosh(1.0 + height / parameter)
            sloped = span
        elif anchor >= 1.0 or not math.isnan(length):
            sloped = parameter * (math.asinh(down / pull) - math.acosh(max(anchor, 1.0)))
            span = free_span(height, length, parameter) if length > height else sloped
        else:
            return None
    else:
        sloped = height * pull / down
        span = math.sqrt(length * length - height * height) if length > height else sloped
    distance = math.hypot(span, height)
    if not (span > 0.0 and sloped > 0.0) or height / distance < MIN_RISE:
        return None
    bearing = -np.asarray(force[:2]) / pull
    return np.array((*(bearing * span), -height, pull * math.hypot(sloped, height) / sloped))


def free_span(height: float, length: float, parameter: float) -> float:
    """The span [m] of a free catenary of ``parameter`` ``c = H/w`` [m] and arc ``length``
    [m] whose ends are ``height`` [m] apart vertically: ``L^2 = b^2 + (2 c sinh(a / 2c))^2``."""
    chord_m = math.sqrt(length * length - height * height)
    return 2.0 * parameter * math.asinh(chord_m / (2.0 * parameter))


def place_heavy_by_angle(
    force: FloatArray,
    height: float,
    length: float,
    weight: float,
    elevation: float,
    azimuth: float,
    winch_tension: float = math.nan,
) -> FloatArray | None:
    """``(p_n, p_e, p_d, T_ch)`` of a drone ``height`` [m] above the anchor on a cable of
    ``weight`` per length [N/m] leaving the anchor at ``elevation`` and ``azimuth`` [rad]:
    the bearing is the azimuth (the cable hangs in the vertical plane through anchor and
    drone). With the winch ``length`` [m] and a rising cable (``sin(el)`` at least
    :data:`MIN_RISE`) the ground station places it alone (:func:`heavy_by_elevation`: a
    weak pull's force, turned and shortened by the wind's drag, is not needed); else (a
    cable leaving the anchor flat may rest on the ground over any stretch) the span is the
    horizontal tension's on the filter's curve (:func:`place`): the force's pull along the
    bearing (:func:`along_bearing`), or where that force points away from the anchor the
    winch's tension ``winch_tension`` [N] times ``cos(el)`` when it is known (a catenary's
    horizontal tension is the same all along it, and a cable resting on the ground carries
    the winch's tension to its touchdown: the heavy 1 N circle's start waited 8 s there).
    Not in place of the force's pull: the free curve's span also takes the force's down
    part, and with the winch's horizontal tension beside it the light 1 N figure-8's start
    (tuning seed 2) came 2.8 s later and 0.13 m worse. None when neither places it."""
    if math.isfinite(length) and height > 0.0 and math.sin(elevation) >= MIN_RISE:
        placed = heavy_by_elevation(height, length, weight, elevation)
        if placed is not None:
            span, tension = placed
            return np.array((span * math.cos(azimuth), span * math.sin(azimuth), -height, tension))
    turned = along_bearing(force, azimuth)
    if turned is None and math.isfinite(winch_tension):
        horizontal = winch_tension * math.cos(elevation)
        bearing = (math.cos(azimuth), math.sin(azimuth))
        turned = np.array((-horizontal * bearing[0], -horizontal * bearing[1], float(force[2])))
    return None if turned is None else place(turned, height, length, weight)


def heavy_by_elevation(
    height: float, length: float, weight: float, elevation: float
) -> tuple[float, float] | None:
    """The span [m] and chord tension [N] of the free catenary (weight ``weight`` [N/m]) of
    arc length ``length`` [m] that leaves the anchor at ``elevation`` [rad] and reaches
    ``height`` [m] above it. With ``c = H/w`` and the anchor's slope ``S = tan(el)``,
    ``C = sqrt(1 + S^2)``, the drone's end has ``sinh = S + L/c`` and ``cosh = C + b/c``;
    ``cosh^2 - sinh^2 = 1`` gives ``c = (L^2 - b^2) / (2 (C b - S L))``, the span
    ``a = c (asinh(S + L/c) - asinh(S))`` and ``T_ch = w c |p| / a``. None where no such
    curve exists (``L <= b`` or ``C b <= S L``: a cable that long cannot rise that steeply)."""
    slope = math.tan(elevation)
    denominator = 2.0 * (math.hypot(1.0, slope) * height - slope * length)
    if not (length > height and denominator > 0.0):
        return None
    parameter = (length * length - height * height) / denominator
    span = parameter * (math.asinh(slope + length / parameter) - math.asinh(slope))
    if not span > 0.0:
        return None
    return span, weight * parameter * math.hypot(span, height) / span


def along_bearing(force: FloatArray, azimuth: float) -> FloatArray | None:
    """The cable force on the drone ``force`` (NED [N]) with its horizontal part replaced by
    its component toward the anchor on the bearing ``azimuth`` [rad] (from north): a cable
    hangs in the vertical plane through anchor and drone, so what the force has across that
    plane is the wind's drag or noise. None when the force does not pull toward the anchor
    along it."""
    bearing = np.array((math.cos(azimuth), math.sin(azimuth)))
    pull = -float(force[:2] @ bearing)
    if not pull > 0.0:
        return None
    return np.array((*(-pull * bearing), float(force[2])))


def place_by_angle(
    force: FloatArray,
    height: float,
    length: float,
    elevation: float,
    azimuth: float,
) -> FloatArray | None:
    """``(p_n, p_e, p_d, T_ch)`` of a weightless cable leaving the anchor at
    ``elevation`` and ``azimuth`` [rad]: the winch ``length`` [m] along that direction
    (``nan``: the span ``height / tan(elevation)``, the height [m] above the anchor;
    :func:`.start_angle.angle_position`), and the tension the cable force on the drone
    ``force`` (NED [N]) along the cable.
    None when the cable does not rise (:data:`MIN_RISE`) or the force does not pull
    toward the anchor."""
    position = angle_position(elevation, azimuth, height, length)
    if position is None:
        return None
    tension = -float(force @ position) / float(np.linalg.norm(position))
    if not tension > 0.0:
        return None
    return np.array((*position, tension))
