"""Memory per point of a long run: a real ``labkit sweep inchip`` process against the virtual lab.

Prints ONE JSON object: the resident memory (``VmRSS`` of the ``labkit`` process, read from
``/proc``) against the points written (the run file, read without locking), sampled as the
run goes, and its least-squares slope in bytes per point after a warm-up of ``--warmup``
points (and before its last, so the run's end does not count), its slope over the second
half of them, and the resident memory at eleven points of the run. The lab runs in this
process, so its own records do not count. Target: under 100 bytes a point. Measured on a
loaded 2-core machine (load 15, ``--points 10000 --warmup 1000 --settle-s 0.01``): 32 bytes
a point (63.39 MiB at point 1017, 63.71 MiB at point 9994) with run-file layout 3 (text
fixed-length, both HDF5 caches bounded); 216 bytes a point (63.77 to 65.39 MiB at point 8735)
with layout 2 (variable-length strings, the metadata cache unbounded); 68 bytes a point over a
2000-point run (``--points 2000 --warmup 200``) with layout 3. Earlier: 674 bytes a
point over points 300-2000 before the chunk cache was bounded (docs/faults.md).

    python bench/memory_bench.py [--points 5000] [--warmup 500] [--settle-s 0.12]
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# the same in-chip sweep as the overhead bench
from run_bench import CONFIG

#: labkit's own repository (the bench runs ``python -m labkit`` from there)
REPO = Path(__file__).resolve().parents[1]


def rss_bytes(pid: int) -> int | None:
    """The resident memory of process ``pid`` (None once it has ended)."""
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def points_written(path: Path) -> int:
    """Complete points in the run file the ``labkit`` process is writing (0 until it can be read)."""
    import h5py

    with contextlib.suppress(Exception), h5py.File(path, "r", locking=False) as f:
        return len(f["points/index"])
    return 0


def measure(points: int, warmup: int, settle_s: float, dwell_cycles: float) -> dict:
    from labkit.experiments.session import lab_instruments_toml
    from labkit.lab import VirtualLab

    freqs = np.geomspace(2000.0, 3000.0, points)
    with tempfile.TemporaryDirectory() as tmp, VirtualLab(seed=3) as lab:
        text = CONFIG.format(freqs=", ".join(f"{f:.6f}" for f in freqs), settle_s=settle_s,
                             dwell_cycles=dwell_cycles, instruments=lab_instruments_toml())
        for role in ("funcgen", "scope", "vibrometer"):
            text = text.replace(lab_instruments_toml((role,)).split('resource = "')[1].split('"')[0],
                                lab.resources[role], 1)
        for role in ("funcgen", "scope"):        # memory is measured, not speed: a loaded machine may be slow
            text = text.replace(f"[instruments.{role}]\n", f"[instruments.{role}]\ntimeout_s = 10\n", 1)
        text = text.replace("[drive]", f'[instruments.control]\nmodel = "LabControl"\nresource = '
                                       f'"{lab.resources["control"]}"\n\n[drive]', 1)
        cfg, out = Path(tmp) / "mem.toml", Path(tmp) / "mem.h5"
        cfg.write_text(text)
        t0 = time.monotonic()
        proc = subprocess.Popen([sys.executable, "-m", "labkit", "sweep", "inchip", str(cfg), "--out", str(out),
                                 "--quiet"], cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        samples: list[tuple[int, int]] = []
        while proc.poll() is None:
            rss = rss_bytes(proc.pid)
            n = points_written(out)
            if rss is not None and warmup <= n < points:     # not the run's end (final status, summary)
                samples.append((n, rss))
            time.sleep(0.5)
        err = proc.stderr.read() if proc.stderr else ""
        wall = time.monotonic() - t0
        file_bytes = out.stat().st_size if out.exists() else 0
    if proc.returncode != 0 or len(samples) < 3:
        return {"error": f"exit {proc.returncode}: {err.strip()[-300:]}", "samples": len(samples)}
    n, rss = np.array(samples, dtype=float).T
    slope = float(np.polyfit(n, rss, 1)[0])
    late = n >= np.median(n)                     # the second half of the points measured
    late_slope = float(np.polyfit(n[late], rss[late], 1)[0]) if np.sum(late) >= 3 else float("nan")
    return {"points": points, "warmup_points": warmup, "samples": len(samples), "run_wall_s": round(wall, 1),
            "rss_slope_bytes_per_point": round(slope, 1),
            "rss_slope_second_half_bytes_per_point": round(late_slope, 1),
            "file_bytes_per_point": round(file_bytes / max(points, 1), 1),
            "rss_mib_at_points": {int(n[i]): round(rss[i] / 2**20, 2)
                                  for i in np.linspace(0, len(n) - 1, 11).round().astype(int)},
            "rss_first_mib": round(rss[0] / 2**20, 2),
            "rss_last_mib": round(rss[-1] / 2**20, 2), "points_first": int(n[0]), "points_last": int(n[-1])}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=5000)
    ap.add_argument("--warmup", type=int, default=500)
    ap.add_argument("--settle-s", type=float, default=0.12)
    ap.add_argument("--dwell-cycles", type=float, default=10.0)
    args = ap.parse_args(argv)
    res = measure(args.points, args.warmup, args.settle_s, args.dwell_cycles)
    out = {"bench": "memory_bench",
           "what": "RSS slope per point of a labkit sweep process (in-chip stepped sine, virtual lab in the bench)",
           **res, "target_bytes_per_point": 100.0,
           "meets_target": bool(res.get("rss_slope_bytes_per_point", float("inf")) < 100.0),
           "loadavg_1min": round(os.getloadavg()[0], 2), "cpus": os.cpu_count()}
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
