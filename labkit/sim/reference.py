"""The reference engine: the same :mod:`labkit.sim.scheme` source run as plain Python.

A second copy of ``scheme.py`` is loaded under the name
``labkit.sim._scheme_python`` while :data:`labkit.sim._jit.PURE` is set, so
none of its functions is compiled (see :mod:`labkit.sim._jit` for why one
source serves both engines). About 1000 times slower than the kernel; use it
for short runs and for checking the compiled engine.
"""
from __future__ import annotations

import importlib.util
import sys
import threading
from pathlib import Path
from types import ModuleType

import numpy as np

from labkit.sim import _jit

_LOCK = threading.Lock()
_NAME = "labkit.sim._scheme_python"


def scheme_python() -> ModuleType:
    """The plain-Python copy of the scheme (loaded once)."""
    with _LOCK:
        mod = sys.modules.get(_NAME)
        if mod is not None:
            return mod
        path = Path(__file__).with_name("scheme.py")
        spec = importlib.util.spec_from_file_location(_NAME, path)
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        _jit.PURE = True
        try:
            spec.loader.exec_module(mod)
        finally:
            _jit.PURE = False
        sys.modules[_NAME] = mod
        return mod


def run(P: np.ndarray, A: np.ndarray, state: np.ndarray, mode: np.ndarray, n_steps: int, dt: float, every: int,
        n_skip: int, n_rec: int, ev_cap: int) -> dict[str, np.ndarray]:
    """Integrate with the plain-Python scheme (same outputs as :func:`labkit.sim.kernel.run`)."""
    from labkit.sim.kernel import run_scheme

    return run_scheme(scheme_python(), P, A, state, mode, n_steps, dt, every, n_skip, n_rec, ev_cap)
