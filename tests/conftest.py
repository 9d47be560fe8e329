"""Fixtures for every test; helpers live in ``clihelpers`` (importable by name)."""
from __future__ import annotations

import os

# Small matrix work on two loaded cores is ~10x slower with threaded BLAS; set
# before anything imports numpy (subprocesses inherit it).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import pytest

from clihelpers import last_json, run_cli  # noqa: F401  (re-exported for older imports)


@pytest.fixture
def cli():
    return run_cli
