"""Small synthetic run files in the interfaces.md layout, for the fit tests (written by the tests)."""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import h5py
import numpy as np

from labkit.analysis.modal.synth import synthetic_frf
from labkit.h5io import stamp

#: tethered-robot-like modes: hip (heavily damped), tether, knee
TRUE_HZ = (438.0, 830.0, 3400.0)
TRUE_ZETA = (0.25, 0.02, 0.015)
#: peak mobilities per location, (mm/s)/V, as in the virtual lab's physics
PEAKS = {"body": (0.05, 3.0, 0.3), "hip": (0.6, 2.2, -1.2), "knee": (0.25, 1.5, 6.0)}


def _col(g, name, data, units):
    ds = g.create_dataset(name, data=data, maxshape=(None,), chunks=True)
    ds.attrs["units"] = units


def write_inchip(path: Path, freq_hz: np.ndarray, *, modes_hz: Sequence[float] = TRUE_HZ,
                 zeta: Sequence[float] = TRUE_ZETA, peaks: dict = PEAKS, noise: float = 0.01,
                 seed: int = 0, status: str = "complete", nan_at: int | None = None) -> Path:
    """An in-chip run file whose FRFs are the velocity-resonance model plus relative noise."""
    wn = 2 * np.pi * np.asarray(modes_hz)
    with h5py.File(path, "w") as f:
        stamp(f, "run_inchip")
        f.attrs.update(config_toml="# synthetic", started_utc="", ended_utc="", status=status, method="stepped")
        for k, (loc, pk) in enumerate(peaks.items()):
            # R * 2 zeta w_i (j w) / (...) is synthetic_frf's mobility with shape R 2 zeta w_i
            shapes = np.asarray(pk) * 2 * np.asarray(zeta) * wn
            h = synthetic_frf(freq_hz, modes_hz, zeta, shapes[None, :], noise=noise, seed=seed + k)[0]
            if nan_at is not None:
                h[nan_at] = np.nan
            g = f.create_group(f"locations/{loc}")
            _col(g, "freq_hz", np.asarray(freq_hz, float), "Hz")
            _col(g, "frf", h, "(mm/s)/V")
            _col(g, "quality", np.full(h.size, 0.999), "1")
    return path


def write_shaker(path: Path, freq_hz: np.ndarray, *, fn_hz: float = 240.0, zeta: float = 0.1,
                 noise: float = 0.01, seed: int = 0) -> Path:
    """A shaker run file with a one-mode base-excitation transmissibility."""
    from labkit.analysis.frf import sdof_transmissibility

    rng = np.random.default_rng(seed)
    T = sdof_transmissibility(freq_hz, fn_hz, zeta)
    T = T * (1 + noise / np.sqrt(2) * (rng.standard_normal(T.size) + 1j * rng.standard_normal(T.size)))
    n = T.size
    with h5py.File(path, "w") as f:
        stamp(f, "run_shaker")
        f.attrs.update(config_toml="# synthetic", status="complete", robot_spot="knee")
        g = f.create_group("points")
        _col(g, "freq_hz", np.asarray(freq_hz, float), "Hz")
        _col(g, "transmissibility", T, "1")
        _col(g, "quality", np.full(n, 0.99), "1")
        ds = g.create_dataset("status", data=np.array(["ok"] * n, dtype=object), dtype=h5py.string_dtype())
        ds.attrs["units"] = "label"
        _col(g, "index", np.arange(1, n + 1), "1")
    return path
