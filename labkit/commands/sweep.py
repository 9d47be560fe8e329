"""``labkit sweep inchip CONFIG --out FILE``: the in-chip swept-sine test of a tethered robot.

The generator drives the robot's PZT (no amplifier), the vibrometer reads the
velocity at each location (body, hip, knee by default; the person is asked
to move the laser, or the virtual lab is told), the scope records drive and
velocity, and each frequency point is demodulated into an FRF, appended and
flushed to the run file. ``--resume FILE`` continues an interrupted run.
"""
from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover - annotations only (the CLI starts light)
    from labkit.experiments.session import SessionSummary

NAME = "sweep"
HELP = "in-chip swept-sine test (stepped sine or chirp) into an HDF5 run file"


def add_experiment_arguments(p: argparse.ArgumentParser) -> None:
    """The options ``sweep inchip`` and ``shaker`` share."""
    p.add_argument("config", help="experiment config (TOML)")
    p.add_argument("--out", help="run file to write (HDF5; must not exist)")
    p.add_argument("--lab", action="store_true",
                   help="point the config's instruments at the running 'labkit lab serve' (the newest), "
                        "else at a virtual lab started in-process")
    p.add_argument("--resume", metavar="FILE",
                   help="continue this interrupted run file after its last complete point")
    p.add_argument("--seed", type=int, default=0, help="virtual lab noise seed (with --lab, "
                   "when no lab is served)")
    p.add_argument("--retry-interlocked", action="store_true",
                   help="with --resume: measure again the points an interlock stopped (their rows stay, "
                        "marked 'interlock, retried')")
    p.add_argument("--force", action="store_true",
                   help="replace an earlier run's per-point videos (FILE's _videos folder)")


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="experiment", metavar="EXPERIMENT", parser_class=type(parser))
    sub.required = True
    p = sub.add_parser("inchip", parents=[common], help="in-chip sweep of the tethered robot",
                       description=__doc__.split("\n\n")[1] if __doc__ else None)
    add_experiment_arguments(p)


def run(args: argparse.Namespace) -> dict[str, Any]:
    from labkit.experiments.session import run_session

    summary = run_session("inchip", args.config, args.out, lab="served" if args.lab else False,
                          resume=args.resume, quiet=args.quiet, seed=args.seed, force=args.force,
                          retry_interlocked=args.retry_interlocked)
    if not args.json:
        print_summary(summary)
    return dict(summary)


def print_summary(s: SessionSummary) -> None:
    print(f"{s['file']}: {s['status']}, {s['points_ok']} of {s['points_planned']} points measured"
          + (f", {s['points_interlocked']} stopped by an interlock" if s.get("points_interlocked") else ""))
    for il in s.get("interlocks", []):
        print(f"  interlock at point {il['index']}: {il['reason']}")
