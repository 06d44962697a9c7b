"""systemd's notify protocol (sd_notify) without a dependency: datagrams to NOTIFY_SOCKET.

When systemd starts a ``Type=notify`` unit it sets ``NOTIFY_SOCKET`` to a unix datagram socket
path (``@`` prefix = Linux abstract namespace). The service writes ``READY=1`` once it is up,
``WATCHDOG=1`` at least every ``WatchdogSec`` (systemd passes it as ``WATCHDOG_USEC``; we ping at
half of it, as sd_watchdog_enabled(3) advises), ``STATUS=...`` free text shown by
``systemctl status`` and ``STOPPING=1`` when shutting down. Without ``NOTIFY_SOCKET`` every call is
a no-op, so the service runs the same from a terminal.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Mapping


class SystemdNotifier:
    """Send sd_notify messages to ``NOTIFY_SOCKET`` if systemd gave one.

    Parameters
    ----------
    environ
        Where to read ``NOTIFY_SOCKET``, ``WATCHDOG_USEC`` and ``WATCHDOG_PID`` (default
        ``os.environ``; tests pass their own mapping).
    """

    def __init__(self, environ: Mapping[str, str] | None = None) -> None:
        env = os.environ if environ is None else environ
        self._address = _socket_address(env.get("NOTIFY_SOCKET", ""))
        self._socket: socket.socket | None = None
        if self._address is not None:
            self._socket = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
            self._socket.setblocking(False)
        self.watchdog_interval_s = _watchdog_interval_s(env)
        self.sent = 0
        self.errors = 0

    @property
    def enabled(self) -> bool:
        """True when systemd asked for notifications (``NOTIFY_SOCKET`` was set)."""
        return self._socket is not None

    def notify(self, **fields: str) -> None:
        """Send ``KEY=value`` lines, e.g. ``notify(READY="1", STATUS="up")``.

        Failures (systemd gone, socket full) are counted, never raised: notification is advice.
        """
        if self._socket is None or self._address is None:
            return
        text = "\n".join(f"{key}={value}" for key, value in fields.items())
        try:
            self._socket.sendto(text.encode("utf-8"), self._address)
            self.sent += 1
        except OSError:
            self.errors += 1

    def ready(self, status: str = "") -> None:
        """Tell systemd start-up is complete (``READY=1``), with an optional status line."""
        self.notify(READY="1", **({"STATUS": status} if status else {}))

    def watchdog(self) -> None:
        """Keep-alive ping (``WATCHDOG=1``)."""
        self.notify(WATCHDOG="1")

    def status(self, text: str) -> None:
        """Free-form one-line status shown by ``systemctl status``."""
        self.notify(STATUS=text.replace("\n", " "))

    def stopping(self) -> None:
        """Tell systemd the service is shutting down (``STOPPING=1``)."""
        self.notify(STOPPING="1")

    def close(self) -> None:
        """Close the socket (idempotent)."""
        if self._socket is not None:
            self._socket.close()
            self._socket = None


def _socket_address(path: str) -> str | bytes | None:
    """NOTIFY_SOCKET as a ``sendto`` address; ``@name`` is the abstract namespace (``\\0name``)."""
    if not path:
        return None
    if path.startswith("@"):
        return b"\0" + path[1:].encode("utf-8")
    if path.startswith("/"):
        return path
    return None  # systemd also allows vsock: addresses; a companion board never needs them


def _watchdog_interval_s(env: Mapping[str, str]) -> float | None:
    """Half of ``WATCHDOG_USEC`` [s], or None when the watchdog is off or meant for another PID."""
    text = env.get("WATCHDOG_USEC", "")
    pid = env.get("WATCHDOG_PID", "")
    if pid and pid != str(os.getpid()):
        return None
    try:
        usec = int(text)
    except ValueError:
        return None
    if usec <= 0:
        return None
    return usec / 2e6
