"""Per-point overhead of the experiment runner against the virtual lab (prints ONE JSON object).

Overhead is each stepped-sine point's wall time minus its settle and dwell
time: what programming the generator, arming and reading the scope (two
channels), the over-range query, demodulation and the flushed HDF5 append cost.
The target is under 20 ms a point. The live stream beside the run file (``RUN.live.jsonl``:
each point's and each event's JSON line, written and flushed) is timed on its own:
target under 2 ms a point, included in the overhead. The lab runs in-process (real sockets, a
real pty), so its own work (computing the records) shares the CPU with the
runner; the machine's load average is reported alongside because a loaded
machine's scheduling delays show up in the wall time.

Two runs: settled long enough that the lab answers with the analytic steady
state (the headline: runner + transports), and settled briefly so the lab
also simulates every transient on the same two cores (reported alongside).

Usage: ``python bench/run_bench.py [--points N] [--dwell-cycles C]``
"""
from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

CONFIG = """
[run]
locations = ["knee"]
{instruments}[drive]
amp_vpp = 4.0
offset_v = 2.0
[frequencies]
list_hz = [{freqs}]
[method]
settle_s = {settle_s}
dwell_cycles = {dwell_cycles}
[scope]
drive_channel = 1
velocity_channel = 2
[vibrometer]
scale_mm_s_per_v = 25.0
"""


def measure(points: int, settle_s: float, dwell_cycles: float) -> dict:
    """Run one in-chip sweep on a fresh virtual lab; per-point overhead statistics."""
    from labkit.experiments.config import comparable, load_inchip
    from labkit.experiments.plans import inchip_plan
    from labkit.experiments.rig import Rig
    from labkit.experiments.runfile import RunFile
    from labkit.experiments.runner import Runner
    from labkit.experiments.session import lab_instruments_toml, virtual_lab

    freqs = np.geomspace(1000.0, 2000.0, points)
    with tempfile.TemporaryDirectory() as tmp:
        cfg_path = Path(tmp) / "bench.toml"
        cfg_path.write_text(CONFIG.format(freqs=", ".join(repr(float(f)) for f in freqs), settle_s=settle_s,
                                          dwell_cycles=dwell_cycles, instruments=lab_instruments_toml()))
        cfg = load_inchip(cfg_path)
        with virtual_lab(cfg) as (lab, cfg):
            plan = inchip_plan(cfg)
            with RunFile.create(Path(tmp) / "bench.h5", cfg, comparable(cfg), plan.points_total) as run, \
                    Rig(cfg) as rig:
                runner = Runner(rig, run, cfg, quiet=True)
                t0 = time.monotonic()
                th0 = time.thread_time()
                runner.run(plan)
                runner_cpu = time.thread_time() - th0        # this thread only: the runner, not the lab
                wall = time.monotonic() - t0
            lab_settle_s = float(lab.model.settle_s()) if hasattr(lab, "model") else float("nan")
    pts = plan.points
    total = np.array([t["total_s"] for t in runner.timing])
    nominal = np.array([p.settle_s + p.dwell_s for p in pts])
    over_ms = (total - nominal) * 1e3
    steady = over_ms[1:]          # the first point pays one-off setup (record length, drive on)
    return {
        "points": len(pts), "settle_s": settle_s, "dwell_cycles": dwell_cycles,
        "lab_computes_transients": bool(settle_s < lab_settle_s),
        "overhead_ms_median": round(float(np.median(steady)), 2),
        "overhead_ms_mean": round(float(np.mean(steady)), 2),
        "overhead_ms_p90": round(float(np.percentile(steady, 90)), 2),
        "overhead_ms_min": round(float(np.min(steady)), 2),
        "overhead_ms_first_point": round(float(over_ms[0]), 2),
        "runner_cpu_ms_per_point": round(runner_cpu / len(pts) * 1e3, 2),
        # the live stream (RUN.live.jsonl): building and writing each point's and event's line
        "live_stream_ms_per_point": round(runner.live.cost_s / len(pts) * 1e3, 3),
        "run_wall_s": round(wall, 3),
    }


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=40)
    ap.add_argument("--dwell-cycles", type=float, default=10.0)
    args = ap.parse_args(argv)
    # Settled long enough, the lab answers with the analytic steady state: the overhead is the
    # runner's and the transports'. Settled briefly, the lab also simulates each point's
    # transient on the same CPU (its cost, not the runner's, but it is in the wall time).
    steady = measure(args.points, 0.12, args.dwell_cycles)
    transient = measure(args.points, 0.02, args.dwell_cycles)
    out = {
        "bench": "run_bench",
        "what": "per-point wall time beyond settle + dwell, in-chip stepped sine, 1-2 kHz, virtual lab in-process",
        "overhead_ms_median": steady["overhead_ms_median"], "target_ms": 20.0,
        "meets_target": bool(steady["overhead_ms_median"] < 20.0),
        "live_stream_ms_per_point": steady["live_stream_ms_per_point"], "live_target_ms": 2.0,
        "live_meets_target": bool(steady["live_stream_ms_per_point"] < 2.0),
        "lab_steady_state": steady, "lab_simulating_transients": transient,
        "loadavg_1min": round(os.getloadavg()[0], 2), "cpus": os.cpu_count(),
    }
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
