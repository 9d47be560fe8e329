"""Convergence of the mean speed, default step against a quarter step; prints ONE JSON object.

    python bench/convergence_table.py [--markdown] [--highg] [--duration-s S]

The cases of ``tests/sim/test_convergence.py`` (0.3 s runs, seed 0) plus 2 kHz, the
demo robot (``c_ad_n = 5e-8``) and 240 Hz at 100 um (23 g, where the robot leaves the
ground); ``--markdown`` prints the table of docs/model.md ("Numerics") instead. Also
reports each run's CPU time and its steps (default step).

``--highg``: instead, shaker runs at 9-90 g (200-600 Hz, 50-150 um; the body lands on its
squeeze film once a period), ``c_ad_n`` = 2 uN and 50 nN: the second table of "Numerics".
"""
from __future__ import annotations

import argparse
import json
import math
import time

from labkit.sim import PZT, RobotParams, Shaker, simulate
from labkit.sim.core import DT_CHECK_ABS_MM_S, DT_CHECK_REL, default_dt

SETS = {"published": RobotParams(), "c_ad 2 uN": RobotParams(c_ad_n=2e-6),
        "demo (c_ad 50 nN)": RobotParams(c_ad_n=5e-8)}
SCENARIOS = [PZT(1800, 20.0)] + [Shaker(f, 25.0) for f in (150, 240, 300, 700, 1500, 2000)] + [Shaker(240, 100.0)]
HIGHG_SETS = {"c_ad 2 uN": RobotParams(c_ad_n=2e-6), "demo (c_ad 50 nN)": RobotParams(c_ad_n=5e-8)}
HIGHG = [Shaker(f, a) for f, a in ((200, 100), (240, 50), (240, 75), (240, 100), (240, 150), (300, 50), (300, 100),
                                   (300, 150), (400, 50), (400, 100), (600, 50))]


def _label(sc: Shaker | PZT) -> str:
    if isinstance(sc, PZT):
        return f"PZT {sc.freq_hz / 1000:g} kHz, 20 V"
    g = sc.amp_um * 1e-6 * (2 * math.pi * sc.freq_hz) ** 2 / 9.81
    return f"shaker {sc.freq_hz:g} Hz, {sc.amp_um:g} um" + (f" ({g:.0f} g)" if g > 10 else "")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--markdown", action="store_true", help="print the docs/model.md table")
    ap.add_argument("--highg", action="store_true", help="the high-acceleration runs instead")
    ap.add_argument("--duration-s", type=float, default=0.3)
    args = ap.parse_args()
    sets, scenarios = (HIGHG_SETS, HIGHG) if args.highg else (SETS, SCENARIOS)
    simulate(RobotParams(), Shaker(240, 25), 0.002)          # compile outside the timings
    rows = []
    for sc in scenarios:
        row: dict = {"run": _label(sc)}
        for name, p in sets.items():
            dt = default_dt(p, sc)
            c0 = time.process_time()
            a = simulate(p, sc, args.duration_s, seed=0)
            cpu = time.process_time() - c0
            b = simulate(p, sc, args.duration_s, seed=0, dt_s=dt / 4)
            tol = max(DT_CHECK_REL * abs(b.mean_speed_mm_s), DT_CHECK_ABS_MM_S)
            row[name] = {"default_mm_s": round(a.mean_speed_mm_s, 4), "quarter_mm_s": round(b.mean_speed_mm_s, 4),
                         "agree": abs(a.mean_speed_mm_s - b.mean_speed_mm_s) <= tol, "dt_s": dt,
                         "cpu_s_default": round(cpu, 3), "steps": a.n_steps, "counters": a.counters}
        rows.append(row)
    if args.markdown:
        print("| run | " + " | ".join(f"{n}: default / quarter (mm/s)" for n in sets) + " |")
        print("|---|" + "---|" * len(sets))
        for row in rows:
            cells = [f"{row[n]['default_mm_s']:.4g} / {row[n]['quarter_mm_s']:.4g}"
                     + ("" if row[n]["agree"] else " (!)") for n in sets]
            print(f"| {row['run']} | " + " | ".join(cells) + " |")
        return
    tol = f"max({DT_CHECK_REL:g} x speed, {DT_CHECK_ABS_MM_S:g} mm/s)"
    print(json.dumps({"duration_s": args.duration_s, "seed": 0, "tolerance": tol, "highg": args.highg,
                      "rows": rows}))


if __name__ == "__main__":
    main()
