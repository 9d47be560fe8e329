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

#: the layout version written (every kind; ``docs/file-formats.md`` has the history):
#: 1 -- no dimension scales; 2 -- each group's axis (``index``, ``t_s``, ``freq_hz``, a sweep's
#: quantity) is an HDF5 dimension scale attached to the datasets along it (:func:`label_dimensions`),
#: and run files' point records hold ``t_s``
SCHEMA_VERSION = 2
#: the newest layout this labkit reads (readers accept every version up to it)
READS_SCHEMA_VERSION = 2


def utc_now() -> str:
    """The current time as an ISO 8601 UTC string."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")


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
        if "lock" in str(exc).lower():      # another process has it open for writing
            from labkit.lockfiles import describe, writer_of

            who = writer_of(path)
            by = f"by {describe(who)}" if who else "by another process (a run in progress holds it)"
            raise InputError(f"being written {by}; read it when that run has ended", file=path) from None
        raise InputError(f"not a readable HDF5 file ({exc})", file=path) from None
    if kind is not None:
        found = f.attrs.get("kind")
        if found is None or not str(found).startswith(kind):
            f.close()
            raise InputError(f"this file holds {found!r}", file=path, key="kind", expected=f"a '{kind}' file")
    if mode == "r":
        raw = f.attrs.get("schema_version", 0)
        raw = raw.item() if isinstance(raw, np.generic) else raw
        try:
            version = int(raw)
        except (TypeError, ValueError):
            version = -1
        if not 0 <= version <= READS_SCHEMA_VERSION:
            f.close()
            raise InputError(f"{raw!r}: written by a newer labkit, or not a version", file=path,
                             key="schema_version", expected=f"an integer 0..{READS_SCHEMA_VERSION}")
    return f


#: the datasets that are a group's axis, in order of preference: a table's point ``index``
#: (run files' ``/points``), sample times, frequency lines
SCALE_NAMES = ("index", "t_s", "freq_hz", "time_unix_s")


def label_dimensions(group: Any) -> None:
    """Make each group's axis a dimension scale and attach it to the group's other datasets.

    So that h5py (``ds.dims``), xarray/h5netcdf and HDFView show coordinates instead of
    anonymous ``phony_dim`` dimensions. Per group (``group`` and every group below it):

    * the axis is the first of ``index``, ``t_s``, ``freq_hz``, ``time_unix_s`` present as a 1-D dataset;
      it is attached to every 1-D dataset of the same length (for growing run-file tables,
      to every growing dataset);
    * a group with a ``dt_s`` attribute and no ``t_s`` (a point's sampled records) gets a
      ``t_s`` dataset (s) first;
    * a simulated sweep's ``values`` gets a copy named after its ``quantity`` (``freq_hz``);
    * in a point table the other columns name ``freq_hz`` (and ``location``) as
      coordinates (the CF ``coordinates`` attribute, which xarray reads);
    * a dataset with an ``axes`` attribute (``"point, draw, foot"``, ``"t_s, leg"``) and no
      labelled dimension yet gets every dimension labelled (:func:`_label_axes`).

    Idempotent; works on empty growing tables (call it when they are created) and on
    finished files (older files can be labelled in place).
    """
    import h5py

    groups = [group]
    group.visititems(lambda _name, obj: groups.append(obj) if isinstance(obj, h5py.Group) else None)
    for g in groups:
        _label_group(g)


def _label_group(g: Any) -> None:
    import h5py

    ds = {k: v for k, v in g.items() if isinstance(v, h5py.Dataset)}
    if "t_s" not in ds and "dt_s" in g.attrs and any(v.ndim == 1 for v in ds.values()):
        n = max(v.shape[0] for v in ds.values() if v.ndim == 1)
        ds["t_s"] = put(g, "t_s", np.arange(n) * float(g.attrs["dt_s"]), "s")
    if "values" in ds and "quantity" in ds["values"].attrs:
        q = str(ds["values"].attrs["quantity"])
        if q not in ds and q.isidentifier():
            ds[q] = put(g, q, ds["values"][()], str(ds["values"].attrs.get("units", "")))
    axis = next((k for k in SCALE_NAMES if k in ds and ds[k].ndim == 1), None)
    if axis is None and "values" in ds and ds["values"].ndim == 1:
        axis = str(ds["values"].attrs.get("quantity", "values"))
        axis = axis if axis in ds else "values"
    if axis is None:
        return
    scale = ds[axis]
    if not scale.is_scale:
        scale.make_scale(axis)
    growing = scale.maxshape[0] is None
    coords = [c for c in ("freq_hz", "location") if c in ds and c != axis] if axis == "index" else []
    for name, v in ds.items():
        # only 1-D datasets: netCDF readers refuse a variable with some dimensions labelled
        # and others not, and a second axis (draw, leg, location) has no dataset of its own
        if name == axis or v.ndim != 1:
            continue
        if "axes" in v.attrs and str(v.attrs["axes"]).split(",")[0].strip() not in (axis, "point"):
            continue                    # along another axis (a per-leg array as long as the time axis)
        fits = v.maxshape[0] is None if growing else v.shape[0] == scale.shape[0]
        if not fits:
            continue
        if not any(s == scale for s in v.dims[0].values()):
            v.dims[0].attach_scale(scale)
        others = [c for c in coords if c != name]
        if others:
            v.attrs["coordinates"] = " ".join(others)
    for v in list(ds.values()):
        if v.ndim >= 1 and "axes" in v.attrs and not any(len(d) for d in v.dims):
            _label_axes(g, v, scale)


def _label_axes(g: Any, v: Any, axis_scale: Any) -> None:
    """Label every dimension of a dataset with an ``axes`` attribute (``"point, draw, foot"``).

    Axis ``point`` is the group's axis (a sweep's quantity); another name uses the group's 1-D
    dataset of that name, or a new index dataset ``0..n-1`` (units ``1``). All or nothing: a
    netCDF reader refuses a variable with some dimensions labelled and others not.
    """
    names = [a.strip() for a in str(v.attrs["axes"]).split(",")]
    if len(names) != v.ndim:
        return
    scales = []
    for i, nm in enumerate(names):
        n = v.shape[i]
        if nm == "point" and axis_scale.ndim == 1 and axis_scale.shape[0] == n:
            scales.append(axis_scale)
            continue
        if not nm.isidentifier() or nm == v.name.rsplit("/", 1)[-1]:
            return
        found = g.get(nm)
        if found is None:
            found = put(g, nm, np.arange(n), "1")
        if found.ndim != 1 or found.shape[0] != n:
            return
        scales.append(found)
    for i, sc in enumerate(scales):
        if not sc.is_scale:
            sc.make_scale(names[i] if sc is not axis_scale else axis_scale.name.rsplit("/", 1)[-1])
        if not any(s == sc for s in v.dims[i].values()):
            v.dims[i].attach_scale(sc)
