"""When the cable angle holds back as slack: only when the filter is sure the cable is slack,
not when its tension estimate merely dips below the threshold.

The angle is what corrects a wrong tension and bearing: a filter whose own estimate says
"slack" and that therefore stops listening to it cannot find out it was wrong. On ArduPilot
SITL (winch and angle, the circle after a taut hold) the tension estimate fell below
``slack_tension_n`` once, the winch and the angle were skipped from then on, and the state
drifted for 80 s (up to 15 m, withheld) until the divergence reset. So an angle is skipped as
slack only when the chord tension is below the threshold by more than ``SURE_SIGMAS`` of its
own standard deviation, and not when it is that sure of a tension below zero: a cable pulls
or hangs, it does not push, so a filter sure of a pushing cable has something else wrong (on
the realistic low-tension circle: its drone on the wrong side of the anchor after a bad
start, the pull read as a push) and must hear the angle; the gate judges it. (The winch length
keeps the point rule, aid/winch.py, unless a load cell's tension has been fused on a cable
with weight: measured, a length fused at an unsure low tension published wrong positions on
the sagging circle; with the load cell it skips below :func:`tension_upper_n`'s bound.)
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.member import MemberFilter

FloatArray = NDArray[np.float64]

SLACK = "slack"
"""The skip reason the aids count."""

SURE_SIGMAS = 3.0
"""How many standard deviations below ``slack_tension_n`` the chord tension must be."""


def tension_std_n(p: FloatArray) -> float:
    """The chord tension's standard deviation [N] in the covariance ``p``."""
    return math.sqrt(max(float(p[state.TENSION, state.TENSION]), 0.0))


def tension_upper_n(x: FloatArray, p: FloatArray) -> float:
    """The chord tension ``T + k sd`` [N] of the state ``x`` (covariance ``p``) the cable is
    surely below (``k`` = :data:`SURE_SIGMAS`)."""
    return float(x[state.TENSION]) + SURE_SIGMAS * tension_std_n(p)


def surely_slack(member: MemberFilter, slack_tension_n: float) -> bool:
    """Whether ``member``'s chord tension ``T`` [N] (standard deviation ``sd``) is surely in
    the slack range ``[0, slack_tension_n)`` [N]: ``T + k sd`` below the threshold but not
    below zero (``k`` = :data:`SURE_SIGMAS`)."""
    upper = tension_upper_n(member.x, member.P)
    return 0.0 <= upper < slack_tension_n
