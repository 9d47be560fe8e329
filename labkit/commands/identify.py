"""``labkit identify [RESOURCE...|--all]``: ask each instrument who it is, match a labkit driver."""
from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from labkit.jsonutil import Json

NAME = "identify"
HELP = "ask instruments who they are (*IDN?, the Polytec controllers' own query) and name their labkit driver"


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.add_argument("resources", nargs="*", metavar="RESOURCE",
                        help="VISA resources or serial ports (TCPIP0::host::5025::SOCKET, ASRL/dev/ttyUSB0::INSTR)")
    parser.add_argument("--all", action="store_true",
                        help="every resource 'labkit devices' lists (and every served virtual lab's instruments)")
    parser.add_argument("--timeout-s", type=float, default=0.5, help="per query (default 0.5 s)")
    parser.add_argument("--self-test", action="store_true", help="also run each SCPI instrument's self-test (*TST?)")


def run(args: argparse.Namespace) -> dict[str, Json]:
    from labkit.errors import InputError
    from labkit.experiments.discovery import identify, list_devices

    resources = list(args.resources)
    if args.all:
        found = list_devices()
        resources += [r for b in found.backends if b.name.startswith(("pyvisa", "pyserial")) for r in b.resources]
        resources += [res for lab in found.labs for role, res in lab["resources"].items() if role != "control"]
    resources = list(dict.fromkeys(resources))
    if not resources:
        raise InputError("no resource to identify", key="RESOURCE",
                         expected="one or more resources, or --all (see 'labkit devices')")
    if not 0.01 <= args.timeout_s <= 60:
        raise InputError(f"{args.timeout_s:g} s", key="--timeout-s", expected="0.01 to 60 s")
    results = [identify(r, args.timeout_s, args.self_test) for r in resources]
    if not args.json:
        for r in results:
            if r.ok:
                errs = "error queue empty" if not r.errors else "error queue held: " + "; ".join(r.errors)
                test = f"; self-test {r.self_test}" if r.self_test else ""
                print(f"{r.resource}: {r.reply}  -> driver {r.driver}  ({errs}{test})")
            else:
                print(f"{r.resource}: NO ANSWER: {r.problem}" + (f"\n    hint: {r.hint}" if r.hint else ""))
    return {"instruments": [r.as_dict() for r in results]}
