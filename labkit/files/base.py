"""What every object :func:`labkit.open` returns has in common."""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict, TypeVar

import numpy as np

from labkit.errors import InputError
from labkit.jsonutil import Json as Json  # re-exported: the readers' JSON-valued fields

if TYPE_CHECKING:  # pragma: no cover - typing only
    import xarray


def text(value: Any) -> str:
    """An HDF5 attribute or string element as ``str``."""
    return value.decode("utf-8", "replace") if isinstance(value, bytes) else str(value)


def attr_value(value: Any) -> Any:
    """An HDF5 attribute as a plain Python value (``*_json`` strings stay strings)."""
    if isinstance(value, bytes):
        return text(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def json_attr(attrs: Any, name: str, default: Any = None) -> Any:
    """A ``*_json`` attribute decoded (``default`` if absent or not JSON)."""
    if name not in attrs:
        return default
    try:
        return json.loads(text(attrs[name]))
    except (TypeError, ValueError):
        return default


def column(ds: Any, n: int | None = None) -> np.ndarray:
    """A dataset's first ``n`` rows as an array (strings decoded to ``str``)."""
    if ds.ndim == 0:                               # a scalar dataset (a run's mean speed)
        value = ds[()]
        return np.asarray(text(value) if isinstance(value, bytes) else value)
    sel = slice(None) if n is None else slice(0, n)
    if ds.dtype.kind in "OS":
        return np.asarray(ds.asstr()[sel], dtype=object).astype(str)
    return np.asarray(ds[sel])


def units_of(ds: Any) -> str:
    return text(ds.attrs.get("units", ""))


def require_xarray() -> Any:
    """Import xarray, or an InputError saying how to get it (it is the ``[xarray]`` extra)."""
    try:
        import xarray
    except ImportError:  # pragma: no cover - depends on the install
        raise InputError("xarray is not installed", key="to_xarray",
                         expected='pip install "labkit[xarray]"') from None
    return xarray


T = TypeVar("T")


class FileSummary(TypedDict):
    """What every :meth:`LabFile.summary` holds (``labkit info --json`` prints it under ``content``);
    each kind's summary extends it (``TrackSummary``, ``RunSummary``, ...)."""

    file: str | None        # None for a sweep listed inside a scenario set (the set's file is the file)
    kind: str
    schema_version: int
    software: str


@dataclass
class LabFile:
    """A file labkit wrote, opened by :func:`labkit.open`.

    Attributes
    ----------
    path:
        The file.
    kind:
        What it is: ``run_inchip``, ``run_shaker``, ``track``, ``modal_fit``,
        ``sim_result``, ``sim_sweep``, ``robot_params``, ``video``, ``track_csv``.
    schema_version:
        The layout version the file was written with (0 when the format has none).
    attrs:
        The file's root attributes as plain values (``*_json`` ones decoded).
    units:
        Units of every array attribute of the object, by name (``freq_hz -> "Hz"``).
    """

    path: Path
    kind: str
    schema_version: int = 0
    attrs: dict[str, Json] = field(default_factory=dict, repr=False)
    units: dict[str, str] = field(default_factory=dict, repr=False)

    @property
    def software(self) -> str:
        """The program that wrote the file (``"labkit 0.1.0"``), if recorded."""
        return str(self.attrs.get("software", ""))

    def summary(self) -> FileSummary:
        """A short JSON-able description (``labkit info`` prints it)."""
        return {"file": str(self.path), "kind": self.kind, "schema_version": self.schema_version,
                "software": self.software}

    def to_xarray(self) -> xarray.Dataset:
        """The data as an :class:`xarray.Dataset` with named dimensions, coordinates and units."""
        raise NotImplementedError(f"{type(self).__name__}.to_xarray")


def root_attrs(f: Any) -> dict[str, Json]:
    """A file's root attributes; ``*_json`` attributes decoded to objects under their name minus ``_json``."""
    out: dict[str, Json] = {}
    for k, v in f.attrs.items():
        if k.endswith("_json"):
            out[k[:-5]] = json_attr(f.attrs, k)
        else:
            out[k] = attr_value(v)
    return out
