"""A dynamic filter's state vector for unit tests of its models."""

from __future__ import annotations

from tether_companion.estimation.dynamic import state


def state_at(position: tuple[float, float, float], tension_n: float) -> list[float]:
    """State (list of ``state.N_STATES``) at ``position`` (NED from the anchor) [m] with chord
    tension ``tension_n`` [N], thrust scale 1 and everything else zero."""
    x = [0.0] * state.N_STATES
    x[0:3] = position
    x[state.TENSION] = tension_n
    x[state.SCALE] = 1.0
    return x
