"""``labkit report``: model against measurement as one self-contained HTML page plus PNG figures."""
from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pragma: no cover - typing only
    from labkit.analysis.report.build import ReportSummary
    from labkit.analysis.report.sidebyside import Comparison

from labkit.errors import InputError

NAME = "report"
HELP = "build a self-contained HTML report (and PNG figures) comparing measurements with the model"


def _drive(text: str) -> tuple[float, float]:
    try:
        f, a = text.split(":")
        return float(f), float(a)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected FREQ_HZ:AMP_UM (e.g. 240:25), got {text!r}") from None


def _tolerance(text: str) -> tuple[str, float]:
    try:
        key, value = text.split("=")
        return key.strip(), float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE (e.g. knee_phase_deg_max=15), got {text!r}") from None


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.add_argument("--runs", nargs="+", default=[], metavar="RUN.h5",
                        help="run files: in-chip sweeps (FRFs) and shaker runs (speeds, knee records)")
    parser.add_argument("--tracks", nargs="+", default=[], metavar="TRACK.h5", help="track files (speeds)")
    parser.add_argument("--fit", metavar="ROBOT.fit.h5", help="resonance fit (kind modal_fit)")
    parser.add_argument("--sim", nargs="+", default=[], metavar="SIM.h5",
                        help="simulated sweeps (sim_sweep over freq_hz) and/or single runs (sim_result)")
    parser.add_argument("--params", metavar="ROBOT.toml",
                        help="robot parameters for simulating the knee at the chosen drives "
                             "(default: the TOML beside --fit, else the sweep's, else the defaults)")
    parser.add_argument("--knee-drive", dest="knee_drives", nargs="+", type=_drive, metavar="FREQ_HZ:AMP_UM",
                        help="drives at which to show the knee (default: those of the measured knee records)")
    parser.add_argument("--knee-duration-s", type=float, default=0.3, help="simulated time per knee drive (s)")
    parser.add_argument("--leg", type=int, default=1, choices=range(1, 7), help="which leg's knee to simulate")
    parser.add_argument("--no-simulate", action="store_true", help="never run the simulator; use --sim files only")
    parser.add_argument("--tolerance", dest="tolerances", nargs="+", type=_tolerance, default=[],
                        metavar="KEY=VALUE",
                        help="change what a comparison is judged against, e.g. speed_relative_rms_max=0.2 "
                             "(keys and defaults: labkit.analysis.compare.Tolerances)")
    parser.add_argument("--compare", nargs=2, metavar=("A_DIR", "B_DIR"),
                        help="instead of building a report, put two reports' headline numbers and section "
                             "verdicts side by side (with --out DIR also as DIR/compare.html and compare.json)")
    parser.add_argument("--scheduler", help="tcp://HOST:PORT of a Dask scheduler for the knee simulations")
    parser.add_argument("--workers", type=int, help="local worker processes for the knee simulations")
    parser.add_argument("--title", default="labkit: model against measurement")
    parser.add_argument("--out", metavar="DIR",
                        help="output folder (report.html, agreement.json, figure_data.json, fig_*.png and "
                             "fig_*.svg); created if missing, its parent must exist")
    parser.add_argument("--force", action="store_true", help="replace a report already in --out")


def run(args: argparse.Namespace) -> ReportSummary | Comparison:
    import shlex
    import sys
    from pathlib import Path

    from labkit.analysis.compare import Tolerances
    from labkit.analysis.report.build import build_report
    from labkit.outputs import check_output_dir

    if args.compare:
        return _compare(args)
    if not args.out:
        raise InputError("missing", key="--out", expected="an output folder (or --compare A_DIR B_DIR)")
    if not args.knee_duration_s > 0:
        raise InputError("must be > 0", key="--knee-duration-s", expected="a duration in s")
    try:
        tol = Tolerances.from_mapping(dict(args.tolerances))
    except ValueError as exc:
        raise InputError(str(exc), key="--tolerance") from None
    out = Path(args.out)
    figures = sorted(p.name for p in out.glob("fig_*.*")) if out.is_dir() else []
    check_output_dir(out, force=args.force, names=["report.html", "agreement.json", "figure_data.json", *figures])
    summary = build_report(args.out, runs=args.runs, tracks=args.tracks, fit=args.fit, sims=args.sim,
                           params=args.params, knee_drives=args.knee_drives, simulate_knee=not args.no_simulate,
                           knee_duration_s=args.knee_duration_s, leg=args.leg - 1, tolerances=tol,
                           command=shlex.join(["labkit", *sys.argv[1:]]),
                           scheduler=args.scheduler, workers=args.workers, title=args.title,
                           quiet=args.quiet or args.json)
    if not args.json:
        print(f"report: {summary['html']}")
        for name in summary["sections"]:
            note = summary["missing"].get(name, "") or summary["notes"].get(name, "")
            print(f"  {name:14s} {summary['verdicts'][name]:10s} {note}")
        for row in summary["agreement"]:
            print(f"  [{row['verdict']}] {row['comparison']}: {row['metric']} = {row['value_text']} "
                  f"(tolerance {row['tolerance']})")
    return summary


def _compare(args: argparse.Namespace) -> Comparison:
    from labkit.analysis.report.sidebyside import compare_reports, comparison_lines

    result = compare_reports(*args.compare)
    if args.out:
        from pathlib import Path

        from labkit.analysis.report.sidebyside import comparison_html
        from labkit.outputs import atomic_outputs, check_output_dir

        out = Path(args.out)
        check_output_dir(out, force=args.force, names=["compare.html", "compare.json"])
        out.mkdir(exist_ok=True)
        import json

        with atomic_outputs([out / "compare.html", out / "compare.json"]) as (t_html, t_json):
            t_html.write_text(comparison_html(result), encoding="utf-8")
            t_json.write_text(json.dumps(result, indent=1), encoding="utf-8")
        result["html"] = str(out / "compare.html")
    if not args.json:
        print("\n".join(comparison_lines(result)))
        if args.out:
            print(f"written: {result['html']}")
    return result
