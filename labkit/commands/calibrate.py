"""``labkit calibrate``: fit model parameters to measured speeds (and leg patterns), or to the paper.

* ``labkit calibrate MEASURED... --fit NAMES --out OUT.toml``: least squares on measured speeds
  (:func:`labkit.sim.calibrate.calibrate`);
* ``labkit calibrate --paper --out OUT.toml``: the unmeasured parameters against the paper's
  observations (:func:`labkit.sim.paper.fit.calibrate_paper`); writing
  ``labkit/sim/presets/paper.toml`` makes the bundled ``paper`` preset;
* ``labkit calibrate --paper --sensitivity --params paper --out SENS.json``: one-at-a-time
  sensitivity of every observation around a parameter set (and ``SENS.png``).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, cast

from labkit.errors import InputError
from labkit.jsonutil import Json, to_jsonable
from labkit.outputs import atomic_outputs, check_outputs

if TYPE_CHECKING:       # the library is imported when a command runs, not when the parser is built
    from labkit.sim import RobotParams
    from labkit.sim.calibrate import CalibrationSummary, Runner
    from labkit.sim.paper.fit import PaperCalibration, PaperCalibrationSummary, Sensitivity, SensitivityJSON

    class CalibrateOutput(CalibrationSummary):
        """The command's summary for measured speeds: the fit's, and the two files written."""

        out: str
        details: str

    class PaperFitOutput(PaperCalibrationSummary):
        """The command's summary for ``--paper``: the search's, and the two files written."""

        out: str
        details: str

    class SensitivityOutput(SensitivityJSON, total=False):
        """The command's summary for ``--paper --sensitivity``: the rows, and the two files written."""

        out: str
        figure: str

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
    parser.add_argument("measured", nargs="*", metavar="MEASURED",
                        help="shaker run files and/or track files, or a CSV/HDF5 table with "
                             "freq_hz, speed_mm_s, speed_std_mm_s[, pattern]")
    parser.add_argument("--fit", dest="names", metavar="NAMES",
                        help="comma-separated RobotParams fields to fit, e.g. c_r,c_ad_n,k_per_s2[1]")
    parser.add_argument("--params", metavar="NAME|ROBOT.toml",
                        help="starting parameters: a preset (published, paper) or a file (default: published)")
    parser.add_argument("--out", required=True, metavar="OUT.toml",
                        help="calibrated parameter file to write (with --sensitivity: OUT.json)")
    paper = parser.add_argument_group("calibration to the paper's observations (--paper)")
    paper.add_argument("--paper", action="store_true",
                       help="fit the unmeasured parameters to the paper's observations (no MEASURED, no --fit)")
    paper.add_argument("--free", metavar="NAMES", help="free parameters (default: all of labkit.sim.paper.fit.FREE)")
    paper.add_argument("--paper-scan", type=int, default=32, metavar="N", help="Sobol points of the first scan")
    paper.add_argument("--paper-rounds", type=int, default=2, metavar="N", help="zoom rounds (N/2 points each)")
    paper.add_argument("--paper-polish", type=int, default=30, metavar="N", help="Nelder-Mead evaluations")
    paper.add_argument("--paper-ensemble", type=int, default=0, metavar="N",
                       help="score each candidate over its nominal robot and N robots drawn from the Monte Carlo "
                            "table (default 0: the nominal robot alone)")
    paper.add_argument("--paper-duration-s", type=float, default=1.0, metavar="S",
                       help="with --paper-ensemble: seconds per ensemble run (default 1)")
    paper.add_argument("--sensitivity", action="store_true",
                       help="with --paper: one-at-a-time sensitivity around --params instead of a fit")
    parser.add_argument("--force", action="store_true", help="replace --out and its .calibration.json")
    parser.add_argument("--amp-um", type=float, help="tray amplitude for speed tables (um)")
    parser.add_argument("--bound", dest="bounds", nargs="+", type=_bound, default=[], metavar="NAME=LO:HI",
                        help="bounds (default: 0 to 4x the start value; c_r in 0..1); with --paper: a search "
                             "box inside a free parameter's physical bounds")
    parser.add_argument("--duration-s", type=float, default=1.0, help="simulated time per point (s)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--rel-step", type=float, default=0.05, help="finite-difference step, relative")
    parser.add_argument("--max-iterations", type=int, default=10)
    # 12, not 6: a walking robot's speed can hinge on a parameter within a narrow basin (the demo
    # robot's 200 Hz speed halves between modal participation 0.5 and 0.6), which 6 points missed
    parser.add_argument("--scan", type=int, default=12,
                        help="Latin-hypercube points scored within the bounds before the local fit (0: none; "
                             "default 12)")
    parser.add_argument("--scan-rounds", type=int, default=3,
                        help="rounds of scanning, each in a 4x narrower box around the best point (default 3)")
    parser.add_argument("--pattern-weight", type=float, default=1.0,
                        help="weight of leg-pattern residuals (0: speeds only)")
    parser.add_argument("--min-std-mm-s", type=float, default=0.05, help="floor of the speed std (mm/s)")
    parser.add_argument("--scheduler", help="tcp://HOST:PORT of a Dask scheduler (default: local processes)")
    parser.add_argument("--workers", type=int, help="local worker processes (default: one per core)")


