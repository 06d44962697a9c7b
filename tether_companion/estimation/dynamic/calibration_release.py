"""When the ground station's calibration states start to learn: :class:`CalibrationRelease`.

The calibration states (``state.CALIBRATION``: the winch's offset and scale, the angle
sensor's elevation and azimuth zeros) are constants of the flight. Learnt from the first
reading on, they took a bad start's error as the sensor's and kept it (docs/
estimation-history.md, calib11: the gusty hover's azimuth zero 0.198 rad at 2 s, sd 0.016,
truth -0.005; 17.9 % of its published ticks beyond 3 sigma). So the bank starts with them as
consider (Schmidt) states (:attr:`~tether_companion.estimation.dynamic.bank.FilterBank.consider`):
every update leaves their means and their own covariance block as they were, the cross block
and everything else as the optimal update has them, so the position's covariance keeps their
spread while the readings correct the position alone. The winch's offset and scale and the
elevation zero are released to learning once the filter has settled:

* one bearing hypothesis is left (the others rejected or merged: a bad start's bearing
  settled) when a winch length has been fused: the thrust-scale hypotheses may still run
  side by side (cal16: waiting for their collapse, 6 s after the filter's start, held the
  simulator's take-off and circles' states to 13 and 10 s, and the position's error with
  them); they differ in the vertical pull the thrust map explains, and with the length the
  range the elevation is compared at is measured. Without a length that range comes from
  the force balance's pull, which the thrust scale splits, so the rule waits for the bank to
  decide (one member left: thrust-scale and bearing hypotheses chosen, merged or collapsed;
  released at one bearing, the angle alone's take-off figure-8 published 0.4 % beyond 3
  sigma against 0.1 %, tuning seeds 1-5), and
* since then, for :data:`SETTLE_S` at least, the ground station's innovations are in band:
  their normalised squared innovations (NIS per degree of freedom, the best member's, gated
  samples included) average at most :data:`MAX_MEAN_NIS` over the last :data:`SETTLE_S`;
* and a cable angle has been fused (``ground_station.py`` gives the samples only then: the
  winch's calibration without an angle is told only through the force balance's cable
  direction, and stays a consider state);
* and the innovations of the readings that teach the released states (the winch's length, the
  angle's elevation) are steady (sitl15): for each, the mean over the last
  :data:`STEADY_WINDOW_S` is either at 0 (the held calibration agrees with the readings:
  nothing to learn) or within the tolerance of the mean over the :data:`STEADY_WINDOW_S`
  before it (a constant to learn). The tolerance is :data:`STEADY_FRACTION` of the state's
  prior standard deviation plus :data:`STEADY_STANDARD_ERRORS` standard errors of the
  reading's noise. The NIS rule cannot see a transient smaller than the calibration's spread
  (that spread is in the innovations' variance), and a state released while the position's
  error still moves takes the transient as a constant and keeps it (no process noise): on
  ArduPilot SITL, released at the end of the fly-out or in a recovering bad start's +0.07 m
  plateau of the winch's innovation, the external-navigation hold's RMS was 0.165 and
  0.107 m; released by this test 0.073 and 0.078 m (docs/estimation-history.md, sitl15).

Held while no length is fused (cal19): once released, the states are held again (consider
states, all four) for a winch reading that may be of a slack cable (skipped, or fused only as
a bound: the drone no farther than the straight chord, an inequality that says nothing of the
encoder while the cable may be slack) and after one not fused (skipped, gated), until a
reading goes through the length's model again. What ties the winch's offset and scale to the
position is that model, ``offset + (1 + scale) L(p, T)``, through the cross-covariance its
fusions left: a first-order relation, valid about the state they were fused at. On a cable
with weight the length's dependence on the tension grows without bound toward slack (the
catenary's excess over the chord, ``w^2 a^3 / (24 H^2)`` for a shallow sag, has
``dL/dH = -w^2 a^3 / (12 H^3)``), and the reading is skipped or bounded exactly where that
relation no longer holds. Learnt through the cross-covariance meanwhile, the states took the
angle's and the force balance's corrections of the position, and the bound's projection, as
the encoder's: the sagging circle, winch + angle, tuning seed 6 (truth -0.18 m) moved the
offset 0 -> +0.37 m in 6 s of slack cable with no length fused (+0.38 m in the cable angle's
updates), then +0.25 m in the chord bound's fusions as the cable came taut; +1.07 m at 30 s,
+0.24 m held. The elevation zero is held with them (the four are one contiguous block in the
members' consider hold): while slack, the anchor's elevation is the sag's, which the filter's
near-zero tension knows poorly. Held, the updates keep the cross-covariance (Schmidt), so a
length fused later still teaches them with what the position learnt meanwhile. Without a
winch (the angle alone) nothing changes.

The azimuth zero is never released (``state.NEVER_RELEASED``): the angle sensor is the
companion's only absolute bearing, and the flight cannot tell its zero from the autopilot's
heading error (the force balance's and the INS's horizontal directions turn with it) nor from
the unmodelled sideways force the wind state takes. On ArduPilot SITL's taut hold (EKF3's heading
0.5-2 degrees off SIM_STATE's, SITL's air calm) the released azimuth zero learnt 0.05 rad
within 3 s of its release at the end of the fly-out, with the filter's wind at 1.1 m/s across
the cable, and turned our position 0.3 m about the anchor for the rest of the hold (the
flight's .tlog replayed, docs/estimation.md, sitlcal13); held, the angle keeps the bearing
(0.03-0.05 m RMS).

A filter that restarts starts a new bank, with the states held again (:meth:`clear`).

With ``dynamic_filter.learn_calibration`` (default on since sitlcal13; off, the states stay
consider states, which keep their spread in the position's covariance and gains): learning all
four cost 2-6x our error on ArduPilot SITL's flight, traced to the azimuth zero (above) and to
the SITL harness's rangefinder mount (the companion had it at the centre of mass, SITL's reads
0.09 m below: the height's disagreement went into the winch's offset and the elevation zero).
Since, on SITL's flight with the simulator's realistic ground-station errors, learning cut our
RMS from 0.145 / 0.158 / 0.155 / 0.221 m held to 0.032 / 0.058 / 0.077 / 0.038 m (GPS hold,
external-navigation hold, circle, landing). Pure.
"""

