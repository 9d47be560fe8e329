"""Peak memory of long single runs: ``labkit simulate shaker --duration-s D`` in a subprocess.

Prints ONE JSON object: per duration the wall time, the peak resident memory of the
process (``getrusage(RUSAGE_CHILDREN).ru_maxrss``, read after each run; each run is
its own process, so the figure is that run's peak once it exceeds the earlier ones)
and the samples the result kept. A long run keeps at most ``labkit.sim.core.MAX_SAMPLES``
samples (its last ``TAIL_PERIODS`` drive periods at the full rate), so the memory must not
grow with the duration; before, ``--duration-s 1000`` took 4.5 GB.

    python bench/sim_memory_bench.py [--durations 10,100,1000] [--freq-hz 240] [--amp-um 25]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def measure(duration_s: float, freq_hz: float, amp_um: float) -> dict:
    """One run in a fresh process; its wall time, peak RSS and kept samples."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run.h5"
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "labkit", "simulate", "shaker", "--freq-hz", str(freq_hz),
                               "--amp-um", str(amp_um), "--duration-s", str(duration_s), "--quiet", "--json",
                               "--out", str(out)], capture_output=True, text=True,
                              env={**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"})
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            raise SystemExit(proc.stderr)
        peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        import h5py

        with h5py.File(out) as f:
            samples = int(f["t_s"].shape[0])
        js = json.loads(proc.stdout.splitlines()[-1])
    return {"duration_s": duration_s, "wall_s": round(wall, 1), "peak_rss_mb": round(peak_mb, 1),
            "samples": samples, "mean_speed_mm_s": js["mean_speed_mm_s"], "n_steps": js["n_steps"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--durations", default="10,100,1000", help="comma list of simulated durations, s")
    ap.add_argument("--freq-hz", type=float, default=240.0)
    ap.add_argument("--amp-um", type=float, default=25.0)
    args = ap.parse_args()
    runs = [measure(float(d), args.freq_hz, args.amp_um) for d in args.durations.split(",")]
    print(json.dumps({"bench": "sim_memory", "freq_hz": args.freq_hz, "amp_um": args.amp_um, "runs": runs,
                      "limit_mb": 1024, "within_limit": all(r["peak_rss_mb"] < 1024 for r in runs)}))


if __name__ == "__main__":
    main()
