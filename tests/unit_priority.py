"""Run a test's processes at the systemd unit's priority (not collected: no ``test_`` prefix).

The unit runs the service at ``Nice=-10`` in a cgroup of its own with ``CPUWeight=1000``, ten
times an ordinary service's or user session's weight. A test reproduces it with Linux
autogroups (``kernel.sched_autogroup_enabled``): a session is a scheduling group of its own,
and reniced by -10 it weighs 9548 against an ordinary group's 1024, the unit's ratio; where
there are no autogroups the process nice of -10 ranks it the same way. Lowering a nice needs
CAP_SYS_NICE (root): without it the test is skipped, saying so.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

import pytest

UNIT_NICE = -10
"""The unit's ``Nice=-10``; as an autogroup nice, the unit's ``CPUWeight=1000`` ratio."""
AUTOGROUP = Path("/proc/self/autogroup")


def _autogroup_nice() -> int | None:
    """This process's autogroup nice, None without autogroups."""
    try:
        return int(AUTOGROUP.read_text().split()[-1])
    except (OSError, ValueError, IndexError):
        return None


def _set_autogroup_nice(nice: int) -> None:
    with contextlib.suppress(FileNotFoundError):  # no autogroups: process nice ranks alone
        AUTOGROUP.write_text(f"{nice}\n")


@contextlib.contextmanager
def at_unit_priority() -> Iterator[None]:
    """This thread and its session's group at the unit's priority, restored after (processes
    started meanwhile without a session of their own share both); skips the test without the
    privilege to lower a nice."""
    nice = os.getpriority(os.PRIO_PROCESS, 0)
    group = _autogroup_nice()
    try:
        os.setpriority(os.PRIO_PROCESS, 0, nice + UNIT_NICE)
        if group is not None:
            _set_autogroup_nice(group + UNIT_NICE)
    except PermissionError:
        os.setpriority(os.PRIO_PROCESS, 0, nice)
        pytest.skip("running at the unit's Nice=-10/CPUWeight=1000 needs CAP_SYS_NICE")
    try:
        yield
    finally:
        os.setpriority(os.PRIO_PROCESS, 0, nice)
        if group is not None:
            _set_autogroup_nice(group)


def in_own_group_at_unit_priority() -> None:
    """``preexec_fn`` of a process started with ``start_new_session=True``: its new group
    and itself at the unit's priority."""
    os.nice(UNIT_NICE)
    group = _autogroup_nice()
    if group is not None:
        _set_autogroup_nice(group + UNIT_NICE)
