"""The compiled engine: :mod:`labkit.sim.scheme` under numba (``cache=True``).

Read :mod:`labkit.sim.scheme` for the scheme and docs/model.md for the physics.
:func:`run` allocates the outputs and calls the compiled loop.
"""
from __future__ import annotations

from types import ModuleType

import numpy as np

from labkit.sim import scheme as _scheme


def run_scheme(mod: ModuleType, P: np.ndarray, A: np.ndarray, state: np.ndarray, mode: np.ndarray, n_steps: int,
               dt: float, every: int, n_skip: int, n_rec: int, ev_cap: int) -> dict[str, np.ndarray]:
    """Integrate with one copy of the scheme (compiled or plain); returns the output arrays."""
    S = np.ascontiguousarray(state, dtype=np.float64).copy()
    md = np.zeros(7, np.int64)          # 6 feet, then the body (AIR or REST on the ground)
    md[:min(7, len(mode))] = mode[:7]
    out = {"rec": np.zeros((n_rec, mod.REC_COLS)), "rec_contact": np.zeros((n_rec, 6), np.int8),
           "frac": np.zeros((6, 3)), "max_air": np.zeros(6), "max_h": np.zeros(6),
           "count": np.zeros(mod.CNT_SIZE, np.int64), "events": np.zeros((ev_cap, mod.EV_COLS))}
    scratch_w, scratch_i = mod.new_scratch()
    mod.integrate(np.ascontiguousarray(P, dtype=np.float64), np.ascontiguousarray(A, dtype=np.float64), S, md,
                  int(n_steps), float(dt), int(every), int(n_skip), out["rec"], out["rec_contact"], out["frac"],
                  out["max_air"], out["max_h"], out["count"], out["events"], scratch_w, scratch_i,
                  np.zeros(mod.S_SIZE), np.zeros(6))
    out["state"] = S
    out["mode"] = md.astype(np.int8)
    return out


def run(P: np.ndarray, A: np.ndarray, state: np.ndarray, mode: np.ndarray, n_steps: int, dt: float, every: int,
        n_skip: int, n_rec: int, ev_cap: int) -> dict[str, np.ndarray]:
    """Integrate with the compiled scheme."""
    return run_scheme(_scheme, P, A, state, mode, n_steps, dt, every, n_skip, n_rec, ev_cap)
