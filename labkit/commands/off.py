"""``labkit off CONFIG``: turn every generator output of a rig off and confirm it.

The way back to a safe rig after anything: a crash, SIGKILL, a power cut of
the computer, a run that ended with "DRIVE OFF NOT CONFIRMED". Only the
config's ``[instruments.funcgen]`` table is read (model, resource, driver
settings), so a config that fails validation elsewhere still works; nothing
but the OFF commands and their confirmation is sent. ``--model`` and
``--resource`` name a generator without a config; ``--lab`` the generator of
the running ``labkit lab serve`` (which records its resources in the user's
runtime folder).

Every channel of the generator is switched off (``OUTPn OFF``), the generator
confirms it has processed them (``*OPC?``), then each channel's state is read
back (``OUTPn?``). Exit 0 when every output reads off; exit 4 with a banner
when that cannot be confirmed (turn the output off by hand); exit 2 for a
config without a generator.

The rig may belong to a run in progress (another process): its drive is
switched off all the same (this is the emergency stop), and the run flags
its next point as having no drive.
"""
from __future__ import annotations

import argparse
from typing import Any

NAME = "off"
HELP = "turn every generator output of a rig off and confirm it (after a crash, or any time)"


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.add_argument("config", nargs="?", help="experiment config (TOML): its [instruments.funcgen] is used")
    parser.add_argument("--lab", action="store_true",
                        help="the generator of the running 'labkit lab serve' (instead of a config)")
    parser.add_argument("--model", help="generator model (33220A, 33500B, DG1000Z), instead of a config")
    parser.add_argument("--resource", help="generator VISA resource, instead of a config")
    parser.add_argument("--timeout-s", type=float, default=3.0, help="per-command timeout (default 3 s)")


def run(args: argparse.Namespace) -> dict[str, Any]:
    from labkit.experiments.safety import turn_off

    model, resource = args.model, args.resource
    if args.lab:
        from labkit.experiments.locks import served_lab

        lab = served_lab()
        model, resource = lab["models"]["funcgen"], lab["resources"]["funcgen"]
    summary = turn_off(None if args.lab else args.config, model=model, resource=resource,
                       timeout_s=args.timeout_s)
    if not args.json:
        chans = ", ".join(str(c) for c in summary["channels_off"])
        print(f"{summary['instrument']} at {summary['resource']}: output(s) {chans} off (confirmed)"
              + (f"; the rig was in use by {summary['in_use_by']}" if summary.get("in_use_by") else ""))
    return summary
