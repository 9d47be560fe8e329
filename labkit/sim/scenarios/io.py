"""HDF5 files of scenarios that hold several runs or several sweeps."""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from labkit.sim.result import SimResult


def write_runs(path: Path, kind: str, runs: Sequence[tuple[str, SimResult]], info: Mapping[str, Any]) -> Path:
    """Several SimResults in one file: each run's traces under /runs/<label>, units on each."""
    import h5py

    from labkit.h5io import put, put_json, stamp

    with h5py.File(path, "w") as f:
        stamp(f, kind)
        put_json(f, "summary_json", dict(info))
        for label, r in runs:
            g = f.create_group(f"runs/{label.replace(' ', '_')}")
            put(g, "t_s", r.t_s, "s")
            put(g, "foot_z_um", r.foot_z_um, "um")
            put(g, "body_z_um", r.body_z_um, "um")
            put(g, "ground_z_um", r.ground_z_um, "um")
            put(g, "contact", r.contact, "label", labels="0 AIR, 1 ADHESION, 2 REST")
            put(g, "patterns", np.array([str(p) for p in r.patterns], dtype="S16"), "label")
            put(g, "mean_speed_mm_s", float(r.mean_speed_mm_s), "mm/s")
    return path


def write_sweep_set(path: Path, sweeps: Mapping[str, Any]) -> Path:
    """Several sweeps in one file (kind ``sim_sweep_set``), one group per label."""
    import h5py

    from labkit.h5io import stamp

    with h5py.File(path, "w") as h:
        stamp(h, "sim_sweep_set")
        for label, s in sweeps.items():
            s.write_group(h.create_group(label))
    return path
