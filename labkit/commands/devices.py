"""``labkit devices``: every instrument resource this computer can see, per back-end; nothing is sent."""
from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from labkit.jsonutil import Json

NAME = "devices"
HELP = "list the instrument resources each back-end can see (USB-TMC, VXI-11, HiSLIP, serial, virtual labs)"


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.description = (HELP + ". One line per back-end says what it can and cannot list, and why; "
                          "no instrument is sent anything. Then: labkit identify --all")


def run(args: argparse.Namespace) -> dict[str, Json]:
    from labkit.experiments.discovery import list_devices

    found = list_devices()
    if not args.json:
        for b in found.backends:
            print(f"{'+' if b.can_list else '-'} {b.name}: {b.note}")
            for r in b.resources:
                port = next((p for p in found.serial_ports if p.resource == r), None)
                extra = f"  ({port.description}{'; ' + port.usb if port and port.usb else ''})" if port else ""
                print(f"    {r}{extra}")
        print("next: labkit identify --all   (or labkit identify RESOURCE ...)")
    return found.as_dict()
