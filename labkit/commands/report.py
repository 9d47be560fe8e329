"""``labkit report``: model against measurement as one self-contained HTML page plus PNG figures."""
from __future__ import annotations

import argparse
from typing import Any

from labkit.errors import InputError

NAME = "report"
HELP = "build a self-contained HTML report (and PNG figures) comparing measurements with the model"


def _drive(text: str) -> tuple[float, float]:
    try:
        f, a = text.split(":")
        return float(f), float(a)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected FREQ_HZ:AMP_UM (e.g. 240:25), got {text!r}") from None


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
    parser.add_argument("--band-k", type=float, default=2.0, help="Monte Carlo band: mean +- K std (default 2)")
    parser.add_argument("--scheduler", help="tcp://HOST:PORT of a Dask scheduler for the knee simulations")
    parser.add_argument("--workers", type=int, help="local worker processes for the knee simulations")
    parser.add_argument("--title", default="labkit: model against measurement")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder (report.html, fig_*.png)")


def run(args: argparse.Namespace) -> dict[str, Any]:
    from analysis.report import build_report

    if not args.knee_duration_s > 0:
        raise InputError("must be > 0", key="--knee-duration-s", expected="a duration in s")
    summary = build_report(args.out, runs=args.runs, tracks=args.tracks, fit=args.fit, sims=args.sim,
                           params=args.params, knee_drives=args.knee_drives, simulate_knee=not args.no_simulate,
                           knee_duration_s=args.knee_duration_s, leg=args.leg - 1, band_k=args.band_k,
                           scheduler=args.scheduler, workers=args.workers, title=args.title, quiet=args.quiet or args.json)
    if not args.json:
        print(f"report: {summary['html']}")
        for name, status in summary["sections"].items():
            note = summary["missing"].get(name, "") or summary["notes"].get(name, "")
            print(f"  {name:14s} {status:8s} {note}")
        for row in summary["agreement"]:
            v = row["value"]
            print(f"  {row['quantity']}: {'n/a' if v is None else f'{v:.3g}'} {row['units']}")
    return summary
