"""Where a report section's numbers came from: its input files with checksums, the software
version and the command that made it — written once per section, never once per row."""
from __future__ import annotations

import hashlib
from collections.abc import Iterable
from pathlib import Path
from typing import Any


def sha256(path: str | Path, chunk: int = 1 << 20) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def file_records(paths: Iterable[str | Path]) -> list[dict[str, Any]]:
    """``{"path", "sha256", "bytes"}`` per distinct existing file, in first-seen order
    (a path that is not a file, e.g. a description of a simulation run here, is kept as
    ``{"path": text}`` without a checksum)."""
    seen: set[str] = set()
    out: list[dict[str, Any]] = []
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


def section_provenance(files: Iterable[str | Path], *, software: str, command: str,
                       notes: dict[str, Any] | None = None) -> dict[str, Any]:
    """The provenance block of one section."""
    return {"files": file_records(files), "software": software, "command": command, "notes": dict(notes or {})}
