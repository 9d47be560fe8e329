"""``labkit info FILE``: summarise any file the toolkit writes.

Run files, tracks, fits and simulations (HDF5), robot parameter files and
experiment configs (TOML), track tables (CSV), videos (``.mkv``, ``.avi``), and
the sidecars: figures (PNG), reports (HTML), JSON summaries, universal files (UFF).
What a file *means* comes from :func:`labkit.open` (``content``); for HDF5
files every dataset's shape, dtype and units are listed as well.
"""
from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeAlias, TypedDict

from labkit.errors import ConfigError, InputError
from labkit.jsonutil import Json
from labkit.lockfiles import LockRecord, describe, writer_of

if TYPE_CHECKING:  # pragma: no cover - typing only
    from labkit.files.base import FileSummary

NAME = "info"
HELP = ("summarise a labkit file: run file, track, fit, simulation (HDF5), parameter file or config (TOML), "
        "track table (CSV), video (.mkv/.avi), figure (PNG), report (HTML), JSON, UFF")


class JsonFileSummary(TypedDict):
    """A JSON sidecar: what it is, its size and its top-level keys."""

    kind: str
    bytes: int
    keys: list[str]
    items: int


class PngSummary(TypedDict):
    kind: str
    width_px: int
    height_px: int
    bytes: int


class HtmlSummary(TypedDict):
    kind: str
    title: str
    sections: int
    figures: int
    bytes: int


class UffSummary(TypedDict):
    kind: str
    datasets_by_type: dict[str, int]


class Unreadable(TypedDict, total=False):
    """The content of a file that names its kind but cannot be read as one."""

    kind: str
    error: str


#: what a sidecar reader returns
Sidecar: TypeAlias = "JsonFileSummary | PngSummary | HtmlSummary | UffSummary"
#: what a file means (``content``): the summary of its kind, a sidecar's, or why it could not be read
Content: TypeAlias = "FileSummary | Sidecar | Unreadable"


class DatasetListing(TypedDict):
    name: str
    shape: list[int]
    dtype: str
    units: Json


class _Info(TypedDict):
    file: str
    format: str


class Info(_Info, total=False):
    """What ``labkit info`` reports (``--json`` prints it): the file, its format, what it means
    (``content``, from :func:`labkit.open` or the sidecar readers) and, by format, its TOML tables
    or its HDF5 attributes, groups, datasets and dimension names."""

    content: Content
    tables: list[str]
    keys: list[str]
    provenance: Json
    provenance_digest: dict[str, Json]
    kind: Json
    schema_version: Json
    attrs: dict[str, Json]
    groups: list[str]
    datasets: list[DatasetListing]
    dims: dict[str, list[str]]
    being_written_by: LockRecord
    being_written: str


def add_arguments(parser: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="a file written by labkit")


def run(args: argparse.Namespace) -> Info:
    summary = summarise(args.file)
    if not args.json:
        _print(summary)
    return summary


def summarise(path: str | Path) -> Info:
    """What ``labkit info`` reports about ``path`` (JSON-able; InputError if unreadable)."""
    from labkit.files import VIDEO_SUFFIXES, open_file

    path = Path(path)
    if not path.is_file():
        raise InputError("no such file", file=path)
    suffix = path.suffix.lower()
    if suffix == ".toml":
        return summarise_toml(path)
    if suffix == ".csv":
        return {"file": str(path), "format": "csv", "content": open_file(path).summary()}
    if suffix in VIDEO_SUFFIXES:
        return {"file": str(path), "format": "video", "content": open_file(path).summary()}
    if suffix in SIDECARS:
        return {"file": str(path), "format": suffix[1:], "content": SIDECARS[suffix](path)}
    import h5py

    if suffix in (".h5", ".hdf5", ".hdf") or h5py.is_hdf5(path):
        return summarise_h5(path)
    raise InputError("not a file labkit writes", file=path,
                     expected="HDF5 (.h5), TOML, CSV, a video (.mkv/.avi/.mp4), PNG, HTML, JSON or UFF")


def _json_summary(path: Path) -> JsonFileSummary:
    """A JSON sidecar (calibration details, report agreement, figure data, demo summary): its top-level keys."""
    import json

    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"not readable JSON ({exc})", file=path) from None
    what = {".calibration.json": "calibration details (labkit calibrate)",
            "agreement.json": "model-measurement agreement (labkit report)",
            "figure_data.json": "the report's figure data (labkit report)",
            "demo_summary.json": "demo summary (labkit demo)"}
    kind = next((v for k, v in what.items() if path.name.endswith(k)), "JSON")
    keys = sorted(obj) if isinstance(obj, dict) else []
    return {"kind": kind, "bytes": path.stat().st_size, "keys": keys,
            "items": len(obj) if isinstance(obj, (dict, list)) else 1}


