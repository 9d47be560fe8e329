"""The paper's operating point over drawn robots, and its smoothness; prints ONE JSON object.

    python bench/ensemble_bench.py speed  [--params paper] [--seeds 0 1] [--robots 12] [--duration 2]
    python bench/ensemble_bench.py smooth [--params paper] [--seed 0] [--robots 12] [--duration 2] [--step 0.05]
    python bench/ensemble_bench.py law --runs SPEED.json... [--nominal-un 2.0 2.5 ...] [--held-ratio 0.85]

``speed``: |speed| at 240 Hz, 25 um (a constant tray amplitude) of the nominal robot and of
``--robots`` robots drawn from the Monte Carlo table (:data:`labkit.sim.uncertainty.DEFAULT_TABLE`)
per draw seed: median, mean, sd, range and how many lie in the paper's band 2-6 mm/s (Fig. 8 at
240 Hz, ``fig8_speed_240hz`` of ``labkit/sim/paper/observations.toml``).

Per seed it also lists each drawn robot's adhesion at first contact over the largest pull on its
feet standing on the tray (``adhesion_over_pull``, :func:`labkit.sim.paper.release.stuck_pull`:
the linear robot's, an upper bound; the simulated robot stays down from ~0.8 of it) and how many
robots it holds down (``held_by_adhesion``, ratio >= 1).

``law``: over saved ``speed`` outputs (any nominal adhesions; each names its parameter set), each
drawn robot's speed against its own adhesion at first contact: the rank correlation, the fit
``v = a + b ln(F_ad)`` over the walkers and its scatter, the band as an adhesion window, and, drawing
robots from that law (the adhesion log-normal with the table's sigma, the scatter normal, robots
held down above ``--held-ratio`` of their standing pull), the share inside the band at each
``--nominal-un`` and the chance that 12 robots have 8 or more inside.

``smooth``: the mean |speed| of the same drawn ensemble with one uncertain parameter of the
nominal robot moved by -``step`` and +``step`` (relative) before the draws (common random
numbers: every variant's robots carry the same draw factors), and the largest relative change
of the ensemble mean per parameter (the target: below 30 % at +-5 %).
"""
from __future__ import annotations

import argparse
import json
import statistics
import time
from typing import Any

from labkit.executor import map_tasks
from labkit.sim import RobotParams, Shaker
from labkit.sim.presets import load
from labkit.sim.sweep import PointTask, run_point

FREQ_HZ = 240.0
AMP_UM = 25.0
BAND_MM_S = (2.0, 6.0)
#: The uncertain parameters of the smoothness test: label -> how a relative factor changes the set.
PARAMETERS = ("b_g_body_n_m2_s", "b_g_foot_n_m2_s", "foot_pad_um", "film_gap_nm", "modal_participation",
              "body_mass_mg", "c_ad_n", "amp_um")


def scaled(params: RobotParams, name: str, factor: float) -> tuple[RobotParams, float]:
    """``params`` with one parameter times ``factor`` (body mass with the total) and the tray amplitude."""
    if name == "amp_um":
        return params, AMP_UM * factor
    if name == "body_mass_mg":
        body = params.body_mass_mg * factor
        return params.replace(body_mass_mg=body, mass_mg=params.mass_mg + body - params.body_mass_mg), AMP_UM
    return params.replace(**{name: getattr(params, name) * factor}), AMP_UM


def tasks(params: RobotParams, amp_um: float, robots: int, seed: int, duration_s: float,
          nominal: bool, control: str = "check") -> list[PointTask]:
    """:func:`labkit.sim.sweep.run_point` tasks: draw 0 the nominal robot, 1..robots drawn ones;
    ``control`` is ``simulate``'s error control (its default, ``"check"``, as every scenario run)."""
    first = 0 if nominal else 1
    sc = Shaker(FREQ_HZ, amp_um)
    from labkit.sim.uncertainty import DEFAULT_TABLE

    return [PointTask(params, sc, "amp_um", amp_um, d, seed, duration_s, dict(DEFAULT_TABLE), control=control)
            for d in range(first, robots + 1)]


