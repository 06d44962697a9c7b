"""Status settings of the published estimate with no pull-against-drag rule (shared by tests
of the published covariance's terms)."""

from __future__ import annotations

from tether_companion.estimation.dynamic.published import StatusSettings

NO_DRAG_RULE = StatusSettings(
    slack_tension_n=0.2,
    max_horizontal_std_m=0.5,
    winch_length_noise_std_m=0.05,
    pull_per_wind_n_s_per_m=0.0,
    wind_std_mps=1.0,
)
"""Slack below 0.2 N, withheld beyond 0.5 m, the winch's 0.05 m, no drag rule."""
