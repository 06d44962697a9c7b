"""What every cable model of :mod:`tether_companion.physics.cable` shares: the protocol the
simulator calls (:class:`CableModel`) and the winch state and array wrapper of
:class:`CableBase` (NED, anchor at the origin, SI units)."""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

MIN_DISTANCE_M = 1e-9
"""Below this anchor-to-drone distance the cable direction is undefined: zero force."""


class CableModel(Protocol):
    """What the simulator needs from a cable model (:mod:`tether_companion.physics.cable`'s
    docstring)."""

    tension_n: float
    paid_out_m: float
    released: bool
    history_free: bool
    """Whether ``force_components`` gives the same floats for the same arguments whatever it
    was asked before (the simulator then reuses an evaluation at the same state)."""

    def force_components(
        self, pn: float, pe: float, pd: float, vn: float, ve: float, vd: float
    ) -> tuple[float, float, float]:
        """Force on the drone (north, east, down) [N]; sets ``tension_n``."""

    def force_on_drone_ned_n(
        self, position_ned_m: ArrayLike, velocity_ned_m_s: ArrayLike
    ) -> FloatArray:
        """Force on the drone, shape (3,), NED [N]; sets ``tension_n``."""

    def advance(self, dt_s: float) -> None:
        """Advance the winch by ``dt_s`` seconds."""

    def set_tension_n(self, tension_n: float) -> None:
        """Set the winch's tension set-point [N]."""

    def set_winch_rate_mps(self, rate_mps: float) -> None:
        """Set the winch rate [m/s], positive paying out."""

    def release(self) -> None:
        """Let the cable go: zero force from now on."""


class CableBase:
    """Shared state and the array wrapper around ``force_components``."""

    history_free = True

    def __init__(
        self, paid_out_m: float, winch_rate_mps: float, min_length_m: float, spool_length_m: float
    ) -> None:
        self.tension_n = 0.0
        self.paid_out_m = float(paid_out_m)
        self.released = False
        self.winch_rate_mps = float(winch_rate_mps)
        self.min_length_m = float(min_length_m)
        self.spool_length_m = float(spool_length_m)

    def force_components(
        self, pn: float, pe: float, pd: float, vn: float, ve: float, vd: float
    ) -> tuple[float, float, float]:
        raise NotImplementedError

    def force_on_drone_ned_n(
        self, position_ned_m: ArrayLike, velocity_ned_m_s: ArrayLike
    ) -> FloatArray:
        """Force on the drone (3,), NED [N], for its position (3,) [m] and velocity (3,) [m/s].

        Sets ``tension_n`` to the tension at the drone end [N].
        """
        pn, pe, pd = (float(x) for x in np.asarray(position_ned_m, dtype=float).reshape(3))
        vn, ve, vd = (float(x) for x in np.asarray(velocity_ned_m_s, dtype=float).reshape(3))
        return np.array(self.force_components(pn, pe, pd, vn, ve, vd))

    def advance(self, dt_s: float) -> None:
        """Reel the winch at its rate for ``dt_s`` [s], within [min_length_m, spool_length_m]."""
        if self.winch_rate_mps != 0.0 and not self.released:
            length = self.paid_out_m + self.winch_rate_mps * dt_s
            self.paid_out_m = min(max(length, self.min_length_m), self.spool_length_m)

    def set_winch_rate_mps(self, rate_mps: float) -> None:
        """Set the winch rate [m/s]: positive pays cable out, negative reels it in."""
        if not math.isfinite(rate_mps):
            raise ValueError(f"winch rate must be finite, got {rate_mps!r}")
        self.winch_rate_mps = float(rate_mps)

    def set_tension_n(self, tension_n: float) -> None:
        raise ValueError(
            f"{type(self).__name__} has no tension set-point (tension follows from length); "
            "use set_winch_rate_mps"
        )

    def release(self) -> None:
        """Let the cable go: the force is zero from now on."""
        self.released = True
        self.tension_n = 0.0
