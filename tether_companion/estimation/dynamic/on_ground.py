"""When the dynamic filter counts the drone as on the ground: three independent signs (the
motors' thrust far below the weight, the flight controller's land detector, the filter's own
height below ``touchdown_height_m``), any of which withholds the position (status
``on_ground``, the reason naming the sign) and keeps the force balance from being fused (the
ground's contact force is no part of the model). Pure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

THRUST_BELOW_WEIGHT = "thrust far below the weight: on the ground"
"""The on-ground reason when the motors' thrust is far below the weight."""
AUTOPILOT_LANDED = "the autopilot says landed (EXTENDED_SYS_STATE ON_GROUND)"
"""The on-ground reason when the flight controller's land detector says it is on the ground."""


AUTOPILOT_LANDED_TIMEOUT_S = 3.0
"""The flight controller's landed state counts for this long after its report [s]
(flight-controller time): ArduPilot streams EXTENDED_SYS_STATE in its EXTENDED_STATUS group
(1-4 Hz), PX4 at 1 Hz or more; the service asks for 5 Hz (service/streams.py)."""


@dataclass(frozen=True, slots=True)
class AutopilotLanded:
    """The flight controller's latest landed state: ``landed`` (EXTENDED_SYS_STATE ON_GROUND)
    reported at ``time_s`` [s] (flight-controller time; -inf: never)."""

    landed: bool = False
    time_s: float = -math.inf

    def on_ground(self, now_s: float) -> bool:
        """Whether it says landed and is at most :data:`AUTOPILOT_LANDED_TIMEOUT_S` old at
        ``now_s`` [s]."""
        return self.landed and now_s - self.time_s <= AUTOPILOT_LANDED_TIMEOUT_S


def on_ground_reason(
    thrust_below_weight: bool,
    down_m: float,
    ground_down_m: float,
    touchdown_height_m: float,
    autopilot_landed: bool = False,
) -> str:
    """Why the drone counts as on the ground at one tick (empty when it does not).

    Three independent signs, any one of which is enough (the first that holds names the
    reason): the thrust, the autopilot's land detector, the filter's own height.

    Parameters
    ----------
    thrust_below_weight
        The thrust is below ``min_thrust_fraction`` of the weight (motors idling: resting).
    down_m
        The filter's down position of the centre of mass, NED from the anchor [m].
    ground_down_m
        The ground's down position [m]: the anchor's height above the ground, the ground
        taken as flat.
    touchdown_height_m
        Height above the ground [m] below which the drone is touching down (or just lifted
        off). Then the ground's contact force, which is not in the model, may act (at the
        first touch the simulated drone stops within one physics step, and no force balance
        says so), and the rangefinder, below its minimum range, no longer measures the
        height: on the take-off's landing the down error grew to 0.3-0.6 m within 0.3 s of
        the touch at a claimed 0.11-0.14 m (docs/estimation-history.md, "The touchdown (split10)").
        A NaN height never counts.
    autopilot_landed
        The flight controller's latest landed state (EXTENDED_SYS_STATE, fresh) is ON_GROUND:
        its land detector, which sees what this filter does not (the motors' output against
        the hover throttle, the climb rate of its own EKF, for about a second). TAKEOFF and
        LANDING are not on-ground signs: both autopilots send them for the whole climb or
        descent of a take-off or landing mode, in the air (ArduCopter's ``landed_state()``,
        PX4's EXTENDED_SYS_STATE stream: ON_GROUND only while landed).
    """
    if thrust_below_weight:
        return THRUST_BELOW_WEIGHT
    if autopilot_landed:
        return AUTOPILOT_LANDED
    height_m = ground_down_m - down_m
    if height_m < touchdown_height_m:
        return (
            f"touching down: {height_m:.2f} m above the ground < {touchdown_height_m:g} m"
            " (ground contact not modelled, rangefinder at its minimum range)"
        )
    return ""
