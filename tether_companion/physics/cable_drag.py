"""The wind's drag on the tether, as the force it puts on the drone (pure, SI units).

The cable is taken along its chord from the anchor (origin) to the drone at ``p`` and at
rest, so the air moves past it at the wind velocity ``w``. Per unit length it feels the
cross-flow drag of a cylinder, ``q = 0.5 rho C_d d |w_perp| w_perp``, with ``w_perp`` the wind's
component across the chord (the along-cable component's skin friction is neglected). A
uniformly loaded line carries half the total load ``q L`` to each end, so the drone feels
``0.5 q |p|``. A tether of 4 mm in a 5 m/s cross wind over 6 m puts about 0.05 N on the drone:
small beside a few newtons of winch tension, and along the wind, where rotor drag acts too.
"""

from __future__ import annotations

import math

from tether_companion.physics.aerodynamics import AIR_DENSITY_KG_M3

CYLINDER_DRAG_COEFFICIENT = 1.2
"""Cross-flow drag coefficient of a smooth cylinder at the Reynolds numbers of a tether."""


def cable_drag_force_ned_n(
    position_ned_m: tuple[float, float, float],
    wind_ned_m_s: tuple[float, float, float],
    diameter_m: float,
    drag_coefficient: float = CYLINDER_DRAG_COEFFICIENT,
    air_density_kg_m3: float = AIR_DENSITY_KG_M3,
) -> tuple[float, float, float]:
    """Force of the wind's drag on the cable at the drone end, NED [N] (see module docstring).

    Parameters
    ----------
    position_ned_m
        Drone position from the anchor, NED [m].
    wind_ned_m_s
        Wind velocity, NED [m/s].
    diameter_m
        Cable diameter [m] (0: no drag).
    drag_coefficient, air_density_kg_m3
        Cross-flow drag coefficient [-] and air density [kg/m^3].
    """
    pn, pe, pd = position_ned_m
    length = math.sqrt(pn * pn + pe * pe + pd * pd)
    if diameter_m <= 0.0 or length <= 0.0:
        return (0.0, 0.0, 0.0)
    wn, we, wd = wind_ned_m_s
    along = (wn * pn + we * pe + wd * pd) / length
    xn, xe, xd = wn - along * pn / length, we - along * pe / length, wd - along * pd / length
    cross = math.sqrt(xn * xn + xe * xe + xd * xd)
    k = 0.25 * air_density_kg_m3 * drag_coefficient * diameter_m * cross * length
    return (k * xn, k * xe, k * xd)
