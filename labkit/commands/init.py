"""``labkit init``: write a commented experiment config from the instruments found (or a served lab)."""
from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pragma: no cover - typing only
    from labkit.experiments.bench import InitSummary

NAME = "init"
HELP = "write a commented config (every key, unit, default, limit; TODOs for the wiring) from identified instruments"


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.add_argument("resources", nargs="*", metavar="RESOURCE", help="instruments to identify and use")
    parser.add_argument("--all", action="store_true", help="identify everything 'labkit devices' lists")
    parser.add_argument("--lab", action="store_true", help="the instruments of the running 'labkit lab serve'")
    parser.add_argument("--kind", choices=("inchip", "shaker"), default="inchip", help="experiment (default inchip)")
    parser.add_argument("--out", required=True, metavar="FILE", help="config to write (TOML; must not exist)")
    parser.add_argument("--force", action="store_true", help="overwrite an existing --out FILE")
    parser.add_argument("--start-hz", type=float, help="first frequency (default 300 in-chip, 150 shaker)")
    parser.add_argument("--stop-hz", type=float, help="last frequency (default 5000 in-chip, 300 shaker)")
    parser.add_argument("--count", type=int, help="frequencies (default 200 in-chip, 3 shaker)")
    parser.add_argument("--timeout-s", type=float, default=0.5, help="per identity query (default 0.5 s)")


def run(args: argparse.Namespace) -> InitSummary:
    from labkit.experiments.bench import init_config

    summary = init_config(args.out, kind=args.kind, resources=args.resources, all_devices=args.all, lab=args.lab,
                          band=(args.start_hz, args.stop_hz, args.count), force=args.force,
                          timeout_s=args.timeout_s)
    if not args.json:
        for role, found in summary["instruments"].items():
            print(f"{role}: {found or 'not found: TODO in the config'}")
        todo = summary["todo"]
        print(f"wrote {summary['config']}" + (f"; edit its TODOs ({', '.join(todo)})" if todo else ""))
        print(f"next: {summary['next']}")
    return summary