def _load_params(text: str | None) -> RobotParams:
    from labkit.sim.presets import load

    return load(text)

def run(args: argparse.Namespace) -> CalibrateOutput | PaperFitOutput | SensitivityOutput:
    if args.paper:
        return _run_paper(args)
    if args.sensitivity:
        raise InputError("--sensitivity needs --paper", key="--sensitivity", expected="--paper --sensitivity")
    return _run_measured(args)


def _check_measured_args(args: argparse.Namespace) -> list[str]:
    """The names to fit; InputError naming the first bad argument."""
    if not args.measured:
        raise InputError("no measured files", key="MEASURED", expected="shaker run/track files or a speed table "
                         "(or --paper to calibrate to the paper's observations)")
    if not args.names:
        raise InputError("no parameters to fit", key="--fit", expected="e.g. --fit c_r,c_ad_n")
    if not args.duration_s > 0:
        raise InputError("must be > 0", key="--duration-s", expected="a duration in s")
    if not 0 < args.rel_step < 1:
        raise InputError("must be in (0, 1)", key="--rel-step")
    names = [n.strip() for n in args.names.split(",") if n.strip()]
    if not names:
        raise InputError("no parameter named", key="--fit", expected="e.g. c_r,c_ad_n")
    return names


def _run_measured(args: argparse.Namespace) -> CalibrateOutput:
    """Least squares on measured speeds: OUT.toml and OUT.calibration.json."""
    from labkit.analysis.observations import observations_from_files
    from labkit.sim.calibrate import FitOptions, Runner, calibrate

    names = _check_measured_args(args)
    out = Path(args.out)
    side = out.with_suffix(".calibration.json")
    if out.suffix.lower() != ".toml":
        raise InputError("not a .toml path", file=out, key="--out", expected="OUT.toml")
    check_outputs([out, side], force=args.force)         # before any simulation
    params = _load_params(args.params)
    obs = observations_from_files(args.measured, amp_um=args.amp_um)
    options = FitOptions(duration_s=args.duration_s, seed=args.seed, bounds=dict(args.bounds), rel_step=args.rel_step,
                         pattern_weight=args.pattern_weight, max_iterations=args.max_iterations,
                         min_std_mm_s=args.min_std_mm_s, scan=max(0, args.scan), scan_rounds=max(1, args.scan_rounds))
    cal = calibrate(params, names, obs, options,
                    Runner(scheduler=args.scheduler, workers=args.workers, quiet=args.quiet or args.json))
    prov = cal.provenance(args.params or "RobotParams() defaults")
    summary: CalibrateOutput = {"out": str(out), "details": str(side), **cal.summary()}
    # both written to temporary names, then renamed together: old files survive any failed write
    with atomic_outputs([out, side]) as (tmp, tmp_side):
        cal.params.to_toml(tmp, provenance=cast("dict[str, Json]", prov))
        side_js = {k: v for k, v in summary.items() if k != "details"}
        tmp_side.write_text(json.dumps(to_jsonable(side_js, finite=True), indent=1), encoding="utf-8")
    if not args.json:
        print(f"calibrated {', '.join(cal.names)} on {len(obs.freq_hz)} points ({cal.n_sims} simulations)")
        for n, d in summary["parameters"].items():
            print(f"  {n}: {d['initial']:.4g} -> {d['fitted']:.4g} +- {d['std']:.2g}")
        print(f"  RMS speed error: {cal.before.rms_error_mm_s:.3g} -> {cal.after.rms_error_mm_s:.3g} mm/s")
        if cal.before.pattern_agreement is not None and cal.after.pattern_agreement is not None:
            print(f"  pattern agreement: {cal.before.pattern_agreement:.2f} -> {cal.after.pattern_agreement:.2f}")
        print(f"wrote {out}")
    return summary


