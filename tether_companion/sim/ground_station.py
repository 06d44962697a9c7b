"""The ground station's events on a simulated flight: tension set-points, winch rates, tugs
and the tether's release, at the times a scenario lists or when called (the emulator)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from tether_companion.physics.cable import CableModel
from tether_companion.physics.rigid_body import RigidBody
from tether_companion.sim.events import Event


class GroundStationEvents:
    """The :class:`~tether_companion.sim.simulator.Simulator`'s ground-station methods (a base
    class: the simulator provides the attributes declared here)."""

    body: RigidBody
    cable: CableModel
    time_s: float
    _tension_step: int
    """The simulator's step whose cable tension is known (-1: evaluate it again)."""
    _tug_end_s: float
    _events: list[Event]
    _next_event: int
    _next_event_s: float

    def _cable_changed(self) -> None:
        """The cable's force at a given state changed in place: forget what was evaluated
        with the former one (the tension now, the next step's first RK4 stage)."""
        self._tension_step = -1
        self.body.forget_forces()

    def set_tension_n(self, tension_n: float) -> None:
        """Set the winch tension [N] (constant-tension cable only)."""
        self.cable.set_tension_n(tension_n)
        self._cable_changed()

    def set_winch_rate_mps(self, rate_mps: float) -> None:
        """Set the winch rate [m/s], positive paying out."""
        self.cable.set_winch_rate_mps(rate_mps)

    def set_paid_out_m(self, length_m: float) -> None:
        """Set the paid-out cable length [m] (the winch jumps to it)."""
        self.cable.paid_out_m = length_m
        self._cable_changed()

    def apply_tug(self, force_ned_n: ArrayLike, duration_s: float) -> None:
        """Pull on the drone with an extra NED force [N] for ``duration_s`` seconds from now."""
        force = np.asarray(force_ned_n, dtype=float).reshape(3)
        if not (np.all(np.isfinite(force)) and math.isfinite(duration_s) and duration_s > 0.0):
            raise ValueError(
                f"tug needs a finite force and a duration > 0 s, got {force}, {duration_s!r}"
            )
        self.body.tug_force_ned_n = tuple(force.tolist())  # type: ignore[assignment]
        self._tug_end_s = self.time_s + duration_s

    def release_tether(self) -> None:
        """Let the tether go: no cable force from now on."""
        self.cable.release()
        self._cable_changed()

    def _apply_event(self, event: Event) -> None:
        if event.kind == "set_tension":
            self.set_tension_n(event.tension_n)
        elif event.kind == "winch_rate":
            self.set_winch_rate_mps(event.winch_rate_mps)
        elif event.kind == "tug":
            self.apply_tug(event.force_ned_n, event.duration_s)
        else:
            self.release_tether()

    def _apply_due_events(self, until_s: float) -> None:
        events = self._events
        while self._next_event < len(events) and events[self._next_event].time_s <= until_s:
            self._apply_event(events[self._next_event])
            self._next_event += 1
        more = self._next_event < len(events)
        self._next_event_s = events[self._next_event].time_s if more else math.inf
