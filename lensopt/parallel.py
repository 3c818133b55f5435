"""Run independent tasks serially or on Dask (a fresh ``LocalCluster`` or an existing scheduler).

A leaf utility (it imports nothing else from lensopt) shared by the tolerance Monte Carlo and the design
sweeps. Every task is ``fn(shared, item)``: ``shared`` is sent to each worker once, the items one by
one. Results come back in the order of ``items`` whatever order the workers finish in, so a serial run
and a distributed run give the same list; ``on_done`` sees each result as it arrives (to write it to
disk or show progress).
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

__all__ = ["dask_client", "run_tasks"]

S = TypeVar("S")
T = TypeVar("T")
R = TypeVar("R")


@contextlib.contextmanager
def dask_client(scheduler: str, workers: int) -> Iterator[Any]:
    """A ``distributed.Client``: ``local`` starts a LocalCluster of ``workers`` single-threaded worker
    processes (closed on exit); anything else is the address of a running scheduler (``tcp://…``)."""
    from distributed import Client, LocalCluster

    # Dask logs every connection at INFO; keep that to --verbose runs (root logger at INFO or below).
    log = logging.getLogger("distributed")
    old_level = log.level
    if logging.getLogger().getEffectiveLevel() > logging.INFO:
        log.setLevel(max(old_level, logging.WARNING))
    cluster = None
    if scheduler == "local":
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
    else:
        client = Client(scheduler)
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
        log.setLevel(old_level)


def run_tasks(fn: Callable[[S, T], R], items: Sequence[T], *, shared: S, scheduler: str | None = None,
              workers: int = 2, on_done: Callable[[int, R], None] | None = None) -> list[R]:
    """``[fn(shared, item) for item in items]``, serially (``scheduler`` None) or on Dask.

    Args:
        fn: a module-level function (workers import it by name).
        scheduler: None (in this process, in order), ``local`` (a LocalCluster of ``workers``
            processes) or a scheduler address.
        on_done: called in this process as ``on_done(index, result)`` when a task finishes (in the order
            they finish on Dask). A KeyboardInterrupt stops the run; finished tasks have been reported.
    """
    if scheduler is None:
        out = []
        for i, item in enumerate(items):
            r = fn(shared, item)
            if on_done is not None:
                on_done(i, r)
            out.append(r)
        return out
    from distributed import as_completed

    results: list[Any] = [None] * len(items)
    if not items:
        return results
    with dask_client(scheduler, workers) as client:
        shared_f = client.scatter(shared, broadcast=True)
        futures = [client.submit(fn, shared_f, item, pure=False) for item in items]
        index = {f.key: i for i, f in enumerate(futures)}
        try:
            for fut in as_completed(futures):
                i = index[fut.key]
                results[i] = fut.result()
                if on_done is not None:
                    on_done(i, results[i])
        finally:
            for f in futures:
                f.cancel()
    return results
