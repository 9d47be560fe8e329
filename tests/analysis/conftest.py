"""Fixtures of the analysis tests.

``single_thread_blas`` (autouse): numpy's OpenBLAS runs single-threaded during
these tests and is restored afterwards.  The fits multiply many small matrices
(thousands x tens), where a multi-threaded BLAS gains nothing and, on a busy
2-core machine running other suites at once, spins and slows them ~10x.
"""
from __future__ import annotations

import ctypes
import re

import pytest


def _openblas():
    """numpy's bundled OpenBLAS (get, set) thread functions, or None if not found."""
    try:
        import numpy  # noqa: F401  (loads the library)

        with open("/proc/self/maps") as fh:
            libs = sorted(set(re.findall(r"(/\S*openblas\S*\.so\S*)", fh.read())))
    except OSError:
        return None
    for path in libs:
        lib = ctypes.CDLL(path)
        for suffix in ("64_", ""):
            get = getattr(lib, f"scipy_openblas_get_num_threads{suffix}", None) or \
                getattr(lib, f"openblas_get_num_threads{suffix}", None)
            put = getattr(lib, f"scipy_openblas_set_num_threads{suffix}", None) or \
                getattr(lib, f"openblas_set_num_threads{suffix}", None)
            if get is not None and put is not None:
                return get, put
    return None


@pytest.fixture(autouse=True, scope="module")
def single_thread_blas():
    fns = _openblas()
    if fns is None:
        yield
        return
    get, put = fns
    before = int(get())
    put(1)
    try:
        yield
    finally:
        put(before)
