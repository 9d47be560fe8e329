"""Conventions shared by every HDF5 file labkit writes.

Every file carries, on its root group:

* ``kind`` — what the file is (``"sim_result"``, ``"sim_sweep"``, ``"run_inchip"``,
  ``"run_shaker"``, ``"track"``, ...); :func:`labkit.commands.info` keys on it,
* ``schema_version`` — an integer, raised when the layout changes; readers
  accept every version up to their own,
* ``software`` — ``"labkit <version>"``, and ``created_utc`` (ISO 8601).

Every dataset carries a ``units`` attribute (``"1"`` for dimensionless,
``"label"`` for enumerations, ``"s"``, ``"mm/s"``, ...).
"""
from __future__ import annotations

import datetime as _dt
import json
from pathlib import Path
from typing import Any

import numpy as np

from labkit import __version__
from labkit.errors import InputError
from labkit.jsonutil import to_jsonable

SCHEMA_VERSION = 1


def utc_now() -> str:
    """The current time as an ISO 8601 UTC string."""
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds")


def stamp(root: Any, kind: str, schema_version: int = SCHEMA_VERSION) -> None:
    """Write the identifying attributes on a file's root group."""
    root.attrs["kind"] = kind
    root.attrs["schema_version"] = int(schema_version)
    root.attrs["software"] = f"labkit {__version__}"
    root.attrs["created_utc"] = utc_now()


def put(group: Any, name: str, data: Any, units: str, **attrs: Any) -> Any:
    """Create dataset ``name`` holding ``data`` with its ``units`` (and more attributes)."""
    ds = group.create_dataset(name, data=np.asarray(data))
    ds.attrs["units"] = units
    for key, value in attrs.items():
        ds.attrs[key] = value
    return ds


def put_json(group: Any, name: str, obj: Any) -> None:
    """Store a JSON-able object as a string attribute (snapshots, summaries)."""
    group.attrs[name] = json.dumps(to_jsonable(obj), sort_keys=True)


def get_json(group: Any, name: str, default: Any = None) -> Any:
    """Read back an attribute written by :func:`put_json`."""
    if name not in group.attrs:
        return default
    return json.loads(group.attrs[name])



def open_h5(path: str | Path, mode: str = "r", *, kind: str | None = None):
    """Open an HDF5 file labkit wrote; a clear :class:`InputError` if it is not one.

    With ``kind``, the file's ``kind`` attribute must match (a prefix match:
    ``kind="run"`` accepts ``"run_inchip"``).
    """
    import h5py

    path = Path(path)
    if mode == "r" and not path.exists():
        raise InputError("no such file", file=path)
    try:
        f = h5py.File(path, mode)
    except OSError as exc:
        raise InputError(f"not a readable HDF5 file ({exc})", file=path) from None
    if kind is not None:
        found = f.attrs.get("kind")
        if found is None or not str(found).startswith(kind):
            f.close()
            raise InputError(f"this file holds {found!r}", file=path, key="kind", expected=f"a '{kind}' file")
        version = int(f.attrs.get("schema_version", 0))
        if version > SCHEMA_VERSION:
            f.close()
            raise InputError(f"written by a newer labkit (schema {version})", file=path,
                             key="schema_version", expected=f"<= {SCHEMA_VERSION}")
    return f