def _run_paper(args: argparse.Namespace) -> PaperFitOutput | SensitivityOutput:
    from labkit.sim.calibrate import Runner
    from labkit.sim.paper.fit import free_by_name

    if args.measured or args.names:
        raise InputError("--paper fits the paper's observations, not measured files", key="--paper",
                         expected="no MEASURED and no --fit (use --free to choose parameters)")
    free = None if not args.free else [n.strip() for n in args.free.split(",") if n.strip()]
    known = list(free_by_name())
    for n in free or []:
        if n not in known:
            raise InputError(f"unknown free parameter {n!r}", key="--free", expected=", ".join(known))
    runner = Runner(scheduler=args.scheduler, workers=args.workers, quiet=args.quiet or args.json)
    if args.sensitivity:
        return _paper_sensitivity(args, free, runner)
    return _paper_fit(args, free, runner)


def _paper_sensitivity(args: argparse.Namespace, free: list[str] | None, runner: Runner) -> SensitivityOutput:
    """``--paper --sensitivity``: one-at-a-time around ``--params``; OUT.json and OUT.png."""
    from labkit.sim import RobotParams
    from labkit.sim.paper.fit import sensitivity

    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise InputError("not a .json path", file=out, key="--out", expected="SENS.json")
    png = out.with_suffix(".png")
    check_outputs([out, png], force=args.force)
    sens = sensitivity(_load_params(args.params), RobotParams(), free=free, seed=args.seed, runner=runner)
    js = sens.to_json(args.params or "published")
    with atomic_outputs([out, png]) as (tmp, tmp_png):
        tmp.write_text(json.dumps(to_jsonable(js, finite=True), indent=1), encoding="utf-8")
        _sensitivity_figure(sens, js["params"], tmp_png)
    if not runner.quiet:
        print(f"sensitivity around {js['params']} (cost {sens.base_cost:.3f}); x{sens.factor:g} steps")
        for r in sens.rows:
            print(f"  {r['parameter']:>20} {r['direction']:>4} -> cost {r['cost']:7.3f}"
                  + (f"; loses {', '.join(r['lost'])}" if r["lost"] else "")
                  + (f"; gains {', '.join(r['gained'])}" if r["gained"] else ""))
        print(f"wrote {out}, {png}")
    done: SensitivityOutput = {"out": str(out), "figure": str(png), **js}
    return done


