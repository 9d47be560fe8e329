"""The executor returns results in input order, locally and serially alike."""
from __future__ import annotations

import math
import time

from labkit.executor import map_tasks


def _square_root(x: float) -> float:
    return math.sqrt(x)


def _root_after_wait(x: float) -> float:
    time.sleep(0.02 * (8 - x))     # early items finish last: completion order is reversed
    return math.sqrt(x)


def test_local_processes_keep_order():
    items = [float(i) for i in range(8)]
    assert map_tasks(_root_after_wait, items, workers=2, quiet=True) == [math.sqrt(x) for x in items]


def test_serial_equals_local():
    items = [2.0, 3.0, 5.0]
    assert map_tasks(_square_root, items, scheduler="serial") == map_tasks(_square_root, items, workers=2)
