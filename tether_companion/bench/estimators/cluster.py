"""Monte Carlo over Dask: a local cluster of processes, or an existing scheduler.

``distributed`` is an optional dependency (the ``bench`` and ``test`` extras); without it,
:func:`require_distributed` raises :class:`~tether_companion.errors.InputError`, which the
command line turns into one line and exit code 2.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from tether_companion.errors import InputError

INSTALL_HINT = "pip install 'tether-companion[bench]' (or: pip install distributed)"
CONNECT_TIMEOUT_S = 10.0
WORKER_TIMEOUT_S = 60.0
"""How long a scheduler may be without any worker before the run gives up [s]."""


def require_distributed() -> Any:
    """The ``distributed`` module, or an :class:`InputError` saying what to install."""
    try:
        import distributed
    except ImportError:
        raise InputError(f"bench estimators needs dask.distributed: {INSTALL_HINT}") from None
    return distributed


@contextmanager
def dask_client(scheduler: str | None, workers: int | None) -> Iterator[Any]:
    """A ``distributed.Client``: on ``scheduler`` (``tcp://HOST:PORT``, waiting up to
    :data:`WORKER_TIMEOUT_S` for a worker) when given, else on a :class:`LocalCluster` of
    ``workers`` single-threaded processes (default: all cores).

    Raises
    ------
    InputError
        ``distributed`` is missing or the scheduler cannot be reached.
    """
    distributed = require_distributed()
    if scheduler is not None:
        try:
            client = distributed.Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S:g}s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(
                f"cannot reach the dask scheduler at {scheduler!r}: {exc}".replace("\n", " ")
            ) from None
        with client:
            try:
                client.wait_for_workers(1, timeout=WORKER_TIMEOUT_S)
            except TimeoutError:
                raise InputError(
                    f"the dask scheduler at {scheduler!r} has no worker after "
                    f"{WORKER_TIMEOUT_S:g} s (start one: dask worker {scheduler})"
                ) from None
            yield client
        return
    cluster = distributed.LocalCluster(
        n_workers=workers or os.cpu_count() or 1,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        silence_logs=logging.ERROR,
    )
    with cluster, distributed.Client(cluster) as client:
        yield client


def map_tasks(
    client: Any,
    function: Callable[[Any], Any],
    tasks: Sequence[Any],
    keys: Sequence[str],
    on_done: Callable[[], None] | None = None,
) -> list[Any]:
    """``function`` over ``tasks`` on the cluster; results in the order of ``tasks``.

    Tasks are submitted as impure (a re-run on a shared scheduler recomputes) under readable
    ``keys``; an exception on a worker is re-raised here.
    """
    distributed = require_distributed()
    futures = [
        client.submit(function, task, key=key, pure=False)
        for task, key in zip(tasks, keys, strict=True)
    ]
    index = {future.key: i for i, future in enumerate(futures)}
    results: list[Any] = [None] * len(futures)
    for future in distributed.as_completed(futures):
        results[index[future.key]] = future.result()
        if on_done is not None:
            on_done()
    return results
