"""Where a report's numbers came from: its input files with checksums, the software version
and the command that made it — written once per report; each section refers to the inputs
it used by their number in that list."""
from __future__ import annotations

import hashlib
from collections.abc import Iterable
from pathlib import Path
from typing import TypedDict


def sha256(path: str | Path, chunk: int = 1 << 20) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def display_path(path: str | Path, base: str | Path) -> str:
    """``path`` as shown in a report in folder ``base``: relative to it (no absolute paths on the page)."""
    import os

    p = Path(path)
    if not p.is_absolute() and not p.exists():
        return str(path)                    # a description, e.g. of a simulation run by the report
    return os.path.relpath(p.resolve(), Path(base).resolve())


def report_command(out: str | Path, runs: Iterable[str], tracks: Iterable[str], fit: str | None,
                   sims: Iterable[str], params: str | None) -> str:
    """The ``labkit report`` command that reads the same inputs, with paths relative to the folder
    holding the report folder (run it from there)."""
    import os
    import shlex

    base = Path(out).resolve().parent

    def rel(path: str) -> str:
        return os.path.relpath(Path(path).resolve(), base)

    words = ["labkit", "report"]
    for flag, paths in (("--runs", runs), ("--tracks", tracks), ("--sim", sims)):
        paths = [rel(p) for p in paths]
        if paths:
            words += [flag, *paths]
    for flag, path in (("--fit", fit), ("--params", params)):
        if path:
            words += [flag, rel(path)]
    return shlex.join([*words, "--out", Path(out).resolve().name])


class InputRecord(TypedDict, total=False):
    """One input of a report (``agreement.json``: ``meta.input_files``): its path, and for a file its
    SHA-256 and size; ``shown_as`` is the path relative to the report's folder, ``number`` its place
    in the report's list (in a section's provenance)."""

    path: str
    sha256: str
    bytes: int
    shown_as: str
    number: int


class SectionProvenance(TypedDict, total=False):
    """A section's provenance (empty for a missing section): its inputs and its notes."""

    files: list[InputRecord]
    notes: dict[str, str]


class RunInputs(TypedDict):
    """The inputs as given to :func:`labkit.analysis.report.build_report`."""

    runs: list[str]
    tracks: list[str]
    fit: str | None
    sims: list[str]
    params: str | None


class ReportMeta(TypedDict):
    """The report's provenance, once (``agreement.json``: ``meta``)."""

    created_utc: str
    software: str
    command: str
    command_as_given: str | None
    input_files: list[InputRecord]
    inputs: RunInputs
    tolerances: dict[str, float]


def file_records(paths: Iterable[str | Path]) -> list[InputRecord]:
    """``{"path", "sha256", "bytes"}`` per distinct existing file, in first-seen order
    (a path that is not a file, e.g. a description of a simulation run here, is kept as
    ``{"path": text}`` without a checksum)."""
    seen: set[str] = set()
    out: list[InputRecord] = []
    for p in paths:
        key = str(p)
        if key in seen:
            continue
        seen.add(key)
        path = Path(key)
        if path.is_file():
            out.append({"path": key, "sha256": sha256(path), "bytes": path.stat().st_size})
        else:
            out.append({"path": key})
    return out


def section_provenance(files: Iterable[str | Path], *, inputs: list[InputRecord],
                       notes: dict[str, str] | None = None) -> SectionProvenance:
    """One section's provenance: its files (as in ``inputs``, with their number there) and notes."""
    index = {f["path"]: i for i, f in enumerate(inputs, 1)}
    mine: list[InputRecord] = [{**inputs[index[str(p)] - 1], "number": index[str(p)]}
                               for p in dict.fromkeys(map(str, files)) if str(p) in index]
    return {"files": mine, "notes": dict(notes or {})}