def _png_summary(path: Path) -> PngSummary:
    """A figure: its size in pixels (from the PNG header)."""
    head = path.read_bytes()[:24]
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n":
        raise InputError("not a PNG file", file=path, expected="a PNG signature")
    return {"kind": "figure", "width_px": int.from_bytes(head[16:20], "big"),
            "height_px": int.from_bytes(head[20:24], "big"), "bytes": path.stat().st_size}


def _html_summary(path: Path) -> HtmlSummary:
    """A report page: title, sections and figures (self-contained: figures are inline)."""
    import re

    page = path.read_text(encoding="utf-8", errors="replace")
    title = re.search(r"<title>(.*?)</title>", page, re.S | re.I)
    # a figure is an <img> or an inline <svg> (labkit's reports inline every figure as SVG)
    return {"kind": "report", "title": title.group(1).strip() if title else "",
            "sections": len(re.findall(r"<section\b", page, re.I)),
            "figures": len(re.findall(r"<img\b", page, re.I)) + len(re.findall(r"<svg\b", page, re.I)),
            "bytes": len(page.encode())}


def _uff_summary(path: Path) -> UffSummary:
    """A universal file (``labkit fit --uff``): its datasets by type (58: FRFs, ...)."""
    lines = path.read_text(encoding="ascii", errors="replace").splitlines()
    types: dict[str, int] = {}
    i = 0
    while i < len(lines) - 1:
        if lines[i].strip() == "-1" and lines[i + 1].strip().isdigit():
            t = lines[i + 1].strip()
            types[t] = types.get(t, 0) + 1
            i += 2
            while i < len(lines) and lines[i].strip() != "-1":
                i += 1
        i += 1
    if not types:
        raise InputError("no universal-file datasets", file=path, expected="blocks delimited by '    -1'")
    return {"kind": "universal file", "datasets_by_type": types}


#: sidecar files labkit writes beside its data files, by suffix
SIDECARS: dict[str, Callable[[Path], Sidecar]] = {".json": _json_summary, ".png": _png_summary,
                                                  ".html": _html_summary, ".uff": _uff_summary}


def summarise_toml(path: Path) -> Info:
    """Tables and keys of a TOML file; for a robot parameter file its modes and provenance digest."""
    from labkit.files.kinds import CONFIG_TABLES, provenance_digest, read_config, read_params
    from labkit.tomlio import load_toml

    table, raw = load_toml(path)
    out: Info = {"file": str(path), "format": "toml",
                           "tables": sorted(k for k, v in table.items() if isinstance(v, dict)),
                           "keys": sorted(k for k, v in table.items() if not isinstance(v, dict)),
                           "provenance": table.get("provenance", {})}
    if any(isinstance(table.get(k), dict) for k in CONFIG_TABLES):      # an experiment config
        out["content"] = read_config(path, table, raw).summary()
    elif "k_per_s2" in table or "provenance" in table:        # a robot parameter file
        try:
            out["content"] = read_params(path).summary()
        except ConfigError as exc:
            out["content"] = {"kind": "robot_params", "error": str(exc)}
        out["provenance_digest"] = provenance_digest(out["provenance"]) if isinstance(out["provenance"], dict) else {}
    return out


def summarise_h5(path: Path) -> Info:
    """Root attributes, every dataset's shape, dtype and units, and the typed summary of known kinds.

    A file that a run is writing (it holds the file's lock) gets ``being_written_by`` (the
    writer's PID, host, command and start time); its listing is empty when HDF5 refuses to
    open it while the writer has it open.
    """
    busy = writer_of(path)
    try:
        out = _summarise_h5(path)
    except InputError:
        if busy is None:
            raise
        out = {"file": str(path), "format": "hdf5", "kind": None, "schema_version": None, "attrs": {},
               "groups": [], "datasets": [], "dims": {}}
    if busy is not None:
        out["being_written_by"] = _writer(busy)
        out["being_written"] = f"being written by {describe(busy)}"
    return out


def _writer(busy: LockRecord) -> LockRecord:
    """What ``labkit info`` shows of a lock record: who (PID, host), running what, since when."""
    out: LockRecord = {}
    if "pid" in busy:
        out["pid"] = busy["pid"]
    if "host" in busy:
        out["host"] = busy["host"]
    if "command" in busy:
        out["command"] = busy["command"]
    if "since" in busy:
        out["since"] = busy["since"]
    return out


