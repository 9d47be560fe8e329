"""``labkit lab serve``: run the virtual lab until interrupted.

Prints the instruments' resource strings as one JSON object on standard
output (flushed at once, so a parent process can read it and connect), then
serves until SIGINT or SIGTERM; the lab is shut down (generator outputs off,
sockets and the pseudo-terminal closed) in every case.
"""
from __future__ import annotations

import argparse
import sys
import threading
from typing import Any

NAME = "lab"
HELP = "the virtual lab: simulated instruments over real transports (lab serve)"


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="lab_command", metavar="ACTION")
    sub.required = True
    serve = sub.add_parser("serve", parents=[common], help="start the lab and serve until interrupted",
                           description="Start a simulated function generator and oscilloscope (raw SCPI "
                                       "sockets on 127.0.0.1; default Keysight 33522B and InfiniiVision "
                                       "DSOX3024T, or the Rigol DG1000Z/DS1000Z, 33511B, 33220A ...) and a "
                                       "Polytec vibrometer controller (pseudo-terminal; OFV-5000 or OFV-3001); "
                                       "print their resource strings as one JSON object; serve until Ctrl-C.")
    serve.add_argument("--robot", metavar="FILE", help="robot parameter file (TOML); default: the paper's")
    serve.add_argument("--seed", type=int, default=0, help="seed of the lab's noise (default 0)")
    serve.add_argument("--setup", choices=("inchip", "shaker"), default="inchip", help="initial set-up")
    serve.add_argument("--spot", choices=("body", "hip", "knee", "tray"), default="knee",
                       help="initial laser spot")
    from labkit.lab.models import FUNCGEN_MODELS, SCOPE_MODELS, VIBROMETER_MODELS
    serve.add_argument("--funcgen", choices=list(FUNCGEN_MODELS), default="33522B", metavar="MODEL",
                       help=f"simulated generator: {', '.join(FUNCGEN_MODELS)} (default 33522B)")
    serve.add_argument("--scope", choices=list(SCOPE_MODELS), default="DSOX3024T", metavar="MODEL",
                       help=f"simulated oscilloscope: {', '.join(SCOPE_MODELS)} (default DSOX3024T)")
    serve.add_argument("--vibrometer", choices=list(VIBROMETER_MODELS), default="OFV-5000", metavar="MODEL",
                       help="simulated vibrometer controller: OFV-5000 (default) or OFV-3001")


def run(args: argparse.Namespace) -> dict[str, Any]:
    from labkit.cli import emit_json, require_file
    from labkit.lab import VirtualLab

    robot = require_file(args.robot, "robot parameter file") if args.robot else None
    lab = VirtualLab(robot=robot, seed=args.seed, funcgen_model=args.funcgen, scope_model=args.scope,
                     vibrometer_model=args.vibrometer)
    lab.set_setup(args.setup)
    lab.set_spot(args.spot)
    stop = threading.Event()
    from labkit.experiments.locks import announce_lab, withdraw_lab

    try:
        lab.start()
        emit_json(lab.resources)   # always: this line is how clients find the lab
        announce_lab(lab.resources, lab.models)   # and this file is how `labkit off --lab` does
        if not args.json:
            models = ", ".join(f"{role}: {model}" for role, model in lab.models.items())
            print(f"virtual lab serving ({models}); Ctrl-C to stop", file=sys.stderr, flush=True)
        while not stop.wait(0.5):
            pass
    finally:
        withdraw_lab()
        lab.close()
    return {}  # pragma: no cover - only reached if the wait ends without a signal
