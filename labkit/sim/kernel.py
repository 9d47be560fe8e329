"""The compiled engine: :mod:`labkit.sim.scheme` under numba (``cache=True``).

Read :mod:`labkit.sim.scheme` for the scheme and docs/model.md for the physics.
:class:`Integration` holds a run's state, scratch and accumulated outputs and integrates
it piece by piece (a long run shows progress and keeps only the samples it is asked
for); :func:`run` integrates one piece.
"""
from __future__ import annotations

import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from labkit.sim import scheme as _scheme

#: What the first compilation took on the development machine (2 cores), s: the
#: message before it says so.
COMPILE_S = "30-120"
_compiled = False


class Integration:
    """One run of the scheme ``mod`` (compiled or plain) from ``state`` and ``mode``,
    integrated in pieces by :meth:`advance`; the statistics (``frac``, ``max_air``,
    ``max_h``, ``count``, ``events``) accumulate over the pieces. With ``stop_when_active``
    the kernel stops at the first step after which a foot or the body is not held
    (:data:`labkit.sim.scheme.STOP_WHEN_ACTIVE`; :attr:`stopped`)."""

    def __init__(self, mod: ModuleType, P: np.ndarray, A: np.ndarray, state: np.ndarray, mode: np.ndarray,
                 dt: float, n_skip: int, ev_cap: int, stop_when_active: bool = False) -> None:
        self.mod = mod
        self.P = np.ascontiguousarray(P, dtype=np.float64)
        self.A = np.ascontiguousarray(A, dtype=np.float64)
        self.S = np.ascontiguousarray(state, dtype=np.float64).copy()
        self.md = np.zeros(7, np.int64)          # 6 feet, then the body (AIR or REST on the ground)
        self.md[:min(7, len(mode))] = mode[:7]
        self.dt = float(dt)
        self.n_skip = int(n_skip)
        self.n0 = 0                               # the next step's index
        self.out = {"frac": np.zeros((6, 3)), "max_air": np.zeros(6), "max_h": np.zeros(6),
                    "count": np.zeros(mod.CNT_SIZE, np.int64),
                    # rows are written in order and only the first count[CNT_EVENTS] read (outputs):
                    # empty, not zeros, spares a run zeroing (and mapping) 9.6 MB, 0.1 ms
                    "events": np.empty((ev_cap, mod.EV_COLS))}
        if stop_when_active:
            self.out["count"][mod.CNT_STOP] = mod.STOP_WHEN_ACTIVE
        self.W, self.I = mod.new_scratch()
        self.T = np.zeros(mod.S_SIZE)
        self.air_run = np.zeros(6)

    def advance(self, n_steps: int, every: int) -> tuple[np.ndarray, np.ndarray]:
        """Integrate the next ``n_steps`` steps; returns the samples (``rec``, ``rec_contact``)
        taken every ``every`` steps from this piece's first step, its last one included.
        ``rec`` is samples x REC_COLS, column-major (the kernel writes each column contiguous:
        reading one quantity then reads only its own memory)."""
        n_rec = n_steps // every + 1
        rec = np.zeros((self.mod.REC_COLS, n_rec))
        rec_contact = np.zeros((n_rec, 6), np.int8)
        o = self.out
        if self.mod is _scheme:
            announce_compile()
        self.mod.integrate(self.P, self.A, self.S, self.md, int(self.n0), int(n_steps), self.dt, int(every),
                           self.n_skip, rec, rec_contact, o["frac"], o["max_air"], o["max_h"], o["count"],
                           o["events"], self.W, self.I, self.T, self.air_run)
        self.n0 += int(n_steps)
        return rec.T, rec_contact

    @property
    def stopped(self) -> bool:
        """Did a run started with ``stop_when_active`` stop early (a foot or the body not held)?"""
        return bool(self.out["count"][self.mod.CNT_STOP] == self.mod.STOPPED)

    def outputs(self) -> dict[str, np.ndarray]:
        """The accumulated outputs (``events``: the rows logged), the state and the contact modes
        after the last piece, and whether the run stopped early (``stopped``)."""
        return {**self.out, "events": self.out["events"][:self.out["count"][self.mod.CNT_EVENTS]], "state": self.S,
                "mode": self.md.astype(np.int8), "stopped": np.array([self.stopped])}


def run_scheme(mod: ModuleType, P: np.ndarray, A: np.ndarray, state: np.ndarray, mode: np.ndarray, n_steps: int,
               dt: float, every: int, n_skip: int, n_rec: int, ev_cap: int) -> dict[str, np.ndarray]:
    """Integrate with one copy of the scheme (compiled or plain) in one piece; returns the output arrays."""
    run = Integration(mod, P, A, state, mode, dt, n_skip, ev_cap)
    rec, rec_contact = run.advance(n_steps, every)
    return {"rec": rec[:n_rec], "rec_contact": rec_contact[:n_rec], **run.outputs()}


def run(P: np.ndarray, A: np.ndarray, state: np.ndarray, mode: np.ndarray, n_steps: int, dt: float, every: int,
        n_skip: int, n_rec: int, ev_cap: int) -> dict[str, np.ndarray]:
    """Integrate with the compiled scheme."""
    return run_scheme(_scheme, P, A, state, mode, n_steps, dt, every, n_skip, n_rec, ev_cap)


def kernel_cached() -> bool:
    """True when numba's disk cache holds the compiled kernel for the current source (the
    first call in this process loads it instead of compiling). Reads numba's cache index of
    :func:`labkit.sim.scheme.integrate` the way numba does (the source file's time stamp and
    size must match); anything unexpected counts as not cached."""
    try:
        dispatcher: Any = _scheme.integrate
        index = dispatcher._cache._cache_file._load_index()
        return bool(index)
    except Exception:
        return False


def announce_compile(stream=None) -> None:
    """Say, once per process and before it starts, that the kernel is being compiled
    (numba's first call in a fresh install or after the source changed)."""
    global _compiled
    if _compiled:
        return
    _compiled = True
    if getattr(_scheme.integrate, "signatures", None) or kernel_cached():
        return
    where = Path(_scheme.__file__).parent / "__pycache__"
    print(f"compiling the simulator kernel, once, ~{COMPILE_S} s (cached in {where} for later runs) ...",
          file=stream or sys.stderr, flush=True)
