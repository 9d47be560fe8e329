"""Benchmark: a three-location modal fit of 4000 frequency lines, stabilisation diagram included.

Prints one JSON object: wall time per fit (median of repeats; target < 0.5 s)
and the accuracy of the fitted frequencies and damping ratios.

BLAS runs single-threaded unless ``OPENBLAS_NUM_THREADS`` is set: the matrices
here are small (4000 x ~40), where thread start-up costs more than it saves,
and a multi-threaded BLAS on a shared, busy machine can be 10x slower.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from labkit.analysis.modal.fit import fit_modes  # noqa: E402
from labkit.analysis.modal.synth import synthetic_frf  # noqa: E402

TARGET_S = 0.5


def main() -> dict:
    f = np.linspace(100.0, 5000.0, 4000)
    fn = np.array([438.0, 830.0, 3400.0])
    zeta = np.array([0.25, 0.02, 0.015])
    shapes = np.array([[0.05, 3.0, 0.3], [0.6, 2.2, -1.2], [0.25, 1.5, 6.0]]) * (2 * zeta * 2 * np.pi * fn)
    H = synthetic_frf(f, fn, zeta, shapes, noise=0.01, seed=0)
    frf = {"body": H[0], "hip": H[1], "knee": H[2]}
    fit_modes(f, frf)                                   # warm-up (imports, caches)
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        fit = fit_modes(f, frf)
        times.append(time.perf_counter() - t0)
    got_f = np.array([m.freq_hz for m in fit.modes])
    got_z = np.array([m.damping_ratio for m in fit.modes])
    ok_modes = got_f.size == fn.size
    s = fit.stabilisation
    out = {
        "bench": "fit", "lines": int(f.size), "locations": 3, "method": fit.method,
        "stabilisation_orders": [int(s.orders.min()), int(s.orders.max())], "stabilisation_poles": int(s.order.size),
        "seconds_median": float(np.median(times)), "seconds_min": float(np.min(times)),
        "target_s": TARGET_S, "n_modes": int(got_f.size),
        "freq_rel_err_max": float(np.max(np.abs(got_f / fn - 1))) if ok_modes else None,
        "damping_rel_err_max": float(np.max(np.abs(got_z / zeta - 1))) if ok_modes else None,
        "freq_rel_std": [float(m.freq_hz_std / m.freq_hz) for m in fit.modes],
        "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
    }
    out["ok"] = bool(ok_modes and out["seconds_median"] < TARGET_S)
    return out


if __name__ == "__main__":
    print(json.dumps(main()))
