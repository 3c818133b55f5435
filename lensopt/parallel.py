"""Independent tasks serially or on Dask, and the state and set-up of a torch.distributed (torchrun) run.

A leaf utility (it imports nothing else from lensopt but the errors). ``run_tasks`` is shared by the
tolerance Monte Carlo and the design sweeps: every task is ``fn(shared, item)``; ``shared`` is sent to
each worker once, the items one by one. Results come back in the order of ``items`` whatever order the
workers finish in, so a serial run and a distributed run give the same list; ``on_done`` sees each
result as it arrives (to write it to disk or show progress). ``Dist`` is a process's place in a
data-parallel run (rank, world size, collectives); ``init_distributed``, ``distributed`` and
``check_same_settings`` set up the data-parallel training runs (``train-irm``, the joint optimization).

**Which scheduler (``auto``, the default of ``tolerance`` and ``sweep``).** A Dask LocalCluster costs its
start-up — worker processes that import torch and lensopt, the shared object sent to each, the close —
measured 13–15 s on the 2-core development machines, and it can at best divide the work by its
worker count W. It therefore pays only when the work left is more than W/(W − 1) times that start-up
(twice it for 2 workers). ``auto`` runs the first task in this process, times it, and estimates the
work left as that time × the tasks left: below ``AUTO_SERIAL_BELOW_S`` (30 s), or with fewer than two
usable CPU cores, the rest runs serially too; above it, on a LocalCluster of
min(workers, cores) processes. (The Monte Carlo of ``tolerance lenses/cmount_4p.json --profile s6.2
--trials 200`` is ~5 s of work: serial, 3× faster than on the cluster.)
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

from lensopt.errors import LensoptError

if TYPE_CHECKING:
    from torch import Tensor

__all__ = ["AUTO_SERIAL_BELOW_S", "auto_plan", "dask_client", "run_tasks", "Dist", "init_distributed", "distributed",
           "check_same_settings"]

AUTO_SERIAL_BELOW_S = 30.0
"""``auto`` keeps estimated work below this many seconds in this process (see the module doc)."""

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
    # Its warnings are about its own machinery (a worker slow to stop at close: "still alive after 4.0
    # seconds, killing"), not about the tasks, whose errors come back as exceptions: errors only.
    if logging.getLogger().getEffectiveLevel() > logging.INFO:
        log.setLevel(max(old_level, logging.ERROR))
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


def usable_cores() -> int:
    """CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def auto_plan(first_s: float, left: int, workers: int, cores: int | None = None) -> tuple[str | None, str]:
    """What ``auto`` does with ``left`` tasks after a first one that took ``first_s`` seconds: (None,
    why) to go on serially, or ("local", why) for a LocalCluster (the rule of the module doc)."""
    cores = usable_cores() if cores is None else cores
    work = first_s * left
    if left == 0:
        return None, "serial (one task)"
    if min(workers, cores) < 2:
        return None, f"serial ({cores} usable CPU core{'s' if cores != 1 else ''})"
    if work < AUTO_SERIAL_BELOW_S:
        return None, (f"serial (auto: about {work:.1f} s of work left, below the {AUTO_SERIAL_BELOW_S:g} s a "
                      "local cluster needs to pay for its start)")
    return "local", f"local cluster of {min(workers, cores)} workers (auto: about {work:.0f} s of work left)"


def run_tasks(fn: Callable[[S, T], R], items: Sequence[T], *, shared: S, scheduler: str | None = None,
              workers: int = 2, on_done: Callable[[int, R], None] | None = None,
              on_plan: Callable[[str], None] | None = None) -> list[R]:
    """``[fn(shared, item) for item in items]``, serially (``scheduler`` None) or on Dask.

    Args:
        fn: a module-level function (workers import it by name).
        scheduler: None (in this process, in order), ``auto`` (the first task here, then serial or a
            LocalCluster by ``auto_plan``), ``local`` (a LocalCluster of ``workers`` processes) or a
            scheduler address.
        on_done: called in this process as ``on_done(index, result)`` when a task finishes (in the order
            they finish on Dask). A KeyboardInterrupt stops the run; finished tasks have been reported.
        on_plan: told in words how the tasks run (serial, a cluster, what ``auto`` chose and why).
    """
    if scheduler == "auto":
        if not items:
            return []
        t0 = time.perf_counter()
        first = fn(shared, items[0])
        took = time.perf_counter() - t0
        if on_done is not None:
            on_done(0, first)
        sched, why = auto_plan(took, len(items) - 1, workers)
        if on_plan is not None:
            on_plan(why)
        shift = None if on_done is None else (lambda i, r: on_done(i + 1, r))
        rest = run_tasks(fn, items[1:], shared=shared, scheduler=sched, workers=min(workers, usable_cores()),
                         on_done=shift)
        return [first, *rest]
    if on_plan is not None:
        on_plan("serial" if scheduler is None else
                f"local cluster of {workers} workers" if scheduler == "local" else f"Dask scheduler {scheduler}")
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


