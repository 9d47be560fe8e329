"""``labkit off CONFIG``: turn every generator output of a rig off and confirm it.

The way back to a safe rig after anything: a crash, SIGKILL, a power cut of
the computer, a run that ended with "DRIVE OFF NOT CONFIRMED". Only the
config's ``[instruments.funcgen]`` table is read (model, resource, driver
settings), so a config that fails validation elsewhere still works; nothing
but the OFF commands and their confirmation is sent. ``--model`` and
``--resource`` name a generator without a config; ``--lab`` the generator of
every running ``labkit lab serve`` (each records its resources in the user's
runtime folder, one file per serving process).

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
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover - annotations only (the CLI starts light)
    from labkit.experiments.safety import OffSummary

NAME = "off"
HELP = "turn every generator output of a rig off and confirm it (after a crash, or any time)"


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.add_argument("config", nargs="?", help="experiment config (TOML): its [instruments.funcgen] is used")
    parser.add_argument("--lab", action="store_true",
                        help="the generators of every running 'labkit lab serve' (instead of a config)")
    parser.add_argument("--model", help="generator model (33220A, 33500B, DG1000Z), instead of a config")
    parser.add_argument("--resource", help="generator VISA resource, instead of a config")
    parser.add_argument("--timeout-s", type=float, default=3.0, help="per-command timeout (default 3 s)")


def run(args: argparse.Namespace) -> dict[str, Any]:
    from labkit.experiments.safety import turn_off

    if args.lab:
        from labkit.errors import LabkitError
        from labkit.experiments.locks import served_lab, served_labs

        labs = served_labs() or [served_lab()]      # none: served_lab() says so (exit 2)
        summaries, failed = [], None
        for lab in labs:                            # every lab is tried, even after one failed
            try:
                summaries.append(turn_off(None, model=lab["models"]["funcgen"],
                                          resource=lab["resources"]["funcgen"], timeout_s=args.timeout_s))
                _print(args, summaries[-1])
            except LabkitError as exc:
                failed = failed or exc
        if failed is not None:
            raise failed
        return summaries[0] | {"labs": summaries}
    summary = turn_off(args.config, model=args.model, resource=args.resource, timeout_s=args.timeout_s)
    _print(args, summary)
    return dict(summary)


def _print(args: argparse.Namespace, summary: OffSummary) -> None:
    if not args.json:
        chans = ", ".join(str(c) for c in summary["channels_off"])
        print(f"{summary['instrument']} at {summary['resource']}: output(s) {chans} off (confirmed)"
              + (f"; the rig was in use by {summary['in_use_by']}" if summary.get("in_use_by") else ""))
