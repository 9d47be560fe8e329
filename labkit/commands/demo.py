"""``labkit demo``: the whole toolkit on the virtual lab in one command.

In-chip sweep of body, hip and knee -> resonance fit -> robot parameter file;
shaker run over a frequency grid with video -> tracked speeds; simulated sweep
with the fitted parameters and Monte Carlo error bars -> report. Prints where
everything went and the headline figures (identified resonances against the
virtual robot's, measured against simulated speeds).
"""
from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from labkit.demo.results import DemoSummary

NAME = "demo"
HELP = "run the whole toolkit on the virtual lab: sweep, fit, shaker + video, track, simulate, report"


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="labkit-demo", metavar="DIR",
                        help="output folder (default ./labkit-demo; must be new or empty)")
    parser.add_argument("--quick", action="store_true",
                        help="fewer points, shorter records (well under a minute; for tests)")
    parser.add_argument("--seed", type=int, default=0, help="virtual lab noise and Monte Carlo seed")
    parser.add_argument("--force", action="store_true",
                        help="replace the output folder of an earlier `labkit demo`")


def run(args: argparse.Namespace) -> DemoSummary:
    if not args.quiet:      # at once, before the imports and the virtual lab's start (seconds)
        import sys

        print(f"labkit demo: 7 stages into {args.out}; the first start loads the simulator's compiled kernel "
              "(compiles it on a fresh install, once)", file=sys.stderr, flush=True)
    from labkit.demo.results import format_summary
    from labkit.demo.run import run_demo

    summary = run_demo(args.out, quick=args.quick, seed=args.seed, quiet=args.quiet, force=args.force)
    if not args.json:
        print(format_summary(summary))
    return summary
