"""``labkit shaker CONFIG --out FILE``: out-of-chip shaker run of a released robot.

A grid of frequencies x amplitudes (drive volts, or tray displacement reached
by measuring the tray with the vibrometer and adjusting the drive); at each
point the tray's and the robot's vertical velocity are recorded, with an
optional video. Interlocks: vibrometer over-range, tray displacement limit,
shaker envelope.
"""
from __future__ import annotations

import argparse
from typing import Any

NAME = "shaker"
HELP = "shaker run: frequency x amplitude grid, tray and robot velocity, optional video"


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    from labkit.commands.sweep import add_experiment_arguments

    add_experiment_arguments(parser)


def run(args: argparse.Namespace) -> dict[str, Any]:
    from labkit.commands.sweep import print_summary
    from labkit.experiments.session import run_session

    summary = run_session("shaker", args.config, args.out, lab="served" if args.lab else False,
                          resume=args.resume, quiet=args.quiet, seed=args.seed, force=args.force,
                          retry_interlocked=args.retry_interlocked)
    if not args.json:
        print_summary(summary)
    return dict(summary)
