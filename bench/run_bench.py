"""Per-point overhead of the experiment runner against the virtual lab (prints ONE JSON object).

Overhead is each stepped-sine point's wall time minus its settle and dwell
time: what programming the generator, arming and reading the scope (two
channels), the over-range query, demodulation and the flushed HDF5 append cost.
The target is under 20 ms a point. The lab runs in-process (real sockets, a
real pty), so its own work (computing the records) shares the CPU with the
runner; the machine's load average is reported alongside because a loaded
machine's scheduling delays show up in the wall time.

Usage: ``python bench/run_bench.py [--points N] [--settle-s S] [--dwell-cycles C]``
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
[instruments.funcgen]
model = "33500B"
resource = "TCPIP0::192.0.2.1::5025::SOCKET"
[instruments.scope]
model = "InfiniiVision"
resource = "TCPIP0::192.0.2.2::5025::SOCKET"
[instruments.vibrometer]
model = "OFV-5000"
resource = "ASRL/dev/ttyUSB0::INSTR"
[drive]
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


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=40)
    ap.add_argument("--settle-s", type=float, default=0.02)
    ap.add_argument("--dwell-cycles", type=float, default=10.0)
    args = ap.parse_args(argv)

    from labkit.experiments.config import comparable, load_inchip
    from labkit.experiments.plans import inchip_plan
    from labkit.experiments.rig import Rig
    from labkit.experiments.runfile import RunFile
    from labkit.experiments.runner import Runner
    from labkit.experiments.session import virtual_lab

    freqs = np.geomspace(1000.0, 2000.0, args.points)
    with tempfile.TemporaryDirectory() as tmp:
        cfg_path = Path(tmp) / "bench.toml"
        cfg_path.write_text(CONFIG.format(freqs=", ".join(repr(float(f)) for f in freqs), settle_s=args.settle_s,
                                          dwell_cycles=args.dwell_cycles))
        cfg = load_inchip(cfg_path)
        cpu0 = time.process_time()
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
        cpu = time.process_time() - cpu0
    pts = plan.points
    total = np.array([t["total_s"] for t in runner.timing])
    nominal = np.array([p.settle_s + p.dwell_s for p in pts])
    over_ms = (total - nominal) * 1e3
    # the first point pays one-off setup (record length, drive on): report it apart
    steady = over_ms[1:]
    out = {
        "bench": "run_bench", "what": "per-point overhead beyond settle + dwell, in-chip stepped sine, virtual lab",
        "points": len(pts), "settle_s": args.settle_s, "dwell_cycles": args.dwell_cycles,
        "freq_hz": [float(freqs[0]), float(freqs[-1])],
        "overhead_ms_median": round(float(np.median(steady)), 2),
        "overhead_ms_mean": round(float(np.mean(steady)), 2),
        "overhead_ms_p90": round(float(np.percentile(steady, 90)), 2),
        "overhead_ms_min": round(float(np.min(steady)), 2),
        "overhead_ms_first_point": round(float(over_ms[0]), 2),
        "target_ms": 20.0, "meets_target": bool(np.median(steady) < 20.0),
        "run_wall_s": round(wall, 3), "process_cpu_s_incl_lab": round(cpu, 3),
        "runner_cpu_ms_per_point": round(runner_cpu / len(pts) * 1e3, 2),
        "loadavg_1min": os.getloadavg()[0], "cpus": os.cpu_count(),
    }
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
