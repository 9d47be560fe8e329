"""One executor for every sweep, Monte Carlo and calibration.

Local processes by default; a Dask distributed cluster when a scheduler
address is given (``--scheduler tcp://HOST:PORT``). Results come back in the
order of the inputs, whichever backend ran them, so a sweep gives the same
numbers on a laptop and on a cluster.
"""
from __future__ import annotations

import atexit
import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from labkit.progress import progress


def default_workers() -> int:
    """Worker processes used when none are asked for: one per core."""
    return max(1, os.cpu_count() or 1)


def map_tasks(fn: Callable[[Any], Any], items: Sequence[Any], *, scheduler: str | None = None,
              workers: int | None = None, desc: str = "", quiet: bool = False) -> list[Any]:
    """Apply ``fn`` to every item, in parallel, and return the results in order.

    Parameters
    ----------
    fn:
        A module-level function (it is pickled by reference).
    items:
        Its arguments, one per task.
    scheduler:
        ``None`` for local processes; ``"tcp://host:port"`` for an existing
        Dask distributed scheduler; ``"serial"`` to run in this process (for
        debugging and tiny jobs).
    workers:
        Local worker processes (default: one per core). Ignored with Dask.
    """
    items = list(items)
    if not items:
        return []
    if scheduler == "serial" or (scheduler is None and (workers == 1 or len(items) == 1)):
        results = []
        with progress(len(items), desc, quiet=quiet) as bar:
            for item in items:
                results.append(fn(item))
                bar.update(1)
        return results
    if scheduler is None:
        return _map_local(fn, items, workers or default_workers(), desc, quiet)
    return _map_dask(fn, items, scheduler, desc, quiet)


_POOLS: dict[int, ProcessPoolExecutor] = {}


def _pool(workers: int) -> ProcessPoolExecutor:
    """A process pool kept for the life of the process: its workers load the simulator once.

    A new pool per call cost ~2 s of worker start-up each time (calibration
    calls map_tasks once per Jacobian).
    """
    pool = _POOLS.get(workers)
    if pool is None:
        # forkserver: the parent may hold threads (Dask, the virtual lab) that fork would copy badly.
        ctx = multiprocessing.get_context("forkserver")
        pool = _POOLS[workers] = ProcessPoolExecutor(max_workers=workers, mp_context=ctx)
    return pool


@atexit.register
def _shutdown_pools() -> None:
    for pool in _POOLS.values():
        pool.shutdown(wait=False, cancel_futures=True)
    _POOLS.clear()


def _map_local(fn, items, workers, desc, quiet):
    results: list[Any] = [None] * len(items)
    pool = _pool(workers)
    futures: dict = {}
    try:
        with progress(len(items), desc, quiet=quiet) as bar:
            futures = {pool.submit(fn, item): i for i, item in enumerate(items)}
            for fut in as_completed(futures):
                results[futures[fut]] = fut.result()
                bar.update(1)
    except BaseException as exc:
        for fut in futures:
            fut.cancel()                  # no queued work left behind for the next call
        if isinstance(exc, BrokenProcessPool) or not isinstance(exc, Exception):
            # a dead worker, Ctrl-C or SIGTERM: drop the pool; the next call starts a new one
            _POOLS.pop(workers, None)
            pool.shutdown(wait=False, cancel_futures=True)
        raise
    return results


def _map_dask(fn, items, scheduler, desc, quiet):
    try:
        from distributed import Client
        from distributed import as_completed as dask_completed
    except ImportError:
        from labkit.errors import InputError
        raise InputError("--scheduler needs dask.distributed: pip install 'labkit[dask]'") from None
    from labkit.errors import InstrumentError

    try:
        client = Client(scheduler, timeout="10s", set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise InstrumentError(f"cannot reach the Dask scheduler: {exc}", instrument="dask",
                              command=scheduler) from None
    try:
        futures = client.map(fn, items, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        results: list[Any] = [None] * len(items)
        with progress(len(items), desc, quiet=quiet) as bar:
            # loop=: the client is not the default one, so as_completed cannot find it alone
            for fut in dask_completed(futures, loop=client.loop):
                results[index[fut.key]] = fut.result()
                bar.update(1)
        return results
    finally:
        client.close()
