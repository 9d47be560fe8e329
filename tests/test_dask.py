"""Sweeps on a cluster: a REAL dask.distributed LocalCluster on loopback (2 worker processes)
gives the same results as local processes and as a serial run."""
from __future__ import annotations

import logging
import math

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")   # a declared dependency: present in the venv and CI


@pytest.fixture(scope="module")
def scheduler():
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None, silence_logs=logging.ERROR) as cluster:
        addr = cluster.scheduler_address
        assert addr.startswith("tcp://127.0.0.1:")
        yield addr


@pytest.mark.slow
def test_map_tasks_on_dask_equals_local(scheduler):
    from labkit.executor import map_tasks

    items = [float(i) for i in range(40)]
    on_dask = map_tasks(math.sqrt, items, scheduler=scheduler, quiet=True)
    assert on_dask == map_tasks(math.sqrt, items, workers=2, quiet=True) == [math.sqrt(x) for x in items]


@pytest.mark.slow
def test_both_dask_workers_take_part(scheduler):
    from distributed import Client

    from labkit.executor import map_tasks

    with Client(scheduler, set_as_default=False) as client:
        workers = client.scheduler_info()["workers"]
        assert len(workers) == 2 and all(a.startswith("tcp://127.0.0.1:") for a in workers)
    pids = set(map_tasks(_pid_after_sleep, [0.2] * 8, scheduler=scheduler, quiet=True))
    assert len(pids) == 2


def _pid_after_sleep(seconds: float) -> int:
    import os
    import time

    time.sleep(seconds)
    return os.getpid()


@pytest.mark.slow
def test_sweep_on_dask_equals_local_and_serial(scheduler):
    from labkit.sim import RobotParams, Shaker, sweep

    kw = dict(quantity="freq_hz", values=[150.0, 240.0, 300.0], draws=2, duration_s=0.3, seed=3, quiet=True)
    p, sc = RobotParams(), Shaker(freq_hz=240.0, amp_um=25.0)
    on_dask = sweep(p, sc, scheduler=scheduler, **kw)
    local = sweep(p, sc, workers=2, **kw)
    serial = sweep(p, sc, scheduler="serial", **kw)
    assert on_dask.speeds_mm_s.shape == (3, 2)
    for other in (local, serial):
        np.testing.assert_array_equal(on_dask.speeds_mm_s, other.speeds_mm_s)
        np.testing.assert_array_equal(on_dask.contact_fraction, other.contact_fraction)
        np.testing.assert_array_equal(on_dask.patterns, other.patterns)
        np.testing.assert_array_equal(on_dask.impacts, other.impacts)
    # the draws really differ (a perturbed robot), so equality is not trivially of constants
    assert not np.array_equal(on_dask.speeds_mm_s[:, 0], on_dask.speeds_mm_s[:, 1])
    assert on_dask.meta["scheduler"] == scheduler
