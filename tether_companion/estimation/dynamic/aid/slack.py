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
keeps the point rule, aid/winch.py: measured, a length fused at an unsure low tension
published wrong positions on the sagging circle.)
"""

from __future__ import annotations

import math

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.member import MemberFilter

SLACK = "slack"
"""The skip reason the aids count."""

SURE_SIGMAS = 3.0
"""How many standard deviations below ``slack_tension_n`` the chord tension must be."""


def surely_slack(member: MemberFilter, slack_tension_n: float) -> bool:
    """Whether ``member``'s chord tension ``T`` [N] (standard deviation ``sd``) is surely in
    the slack range ``[0, slack_tension_n)`` [N]: ``T + k sd`` below the threshold but not
    below zero (``k`` = :data:`SURE_SIGMAS`)."""
    tension = float(member.x[state.TENSION])
    variance = float(member.P[state.TENSION, state.TENSION])
    upper = tension + SURE_SIGMAS * math.sqrt(max(variance, 0.0))
    return 0.0 <= upper < slack_tension_n