def _paper_fit(args: argparse.Namespace, free: list[str] | None, runner: Runner) -> PaperFitOutput:
    """``--paper``: the search; OUT.toml (the preset) and OUT.calibration.json (every evaluation)."""
    from labkit.sim.paper.fit import SearchSettings, calibrate_paper

    out = Path(args.out)
    if out.suffix.lower() != ".toml":
        raise InputError("not a .toml path", file=out, key="--out", expected="OUT.toml")
    if not (args.paper_duration_s > 0):
        raise InputError(f"must be > 0, got {args.paper_duration_s}", key="--paper-duration-s",
                         expected="seconds per ensemble run")
    side = out.with_suffix(".calibration.json")
    check_outputs([out, side], force=args.force)
    start = _load_params(args.params)
    settings = SearchSettings(scan=max(1, args.paper_scan), rounds=max(0, args.paper_rounds),
                              polish=max(0, args.paper_polish), seed=args.seed,
                              ensemble=max(0, args.paper_ensemble), ensemble_duration_s=args.paper_duration_s,
                              box=tuple((n, lo, hi) for n, (lo, hi) in args.bounds))

    def log(msg: str) -> None:
        if not runner.quiet:
            print(msg, flush=True)

    cal = calibrate_paper(start, settings, free=free, runner=runner, log=log)
    prov = cal.provenance()
    prov["start_params"] = args.params or "published"
    summary = cal.summary()
    with atomic_outputs([out, side]) as (tmp, tmp_side):
        cal.params.replace(provenance={}).to_toml(tmp, provenance=cast("dict[str, Json]", prov))
        side_js = {"out": str(out), **summary, "history": [h.to_json() for h in cal.history]}
        tmp_side.write_text(json.dumps(to_jsonable(side_js, finite=True), indent=1), encoding="utf-8")
    if not runner.quiet:
        _print_paper_fit(cal, out)
    done: PaperFitOutput = {"out": str(out), "details": str(side), **summary}
    return done


def _print_paper_fit(cal: PaperCalibration, out: Path) -> None:
    print(f"calibrated {', '.join(f.name for f in cal.free)} to {len(cal.after.violations)} paper "
          f"observations ({len(cal.history)} evaluations, {cal.wall_s:.1f} s)")
    for n, v in cal.fitted.items():
        lo, hi = cal.spread[n]
        print(f"  {n}: {cal.start[n]:.4g} -> {v:.4g} (near-optimal {lo:.3g} .. {hi:.3g})")
    print(f"  cost (sum of tanh(violation), ~ observations not met): {cal.before.cost:.3f} -> {cal.after.cost:.3f}")
    for k, v in cal.after.violations.items():
        b = cal.before.violations[k]
        print(f"  {'PASS' if v == 0 else 'FAIL'}  {k}: violation {b:.3g} -> {v:.3g}")
    if cal.never_together:
        print("  never met together in the search: " + "; ".join(f"{a} / {b}" for a, b in cal.never_together))
    print(f"wrote {out}")


def _sensitivity_figure(sens: Sensitivity, params: str, path: Path) -> None:
    """Heat map: change of each observation's cost ``tanh(violation)`` per parameter step (rows) and observation."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    ids = list(sens.base)
    rows = sens.rows
    d = np.array([[np.tanh(r["violations"][i]) - np.tanh(sens.base[i]) for i in ids] for r in rows])
    fig, ax = plt.subplots(figsize=(9.0, 0.28 * len(rows) + 2.4), dpi=100)
    try:
        im = ax.imshow(d, cmap="RdBu_r", vmin=-1.0, vmax=1.0, aspect="auto")
        ax.set_xticks(range(len(ids)), ids, rotation=60, ha="right", fontsize=6)
        ax.set_yticks(range(len(rows)), [f"{r['parameter']} {r['direction']}" for r in rows], fontsize=6)
        for y, r in enumerate(rows):
            for x, i in enumerate(ids):
                if i in r["lost"] or i in r["gained"]:
                    ax.text(x, y, "x" if i in r["lost"] else "o", ha="center", va="center", fontsize=6)
        fig.colorbar(im, ax=ax, label="change of tanh(violation) (red: worse)")
        ax.set_title(f"one-at-a-time sensitivity around {params} (x{sens.factor:g}; "
                     "x: observation lost, o: gained)", fontsize=8)
        fig.tight_layout()
        fig.savefig(path, format="png")
    finally:
        plt.close(fig)