@dataclass(frozen=True)
class Dist:
    """This process's place in a data-parallel run (rank 0 of 1 without torch.distributed)."""

    rank: int = 0
    world: int = 1
    device: str = "cpu"  # where collectives run: cpu for gloo, the rank's GPU for NCCL

    @property
    def active(self) -> bool:
        return self.world > 1

    def share(self, n: int) -> slice:
        """This rank's slice of a batch of ``n`` (equal shares; ``n`` must divide)."""
        k = n // self.world
        return slice(self.rank * k, (self.rank + 1) * k)

    def mean(self, t: Tensor) -> Tensor:
        """All-reduced mean over ranks (identity for one process)."""
        if not self.active:
            return t
        import torch.distributed as dist

        src = t.device
        t = t.detach().clone().to(self.device)
        dist.all_reduce(t)
        return (t / self.world).to(src)

    def any(self, flag: bool) -> bool:
        """True on every rank if ``flag`` is true on any (a stop request must be seen by all ranks at the
        same step boundary, or the others would wait in the next collective)."""
        if not self.active:
            return flag
        import torch
        import torch.distributed as dist

        t = torch.tensor([int(flag)], device=self.device)
        dist.all_reduce(t, op=dist.ReduceOp.MAX)
        return bool(t.item())

    def broadcast(self, t: Tensor) -> Tensor:
        """Rank 0's ``t`` on every rank (identity for one process)."""
        if not self.active:
            return t
        import torch.distributed as dist

        src = t.device
        t = t.detach().clone().contiguous().to(self.device)
        dist.broadcast(t, 0)
        return t.to(src)


def init_distributed(device: Any) -> Dist:
    """This process's ``Dist``: torchrun sets RANK/WORLD_SIZE (the process group is gloo on the CPU, NCCL on
    CUDA, where each rank's collectives run on its GPU); else rank 0 of 1. ``device``: the run's
    ``torch.device``."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return Dist()
    import torch
    import torch.distributed as dist

    if not dist.is_initialized():
        dist.init_process_group("nccl" if device.type == "cuda" else "gloo")
    rank = dist.get_rank()
    where = f"cuda:{rank % torch.cuda.device_count()}" if device.type == "cuda" else "cpu"
    return Dist(rank, dist.get_world_size(), where)


@contextlib.contextmanager
def distributed(device: Any) -> Iterator[tuple[Dist, Any]]:
    """``(Dist, device)`` of a data-parallel run: under torchrun on CUDA each rank works on its own GPU
    (``cuda:rank % count``, made current); the process group is destroyed when the block ends."""
    dist = init_distributed(device)
    if device.type == "cuda" and dist.active:
        import torch

        device = torch.device(dist.device)
        torch.cuda.set_device(device)
    try:
        yield dist, device
    finally:
        if dist.active:
            import torch.distributed as tdist

            tdist.destroy_process_group()


def check_same_settings(world: int, settings: dict[str, Any]) -> None:
    """Every rank of a ``world``-process run must run the same command on the same spec: compare a hash of
    ``settings`` across ranks (nothing to compare for one process)."""
    if world <= 1:
        return
    import hashlib

    import torch.distributed as tdist

    h = hashlib.sha256(json.dumps(settings, sort_keys=True, default=str).encode()).hexdigest()
    hashes: list[str] = [""] * world
    tdist.all_gather_object(hashes, h)
    if len(set(hashes)) > 1:
        bad = [r for r, x in enumerate(hashes) if x != hashes[0]]
        raise LensoptError(f"processes were started with different settings (ranks {bad} differ from rank 0); "
                           "start every rank with the same command and spec", path="torchrun")
