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
#: and run files' point records hold ``t_s``; 3 -- run files' text columns (a point's status,
#: location, reason, video; the events' text) are fixed-length UTF-8 with checksums, not
#: variable-length strings (other kinds: as version 2)
SCHEMA_VERSION = 3
#: the newest layout this labkit reads (readers accept every version up to it)
READS_SCHEMA_VERSION = 3


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



def open_h5(path: str | Path, mode: str = "r", *, kind: str | None = None, verify: bool | None = None):
    """Open an HDF5 file labkit wrote; a clear :class:`InputError` if it is not one.

    With ``kind``, the file's ``kind`` attribute must match (a prefix match:
    ``kind="run"`` accepts ``"run_inchip"``). A file that cannot be opened is named for
    what it is (:func:`why_unreadable`): being written (by the run holding its lock, from
    the lock file), truncated, or corrupt. With ``verify`` (the default for run files),
    every dataset is read once, so a failed checksum names its dataset (:func:`verify_datasets`).
    """
    import h5py

    path = Path(path)
    if mode == "r" and not path.exists():
        raise InputError("no such file", file=path)
    try:
        f = _open_as_of_last_flush(path) if mode == "r" else h5py.File(path, mode)
    except OSError as exc:
        raise InputError(why_unreadable(path, exc), file=path) from None
    try:
        _check_kind(f, path, mode, kind)
        if mode == "r" and (verify or (verify is None and str(f.attrs.get("kind", "")).startswith("run"))):
            verify_datasets(f, path)
    except BaseException:
        f.close()
        raise
    return f


def _open_as_of_last_flush(path: Path) -> Any:
    """``path`` read-only; a flush its writer's crash cut short is read as finished (its journal
    overlaid, nothing written: :mod:`labkit.h5journal`), unless a run still writes it."""
    import h5py

    from labkit.h5journal import committed_records, journal_path, open_recovered
    from labkit.lockfiles import writer_of

    if journal_path(path).exists() and writer_of(path) is None:
        records = committed_records(path)
        if records:
            return open_recovered(path, records)
    return h5py.File(path, "r")


def _check_kind(f: Any, path: Path, mode: str, kind: str | None) -> None:
    try:
        found = f.attrs.get("kind")
        raw = f.attrs.get("schema_version", 0)
    except (OSError, RuntimeError, KeyError, ValueError) as exc:
        raise InputError(f"corrupt: its root attributes cannot be read ({exc})", file=path) from None
    if kind is not None and (found is None or not str(found).startswith(kind)):
        raise InputError(f"this file holds {found!r}", file=path, key="kind", expected=f"a '{kind}' file")
    if mode == "r":
        raw = raw.item() if isinstance(raw, np.generic) else raw
        try:
            version = int(raw)
        except (TypeError, ValueError):
            version = -1
        if not 0 <= version <= READS_SCHEMA_VERSION:
            raise InputError(f"{raw!r}: written by a newer labkit, or not a version", file=path,
                             key="schema_version", expected=f"an integer 0..{READS_SCHEMA_VERSION}")


def why_unreadable(path: str | Path, exc: BaseException | None = None) -> str:
    """Why HDF5 cannot open ``path``, in words: being written (by whom), truncated, corrupt, not HDF5.

    Who writes it comes from the run's lock file (:func:`labkit.lockfiles.writer_of`); HDF5's
    own file lock (errno EAGAIN) without a labkit run holding the file is another program.
    Truncation is read from the file's superblock (its stored end-of-file address).
    """
    import errno
    import os

    from labkit.lockfiles import describe, writer_of

    who = writer_of(path)
    if who is not None and who.get("pid") != os.getpid():     # (this process's own lock: --resume)
        return f"being written by {describe(who)}; read it when that run has ended"
    if isinstance(exc, OSError) and exc.errno in (errno.EAGAIN, errno.EACCES) and exc.errno is not None:
        if exc.errno == errno.EACCES:
            return "not readable by this user (permission denied)"
        return ("open for writing by another program (HDF5's file lock is held; no labkit run holds it); "
                "read it when that program has closed it")
    size = Path(path).stat().st_size
    sb = superblock(path)
    if sb is None:
        if size == 0 or not Path(path).read_bytes()[:4096].strip(b"\0"):
            return f"truncated: {size} bytes, nothing written yet (the writer stopped at its first byte)"
        return "not a readable HDF5 file (no HDF5 signature: not HDF5, or its first bytes are damaged)"
    base, eof = sb
    if eof is not None and size < base + eof:
        return (f"truncated: {size} bytes on disk, its header says {base + eof} (the writer was stopped "
                "before it finished, or the copy is incomplete)")
    return f"corrupt: HDF5 cannot read its structure ({_hdf5_reason(exc)})"


def _hdf5_reason(exc: BaseException | None) -> str:
    text = str(exc) if exc is not None else "unknown"
    return text.split("(", 1)[-1].rstrip(")") if "(" in text else text


_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def superblock(path: str | Path) -> tuple[int, int | None] | None:
    """``(base address, stored end-of-file address)`` from an HDF5 superblock, None without a signature.

    The end-of-file address is None when the file is too short to hold it. Layout: the
    HDF5 File Format Specification, section II.A (versions 0-3).
    """
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    for at in (0, 512, 1024, 2048, 4096, 8192, 16384, 32768):
        if head[at:at + 8] != _SIGNATURE:
            continue
        b = head[at:]
        if len(b) < 16:
            return at, None
        version = b[8]
        if version in (0, 1):
            so = b[13]
            start = 24 + (4 if version == 1 else 0)
        else:
            so = b[9]
            start = 12
        fields = [b[start + i * so:start + (i + 1) * so] for i in range(3)]
        if len(fields[2]) < so or so not in (2, 4, 8):
            return at, None
        return at, int.from_bytes(fields[2], "little")
    return None


def verify_datasets(f: Any, path: str | Path) -> int:
    """Read every dataset (HDF5 checks the Fletcher-32 checksums of those that carry one).

    Returns the number of datasets read. Raises :class:`InputError` (exit 2) naming the
    first dataset, group or attribute that cannot be read.
    """
    import h5py

    names: list[str] = []
    try:
        f.visit(names.append)
    except (OSError, RuntimeError, KeyError, ValueError) as exc:
        raise InputError(f"corrupt: its group structure cannot be read ({_hdf5_reason(exc)})", file=path) from None
    n = 0
    for name in names:
        obj = None
        try:
            obj = f[name]
            dict(obj.attrs)
            if isinstance(obj, h5py.Dataset):
                obj[()]
                n += 1
        except (OSError, RuntimeError, KeyError, ValueError, TypeError) as exc:
            what = "dataset" if isinstance(obj, h5py.Dataset) else "object"
            how = "fails its checksum" if getattr(obj, "fletcher32", False) else "cannot be read"
            raise InputError(f"corrupt: {what} /{name} {how} ({_hdf5_reason(exc)})",
                             file=path) from None
    return n


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
