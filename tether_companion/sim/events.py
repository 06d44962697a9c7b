"""Timed ground-station events of a scenario: tension set-points, winch rates, tugs, release."""

from __future__ import annotations

from dataclasses import dataclass

from tether_companion.config import ConfigError, spec

EVENT_KINDS: tuple[str, ...] = ("set_tension", "winch_rate", "tug", "release")

_REQUIRED: dict[str, tuple[str, ...]] = {
    "set_tension": ("tension_n",),
    "winch_rate": ("winch_rate_mps",),
    "tug": ("force_ned_n", "duration_s"),
    "release": (),
}
_OPTIONAL_FIELDS: tuple[str, ...] = ("tension_n", "winch_rate_mps", "force_ned_n", "duration_s")


@dataclass(frozen=True)
class Event:
    """One entry of a scenario's ``events`` list.

    ``set_tension`` needs ``tension_n``; ``winch_rate`` needs ``winch_rate_mps``; ``tug`` needs
    ``force_ned_n`` and ``duration_s``; ``release`` needs nothing. Other fields must be absent.
    """

    time_s: float = spec(minimum=0.0, doc="when the event happens, from the start of the run [s]")
    kind: str = spec(choices=EVENT_KINDS, doc="what happens")
    tension_n: float | None = spec(None, minimum=0.0, doc="new winch tension (set_tension) [N]")
    winch_rate_mps: float | None = spec(
        None, minimum=-10.0, maximum=10.0, doc="new winch rate, + pays out (winch_rate) [m/s]"
    )
    force_ned_n: tuple[float, float, float] | None = spec(
        None, minimum=-100.0, maximum=100.0, doc="tug force on the drone, NED (tug) [N]"
    )
    duration_s: float | None = spec(None, exclusive_minimum=0.0, doc="tug duration (tug) [s]")

    def validate(self) -> None:
        """Exactly the fields the kind needs."""
        needed = _REQUIRED[self.kind]
        for name in _OPTIONAL_FIELDS:
            value = getattr(self, name)
            if name in needed and value is None:
                raise ConfigError("", name, value, f"is required for a {self.kind!r} event")
            if name not in needed and value is not None:
                allowed = ", ".join(needed) or "no other fields"
                raise ConfigError(
                    "", name, value, f"not used by a {self.kind!r} event (it takes {allowed})"
                )
