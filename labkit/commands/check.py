"""``labkit check CONFIG``: the wiring and loopback check before a run, one PASS / WARN / FAIL line per check."""
from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from labkit.jsonutil import Json

NAME = "check"
HELP = "check a rig's wiring before a run (identities, sync/trigger, drive, vibrometer, output off); exit 0 if no FAIL"


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.add_argument("config", help="experiment config (TOML), in-chip or shaker")
    parser.add_argument("--lab", action="store_true",
                        help="the running 'labkit lab serve' (else a virtual lab in-process) instead of the "
                             "config's resources")


def run(args: argparse.Namespace) -> dict[str, Json]:
    from labkit.experiments.bench import CheckFailed, run_check

    report = run_check(args.config, lab="served" if args.lab else False)
    if not args.json:
        for line in report.lines:
            print(line.text(), flush=True)
    n_fail = sum(line.status == "FAIL" for line in report.lines)
    n_warn = sum(line.status == "WARN" for line in report.lines)
    if n_fail:
        if args.json:
            from labkit.cli import emit_json

            emit_json(report.as_dict())
        raise CheckFailed(f"{n_fail} check(s) FAILED, {n_warn} warning(s): fix the wiring before a run")
    kind = "sweep inchip" if report.kind == "inchip" else "shaker"
    if not args.json:
        print(f"all checks passed ({n_warn} warning(s)); next: labkit {kind} {args.config} --out run.h5")
    return report.as_dict()
