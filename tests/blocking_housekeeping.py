"""The service with a housekeeping turn that blocks its event loop for ``BLOCK_S`` once every
``EVERY_S`` (test only: the negative control of ``test_service_load.py``). Run as the CLI:
``python blocking_housekeeping.py run --config FILE``."""

from __future__ import annotations

import sys
import time

from tether_companion import cli
from tether_companion.mavlink.link import Link
from tether_companion.service.app import CompanionService

BLOCK_S = 0.12
EVERY_S = 1.0

_housekeep = CompanionService.housekeep
_next_block_s = [0.0]


def _blocking_housekeep(self: CompanionService, link: Link, now_s: float) -> None:
    _housekeep(self, link, now_s)
    if now_s >= _next_block_s[0]:
        _next_block_s[0] = now_s + EVERY_S
        time.sleep(BLOCK_S)


CompanionService.housekeep = _blocking_housekeep  # type: ignore[method-assign]

if __name__ == "__main__":
    sys.exit(cli.main())