def stats(speeds: list[float]) -> dict[str, Any]:
    lo, hi = BAND_MM_S
    return {"median": statistics.median(speeds), "mean": statistics.fmean(speeds),
            "sd": statistics.pstdev(speeds), "min": min(speeds), "max": max(speeds),
            "in_band": sum(lo <= s <= hi for s in speeds), "of": len(speeds), "still": sum(s < 0.1 for s in speeds),
            "speeds": [round(s, 3) for s in speeds]}


def adhesion_ratios(params: RobotParams, robots: int, seed: int) -> list[float]:
    """Each drawn robot's adhesion at first contact over the pull its feet feel standing on the
    tray (:func:`labkit.sim.paper.release.stuck_pull`, an upper bound): above 1 it cannot leave
    the tray (drawn as :func:`labkit.sim.sweep.run_point` draws them)."""
    import numpy as np

    from labkit.sim.paper.release import stuck_pull
    from labkit.sim.scenarios.runs import task_seed
    from labkit.sim.uncertainty import draw_params

    out = []
    for d in range(1, robots + 1):
        p = draw_params(params, np.random.default_rng(task_seed(seed, d)))
        out.append(round(p.c_ad_n / stuck_pull(p, FREQ_HZ, AMP_UM).threshold_n, 3))
    return out


def speed(args: argparse.Namespace, params: RobotParams) -> dict[str, Any]:
    from labkit.sim.paper.release import stuck_pull

    out: dict[str, Any] = {"nominal_threshold_n": stuck_pull(params, FREQ_HZ, AMP_UM).threshold_n}
    for seed in args.seeds:
        rows = map_tasks(run_point, tasks(params, AMP_UM, args.robots, seed, args.duration, True, args.control),
                         workers=args.workers, quiet=True)
        sp = [abs(r.speed_mm_s) for r in rows]
        ratio = adhesion_ratios(params, args.robots, seed)
        out[str(seed)] = {"nominal": round(sp[0], 3), "drawn": stats(sp[1:]), "adhesion_over_pull": ratio,
                          "held_by_adhesion": sum(r >= 1.0 for r in ratio)}
    return out


def smooth(args: argparse.Namespace, params: RobotParams) -> dict[str, Any]:
    variants = [("base", 1.0)] + [(n, f) for n in PARAMETERS for f in (1 - args.step, 1 + args.step)]
    batch: list[PointTask] = []
    for name, f in variants:
        p, amp = (params, AMP_UM) if name == "base" else scaled(params, name, f)
        batch += tasks(p, amp, args.robots, args.seed, args.duration, False, args.control)
    rows = map_tasks(run_point, batch, workers=args.workers, quiet=True)
    n = args.robots
    means = [statistics.fmean(abs(r.speed_mm_s) for r in rows[k * n:(k + 1) * n]) for k in range(len(variants))]
    base = means[0]
    table = {}
    for i, name in enumerate(PARAMETERS):
        down, up = means[1 + 2 * i], means[2 + 2 * i]
        table[name] = {"down": round(down, 3), "up": round(up, 3),
                       "largest_change": round(max(abs(down - base), abs(up - base)) / base, 3) if base else None}
    worst = max((v["largest_change"] or 0.0) for v in table.values())
    return {"base_mean_mm_s": round(base, 3), "step": args.step, "seed": args.seed, "parameters": table,
            "largest_change": worst, "target": 0.30, "met": worst < 0.30}


def drawn_adhesion_and_pull(params: RobotParams, robots: int, seed: int) -> list[tuple[float, float]]:
    """Each drawn robot's adhesion at first contact and standing pull ``T`` (N), drawn as
    :func:`labkit.sim.sweep.run_point` draws them."""
    import numpy as np

    from labkit.sim.paper.release import stuck_pull
    from labkit.sim.scenarios.runs import task_seed
    from labkit.sim.uncertainty import draw_params

    out = []
    for d in range(1, robots + 1):
        p = draw_params(params, np.random.default_rng(task_seed(seed, d)))
        out.append((p.c_ad_n, stuck_pull(p, FREQ_HZ, AMP_UM).threshold_n))
    return out


