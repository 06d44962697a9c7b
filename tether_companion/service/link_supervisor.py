"""Opening the flight-controller link and opening it again: the service's connection lifecycle.

:class:`LinkSupervisor` opens the configured link (each attempt bounded by
``LINK_OPEN_TIMEOUT_S``: a name lookup or TCP connect that hangs counts as failed), hands the
open link to the service's ``serve`` coroutine until it returns or the link closes, closes it,
and starts over, with exponential back-off (``link.retry_initial_s`` doubling up to
``link.retry_max_s``) between failed opens and after each close. A failure is said at once on
stderr (the journal), once per change of reason, and always in :class:`ServiceState`
(``link_text``, ``last_error``, ``link_open_failures``, ``link_opens``).

What happens on an open link (receive path, housekeeping) is
:class:`~tether_companion.service.app.CompanionService`'s.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import sys
from collections.abc import Awaitable, Callable

from tether_companion.mavlink.link import Link, LinkClosed
from tether_companion.service.link_config import LinkConfig
from tether_companion.service.state import ServiceState

LINK_OPEN_TIMEOUT_S = 2.0
"""An open (name lookup, TCP connect) taking longer than this [s] counts as failed."""


class LinkSupervisor:
    """Opens, serves and re-opens one endpoint (see the module docstring).

    Parameters
    ----------
    endpoint
        The endpoint's text, as shown (``udpout:127.0.0.1:14550``).
    open_link
        Opens the link (raises OSError when it cannot).
    config
        The ``link`` section (back-off bounds).
    state
        Where the link's state is shown.
    """

    def __init__(
        self,
        endpoint: str,
        open_link: Callable[[], Awaitable[Link]],
        config: LinkConfig,
        state: ServiceState,
    ) -> None:
        self.endpoint = endpoint
        self._open_link = open_link
        self.config = config
        self.state = state

    async def run(self, stop: asyncio.Event, serve: Callable[[Link], Awaitable[None]]) -> None:
        """Until ``stop`` is set: open the link, ``await serve(link)`` (LinkClosed ends it
        like a return), close the link, wait the back-off, again."""
        cfg = self.config
        state = self.state
        endpoint = self.endpoint
        delay = cfg.retry_initial_s
        reported = ""
        while not stop.is_set():
            try:
                link = await asyncio.wait_for(self._open_link(), LINK_OPEN_TIMEOUT_S)
            except OSError as exc:  # TimeoutError is one too
                reason = open_failure(exc).removeprefix(f"{endpoint}: ")
                state.link_open_failures += 1
                state.last_error = f"cannot open {endpoint}: {reason}"
                state.link_text = f"cannot open {endpoint} (retry in {delay:.1f} s)"
                if reason != reported:
                    reported = reason
                    log(
                        f"cannot open {endpoint}: {reason}; retrying with back-off "
                        f"({cfg.retry_initial_s:g} s doubling up to {cfg.retry_max_s:g} s)"
                    )
                await wait_or_stop(stop, delay)
                delay = min(2.0 * delay, cfg.retry_max_s)
                continue
            if reported:
                log(f"opened {endpoint}")
                reported = ""
            delay = cfg.retry_initial_s
            state.link_opens += 1
            state.link_text = f"opened {endpoint}"
            try:
                await serve(link)
            except LinkClosed:
                state.last_error = f"{endpoint} closed"
            finally:
                state.link_up = False
                await link.close()
            state.link_text = f"{endpoint} closed (reopen in {delay:.1f} s)"
            if not stop.is_set():
                log(f"{endpoint} closed; reopening in {delay:g} s")
            await wait_or_stop(stop, delay)


def open_failure(exc: OSError) -> str:
    """Why a link did not open, in words (no errno numbers)."""
    if isinstance(exc, TimeoutError):
        return f"no answer within {LINK_OPEN_TIMEOUT_S:g} s"
    if isinstance(exc, socket.gaierror):
        return f"cannot resolve the host ({exc.strerror})"
    return exc.strerror or str(exc)


def log(line: str) -> None:
    """One line for the journal (stderr)."""
    print(f"tether-companion: {line}", file=sys.stderr, flush=True)


async def wait_or_stop(stop: asyncio.Event, timeout_s: float) -> None:
    """Wait ``timeout_s`` [s], or less when ``stop`` is set meanwhile."""
    with contextlib.suppress(asyncio.TimeoutError):
        await asyncio.wait_for(stop.wait(), timeout=timeout_s)
