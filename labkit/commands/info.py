"""``labkit info FILE``: summarise any file the toolkit writes (HDF5 or TOML)."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from labkit.errors import InputError

NAME = "info"
HELP = "summarise a labkit file: run file, simulation, track (HDF5) or parameter file (TOML)"


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="an HDF5 or TOML file written by labkit")


def run(args: argparse.Namespace) -> dict[str, Any]:
    path = Path(args.file)
    if not path.is_file():
        raise InputError("no such file", file=path)
    if path.suffix.lower() == ".toml":
        summary = summarise_toml(path)
    else:
        summary = summarise_h5(path)
    if not args.json:
        _print(summary)
    return summary


def summarise_toml(path: Path) -> dict[str, Any]:
    from labkit.tomlio import load_toml

    table, _ = load_toml(path)
    return {"file": str(path), "format": "toml", "tables": sorted(k for k, v in table.items() if isinstance(v, dict)),
            "keys": sorted(k for k, v in table.items() if not isinstance(v, dict)),
            "provenance": table.get("provenance", {})}


def summarise_h5(path: Path) -> dict[str, Any]:
    """Root attributes plus every dataset's shape, dtype and units."""
    import h5py

    from labkit.h5io import open_h5

    datasets: list[dict[str, Any]] = []
    groups: list[str] = []
    with open_h5(path) as f:
        attrs = {k: _attr(v) for k, v in f.attrs.items() if len(str(v)) < 400}

        def visit(name: str, obj: Any) -> None:
            if isinstance(obj, h5py.Dataset):
                datasets.append({"name": name, "shape": list(obj.shape), "dtype": str(obj.dtype),
                                 "units": _attr(obj.attrs.get("units", ""))})
            else:
                groups.append(name)

        f.visititems(visit)
    return {"file": str(path), "format": "hdf5", "kind": attrs.get("kind"),
            "schema_version": attrs.get("schema_version"), "attrs": attrs,
            "groups": groups, "datasets": datasets}


def _attr(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if hasattr(value, "tolist"):
        return value.tolist()
    return value


def _print(summary: dict[str, Any]) -> None:
    print(f"{summary['file']} ({summary['format']})")
    if summary["format"] == "toml":
        print(f"  tables: {', '.join(summary['tables'])}")
        return
    for key, value in summary["attrs"].items():
        print(f"  {key}: {value}")
    print(f"  {len(summary['groups'])} groups, {len(summary['datasets'])} datasets")
    for ds in summary["datasets"][:40]:
        print(f"    {ds['name']}  {tuple(ds['shape'])} {ds['dtype']} [{ds['units']}]")
    if len(summary["datasets"]) > 40:
        print(f"    ... {len(summary['datasets']) - 40} more")
