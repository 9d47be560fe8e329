"""Converged by default: random Monte Carlo cases against their dt -> 0 limit; prints ONE JSON object.

    python bench/convergence_bench.py [--cases 20] [--duration-s 0.3] [--seed 0] [--fine 16]
    python bench/convergence_bench.py --pzt FREQ_HZ VOLTAGE_V --draw D [--fine 32]

Each case ``i`` (seed ``i`` for the run's start): a draw of the ``paper`` robot
(:func:`labkit.sim.uncertainty.draw_params`, the sweeps' uncertainty table) under a random
drive, alternately a shaker (100-1800 Hz, 5-100 um) and the PZT (100-2000 Hz, 1-30 V), all
uniform. The run at the default settings (``simulate``'s error control on) is compared with
the same run, error control off, at 1/``--fine`` of the default step: a case passes when it
is flagged chaotic, or when the two mean speeds agree within max(3 %, 0.02 mm/s) of the fine
one. Also printed: the same at the default step without error control (what runs gave
before), the CPU time of both, and for a case flagged chaotic whether two starts 0.05 um
apart differ beyond the tolerance at the fine step too (``chaotic_at_fine_step``).

``--pzt F V --draw D``: one case, the PZT drive on draw ``D`` of the sweeps' seeding (seed 0:
the robot of a sweep's draw ``D``, :func:`labkit.sim.sweep._task_seed`), against 1/``--fine``.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

from labkit.sim import PZT, RobotParams, Shaker, simulate
from labkit.sim.core import default_dt
from labkit.sim.errorcontrol import agree
from labkit.sim.sweep import _task_seed
from labkit.sim.uncertainty import draw_params


def random_case(seed: int, i: int) -> tuple[RobotParams, Shaker | PZT]:
    """Case ``i``: a draw of the paper robot from ``default_rng([seed, i])``, then its drive
    from the same generator: a shaker for even ``i``, the PZT for odd ``i``."""
    rng = np.random.default_rng([seed, i])
    p = draw_params(RobotParams.preset("paper"), rng)
    if i % 2 == 0:
        return p, Shaker(float(rng.uniform(100, 1800)), float(rng.uniform(5, 100)))
    return p, PZT(float(rng.uniform(100, 2000)), float(rng.uniform(1, 30)))


def case(p: RobotParams, sc: Shaker | PZT, duration_s: float, seed: int, fine: int) -> dict:
    """One case: default settings, the default step unchecked, and 1/``fine`` of it."""
    c0 = time.process_time()
    r = simulate(p, sc, duration_s, seed=seed)
    cpu = time.process_time() - c0
    c0 = time.process_time()
    plain = simulate(p, sc, duration_s, seed=seed, error_control="off")
    cpu_plain = time.process_time() - c0
    ref = simulate(p, sc, duration_s, seed=seed, dt_s=default_dt(p, sc) / fine, error_control="off")
    chaotic = r.convergence.status == "chaotic"
    ok = bool(agree(r.mean_speed_mm_s, ref.mean_speed_mm_s))
    limit_spread = None
    if chaotic:     # is it chaotic at the fine step too (starts 0.05 um apart, the control's probe)?
        other = simulate(p, sc, duration_s, seed=seed + 1, dt_s=default_dt(p, sc) / fine, error_control="off")
        limit_spread = other.mean_speed_mm_s - ref.mean_speed_mm_s
    return {"drive": {"type": type(sc).__name__.lower(), **sc.to_dict()}, "speed_mm_s": r.mean_speed_mm_s,
            "fine_speed_mm_s": ref.mean_speed_mm_s, "unchecked_speed_mm_s": plain.mean_speed_mm_s,
            "unchecked_agrees": bool(agree(plain.mean_speed_mm_s, ref.mean_speed_mm_s)),
            "agrees": ok, "chaotic": chaotic, "passes": chaotic or ok, "fine_seed_spread_mm_s": limit_spread,
            "chaotic_at_fine_step": None if limit_spread is None else
            not bool(agree(ref.mean_speed_mm_s + limit_spread, ref.mean_speed_mm_s)),
            "convergence": r.convergence.summary(),
            "flags": r.validity.flags if r.validity else [], "cpu_s": round(cpu, 3),
            "cpu_s_unchecked": round(cpu_plain, 3)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=20)
    ap.add_argument("--duration-s", type=float, default=0.3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--fine", type=int, default=16, help="the reference step: default / FINE")
    ap.add_argument("--pzt", type=float, nargs=2, metavar=("FREQ_HZ", "VOLTAGE_V"))
    ap.add_argument("--draw", type=int, default=0)
    args = ap.parse_args()
    simulate(RobotParams(), Shaker(240, 25), 0.002, error_control="off")       # compile outside the timings
    t0 = time.perf_counter()
    if args.pzt:
        paper = RobotParams.preset("paper")
        seed = _task_seed(args.seed, args.draw)
        p = draw_params(paper, np.random.default_rng(seed)) if args.draw else paper
        rows = [case(p, PZT(*args.pzt), args.duration_s, seed, args.fine)]
    else:
        rows = [case(*random_case(args.seed, i), args.duration_s, i, args.fine) for i in range(args.cases)]
    tol = "max(0.03 x fine speed, 0.02 mm/s)"
    print(json.dumps({"duration_s": args.duration_s, "seed": args.seed, "fine": args.fine, "tolerance": tol,
                      "cases": len(rows), "chaotic": sum(r["chaotic"] for r in rows),
                      "non_chaotic_agree": sum(r["agrees"] and not r["chaotic"] for r in rows),
                      "non_chaotic": sum(not r["chaotic"] for r in rows), "passes": sum(r["passes"] for r in rows),
                      "unchecked_agree": sum(r["unchecked_agrees"] for r in rows),
                      "chaotic_at_fine_step": sum(bool(r["chaotic_at_fine_step"]) for r in rows),
                      "not_converged": sum(r["convergence"]["status"] == "not_converged" for r in rows),
                      "wall_s": round(time.perf_counter() - t0, 1), "rows": rows}))


if __name__ == "__main__":
    main()
