"""MAVLink routing between the emulated flight controller's links, as ArduPilot routes.

ArduPilot forwards what it receives on one telemetry port to the others, so that a ground
station on the radio reaches a companion computer on another port (ArduPilot's developer
documentation, "MAVLink Routing in ArduPilot"). The rules, as this module applies them:

* every message teaches a route: its sender (system, component) is reachable on the link it
  came in on;
* a message addressed to another system, or to another component of ours, goes out on every
  other link where a route to that target is known (to the target system on any of its
  components when the system is not ours), once per link, never back on the link it came in
  on;
* a broadcast (no target fields, or target 0) goes out on every other link with a known route
  to a system it addresses, and is also processed locally when it addresses us;
* a message for another component of ours is processed locally only when it could be
  forwarded nowhere.

Messages are forwarded as received, bytes unchanged (signatures intact). Pure: the flight
controller asks where each message goes and queues the bytes.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True, slots=True)
class Routing:
    """Where one received message goes: the links to forward it to, and whether the flight
    controller acts on it itself."""

    forward_to: tuple[int, ...]
    process_locally: bool


@dataclass
class MavlinkRoutes:
    """The routes learnt from received messages: (system, component) -> links seen on.

    Parameters
    ----------
    system_id, component_id
        The flight controller's own ids (never learnt as a route).
    """

    system_id: int
    component_id: int
    _routes: dict[tuple[int, int], set[int]] = field(default_factory=dict)

    def learn(self, system: int, component: int, link_id: int) -> None:
        """A message from ``(system, component)`` arrived on ``link_id``."""
        if system == self.system_id and component == self.component_id:
            return  # our own ids echoed back: not a route
        self._routes.setdefault((system, component), set()).add(link_id)

    def forget_link(self, link_id: int) -> None:
        """A link closed: no route leads through it any more."""
        for links in self._routes.values():
            links.discard(link_id)

    def route(self, target_system: int, target_component: int, in_link: int) -> Routing:
        """Where a message received on ``in_link`` with these targets goes (0: broadcast; a
        message without target fields is a broadcast)."""
        broadcast_system = target_system == 0
        broadcast_component = target_component == 0
        ours = broadcast_system or target_system == self.system_id
        for_us = ours and (broadcast_component or target_component == self.component_id)
        if for_us and not broadcast_system and not broadcast_component:
            return Routing((), True)
        links: set[int] = set()
        for (system, component), seen_on in self._routes.items():
            if broadcast_system or (
                system == target_system
                and (broadcast_component or component == target_component or not ours)
            ):
                links |= seen_on
        links.discard(in_link)
        forward_to = tuple(sorted(links))
        return Routing(forward_to, for_us or (ours and not forward_to))
