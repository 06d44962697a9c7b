"""State layout of the dynamic tether filter, declared once (the derivation and the filter
both read it).

==========  =====  ==========================================================  ========
name        index  meaning                                                     unit
==========  =====  ==========================================================  ========
position    0-2    drone relative to the tether anchor, NED                    m
velocity    3-5    drone velocity, NED                                         m/s
tension     6      chord tension: cable force on the drone along the chord     N
                   (anchor to drone), the catenary's weight term aside
scale       7      thrust scale: true thrust / thrust map's (battery sag,      1
                   map error)
bias        8-10   accelerometer bias, FRD body                                m/s^2
wind        11-12  wind north, east                                            m/s
winch_cal   13-14  winch encoder's zero offset [m] and scale error [1]: it      m, 1
                   reads ``offset + (1 + scale) L``
angle_cal   15-16  cable-angle sensor's zero errors: elevation, azimuth; it     rad
                   reads the true angle plus them
==========  =====  ==========================================================  ========

The four ground-station calibration states are constants of a flight (no process noise).
Their prior enters with the start where a reading placed the drone (``initialise.py``,
correlated with the position), else with their sensor's first reading (``ground_station.py``):
until then their variance is at most :data:`UNSET_CALIBRATION_VARIANCE` and no model depends
on them, so a filter without a ground station is unchanged by them. They are consider
(Schmidt) states until the filter has settled (``calibration_release.py``): updates leave
their means and their own covariance block as they were; the azimuth zero stays one for the
whole flight (:data:`NEVER_RELEASED`).
"""

from __future__ import annotations

NAMES: tuple[str, ...] = (
    "p_n",
    "p_e",
    "p_d",
    "v_n",
    "v_e",
    "v_d",
    "tension",
    "scale",
    "b_x",
    "b_y",
    "b_z",
    "wind_n",
    "wind_e",
    "winch_offset",
    "winch_scale",
    "elevation_zero",
    "azimuth_zero",
)
"""State component names in order (also the sympy symbols' names)."""
N_STATES = len(NAMES)

POSITION = slice(0, 3)
VELOCITY = slice(3, 6)
POSITION_VELOCITY = slice(0, 6)
TENSION = 6
SCALE = 7
BIAS = slice(8, 11)
WIND = slice(11, 13)
WINCH_OFFSET = 13
WINCH_SCALE = 14
ELEVATION_ZERO = 15
AZIMUTH_ZERO = 16
CALIBRATION = slice(13, 17)
NEVER_RELEASED = slice(16, 17)
"""The calibration states that stay consider states when the others are released: the
azimuth zero (``calibration_release.py``: the companion has no other absolute bearing, so
learning it takes the autopilot's heading error and the force balance's unmodelled sideways
force as the sensor's zero)."""

UNSET_CALIBRATION_VARIANCE = 1e-9
"""The floor every state's variance starts with (``initialise.py``; it keeps the covariance
positive definite): a calibration state still at it has not had its prior yet [m^2, 1,
rad^2]."""

ROTATION_INPUTS = 9
"""The first nine inputs of every model: ``R_v^b`` (NED to FRD body) row by row."""
