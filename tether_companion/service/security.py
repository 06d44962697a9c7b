"""The service's link security from its configuration: key, signer, verifier, trust gate.

:class:`LinkSecurity` loads the signing key once at start (a missing or group/world-readable
key file stops the service with exit code 2), keeps one signer and one verifier for the whole
run (their timestamps must never go back, across link re-opens too) and makes a fresh
:class:`~tether_companion.mavlink.trust.LinkTrust` for each opened link (the flight
controller's address is pinned per link).

Commands: :func:`command_refusal` says why a COMMAND_LONG to this component is refused (a
sender outside ``security.command_sources``, or unsigned with signing required); the session
answers it COMMAND_ACK DENIED and counts it.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.mavlink.signing import SignatureVerifier, Signer, is_signed, load_key
from tether_companion.mavlink.trust import OFF, REQUIRED, LinkTrust
from tether_companion.service.link_config import LinkConfig, SecurityConfig

NOT_A_COMMAND_SOURCE = "not_a_command_source"
UNSIGNED_COMMAND = "unsigned_command"


class LinkSecurity:
    """Signer, verifier and per-link trust gates for one service run.

    Parameters
    ----------
    security
        The ``security`` section.
    link
        The ``link`` section (the flight controller's ids, whose address is pinned).
    monotonic_s
        Local clock [s] for the address pin.
    unix_s
        Wall clock [s] for signing timestamps.

    Raises
    ------
    ConfigError
        When the key file is missing, unreadable, accessible to others or malformed.
    """

    def __init__(
        self,
        security: SecurityConfig,
        link: LinkConfig,
        *,
        monotonic_s: Callable[[], float] = time.monotonic,
        unix_s: Callable[[], float] = time.time,
    ) -> None:
        self.config = security
        self.link = link
        self._monotonic_s = monotonic_s
        self.key: bytes | None = None
        self.signer: Signer | None = None
        self.verifier: SignatureVerifier | None = None
        if security.signing != OFF:
            self.key = load_key(security.key_file)
            self.signer = Signer(self.key, security.link_id, unix_s)
            self.verifier = SignatureVerifier(self.key, unix_s)

    def new_trust(self) -> LinkTrust:
        """A trust gate for a newly opened link (shares the signer's and verifier's clocks)."""
        return LinkTrust(
            self.config.signing,
            verifier=self.verifier,
            signer=self.signer,
            fc_ids=(self.link.fc_system_id, self.link.fc_component_id),
            command_sources=self.config.command_sources,
            repin_silence_s=self.link.link_timeout_s,
            monotonic_s=self._monotonic_s,
        )

    def setup_signing_message(self) -> MAVLinkMessage:
        """SETUP_SIGNING carrying our key and timestamp to the flight controller."""
        assert self.key is not None and self.signer is not None
        return dialect.MAVLink_setup_signing_message(
            self.link.fc_system_id,
            self.link.fc_component_id,
            list(self.key),
            self.signer.next_timestamp(),
        )


def command_refusal(msg: MAVLinkMessage, security: SecurityConfig) -> str | None:
    """Why a command to this component is refused, or None when its sender may command us."""
    if msg.get_srcSystem() not in security.command_sources:
        return NOT_A_COMMAND_SOURCE
    if security.signing == REQUIRED and not is_signed(msg.get_msgbuf()):
        return UNSIGNED_COMMAND
    return None
