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

* the bank has decided (one member left: the thrust-scale and bearing hypotheses chosen,
  merged or collapsed), and
* since then, for :data:`SETTLE_S` at least, the ground station's innovations are in band:
  their normalised squared innovations (NIS per degree of freedom, the best member's, gated
  samples included) average at most :data:`MAX_MEAN_NIS` over the last :data:`SETTLE_S`;
* and a cable angle has been fused (``ground_station.py`` gives the samples only then: the
  winch's calibration without an angle is told only through the force balance's cable
  direction, and stays a consider state).

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
external-navigation hold, circle, landing); with SITL's exact sensors it costs up to 0.03 m in
the hold after the fly-out (the 3 s release takes the fly-out's transient as a constant:
docs/estimation.md, "State and model"). Pure.
"""

from __future__ import annotations

import math
from collections import deque

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.bank import FilterBank

SETTLE_S = 3.0
"""How long [s] the ground station's innovations must have been in band, after the bank
decided, before the calibration states learn."""
MAX_MEAN_NIS = 2.0
"""The band: the mean NIS per degree of freedom over the last :data:`SETTLE_S` (1 for a
consistent filter; a bad start's bearing shows tens)."""


class CalibrationRelease:
    """Watches the ground station's innovations and releases the bank's consider states
    by the module's rule.

    Attributes
    ----------
    released_time_s
        Filter time [s] at which the states were released (``nan``: held, or none).
    """

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = enabled
        """Whether the states are ever released (``dynamic_filter.learn_calibration``)."""
        self._samples: deque[tuple[float, float]] = deque()
        """(filter time [s], NIS per degree of freedom) since the bank decided, the last
        :data:`SETTLE_S`."""
        self._decided_s = math.nan
        """The filter time of the first sample after the bank decided [s]."""
        self.released_time_s = math.nan

    def add(self, bank: FilterBank, time_s: float, nis: float, dof: int) -> None:
        """A ground-station sample's NIS (``dof`` degrees of freedom) at filter time
        ``time_s`` [s], tested against ``bank``'s best member; the bank's consider states
        are released when the rule holds."""
        if not self.enabled or bank.consider != state.CALIBRATION or not math.isfinite(nis):
            return
        if not bank.decided:
            self.clear()
            return
        if math.isnan(self._decided_s):
            self._decided_s = time_s
        samples = self._samples
        samples.append((time_s, nis / dof))
        while samples[0][0] < time_s - SETTLE_S:
            samples.popleft()
        if time_s - self._decided_s < SETTLE_S:
            return
        if sum(v for _, v in samples) <= MAX_MEAN_NIS * len(samples):
            bank.release(state.NEVER_RELEASED)
            self.released_time_s = time_s

    def clear(self) -> None:
        """Forget the samples (the bank is undecided, or the filter restarts)."""
        self._samples.clear()
        self._decided_s = math.nan
        self.released_time_s = math.nan
