"""Where the simulated cable leaves the anchor: the truth a ground-station cable-angle sensor
measures (the emulator's and the bench's).

For the straight models (:class:`~tether_companion.physics.cable.ConstantTensionCable`,
:class:`~tether_companion.physics.cable.ElasticCable`) the direction from the anchor to the
drone. For :class:`~tether_companion.physics.cable.CatenaryCable` the catenary's tangent at
the anchor, in the cases of that model: the free curve of the stretched length
(``paid_out_m + stretch_m``, the stretch of the cable's last force evaluation) through both
ends (Martins 2019 case 2: the cable pulls the anchor up by ``w s1``, horizontally by ``w a``,
:func:`~tether_companion.physics.catenary_forces.end_tensions`), flat toward the drone where
the cable rests on the ground (a touchdown point beyond the anchor, or a drone at or below
the anchor's level with the line not stretched). For
:class:`~tether_companion.physics.cable_winch.WinchCatenaryCable` its free catenary's angle at
the anchor (:func:`~tether_companion.physics.cable_winch.winch_catenary`), flat where it rests
on the ground, along the chord with the drone at or below the anchor's level. Reads the
cable's state, never changes it (the flight stays the same with or without the sensor).

NED, anchor at the origin; unit vectors; pure.
"""

from __future__ import annotations

import math

from tether_companion.physics.cable import CableModel, CatenaryCable
from tether_companion.physics.cable_base import MIN_DISTANCE_M
from tether_companion.physics.cable_winch import WinchCatenaryCable, winch_catenary
from tether_companion.physics.catenary import solve_known_length, solve_lowest_point_at_anchor
from tether_companion.physics.catenary_forces import end_tensions


def anchor_direction_ned(
    cable: CableModel, position_ned_m: tuple[float, float, float]
) -> tuple[float, float, float] | None:
    """The unit vector along which ``cable`` leaves the anchor toward the drone at
    ``position_ned_m`` [m] (NED), or None (released, no cable, the drone at the anchor)."""
    pn, pe, pd = (float(v) for v in position_ned_m)
    horizontal = math.hypot(pn, pe)
    chord = math.hypot(horizontal, pd)
    if cable.released or chord < MIN_DISTANCE_M:
        return None
    if isinstance(cable, WinchCatenaryCable):
        shape = winch_catenary(horizontal, -pd, cable.set_point_n, cable.weight_per_length_n_per_m)
        along, up = math.cos(shape.anchor_elevation_rad), math.sin(shape.anchor_elevation_rad)
        if horizontal <= 0.0:
            return 0.0, 0.0, -up
        return along * pn / horizontal, along * pe / horizontal, -up
    if not isinstance(cable, CatenaryCable):
        return pn / chord, pe / chord, pd / chord
    height = -pd
    if horizontal <= 0.0:  # straight above (or below) the anchor
        return 0.0, 0.0, math.copysign(1.0, pd)
    flat = (pn / horizontal, pe / horizontal, 0.0)
    length = cable.paid_out_m
    if height <= 0.0:  # on the ground, or below the anchor: flat unless stretched straight
        return (pn / chord, pe / chord, pd / chord) if chord > length else flat
    if length >= horizontal + height:  # lies flat to below the drone and hangs straight up
        return flat
    if length >= solve_lowest_point_at_anchor(horizontal, height).length_m:
        return flat  # touches down beyond the anchor
    curve = solve_known_length(horizontal, height, length + cable.stretch_m)
    ends = end_tensions(curve, cable.weight_per_length_n_per_m)
    up = ends.on_anchor_vertical_n
    norm = math.hypot(ends.horizontal_n, up)
    along = ends.horizontal_n / norm
    return flat[0] * along, flat[1] * along, -up / norm
