"""Optional winch paid-out length: the cable's arc length as the encoder reads it, with its
zero offset and scale error (states ``winch_offset``, ``winch_scale``; generated
``winch_length_*``: the catenary's, ``|p|`` for a weightless cable). While the filter's
tension is below ``slack_tension_n`` the cable may be slack and its length says only that the
drone is no farther from the anchor than that: the reading is skipped, unless the filter has
the drone beyond it, when the distance ``|p|`` itself (as read) is fused to the length (the
one statement that holds for any cable; the catenary's arc, longer than the chord at a deep
sag, is not: fused there it published wrong positions on the sagging circle). The reading was
taken ``latency_s`` before its time stamp (and the stamp may be older than the filter): it is
fused as the length at the drone's position then
(:func:`~tether_companion.estimation.dynamic.aiding.at_reading_time`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.aid.slack import SLACK
from tether_companion.estimation.dynamic.aiding import AidStatus, at_reading_time, fuse
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.models import ModelConstants, evaluate

FloatArray = NDArray[np.float64]

NAME = "winch"


class WinchAid:
    """Fuses a paid-out length [m] with noise ``noise_std_m`` [m] while the chord tension is
    above ``slack_tension_n`` [N], and below it as a bound on the distance the filter's drone
    exceeds; each reading taken ``latency_s`` [s] before its time stamp."""

    def __init__(self, noise_std_m: float, slack_tension_n: float, latency_s: float = 0.0) -> None:
        self.status = AidStatus()
        self._r = np.array([[noise_std_m**2]])
        self._slack_n = slack_tension_n
        self._latency_s = latency_s

    def fuse(
        self,
        bank: FilterBank,
        constants: ModelConstants,
        length_m: float,
        time_s: float,
        age_s: float = 0.0,
    ) -> bool:
        """Fuse one reading [m] at filter time ``time_s`` [s], stamped ``age_s`` [s] before
        it (so taken ``latency_s + age_s`` before)."""
        best = bank.best
        z = np.array((length_m,))
        latency_s = self._latency_s + age_s
        if best.x[state.TENSION] < self._slack_n:
            chord = at_reading_time(_chord, latency_s)
            if not float(chord(best.x)[0][0]) > length_m:
                self.status.skip(SLACK)
                return False
            return fuse(bank, NAME, self.status, z, chord, self._r, time_s)
        c = constants.values()
        model = constants.models.winch_length

        def measure(xs: FloatArray) -> tuple[FloatArray, FloatArray]:
            return evaluate(model, xs, (), c, 1)

        delayed = at_reading_time(measure, latency_s)
        return fuse(bank, NAME, self.status, z, delayed, self._r, time_s)


def _chord(xs: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The anchor-to-drone distance as the encoder reads it, ``offset + (1 + scale) |p|``
    [m], and its Jacobian (1, n)."""
    p = xs[state.POSITION]
    distance = float(np.linalg.norm(p))
    gain = 1.0 + float(xs[state.WINCH_SCALE])
    jac = np.zeros((1, state.N_STATES))
    jac[0, state.POSITION] = gain * p / distance
    jac[0, state.WINCH_OFFSET] = 1.0
    jac[0, state.WINCH_SCALE] = distance
    return np.array((float(xs[state.WINCH_OFFSET]) + gain * distance,)), jac
