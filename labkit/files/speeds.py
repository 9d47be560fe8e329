"""Tables of measured speeds: a CSV (``freq_hz,speed_mm_s[,speed_std_mm_s][,pattern]``) or an
HDF5 file holding those datasets at its root, under ``points/`` or ``data/`` (any ``kind``).

The one reader of this kind (:func:`read_speed_table`); the calibration's
``--measured`` and the report read speed tables through it.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from labkit.errors import InputError

COLUMNS = ("freq_hz", "speed_mm_s", "speed_std_mm_s", "speed_std", "pattern")


def _s(v: Any) -> str:
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)


def _find(f: Any, name: str, groups: tuple[str, ...] = ("", "points", "data")) -> Any:
    for g in groups:
        key = f"{g}/{name}" if g else name
        if key in f:
            return f[key]
    return None


@dataclass(frozen=True)
class SpeedTable:
    """A CSV/HDF5 table of measured speeds (``speed_std_mm_s`` and ``pattern`` optional)."""

    file: str
    freq_hz: np.ndarray
    speed_mm_s: np.ndarray
    speed_std_mm_s: np.ndarray | None = None
    pattern: list[str] | None = None


def _columns(path: Path) -> dict[str, list]:
    """The table's columns as lists of text (CSV) or values (HDF5), by name."""
    cols: dict[str, list] = {}
    if path.suffix.lower() in (".csv", ".txt"):
        try:
            with path.open(newline="", encoding="utf-8") as fh:
                reader = csv.DictReader(line for line in fh if not line.lstrip().startswith("#"))
                for row in reader:
                    for k, v in row.items():
                        cols.setdefault((k or "").strip(), []).append((v or "").strip())
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            raise InputError(f"cannot read CSV: {exc}", file=path) from None
        return cols
    import h5py

    try:
        with h5py.File(path, "r") as f:
            for k in COLUMNS:
                ds = _find(f, k)
                if ds is not None:
                    cols[k] = [_s(v) if isinstance(v, bytes) else v for v in ds[()]]
    except OSError as exc:
        raise InputError(f"not a readable HDF5 or CSV file ({exc})", file=path) from None
    return cols


def read_speed_table(path: str | Path) -> SpeedTable:
    """A table of measured speeds: CSV with header ``freq_hz,speed_mm_s[,speed_std_mm_s][,pattern]``
    or an HDF5 file with those datasets (any ``kind``).

    ``speed_std`` is accepted as an alias of ``speed_std_mm_s``.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("no such file", file=path)
    cols = _columns(path)
    if "speed_std" in cols and "speed_std_mm_s" not in cols:
        cols["speed_std_mm_s"] = cols.pop("speed_std")
    nums: dict[str, np.ndarray] = {}
    for key in ("freq_hz", "speed_mm_s", "speed_std_mm_s"):
        if key not in cols:
            if key == "speed_std_mm_s":
                continue
            raise InputError("missing column", file=path, key=key,
                             expected="columns freq_hz, speed_mm_s[, speed_std_mm_s][, pattern]")
        try:
            nums[key] = np.asarray([float(v) for v in cols[key]], float)
        except ValueError as exc:
            raise InputError(f"not a number: {exc}", file=path, key=key) from None
    if nums["freq_hz"].size == 0:
        raise InputError("no rows", file=path, expected="at least one measured speed")
    pattern = [str(v) for v in cols["pattern"]] if "pattern" in cols and any(cols["pattern"]) else None
    return SpeedTable(str(path), nums["freq_hz"], nums["speed_mm_s"], nums.get("speed_std_mm_s"), pattern)