def law(args: argparse.Namespace) -> dict[str, Any]:
    """The speed against each robot's own adhesion over ``speed`` outputs (``--runs``), and the
    share of robots inside the band that law and the table's adhesion spread allow."""
    import numpy as np
    from scipy.stats import binom, spearmanr

    from labkit.sim.uncertainty import DEFAULT_TABLE

    F, T, V = [], [], []
    for name in args.runs:
        with open(name, encoding="utf-8") as fh:
            run = json.load(fh)
        params = load(run["params"])
        for seed, res in run["result"].items():
            if not seed.isdigit():
                continue
            speeds = res["drawn"]["speeds"]
            for (f, t), v in zip(drawn_adhesion_and_pull(params, len(speeds), int(seed)), speeds):
                F.append(f * 1e6)
                T.append(t * 1e6)
                V.append(v)
    f, t, v = np.array(F), np.array(T), np.array(V)
    walk = v > 0.1
    (a, b), *_ = np.linalg.lstsq(np.vstack([np.ones(walk.sum()), np.log(f[walk])]).T, v[walk], rcond=None)
    scatter = float(np.std(v[walk] - a - b * np.log(f[walk])))
    rng = np.random.default_rng(0)
    sigma = DEFAULT_TABLE["c_ad_n"] if args.sigma is None else args.sigma
    n, lo, hi = 200_000, *BAND_MM_S
    share = {}
    for c in args.nominal_un:
        fd = c * np.exp(sigma * rng.standard_normal(n))
        held = fd / rng.choice(t, n) > args.held_ratio
        vd = a + b * np.log(fd) + scatter * rng.standard_normal(n)
        p = float(((~held) & (vd >= lo) & (vd <= hi)).mean())
        share[str(c)] = {"share_in_band": round(p, 3), "p_8_of_12": round(float(1 - binom.cdf(7, 12, p)), 2)}
    return {"runs": args.runs, "robots": int(f.size), "walkers": int(walk.sum()),
            "spearman_all": round(float(spearmanr(f, v).statistic), 3),
            "spearman_walkers": round(float(spearmanr(f[walk], v[walk]).statistic), 3),
            "speed_mm_s": f"{a:.2f} + {b:.2f} ln(F_ad / 1 uN)", "scatter_mm_s": round(scatter, 2),
            "band_as_adhesion_un": [round(float(np.exp((hi - a) / b)), 2), round(float(np.exp((lo - a) / b)), 2)],
            "adhesion_sigma": sigma, "held_ratio": args.held_ratio, "by_nominal_adhesion_un": share}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("speed", "smooth", "law"))
    ap.add_argument("--params", default="paper", help="a preset name or a parameter file")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--robots", type=int, default=12)
    ap.add_argument("--duration", type=float, default=2.0)
    ap.add_argument("--step", type=float, default=0.05)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--control", choices=("check", "off"), default="check",
                    help="simulate's error control per run (default check, as the scenarios run)")
    ap.add_argument("--runs", nargs="+", default=[], help="law: JSON outputs of `speed` (each names its --params)")
    ap.add_argument("--nominal-un", type=float, nargs="+", default=[1.8, 2.0, 2.25, 2.5, 2.75, 3.0, 3.5],
                    help="law: nominal adhesions (uN) to draw ensembles at")
    ap.add_argument("--sigma", type=float, default=None,
                    help="law: the adhesion's log-normal spread to draw with (default: the Monte Carlo table's)")
    ap.add_argument("--held-ratio", type=float, default=0.85,
                    help="law: adhesion / standing pull above which a robot stays down (the simulator: 0.8-0.85)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    if args.what == "law":
        print(json.dumps({"what": "law", "result": law(args), "wall_s": round(time.perf_counter() - t0, 1)}))
        return
    params = load(args.params)
    body = speed(args, params) if args.what == "speed" else smooth(args, params)
    print(json.dumps({"what": args.what, "params": args.params, "freq_hz": FREQ_HZ, "amp_um": AMP_UM,
                      "robots": args.robots, "duration_s": args.duration, "result": body,
                      "settings": vars(args),
                      "wall_s": round(time.perf_counter() - t0, 1)}))


if __name__ == "__main__":
    main()
