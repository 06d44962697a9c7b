"""The accelerometer's force balance at a fusion tick: :class:`AccelFusion`.

The measurement itself (when to fuse, the innovation, the gate, the status record) is
:class:`~tether_companion.estimation.dynamic.aid.accel.AccelAid`; this adds what the estimator
keeps about it: its counts mirrored into the estimator's
:class:`~tether_companion.estimation.dynamic.output.DynamicHealth` (``accel_fused``,
``accel_gated``, ``on_ground``, ``near_anchor``, ``last_accel_nis``) and how long it has been
gated in a row (:class:`~tether_companion.estimation.dynamic.divergence.GatedAccelerometer`,
a sign of divergence).
"""

from __future__ import annotations

from collections.abc import Sequence

from tether_companion.estimation.dynamic.aid.accel import NEAR_ANCHOR, ON_GROUND, AccelAid
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
    """

    def __init__(self, noise_std_mps2: float, min_distance_m: float, health: DynamicHealth) -> None:
        self.aid = AccelAid(noise_std_mps2, min_distance_m)
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
        and the thrust [N]; the specific force, FRD [m/s^2]); whether it was fused."""
        health = self._health
        status = self.aid.status
        gated_before = status.gated
        fused = self.aid.fuse(bank, constants, inputs, specific_force_body_mps2, time_s, on_ground)
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
