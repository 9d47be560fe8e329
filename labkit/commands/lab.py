"""``labkit lab serve``: run the virtual lab until interrupted.

Prints the instruments' resource strings as one JSON object on standard
output (flushed at once, so a parent process can read it and connect), writes
a config a run can use as is (its instruments and control channel, the lab's
wiring; ``--config FILE``, else beside the lab's record in the user's runtime
folder, path on standard error), records the lab there (one record per serving
process: ``--lab`` runs and ``labkit off --lab`` find it), then serves until
SIGINT or SIGTERM; the lab is shut down (generator outputs off,
sockets and the pseudo-terminal closed) in every case.

``--vxi11`` also serves the generator and the scope over VXI-11
(``TCPIP0::127.x.y.z::inst0::INSTR``, each with a portmapper on port 111 of its own
loopback address): those resources then replace the raw sockets in the JSON, the
config and the record (the sockets stay served, listed in the record's ``sockets``).
Port 111 is privileged: without root the command ends with one line and exit 2.
``--hislip`` does the same over HiSLIP (``TCPIP0::127.0.0.1::hislip0,<port>::INSTR``, an
ephemeral port: no root needed).
"""
from __future__ import annotations

import argparse
import sys
import threading
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from labkit.jsonutil import Json

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
    from labkit.lab.miswire import MISWIRES
    serve.add_argument("--config", metavar="FILE", help="write the lab's config here (default: in the runtime "
                       "folder, beside the lab's record); an existing FILE needs --force")
    serve.add_argument("--force", action="store_true", help="overwrite an existing --config FILE")
    serve.add_argument("--miswire", action="append", choices=MISWIRES, default=[], metavar="FAULT",
                       help=f"cable the lab wrong on purpose (repeatable): {', '.join(MISWIRES)}")
    link = serve.add_mutually_exclusive_group()
    link.add_argument("--vxi11", action="store_true",
                      help="also serve the generator and the scope over VXI-11 (TCPIP0::host::inst0::INSTR; "
                           "port 111 needs root); the config and the JSON then give those resources")
    link.add_argument("--hislip", action="store_true",
                      help="also serve the generator and the scope over HiSLIP (TCPIP0::host::hislip0,PORT::INSTR); "
                           "the config and the JSON then give those resources")
    serve.add_argument("--amplifier-gain-db", type=float, default=20.0, metavar="DB",
                       help="the lab amplifier's real gain (default 20 dB, as its config declares)")


def run(args: argparse.Namespace) -> dict[str, Json]:
    from pathlib import Path

    from labkit.cli import emit_json, require_file
    from labkit.errors import InputError
    from labkit.lab import VirtualLab
    from labkit.lab.miswire import Miswiring

    robot = require_file(args.robot, "robot parameter file") if args.robot else None
    if args.config and Path(args.config).exists() and not args.force:
        raise InputError("already exists; give --force to overwrite it", file=args.config, key="--config")
    if args.config and not Path(args.config).resolve().parent.is_dir():
        raise InputError("the folder does not exist", file=args.config, key="--config")
    lab = VirtualLab(robot=robot, seed=args.seed, funcgen_model=args.funcgen, scope_model=args.scope,
                     vibrometer_model=args.vibrometer, miswire=Miswiring.from_names(args.miswire),
                     amplifier_gain_db=args.amplifier_gain_db, vxi11=args.vxi11,
                     hislip=args.hislip)
    lab.set_setup(args.setup)
    lab.set_spot(args.spot)
    stop = threading.Event()
    from labkit.experiments.locks import announce_lab, lab_file, withdraw_lab
    from labkit.experiments.template import lab_config_text

    config = Path(args.config) if args.config else lab_file().with_suffix(".toml")
    try:
        _start(lab)
        resources = {**lab.resources, **lab.vxi11_resources, **lab.hislip_resources}
        emit_json(resources)   # always: this line is how clients find the lab
        config.write_text(lab_config_text(args.setup, resources, lab.models, path=str(config)))
        # and this record is how `--lab` runs and `labkit off --lab` do
        announce_lab(resources, lab.models, config=str(config.resolve()), setup=args.setup,
                     miswire=lab.miswire.names(), **({"sockets": lab.resources} if resources != lab.resources else {}))
        if not args.json:
            models = ", ".join(f"{role}: {model}" for role, model in lab.models.items())
            print(f"virtual lab serving ({models}); Ctrl-C to stop\n"
                  f"its config: {config}  (labkit check {config}; "
                  f"labkit {'sweep inchip' if args.setup == 'inchip' else 'shaker'} {config} --out run.h5)",
                  file=sys.stderr, flush=True)
        while not stop.wait(0.5):
            pass
    finally:
        withdraw_lab()
        if not args.config:
            config.unlink(missing_ok=True)
        lab.close()
    return {}  # pragma: no cover - only reached if the wait ends without a signal


def _start(lab: Any) -> None:
    """Start the lab; a VXI-11 portmapper refused port 111 is bad input (one line, exit 2)."""
    from labkit.errors import InputError

    try:
        lab.start()
    except PermissionError as exc:
        lab.close()
        raise InputError(f"cannot bind the VXI-11 portmapper's port 111 ({exc.strerror or exc}): port 111 "
                         "is privileged", key="--vxi11",
                         expected="root (sudo labkit lab serve --vxi11), or no --vxi11 (raw sockets "
                                  "TCPIP0::host::port::SOCKET)") from None