from __future__ import annotations

import math
from collections import deque

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.bank import FilterBank

SETTLE_S = 3.0
"""How long [s] the ground station's innovations must have been in band, with one bearing
hypothesis left, before the calibration states learn (1 or 2 s released a transient on
ArduPilot SITL: a recorded flight's hold 0.065 -> 0.090 m, cal16)."""
MAX_MEAN_NIS = 2.0
"""The band: the mean NIS per degree of freedom over the last :data:`SETTLE_S` (1 for a
consistent filter; a bad start's bearing shows tens)."""
STEADY_WINDOW_S = 4.0
"""The steadiness test's window [s]: the last one's mean innovation is compared with 0 and with
the one before's (3 s let a recovering bad start's 4 s plateau on ArduPilot SITL through)."""
STEADY_FRACTION = 0.25
"""The steadiness test's tolerance, a fraction of the state's prior standard deviation (the
winch's zero offset [m], the elevation zero [rad]). A calibration error is a constant the
innovations agree on; a transient (the fly-out's, a recovering bad start's) moved the winch's
innovation's mean by 0.04-0.15 m a window on ArduPilot SITL."""
STEADY_STANDARD_ERRORS = 2.0
"""The steadiness test's allowance for the readings' noise: this many standard errors of a
window's mean (or of the difference of two), from the reading's white noise's standard
deviation."""
WINCH, ELEVATION = 0, 1
"""The innovations the steadiness test watches: the winch length's [m], the elevation's [rad]."""


