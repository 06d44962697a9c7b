"""A free UDP port on 127.0.0.1 for a test's peer that must be told a port before it starts
(MAVSDK's connection string, MAVProxy's ``--out``)."""

from __future__ import annotations

import socket


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that was free a moment ago (bound, read and released)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]
