"""The accelerometer at a fusion tick: :class:`AccelFusion` (the force balance in the air, the
rest on the ground).

The measurement itself (when to fuse, the innovation, the gate, the status record) is
:class:`~tether_companion.estimation.dynamic.aid.accel.AccelAid`; this adds what the estimator
keeps about it: its counts mirrored into the estimator's
:class:`~tether_companion.estimation.dynamic.output.DynamicHealth` (``accel_fused``,
``accel_gated``, ``on_ground``, ``near_anchor``, ``last_accel_nis``) and how long it has been
gated in a row (:class:`~tether_companion.estimation.dynamic.divergence.GatedAccelerometer`,
a sign of divergence). On the ground, resting, the rest
(:class:`~tether_companion.estimation.dynamic.aid.rest.RestAid`: zero velocity, the rest
height) is fused instead, counted in ``rest_fused`` and ``rest_settled``.
"""

from __future__ import annotations

from collections.abc import Sequence

from tether_companion.estimation.dynamic.aid.accel import NEAR_ANCHOR, ON_GROUND, AccelAid
from tether_companion.estimation.dynamic.aid.rest import RestAid, resting_on_ground
from tether_companion.estimation.dynamic.aiding import AidStatus
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.divergence import GatedAccelerometer
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.estimation.dynamic.output import DynamicHealth


class AccelFusion:
    """Fuses the force balance and counts what happened.

    Parameters
    ----------
    noise_std_mps2
        The measurement's noise per axis [m/s^2] (sensor noise and unmodelled forces).
    min_distance_m
        No fusion closer than this to the anchor [m].
    health
        The estimator's counters.
    rest
        The rest on the ground.
    """

    def __init__(
        self, noise_std_mps2: float, min_distance_m: float, health: DynamicHealth, rest: RestAid
    ) -> None:
        self.aid = AccelAid(noise_std_mps2, min_distance_m)
        self.rest = rest
        self.gated = GatedAccelerometer()
        """Since when the force balance has been gated in a row."""
        self._health = health

    @property
    def status(self) -> AidStatus:
        """The measurement's status record."""
        return self.aid.status

    def fuse(
        self,
        bank: FilterBank,
        constants: ModelConstants,
        inputs: list[float],
        specific_force_body_mps2: Sequence[float],
        time_s: float,
        on_ground: bool,
    ) -> bool:
        """Fuse one IMU sample at filter time ``time_s`` [s] (``inputs`` = ``R_v^b`` row-major
        and the thrust [N]; the specific force, FRD [m/s^2]); whether the force balance was
        fused. ``on_ground`` (motors idle or the flight controller says landed): the force
        balance is not, and the rest is when the accelerometer reads the ground's reaction."""
        health = self._health
        status = self.aid.status
        gated_before = status.gated
        fused = self.aid.fuse(bank, constants, inputs, specific_force_body_mps2, time_s, on_ground)
        if on_ground and resting_on_ground(on_ground, specific_force_body_mps2):
            rest = self.rest
            if rest.fuse(bank, time_s):
                health.rest_fused += 1
            health.rest_settled = rest.settled
        health.on_ground = status.skipped_by_reason.get(ON_GROUND, 0)
        health.near_anchor = status.skipped_by_reason.get(NEAR_ANCHOR, 0)
        health.accel_gated = status.gated
        sensors = bank.best.sensors
        if "accel" in sensors:
            health.last_accel_nis = sensors["accel"].last_nis
        if fused:
            health.accel_fused += 1
            self.gated.clear()
        elif status.gated != gated_before:
            self.gated.gated(time_s)
        return fused