class CalibrationRelease:
    """Watches the ground station's innovations and releases the bank's consider states
    by the module's rule.

    Parameters
    ----------
    enabled
        Whether the states are ever released (``dynamic_filter.learn_calibration``).

    Attributes
    ----------
    released_time_s
        Filter time [s] at which the states were released (``nan``: held, or none).
    """

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = enabled
        """Whether the states are ever released (``dynamic_filter.learn_calibration``)."""
        self._tolerance = [0.0, 0.0]
        """The steadiness test's tolerance per watched innovation (winch [m], elevation [rad])."""
        self._noise_std = [0.0, 0.0]
        """The watched readings' noise standard deviations (winch [m], elevation [rad])."""
        self._samples: deque[tuple[float, float]] = deque()
        """(filter time [s], NIS per degree of freedom) since one bearing was left, the last
        :data:`SETTLE_S`."""
        self._innovations: tuple[deque[tuple[float, float]], ...] = (deque(), deque())
        """(filter time [s], innovation) of the winch length [m] and the elevation [rad], the
        last 2 :data:`STEADY_WINDOW_S` (one bearing left or not)."""
        self._start_s = math.nan
        """The filter time [s] of the first sample since one bearing hypothesis was left (the
        bank decided, without a winch length)."""
        self.released_time_s = math.nan

    def add(
        self,
        bank: FilterBank,
        time_s: float,
        nis: float,
        dof: int,
        watched: tuple[int, float, float, float] | None = None,
        ranged: bool = True,
    ) -> None:
        """A ground-station sample's NIS (``dof`` degrees of freedom) at filter time
        ``time_s`` [s], tested against ``bank``'s best member, and the innovation the
        steadiness test watches (``watched``: :data:`WINCH` or :data:`ELEVATION`, the value,
        the prior standard deviation of the calibration state it would teach, the winch's
        zero offset [m] or the elevation zero [rad], and the reading's noise standard
        deviation in the same unit); the bank's consider states are released when the rule
        holds. ``ranged``: whether a winch length has been fused; without one the rule's
        clock waits for the bank to decide (see the module)."""
        if (
            not self.enabled
            or not math.isnan(self.released_time_s)
            or bank.consider != state.CALIBRATION
            or not math.isfinite(nis)
        ):
            return
        if watched is not None and math.isfinite(watched[1]):
            self._tolerance[watched[0]] = STEADY_FRACTION * watched[2]
            self._noise_std[watched[0]] = watched[3]
            window = self._innovations[watched[0]]
            window.append((time_s, watched[1]))
            while window[0][0] < time_s - 2.0 * STEADY_WINDOW_S:
                window.popleft()
        if not (bank.one_bearing if ranged else bank.decided):
            self._samples.clear()
            self._start_s = math.nan
            return
        if math.isnan(self._start_s):
            self._start_s = time_s
        samples = self._samples
        samples.append((time_s, nis / dof))
        while samples[0][0] < time_s - SETTLE_S:
            samples.popleft()
        if time_s - self._start_s < SETTLE_S:
            return
        if sum(v for _, v in samples) > MAX_MEAN_NIS * len(samples):
            return
        if all(
            _steady(window, time_s, tolerance, noise)
            for window, tolerance, noise in zip(
                self._innovations, self._tolerance, self._noise_std, strict=True
            )
        ):
            bank.release(state.NEVER_RELEASED)
            self.released_time_s = time_s

    def follow_length(self, bank: FilterBank, length_fused: bool) -> None:
        """Once released, hold ``bank``'s calibration states (``length_fused`` false: a winch
        reading skipped, gated, or fused only as the slack cable's bound) or let them learn
        (true: one through the length's model); see the module, "Held while no length is
        fused"."""
        if math.isnan(self.released_time_s):
            return
        bank.release(state.NEVER_RELEASED if length_fused else state.CALIBRATION)

    def clear(self) -> None:
        """Forget the samples (the filter restarts)."""
        self._samples.clear()
        for window in self._innovations:
            window.clear()
        self._start_s = math.nan
        self.released_time_s = math.nan


def _steady(
    window: deque[tuple[float, float]], time_s: float, tolerance: float, noise_std: float
) -> bool:
    """Whether the innovations in ``window`` have a steady mean at ``time_s`` [s]: the last
    :data:`STEADY_WINDOW_S`'s mean within ``tolerance`` plus :data:`STEADY_STANDARD_ERRORS`
    standard errors (readings of noise ``noise_std``) of 0 or of the :data:`STEADY_WINDOW_S`
    before it (a sensor that has not reported is steady)."""
    if not window:
        return True
    recent = [v for t, v in window if t > time_s - STEADY_WINDOW_S]
    before = [v for t, v in window if t <= time_s - STEADY_WINDOW_S]
    if len(recent) < 2:
        return False
    allowance = STEADY_STANDARD_ERRORS * noise_std
    mean_recent = sum(recent) / len(recent)
    if abs(mean_recent) <= tolerance + allowance / math.sqrt(len(recent)):
        return True  # nothing to learn: the held calibration agrees with the readings
    if len(before) < 2:
        return False
    difference = mean_recent - sum(before) / len(before)
    error = math.sqrt(1.0 / len(recent) + 1.0 / len(before))
    return abs(difference) <= tolerance + allowance * error
