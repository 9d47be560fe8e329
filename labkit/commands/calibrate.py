"""``labkit calibrate``: fit chosen model parameters to measured speeds (and leg patterns)."""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from labkit.errors import InputError
from labkit.jsonutil import to_jsonable
from labkit.outputs import atomic_outputs, check_outputs

NAME = "calibrate"
HELP = "fit uncertain model parameters (c_r, c_ad_n, ...) to measured speeds; write a new parameter file"


def _bound(text: str) -> tuple[str, tuple[float, float]]:
    try:
        name, rng = text.split("=")
        lo, hi = rng.split(":")
        return name.strip(), (float(lo), float(hi))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected NAME=LO:HI (e.g. c_r=0.1:0.9), got {text!r}") from None


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.add_argument("measured", nargs="+", metavar="MEASURED",
                        help="shaker run files and/or track files, or a CSV/HDF5 table with "
                             "freq_hz, speed_mm_s, speed_std_mm_s[, pattern]")
    parser.add_argument("--fit", dest="names", required=True, metavar="NAMES",
                        help="comma-separated RobotParams fields to fit, e.g. c_r,c_ad_n,k_per_s2[1]")
    parser.add_argument("--params", metavar="ROBOT.toml", help="starting parameters (default: the defaults)")
    parser.add_argument("--out", required=True, metavar="OUT.toml", help="calibrated parameter file to write")
    parser.add_argument("--force", action="store_true", help="replace --out and its .calibration.json")
    parser.add_argument("--amp-um", type=float, help="tray amplitude for speed tables (um)")
    parser.add_argument("--bound", dest="bounds", nargs="+", type=_bound, default=[], metavar="NAME=LO:HI",
                        help="bounds (default: 0 to 4x the start value; c_r in 0..1)")
    parser.add_argument("--duration-s", type=float, default=1.0, help="simulated time per point (s)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--rel-step", type=float, default=0.05, help="finite-difference step, relative")
    parser.add_argument("--max-iterations", type=int, default=10)
    parser.add_argument("--scan", type=int, default=6,
                        help="Latin-hypercube points scored within the bounds before the local fit (0: none)")
    parser.add_argument("--scan-rounds", type=int, default=3,
                        help="rounds of scanning, each in a 4x narrower box around the best point (default 3)")
    parser.add_argument("--pattern-weight", type=float, default=1.0,
                        help="weight of leg-pattern residuals (0: speeds only)")
    parser.add_argument("--min-std-mm-s", type=float, default=0.05, help="floor of the speed std (mm/s)")
    parser.add_argument("--scheduler", help="tcp://HOST:PORT of a Dask scheduler (default: local processes)")
    parser.add_argument("--workers", type=int, help="local worker processes (default: one per core)")


def run(args: argparse.Namespace) -> dict[str, Any]:
    from labkit.analysis.observations import observations_from_files
    from labkit.sim import RobotParams
    from labkit.sim.calibrate import calibrate

    if not args.duration_s > 0:
        raise InputError("must be > 0", key="--duration-s", expected="a duration in s")
    if not 0 < args.rel_step < 1:
        raise InputError("must be in (0, 1)", key="--rel-step")
    names = [n.strip() for n in args.names.split(",") if n.strip()]
    if not names:
        raise InputError("no parameter named", key="--fit", expected="e.g. c_r,c_ad_n")
    out = Path(args.out)
    side = out.with_suffix(".calibration.json")
    if out.suffix.lower() != ".toml":
        raise InputError("not a .toml path", file=out, key="--out", expected="OUT.toml")
    check_outputs([out, side], force=args.force)         # before any simulation
    params = RobotParams.from_toml(args.params) if args.params else RobotParams()
    obs = observations_from_files(args.measured, amp_um=args.amp_um)
    cal = calibrate(params, names, obs, duration_s=args.duration_s, seed=args.seed, bounds=dict(args.bounds),
                    rel_step=args.rel_step, pattern_weight=args.pattern_weight, max_iterations=args.max_iterations,
                    min_std_mm_s=args.min_std_mm_s, scan=max(0, args.scan), scan_rounds=max(1, args.scan_rounds),
                    scheduler=args.scheduler,
                    workers=args.workers, quiet=args.quiet or args.json)
    prov = cal.provenance()
    prov["calibration"]["start_params"] = args.params or "RobotParams() defaults"
    summary = {"out": str(out), **cal.summary()}
    # both written to temporary names, then renamed together: old files survive any failed write
    with atomic_outputs([out, side]) as (tmp, tmp_side):
        cal.params.to_toml(tmp, provenance=prov)
        tmp_side.write_text(json.dumps(to_jsonable(summary, finite=True), indent=1), encoding="utf-8")
    summary["details"] = str(side)
    if not args.json:
        print(f"calibrated {', '.join(cal.names)} on {len(obs.freq_hz)} points ({cal.n_sims} simulations)")
        for n, d in summary["parameters"].items():
            print(f"  {n}: {d['initial']:.4g} -> {d['fitted']:.4g} +- {d['std']:.2g}")
        print(f"  RMS speed error: {cal.before['rms_error_mm_s']:.3g} -> {cal.after['rms_error_mm_s']:.3g} mm/s")
        if "pattern_agreement" in cal.before:
            print(f"  pattern agreement: {cal.before['pattern_agreement']:.2f} -> {cal.after['pattern_agreement']:.2f}")
        print(f"wrote {out}")
    return summary
