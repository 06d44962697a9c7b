"""One rotor of a multicopter: where it sits and which way it spins."""

from __future__ import annotations

from dataclasses import dataclass

from tether_companion.config import spec


@dataclass(frozen=True)
class Motor:
    """One rotor: where it sits and which way it spins.

    ``angle_deg`` is measured in the body x-y plane from the nose (body x), positive toward
    the right wing (body y), as ArduPilot's ``add_motor`` angles are. ``spin`` is seen from
    above: a ``ccw`` propeller pushes the airframe clockwise (positive yaw in FRD).
    ``radius_scale`` is the rotor's distance from the centre relative to the profile's
    ``arm_length_m`` (1 on frames with equal arms).
    """

    angle_deg: float = spec(doc="arm direction from the nose, positive to the right [deg]")
    spin: str = spec(choices=("ccw", "cw"), doc="propeller rotation seen from above")
    radius_scale: float = spec(
        1.0, exclusive_minimum=0.0, maximum=1.0, doc="distance from the centre / arm_length_m"
    )
