"""Optional winch paid-out length: the cable's arc length as the encoder reads it, with its
zero offset and scale error (states ``winch_offset``, ``winch_scale``; generated
``winch_length_*``: the catenary's, ``|p|`` for a weightless cable). While the filter's
tension is below ``slack_tension_n`` (once a load cell's tension has been fused on a cable
with weight: surely below it, ``WinchAid.maybe_slack``), or a cable with weight is surely
longer than its span plus height (:func:`surely_slack_by_length`: slack whatever the
tension), the cable may be slack and its length says only that the drone is no farther from
the anchor than that: the reading is skipped, unless the filter has the drone beyond it,
when the bound ``offset + (1 + scale) |p| <= length`` (the one statement that holds for any
cable; the catenary's arc, longer than the chord at a deep sag, is not: fused there it
published wrong positions on the sagging circle) is fused as the inequality it is, each
member's prior truncated to it (:func:`~tether_companion.estimation.dynamic.aiding.fuse_bound`).
Fused as the equality ``|p| = length`` it put the drone ON the line with the encoder's
noise wherever the slack cable's drone was: the fixed-length sagging circle, winch + angle,
tuning seed 6, 3.6 s: the radial deviation 1.17 -> 0.165 m with the drone 1.5 m inside
(docs/estimation-history.md, cal20). Fused as the catenary's length
after a load cell's tension on a cable with weight, the reading's variance also holds the
length's second-order term in the tension (:func:`tension_curvature_variance`). The reading
was taken ``latency_s`` before its time stamp (and the stamp may be older than the filter):
it is fused as the length at the drone's position then
(:func:`~tether_companion.estimation.dynamic.aiding.at_reading_time`)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.aid.slack import (
    SLACK,
    SURE_SIGMAS,
    tension_std_n,
    tension_upper_n,
)
from tether_companion.estimation.dynamic.aiding import (
    AidStatus,
    at_reading_time,
    fuse,
    fuse_bound,
)
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.models import ModelConstants, evaluate
from tether_companion.estimation.ekf import MeasurementFunction

FloatArray = NDArray[np.float64]

NAME = "winch"


class WinchAid:
    """Fuses a paid-out length [m] with noise ``noise_std_m`` [m] while the chord tension is
    above ``slack_tension_n`` [N] and a cable with weight is not surely slack by its length,
    otherwise as an upper bound on the distance, when the filter's drone exceeds it; each
    reading taken ``latency_s`` [s] before its time stamp."""

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
        age_s: float,
        maybe_slack: bool,
    ) -> bool:
        """Fuse one reading [m] at filter time ``time_s`` [s], stamped ``age_s`` [s] before
        it (so taken ``latency_s + age_s`` before); ``maybe_slack``: :meth:`maybe_slack`'s
        answer for it (the caller asks first: the calibration's hold follows it)."""
        best = bank.best
        z = np.array((length_m,))
        latency_s = self._latency_s + age_s
        if maybe_slack:
            chord = at_reading_time(_chord, latency_s)
            if not float(chord(best.x)[0][0]) > length_m:
                self.status.skip(SLACK)
                return False
            return fuse_bound(bank, NAME, self.status, length_m, chord, self._r[0, 0], time_s)
        c = constants.values()
        model = constants.models.winch_length

        def measure(xs: FloatArray) -> tuple[FloatArray, FloatArray]:
            return evaluate(model, xs, (), c, 1)

        delayed = at_reading_time(measure, latency_s)
        r = self._r
        if constants.weight_n_per_m > 0.0 and constants.tension_measured:
            r = r + tension_curvature_variance(delayed, best.x, best.P)
        return fuse(bank, NAME, self.status, z, delayed, r, time_s)

    def maybe_slack(self, bank: FilterBank, constants: ModelConstants, length_m: float) -> bool:
        """Whether the reading ``length_m`` [m] may be of a slack cable at ``bank``'s best
        member (state ``x``, covariance ``p``); then it is skipped, or fused as a bound on the
        distance (the straight chord), not through the length's model: a cable with weight
        surely slack by its length (:func:`surely_slack_by_length`), or its chord tension
        below ``slack_tension_n``; once a load cell's tension has been fused on a cable with weight
        (``constants.tension_measured``), surely below it (by :data:`~.slack.SURE_SIGMAS`
        standard deviations). Such a cable can pull below that tension (the sagging hover's
        7 m cable 5 m out and 3 m up: 0.12 N, taut), and there its length is the one reading
        of the range: with the load cell's readings below zero taken, the length came only
        when the load cell's noise lifted the tension over 0.2 N, and each moved the drone
        metres (tuning seed 1: its estimate swung through the anchor, 76 ticks published
        beyond 3 sigma). Without a load cell the tension is not measured and the rule stays
        the estimate's (sag14's candidate took the winch + angle filter's sagging circle seed
        1 from NEES 0.13 to 165)."""
        x, p = bank.best.x, bank.best.P
        weight_n_per_m = constants.weight_n_per_m
        if weight_n_per_m > 0.0 and constants.tension_measured:
            tension = tension_upper_n(x, p)
        else:
            tension = float(x[state.TENSION])
        return tension < self._slack_n or surely_slack_by_length(
            x, p, weight_n_per_m, length_m, float(self._r[0, 0])
        )


def surely_slack_by_length(
    x: FloatArray, p: FloatArray, weight_n_per_m: float, length_m: float, noise_m2: float
) -> bool:
    """Whether a cable of weight ``weight_n_per_m`` [N/m] > 0 with the paid-out ``length_m``
    [m] read (noise variance ``noise_m2`` [m^2]) is surely slack at the state ``x`` with
    covariance ``p``: the reading beyond the drone's span plus height ``a + b`` (as the encoder
    would read that length: offset and scale) by more than :data:`~.slack.SURE_SIGMAS`
    standard deviations. False for a weightless cable or a drone right above the anchor.

    A cable with weight from a winch on the anchor's level pulls (``H > 0``) only where it is
    shorter than ``a + b``: as ``H -> 0`` it lies on the ground to below the drone and hangs
    straight up from there (length ``a + b``); a longer one lies there with its excess, slack,
    at any span. The resting cable's model length ``x_t + sqrt(b^2 + 2 b c)`` (``c = H / w``)
    is below ``a + b`` at every tension and reaches it only through the model's linear
    continuation to a pushing cable (``T_ch < 0``, models.py), with a slope in the tension
    that grows without bound near zero (-14 m/N at 0.1 N on the light 7.5 m cable). Fused
    there (a chord tension the load cell's noise had lifted over ``slack_tension_n``) one
    length moved the drone of a truly slack cable 1.4 m out to ``a + b = L`` and its chord
    tension to -0.4 N with a 0.11 N standard deviation (the fixed-length sagging circle,
    tuning seed 1, 21.9 s; docs/estimation-history.md, sag14)."""
    span = math.hypot(float(x[0]), float(x[1]))
    if weight_n_per_m <= 0.0 or span <= 0.0:
        return False
    gain = 1.0 + float(x[state.WINCH_SCALE])
    hanging = span - float(x[2])
    jac = np.zeros(state.N_STATES)
    jac[0] = gain * float(x[0]) / span
    jac[1] = gain * float(x[1]) / span
    jac[2] = -gain
    jac[state.WINCH_OFFSET] = 1.0
    jac[state.WINCH_SCALE] = hanging
    variance = float(jac @ p @ jac) + noise_m2
    excess = length_m - float(x[state.WINCH_OFFSET]) - gain * hanging
    return excess > SURE_SIGMAS * math.sqrt(max(variance, 0.0))


def tension_curvature_variance(measure: MeasurementFunction, x: FloatArray, p: FloatArray) -> float:
    """The variance [m^2] a length ``measure(x)`` linearised at ``x`` leaves out over the
    chord tension's spread (covariance ``p``): the second-order term of a Gaussian filter in
    the tension alone, ``0.5 (h'' sd^2)^2`` with ``h'' sd^2 = h(T + sd) - 2 h(T) + h(T - sd)``
    (central differences over the spread itself, so a kink within it counts; 0 where the
    model is undefined).

    A cable with weight's length falls from ``a + b`` as ``c ln(2 b / c)`` near zero tension
    (``c = H / w``): its slope in the tension grows without bound there and changes by more
    than itself within a spread of 0.1-0.2 N. Linearised at the estimate, a length fused at
    0.2 +- 0.13 N took the tension to 0.64 +- 0.03 N in one update (the sagging hover, tuning
    seed 1); fused near zero tension it pinned the tension at 0 +- 0.015 N while the true one
    rose to 0.3 N (the fixed-length circle, seed 1). At 1 +- 0.1 N on the light cable 5 m out
    it is 2 % of the encoder's noise variance (tests/test_dynamic_resting_slack.py). Added
    only once a load cell's tension has been fused (:class:`WinchAid`)."""
    sd = tension_std_n(p)
    values = []
    for step in (-sd, 0.0, sd):
        xs = x.copy()
        xs[state.TENSION] += step
        values.append(float(measure(xs)[0][0]))
    second = values[0] - 2.0 * values[1] + values[2]
    return 0.5 * second * second if math.isfinite(second) else 0.0


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