def _summarise_h5(path: Path) -> Info:
    import h5py

    from labkit.files import H5_KINDS, open_file
    from labkit.h5io import open_h5

    datasets: list[DatasetListing] = []
    groups: list[str] = []
    dims: dict[str, list[str]] = {}
    with open_h5(path, verify=True) as f:
        attrs: dict[str, Json] = {k: _attr(v) for k, v in f.attrs.items() if len(str(v)) < 400}

        def visit(name: str, obj: Any) -> None:
            if isinstance(obj, h5py.Dataset):
                datasets.append({"name": name, "shape": list(obj.shape), "dtype": str(obj.dtype),
                                 "units": _attr(obj.attrs.get("units", ""))})
                names = [d.label or (d[0].name.rsplit("/", 1)[-1] if len(d) else "") for d in obj.dims]
                if any(names):
                    dims[name] = names
            else:
                groups.append(name)

        f.visititems(visit)
    out: Info = {"file": str(path), "format": "hdf5", "kind": attrs.get("kind"),
           "schema_version": attrs.get("schema_version"), "attrs": attrs,
           "groups": groups, "datasets": datasets, "dims": dims}
    if attrs.get("kind") in H5_KINDS:
        try:
            out["content"] = open_file(path).summary()
        except InputError as exc:       # a damaged file still gets its listing
            out["content"] = {"error": str(exc)}
    return out


def _attr(value: Any) -> Json:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if hasattr(value, "tolist"):
        return value.tolist()
    return value


def _print(summary: Info) -> None:
    print(f"{summary['file']} ({summary['format']})")
    content: Mapping[str, Any] = summary.get("content", {})
    if summary["format"] == "toml":
        _print_toml(summary, content)
    elif summary["format"] != "hdf5":
        for k, v in content.items():
            if k != "file":
                print(f"  {k}: {v}")
    else:
        _print_hdf5(summary, content)


def _print_toml(summary: Info, content: Mapping[str, Any]) -> None:
    """An experiment config's instruments and tables, or a parameter file's modes and provenance."""
    print(f"  tables: {', '.join(summary['tables']) or '-'}")
    if content.get("experiment"):
        _print_config(content)
    elif "content" in summary:
        _print_params(summary, content)


def _print_config(content: Mapping[str, Any]) -> None:
    """An experiment config: its experiment, instruments and the tables a reader checks first."""
    print(f"  experiment config: {content['experiment']} ({content['kind']})")
    for role, model in content.get("instruments", {}).items():
        print(f"  instrument {role}: {model}")
    for k in ("drive", "frequencies", "grid", "method"):
        if k in content:
            print(f"  {k}: " + ", ".join(f"{a} = {b}" for a, b in content[k].items()))


def _print_params(summary: Info, content: Mapping[str, Any]) -> None:
    """A robot parameter file: its modes and where each value came from."""
    for k in ("modal_freq_hz", "modal_damping_ratio"):
        if k in content:
            print(f"  {k}: {', '.join(f'{v:.6g}' for v in content[k])}")
    for k, v in summary.get("provenance_digest", {}).items():
        if k == "modes" and isinstance(v, dict):
            for m, where in v.items():
                print(f"  provenance: mode {m}: {where}")
        else:
            print(f"  provenance: {k}: {v}")


def _print_hdf5(summary: Info, content: Mapping[str, Any]) -> None:
    """The root attributes, what the file's reader says of it, and its groups and datasets."""
    if summary.get("being_written"):
        print(f"  {summary['being_written']}" + ("" if summary["datasets"] else
                                                 "; its contents can be listed when that run has ended"))
    for key, value in summary["attrs"].items():
        print(f"  {key}: {value}")
    for key, value in content.items():
        if key != "file" and key not in summary["attrs"]:
            print(f"  {key}: {value}")
    print(f"  {len(summary['groups'])} groups, {len(summary['datasets'])} datasets")
    for ds in summary["datasets"][:40]:
        names = summary.get("dims", {}).get(ds["name"])
        dims = f"  dims ({', '.join(names)})" if names else ""
        print(f"    {ds['name']}  {tuple(ds['shape'])} {ds['dtype']} [{ds['units']}]{dims}")
    if len(summary["datasets"]) > 40:
        print(f"    ... {len(summary['datasets']) - 40} more")
