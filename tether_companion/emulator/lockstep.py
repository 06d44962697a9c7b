"""Lock-step use of the emulator: no sockets, no wall clock, time moved by the caller.

Tests (and anything that must not depend on the machine's speed) drive a
:class:`~tether_companion.emulator.autopilot.FlightController` through a
:class:`LockstepPeer`: every message goes through real MAVLink frames both ways, exactly as
over a link, but time only advances when :meth:`LockstepPeer.advance` is called::

    controller = build_controller("hover", landed=True)
    gcs = LockstepPeer(controller)
    assert gcs.command(dialect.MAV_CMD_COMPONENT_ARM_DISARM, 1) == dialect.MAV_RESULT_ACCEPTED
    gcs.advance(1.0)
"""

from __future__ import annotations

import dataclasses
import weakref
from collections import Counter
from collections.abc import Mapping

from tether_companion.config import from_mapping
from tether_companion.emulator.autopilot import FlightController
from tether_companion.emulator.config import EmulatorConfig, load_emulator_scenario
from tether_companion.mavlink.framing import FrameEncoder, FrameParser, MAVLinkMessage, dialect


def build_controller(
    scenario: str, *, landed: bool = False, emulator: Mapping[str, object] | None = None
) -> FlightController:
    """A flight controller on a scenario (name or path).

    Parameters
    ----------
    scenario
        Built-in scenario name or YAML path.
    landed
        Start on the ground, disarmed, in STABILIZE.
    emulator
        Emulator settings overriding the file's ``emulator`` section (validated).
    """
    sim_scenario, file_config = load_emulator_scenario(scenario)
    if landed:
        initial = dataclasses.replace(sim_scenario.initial, airborne=False, armed=False)
        sim_scenario = dataclasses.replace(sim_scenario, initial=initial)
    data = {**dataclasses.asdict(file_config), **dict(emulator or {})}
    config = from_mapping(EmulatorConfig, data, source="build_controller")
    return FlightController(sim_scenario, config)


_PEERS: weakref.WeakKeyDictionary[FlightController, list[LockstepPeer]] = (
    weakref.WeakKeyDictionary()
)
"""Every peer of a controller: whatever one peer drains is routed to all of them."""


class LockstepPeer:
    """A ground station or companion attached to a controller by a lock-step link.

    Parameters
    ----------
    controller
        The flight controller; a new link is added for this peer.
    system_id, component_id
        The peer's identity.
    """

    def __init__(
        self, controller: FlightController, system_id: int = 255, component_id: int = 190
    ) -> None:
        self.controller = controller
        self.link_id = controller.add_link()
        self._encoder = FrameEncoder(system_id, component_id)
        self._to_controller = FrameParser()
        self._from_controller = FrameParser()
        config = controller.config
        self._controller_encoder = FrameEncoder(config.system_id, config.component_id)
        self.received: list[MAVLinkMessage] = []
        """Every message the controller sent to this peer, decoded (clear it at will)."""
        self.collecting = True
        """False: drop what the controller sends instead of framing and decoding it (speed)."""
        _PEERS.setdefault(controller, []).append(self)

    def send(self, msg: MAVLinkMessage) -> None:
        """Frame ``msg``, deliver it to the controller and collect the replies."""
        self.send_bytes(self._encoder.encode(msg))

    def send_bytes(self, data: bytes) -> None:
        """Deliver raw bytes (any garbage) to the controller's input path."""
        for decoded in self._to_controller.feed(data):
            self.controller.handle(decoded, self.link_id)
        self._collect()

    def advance(self, seconds: float) -> list[MAVLinkMessage]:
        """Run the controller ``seconds`` of emulator time; returns what it sent meanwhile."""
        self.controller.advance_to(self.controller.time_s + seconds)
        return self._collect()

    def _collect(self) -> list[MAVLinkMessage]:
        """Route the controller's output to every peer; returns what this peer got."""
        before = len(self.received)
        peers = _PEERS.get(self.controller, [self])
        for link_id, msg in self.controller.drain():
            for peer in peers:
                if peer.collecting and (link_id is None or link_id == peer.link_id):
                    frame = msg if isinstance(msg, bytes) else peer._controller_encoder.encode(msg)
                    peer.received.extend(peer._from_controller.feed(frame))
        return self.received[before:]

    def command(self, command: int, *params: float) -> int:
        """Send COMMAND_LONG to the autopilot; returns its COMMAND_ACK result.

        Raises
        ------
        RuntimeError
            When the controller does not answer with exactly one COMMAND_ACK.
        """
        values = list(params) + [0.0] * (7 - len(params))
        before = len(self.received)
        config = self.controller.config
        self.send(
            dialect.MAVLink_command_long_message(
                config.system_id, config.component_id, command, 0, *values
            )
        )
        acks = [
            m
            for m in self.received[before:]
            if m.get_type() == "COMMAND_ACK" and m.command == command
        ]
        if len(acks) != 1:
            raise RuntimeError(f"expected one COMMAND_ACK for command {command}, got {len(acks)}")
        return int(acks[0].result)

    def texts(self) -> list[str]:
        """STATUSTEXT strings received so far."""
        return [m.text for m in self.received if m.get_type() == "STATUSTEXT"]

    def counts(self) -> Counter:
        """Received messages by type."""
        return Counter(m.get_type() for m in self.received)

    def last(self, msg_type: str) -> MAVLinkMessage | None:
        """The latest received message of a type, or None."""
        for msg in reversed(self.received):
            if msg.get_type() == msg_type:
                return msg
        return None
