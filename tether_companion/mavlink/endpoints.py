"""asyncio MAVLink links over UDP, TCP and serial ports.

An endpoint is written as text on the command line or in a config file and parsed with
:func:`parse_endpoint`:

=============================== ==========================================================
``udp:HOST:PORT``               UDP; listens with ``--listen``, sends to HOST:PORT with
                                ``--connect`` (the role comes from the flag)
``udpin:HOST:PORT``             UDP, always listening (replies to every peer heard from)
``udpout:HOST:PORT``            UDP, always sending to HOST:PORT
``tcp:HOST:PORT``               TCP server with ``--listen``, client with ``--connect``
``tcpin:HOST:PORT``             TCP server (every connected client gets every message)
``tcpout:HOST:PORT``            TCP client
``serial:/dev/ttyX:BAUD``       a serial port, 8N1, raw, no flow control
=============================== ==========================================================

``PORT`` 0 when listening picks a free port (see :attr:`Link.local_address`); tests use it.

:func:`open_link` turns an :class:`Endpoint` into a :class:`Link`: ``await link.recv()`` gives
the next decoded message, ``link.send(msg)`` frames and sends one, ``await link.close()``
releases everything. Each link counts what it sends, drops and rejects
(:class:`LinkCounters`, and :class:`~tether_companion.mavlink.framing.FramingCounters` for
input). Sending never blocks: a UDP datagram goes to the kernel at once, a TCP or serial
write is buffered by asyncio and dropped (and counted) once the buffer exceeds 1 MiB, so a
stalled reader cannot stall the caller.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from tether_companion.config import ConfigError
from tether_companion.mavlink.framing import FrameEncoder
from tether_companion.mavlink.link import DEFAULT_RX_QUEUE, Link
from tether_companion.mavlink.signing import Signer
from tether_companion.mavlink.stream_links import (
    SerialLink,
    TcpClientLink,
    TcpServerLink,
    termios_speed,
)
from tether_companion.mavlink.trust import LinkTrust
from tether_companion.mavlink.udp_link import UdpLink

Role = Literal["listen", "connect"]
Transport = Literal["udp", "tcp", "serial"]

_SCHEMES: dict[str, tuple[Transport, Role | None]] = {
    "udp": ("udp", None),
    "udpin": ("udp", "listen"),
    "udpout": ("udp", "connect"),
    "tcp": ("tcp", None),
    "tcpin": ("tcp", "listen"),
    "tcpout": ("tcp", "connect"),
    "serial": ("serial", "connect"),
}
_FORMS = (
    "expected udp:HOST:PORT, udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT, "
    "tcpin:HOST:PORT, tcpout:HOST:PORT or serial:/dev/DEVICE:BAUD"
)


@dataclass(frozen=True)
class Endpoint:
    """Where and how to open a MAVLink link (see the module docstring for the text forms)."""

    transport: Transport
    role: Role
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0
    text: str = ""

    def __str__(self) -> str:
        if self.transport == "serial":
            return f"serial:{self.device}:{self.baud}"
        scheme = {"udp": ("udpin", "udpout"), "tcp": ("tcpin", "tcpout")}[self.transport]
        return f"{scheme[0] if self.role == 'listen' else scheme[1]}:{self.host}:{self.port}"


def parse_endpoint(text: str, role: Role, *, key: str | None = None) -> Endpoint:
    """Parse an endpoint string; ``role`` is the flag it came from (listen or connect).

    ``udp:`` and ``tcp:`` take the role; ``udpin:``/``tcpin:`` always listen,
    ``udpout:``/``tcpout:`` always connect; ``serial:`` is a device.

    Parameters
    ----------
    text
        The endpoint as written by the user.
    role
        ``"listen"`` or ``"connect"``.
    key
        Name of the flag or config key, for error messages (default ``--listen`` /
        ``--connect``).

    Raises
    ------
    ConfigError
        Naming the key, the text and the accepted forms, for anything malformed: unknown
        scheme, missing or non-numeric port, port out of 0..65535 (0 only when listening),
        empty host, unsupported baud rate.
    """
    key = key or f"--{role}"
    if role not in ("listen", "connect"):
        raise ValueError(f"role must be 'listen' or 'connect', got {role!r}")
    if not isinstance(text, str) or ":" not in text:
        raise ConfigError("", key, text, _FORMS)
    scheme, _, rest = text.partition(":")
    scheme = scheme.strip().lower()
    if scheme not in _SCHEMES:
        raise ConfigError("", key, text, f"unknown scheme {scheme!r}; {_FORMS}")
    transport, fixed_role = _SCHEMES[scheme]
    if transport == "serial":
        device, sep, baud_text = rest.rpartition(":")
        if not sep or not device.startswith("/"):
            raise ConfigError("", key, text, "expected serial:/dev/DEVICE:BAUD")
        baud = _parse_int(baud_text, key, text, "BAUD")
        if termios_speed(baud) is None:
            raise ConfigError("", key, text, f"baud rate {baud} is not a standard rate")
        return Endpoint("serial", "connect", device=device, baud=baud, text=text)
    effective_role: Role = fixed_role or role
    host, sep, port_text = rest.rpartition(":")
    host = host.strip().strip("[]")
    if not sep or not host:
        raise ConfigError("", key, text, f"missing host or port; {_FORMS}")
    port = _parse_int(port_text, key, text, "PORT")
    lowest = 0 if effective_role == "listen" else 1
    if not lowest <= port <= 65535:
        raise ConfigError("", key, text, f"port must be {lowest}..65535")
    return Endpoint(transport, effective_role, host=host, port=port, text=text)


def _parse_int(value: str, key: str, text: str, what: str) -> int:
    try:
        return int(value.strip(), 10)
    except ValueError:
        raise ConfigError("", key, text, f"{what} must be an integer; {_FORMS}") from None


async def open_link(
    endpoint: Endpoint,
    *,
    system_id: int,
    component_id: int,
    rx_queue_size: int = DEFAULT_RX_QUEUE,
    trust: LinkTrust | None = None,
    signer: Signer | None = None,
) -> Link:
    """Open ``endpoint`` and return a running :class:`Link`.

    Parameters
    ----------
    endpoint
        From :func:`parse_endpoint`.
    system_id, component_id
        The identity this side sends as.
    rx_queue_size
        Received messages held for :meth:`Link.recv`; the oldest is dropped beyond it.
    trust
        Decides which received frames are believed (signatures, the flight controller's
        address; :mod:`tether_companion.mavlink.trust`); None believes every intact frame.
    signer
        Signs every sent frame (MAVLink 2 signing) when given.

    Raises
    ------
    OSError
        When the socket cannot be bound, the TCP server refuses (ConnectionRefusedError) or
        the serial device cannot be opened; the message names the endpoint.
    """
    encoder = FrameEncoder(system_id, component_id, signer)
    try:
        if endpoint.transport == "udp":
            return await UdpLink.open(endpoint, encoder, rx_queue_size, trust)
        if endpoint.transport == "tcp" and endpoint.role == "listen":
            return await TcpServerLink.open(endpoint, encoder, rx_queue_size, trust)
        if endpoint.transport == "tcp":
            return await TcpClientLink.open(endpoint, encoder, rx_queue_size, trust)
        return await SerialLink.open(endpoint, encoder, rx_queue_size, trust)
    except OSError as exc:
        raise type(exc)(exc.errno, f"{endpoint}: {exc.strerror or exc}") from exc
