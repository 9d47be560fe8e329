"""Run files: one self-describing HDF5 file per run, appended and flushed point by point.

Every dataset carries a ``units`` attribute. Rows are appended to resizable
(chunked, unlimited) datasets and the file is flushed after every point, so a
run killed with SIGKILL leaves a file that opens and holds every completed
point; at most the point in progress is lost. Within a table the ``index``
dataset is always written last: its length is the number of complete rows,
and reopening for ``--resume`` trims any longer sibling back to it. Text columns
(``status``, ``location``, ``reason``, ``video``, the events' ``text``) are
fixed-length UTF-8 (layout 3), so every byte of a point lives in its datasets'
checksummed chunks and nothing in HDF5's global heap.

Common layout (both kinds)
--------------------------
root attributes
    ``kind``, ``schema_version``, ``software``, ``created_utc`` (see
    :func:`labkit.h5io.stamp`); ``config_toml`` (the config file's text),
    ``config_path``, ``config_json`` (the validated config without resources,
    used to match a resumed run), ``versions_json`` (python, numpy, scipy, h5py,
    pyvisa, labkit), ``started_utc``, ``ended_utc``, ``status`` (``"running"``,
    ``"complete"``, ``"interrupted: SIGINT"``, ``"aborted: <why>"``),
    ``points_planned``, ``resumed_utc_json`` (list of resume times),
    ``drive_bounded`` (bool: every acquisition was a finite generator burst, so
    the drive stopped by itself within a point even if the computer died) and
    ``drive_bounded_note`` (why not, e.g. a chirp).
``/instruments/<role>``
    attributes ``model``, ``resource``, ``snapshot_json`` (identity and settings).
``/points``
    one row per finished point, in the order measured (also skipped ones):
    ``index`` (plan index, 1), ``status`` (label: ``ok`` | ``interlock``),
    ``reason`` (text), ``time_unix_s`` (s, end of point), ``duration_s`` (s),
    ``location`` (label) and ``freq_hz`` (Hz), and for shaker runs the data
    below.
``/events``
    ``time_unix_s`` (s), ``text`` (text): safety events (drive on/off, interlocks,
    spot moves, interruptions).
``/virtual_lab`` (runs against the virtual lab only)
    ``output_timeline``: ``t_s`` (s, the lab's clock), ``time_unix_s`` (s),
    ``instrument``, ``channel`` (label), ``on`` (1); attributes ``truth_json``
    and ``t0_monotonic_s`` (the lab clock's zero on ``time.monotonic()``).

In-chip sweep (``kind = "run_inchip"``)
---------------------------------------
root attribute ``method`` (``"stepped"`` | ``"chirp"``), ``drive_amp_vpp``,
``drive_offset_v``. Per location ``/locations/<loc>/`` (loc in body, hip,
knee), rows appended per point (a chirp appends all its frequency lines at
once): ``freq_hz`` (Hz), ``frf`` (complex128, ``(mm/s)/V``: vibrometer
velocity over drive voltage), ``quality`` (1: smaller sine-fit R^2 of the two
channels; for chirps the coherence), ``point_index`` (1); stepped sine adds
``drive_v`` (complex, V) and ``velocity_mm_s`` (complex, mm/s), the complex
amplitudes (peak) of the two channels; chirps add ``coherence`` (1).
With ``keep_raw``: ``/raw/p<index>/`` holding ``drive_v`` and ``velocity_v``
(V, the scope records) with attribute ``dt_s``.

Shaker run (``kind = "run_shaker"``)
------------------------------------
root attributes ``robot_spot`` (knee | hip | body), ``amplitude_kind``
(``tray_amp_um`` | ``drive_vpp``), ``amplifier_json`` (declared gain_db,
attenuator_db, current_limit_a, max_input_vrms), ``shaker_json``
(payload_kg, envelope). ``/points`` adds per point:
``tray_amp_request_um`` (um; NaN when the grid gives drive voltages),
``drive_request_vpp`` (Vpp; NaN in tray mode), ``drive_vpp`` (Vpp, the drive
finally applied), ``iterations`` (1, drive adjustments to reach the tray
amplitude), ``tray_amp_um`` (um, measured: tray velocity / (2 pi f)),
``tray_velocity_mm_s`` and ``robot_velocity_mm_s`` (complex, mm/s, phase
referred to the drive), ``transmissibility`` (complex, 1: robot velocity over
tray velocity), ``quality`` (1), ``video`` (text: the point's video path,
relative to the run file's folder; empty without video), ``video_frames`` (1).
``/records/p<index>/`` keeps the tray's and the robot's velocity records:
``tray_velocity_mm_s``, ``robot_velocity_mm_s`` (mm/s), ``tray_drive_v``,
``robot_drive_v`` (V), attribute ``dt_s``.
"""
from __future__ import annotations

import errno
import json
import logging
import os
import platform
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeAlias, TypedDict

import numpy as np

from labkit.errors import InputError
from labkit.h5io import SCHEMA_VERSION as H5_SCHEMA_VERSION
from labkit.h5io import get_json, label_dimensions, open_h5, put_json, stamp, utc_now
from labkit.jsonutil import Json

if TYPE_CHECKING:  # pragma: no cover - annotations only (kinds imports this module's tables)
    from labkit.experiments.kinds import Config

#: the run file's own failures on the shutdown path (``labkit -v`` shows them)
_log = logging.getLogger(__name__)

#: one value of a table row: a number, a text, or (a chirp's lines) an array of them
Cell: TypeAlias = "float | complex | int | str | np.ndarray | np.generic"
#: a table row: column name -> value (a column missing from it gets a blank)
Row: TypeAlias = "dict[str, Cell]"
#: a root attribute's value
AttrValue: TypeAlias = "str | float | int | bool"


class RunSummary(TypedDict, total=False):
    """:func:`summary`: what a run file holds, as the CLI's ``--json`` line prints it."""

    file: str
    kind: str
    status: str
    points_planned: int
    points_done: int
    points_ok: int
    points_interlocked: int
    points_retried: int
    locations: dict[str, int]          # in-chip: FRF lines per location

#: 1: first layout; 2: dimension scales (``/points/index``, ``freq_hz``, records' ``t_s``);
#: 3: text columns fixed-length UTF-8 with checksums (no variable-length strings, no global heap),
#: see docs/file-formats.md. Readers (labkit.files.runs) read every version.
SCHEMA_VERSION = H5_SCHEMA_VERSION
#: a text column: ``"str<bytes>"``, fixed-length UTF-8 of that many bytes (longer text is cut, ending in
#: :data:`CUT_MARK`). Fixed-length text lives in the dataset's own chunks, checksummed and flushed with
#: the point; variable-length strings would live in HDF5's global heap, which HDF5 may write at any
#: instant between two flushes when its metadata cache is bounded (a kill then left it unreadable).
_LABEL, _TEXT, _LINE = "str32", "str256", "str512"
#: the end of a text cut to its column's width
CUT_MARK = "\u2026"

#: name -> (dtype, units). ``index`` is last on purpose: it is written last.
POINT_FIELDS: dict[str, tuple[str, str]] = {
    "location": (_LABEL, "label"), "freq_hz": ("f8", "Hz"), "status": (_LABEL, "label"),
    "reason": (_TEXT, "text"), "time_unix_s": ("f8", "s"), "duration_s": ("f8", "s"),
}
SHAKER_FIELDS: dict[str, tuple[str, str]] = {
    "tray_amp_request_um": ("f8", "um"), "drive_request_vpp": ("f8", "Vpp"), "drive_vpp": ("f8", "Vpp"),
    "iterations": ("i8", "1"), "tray_amp_um": ("f8", "um"), "tray_velocity_mm_s": ("c16", "mm/s"),
    "robot_velocity_mm_s": ("c16", "mm/s"), "transmissibility": ("c16", "1"), "quality": ("f8", "1"),
    "video": (_TEXT, "path"), "video_frames": ("i8", "1"),
}
STEPPED_FIELDS: dict[str, tuple[str, str]] = {
    "freq_hz": ("f8", "Hz"), "frf": ("c16", "(mm/s)/V"), "quality": ("f8", "1"),
    "drive_v": ("c16", "V"), "velocity_mm_s": ("c16", "mm/s"), "point_index": ("i8", "1"),
}
CHIRP_FIELDS: dict[str, tuple[str, str]] = {
    "freq_hz": ("f8", "Hz"), "frf": ("c16", "(mm/s)/V"), "quality": ("f8", "1"),
    "coherence": ("f8", "1"), "point_index": ("i8", "1"),
}
EVENT_FIELDS = {"time_unix_s": ("f8", "s"), "text": (_LINE, "text")}


def versions() -> dict[str, str]:
    """Versions of the software that wrote a run (for the file's ``versions_json``)."""
    import h5py
    import scipy

    from labkit import __version__

    out = {"labkit": __version__, "python": platform.python_version(), "numpy": np.__version__,
           "scipy": scipy.__version__, "h5py": h5py.version.version, "hdf5": h5py.version.hdf5_version}
    try:
        import pyvisa
        out["pyvisa"] = pyvisa.__version__
    except Exception:  # pragma: no cover - optional at read time
        pass
    return out


def _dtype(code: str) -> np.dtype:
    import h5py

    return h5py.string_dtype("utf-8", int(code[3:])) if code.startswith("str") else np.dtype(code)


#: bytes of a text column's chunk: it fits HDF5's chunk cache (:data:`CHUNK_CACHE_BYTES`) twice
TEXT_CHUNK_BYTES = 4096


def _make_table(group: Any, fields: dict[str, tuple[str, str]], with_index: bool = True) -> None:
    items = list(fields.items()) + ([("index", ("i8", "1"))] if with_index else [])
    for name, (code, units) in items:
        if name in group:
            continue
        dtype = _dtype(code)
        rows = max(8, TEXT_CHUNK_BYTES // dtype.itemsize) if dtype.kind == "S" else 256
        # a Fletcher-32 checksum per chunk, text included
        ds = group.create_dataset(name, shape=(0,), maxshape=(None,), dtype=dtype, chunks=(rows,),
                                  fletcher32=True)
        ds.attrs["units"] = units
        if dtype.kind == "S":
            ds.attrs["_Encoding"] = "utf-8"        # the netCDF convention: xarray reads it as text


def fit_text(values: Any, dtype: np.dtype) -> np.ndarray:
    """Text as a fixed-length UTF-8 column of ``dtype``: each value encoded, and cut at a character
    boundary (ending in :data:`CUT_MARK`) when longer than the column's width."""
    width = dtype.itemsize
    out = []
    for v in np.atleast_1d(np.asarray(values, dtype=object)).tolist():
        raw = (v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)).encode("utf-8")
        if len(raw) > width:
            mark = CUT_MARK.encode("utf-8")
            raw = raw[:width - len(mark)].decode("utf-8", "ignore").encode("utf-8") + mark
        out.append(raw)
    return np.array(out, dtype=dtype)


def _column(values: Any, dtype: np.dtype) -> np.ndarray:
    return fit_text(values, dtype) if dtype.kind == "S" else np.asarray(values, dtype=dtype)


class _Table:
    """Columns of one group appended together, in a fixed order (``index`` last when present).

    The datasets are looked up once and written through h5py's low-level API
    (extend, select the new rows, write): four times cheaper per point than
    ``ds.resize(); ds[n:] = ...``, which matters at tens of points a second.
    A column missing from a row gets a blank (NaN, 0 or "") so the columns
    never differ in length.
    """

    def __init__(self, group: Any) -> None:
        import h5py

        names = [k for k in group.keys() if isinstance(group[k], h5py.Dataset) and group[k].maxshape[0] is None]
        names.sort(key=lambda k: k == "index")
        self.columns = [(k, group[k]) for k in names]

    def append(self, rows: Row) -> None:
        from h5py import h5s

        k = max(int(np.size(v)) for v in rows.values()) if rows else 1
        for name, ds in self.columns:
            arr = _column(rows[name], ds.dtype) if name in rows else _blank(ds.dtype, k)
            arr = np.ascontiguousarray(np.broadcast_to(np.atleast_1d(arr), (k,)))
            n = ds.id.get_space().shape[0]
            ds.id.set_extent((n + k,))
            space = ds.id.get_space()
            space.select_hyperslab((n,), (k,))
            ds.id.write(h5s.create_simple((k,)), space, arr)


def _blank(dtype: np.dtype, k: int) -> np.ndarray:
    if dtype.kind == "O":
        return np.array([""] * k, dtype=dtype)
    if dtype.kind in "fc":
        return np.full(k, np.nan, dtype=dtype)
    return np.zeros(k, dtype=dtype)


def _trim(group: Any, n: int) -> None:
    import h5py

    for ds in group.values():
        if isinstance(ds, h5py.Dataset) and ds.maxshape[0] is None and ds.shape[0] > n:
            ds.resize((n,))


#: the status of a point an interlock stopped that ``--resume --retry-interlocked`` measured again
RETRIED = "interlock, retried"

#: free bytes every write leaves untouched: HDF5's metadata, the shutdown's events and final status
RESERVE_BYTES = 2 * 1024 * 1024
#: bytes a run file takes before its first point (attributes, config text, empty tables)
BASE_BYTES = 256 * 1024
#: set aside for a run file's journal (:mod:`labkit.h5journal`) unless the caller says more: it holds
#: one flush's pages (a point's rows and records and the metadata they touch)
JOURNAL_BYTES = 2 * 1024 * 1024


class WriteFailed(InputError):
    """Writing a point into the run file failed (the disk, the file system, HDF5): the run stops.

    The runner turns the drive off before this is reported; the rows of a point are
    written index last, so the file holds every point completed before (``--resume``
    trims a half-written one).
    """


class DiskFull(InputError):
    """The disk (or the process's file-size limit) has no room for the next write; nothing was written.

    HDF5 does not survive a failed write (the library crashes the process on the next
    flush or close), so run files are never written into the last :data:`RESERVE_BYTES`.
    """


def reserved_bytes(path: str | Path) -> float:
    """Bytes the file system holds for ``path`` beyond its end (:func:`reserve_space`); 0 without."""
    try:
        st = os.stat(path)
    except OSError:
        return 0.0
    return float(max(0, st.st_blocks * 512 - st.st_size))


def reserve_space(path: str | Path, nbytes: float) -> bool:
    """Have the file system set ``nbytes`` aside for ``path`` beyond its end (``fallocate``, keep size).

    HDF5 grows the file into those blocks, which no other process can take: a disk that
    fills up meanwhile never meets the run's writes (HDF5 does not survive ENOSPC). The
    file's size is unchanged, so HDF5 and every reader see the same file. Returns False
    when the file system cannot (then :meth:`RunFile.ensure_room` alone guards); raises
    :class:`DiskFull` when there is no room for the reservation.
    """
    from labkit.h5journal import fallocate_keep_size

    if nbytes <= 0:
        return False
    fd = os.open(path, os.O_WRONLY)
    try:
        err = fallocate_keep_size(fd, os.fstat(fd).st_size, int(nbytes))
    finally:
        os.close(fd)
    if err in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT):
        raise DiskFull(f"no room to set {_mb(nbytes)} aside for this run ({os.strerror(err)})", file=path,
                       key="--out")
    return err == 0


def release_space(path: str | Path) -> None:
    """Give back what :func:`reserve_space` set aside and the run did not use (truncate to its size)."""
    try:
        os.truncate(path, os.stat(path).st_size)
    except OSError:
        pass


def headroom_bytes(path: str | Path) -> float:
    """Bytes that may still be written to ``path``: free space on its file system for this
    user plus the space reserved for it (:func:`reserve_space`), and no more than the soft
    ``RLIMIT_FSIZE`` allows the file to grow."""
    import resource

    path = Path(path)
    folder = path.parent if not path.is_dir() else path
    st = os.statvfs(folder if folder.exists() else Path.cwd())
    free = float(st.f_bavail) * st.f_frsize + (reserved_bytes(path) if path.is_file() else 0.0)
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    if soft != resource.RLIM_INFINITY:
        size = path.stat().st_size if path.is_file() else 0
        free = min(free, float(soft - size))
    return free


def check_room(path: str | Path, need_bytes: float, *, key: str = "--out") -> None:
    """Pre-flight: DiskFull (exit 2, nothing created) unless a run of about ``need_bytes`` fits."""
    free = headroom_bytes(path)
    if free < need_bytes + RESERVE_BYTES:
        raise DiskFull(f"not enough room for this run: about {_mb(need_bytes)} needed plus {_mb(RESERVE_BYTES)} "
                       f"kept in reserve, {_mb(free)} free (file system, or the file-size limit); "
                       "free some space or write elsewhere", file=path, key=key)


#: HDF5's chunk cache per dataset of a run file being written: the 256-row chunk being appended
#: to (4 KiB for complex rows) and one more (the default, 8 MiB a dataset, kept every chunk the
#: run wrote, and 64 KiB still filled over the first 4000 points: memory grew with every point)
CHUNK_CACHE_BYTES = 8 * 1024
#: HDF5's metadata cache of a run file being written (version 3 on), capped: its default grows
#: towards 32 MiB. A run file's metadata while it is written (object headers, the chunk indexes)
#: is about 110 KiB after 10000 points, so the cap holds all of it and HDF5 never has to write
#: metadata out between two of the run's flushes to make room (tests/experiments/test_runfile.py)
METADATA_CACHE_BYTES = 1024 * 1024


def open_for_writing(path: str | Path, mode: str) -> Any:
    """``path`` opened for writing through a redo journal (:mod:`labkit.h5journal`), caches bounded.

    Each ``flush()`` is one atomic step: a kill or power cut at any instant leaves the file as
    of a flush (its journal, if whole, is replayed by :func:`labkit.h5journal.recover` or
    overlaid by readers). Both of HDF5's caches are bounded, so memory stays flat per point.
    A file of a layout before version 3 (variable-length strings, kept in HDF5's global heap,
    which grows with every point) is resumed with HDF5's default metadata cache: capped, it
    wrote the heap between the run's flushes."""
    from labkit.h5journal import open_journaled

    f = open_journaled(path, mode, rdcc_nbytes=CHUNK_CACHE_BYTES, rdcc_nslots=521)
    if mode == "w" or int(f.attrs.get("schema_version", 0)) >= 3:
        mdc = f.id.get_mdc_config()
        mdc.set_initial_size = True
        mdc.initial_size = mdc.max_size = METADATA_CACHE_BYTES
        mdc.min_size = METADATA_CACHE_BYTES // 2
        f.id.set_mdc_config(mdc)
    return f


def _link_into_place(tmp: Path, path: Path) -> None:
    """``tmp`` becomes ``path`` (FileExistsError if ``path`` appeared meanwhile: never overwrite)."""
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise
    except OSError:                 # a file system without hard links: rename, after one more look
        if path.exists():
            raise FileExistsError(path) from None
        os.rename(tmp, path)


def recover_journal(path: Path) -> None:
    """Replay ``path``'s journal if a kill cut a flush (the caller holds the run's lock)."""
    from labkit.h5journal import recover

    try:
        recover(path)
    except OSError as exc:
        raise InputError(f"cannot finish its last write, cut by a crash ({exc.strerror})", file=path,
                         key="--resume") from None


def partial_path(path: Path) -> Path:
    """Where :meth:`RunFile.create` makes ``path`` before linking it into place."""
    return path.with_name(f".{path.name}.partial.{os.getpid()}")


def remove_stale_partials(path: Path) -> list[Path]:
    """Remove what a killed run left while making ``path`` (its process is gone); return them."""
    from labkit.outputs import process_alive

    gone = []
    for p in path.parent.glob(f".{path.name}.partial.*"):
        pid = p.name.rsplit(".", 1)[-1]
        if pid.isdigit() and not process_alive(int(pid)):
            p.unlink(missing_ok=True)
            gone.append(p)
    return gone


def check_free_bytes(folder: str | Path, need_bytes: float, what: str) -> None:
    """DiskFull unless the file system (not counting any run file's reserve) has twice ``need_bytes``."""
    st = os.statvfs(folder)
    free = float(st.f_bavail) * st.f_frsize
    if free < 2 * need_bytes:
        raise DiskFull(f"not enough room for {what} ({_mb(free)} free, about {_mb(need_bytes)} needed); "
                       "the file holds every completed point; free some space, then continue with --resume",
                       file=folder, key="--out")


def _mb(n: float) -> str:
    return f"{n / 1e6:.3g} MB"


class RunFile:
    """Writer of one run file (create with :meth:`create`, continue with :meth:`resume`).

    Use as a context manager; :meth:`finish` records the final status.
    """

    def __init__(self, f: Any, path: Path) -> None:
        self.f = f
        self.path = path
        self.kind = str(f.attrs["kind"])
        self._tables: dict[str, _Table] = {}
        self.full = False                    # a write was refused for want of room
        self.events_dropped = 0              # events not written for want of room
        # plan index -> status of the points finished when the file was opened (the plan's input;
        # not added to per point: a long run's memory stays flat)
        self.done: dict[int, str] = {}
        idx = f["points/index"][...]
        st = f["points/status"].asstr()[...] if len(idx) else []
        for i, s in zip(idx, st):
            if str(s) != RETRIED:
                self.done[int(i)] = str(s)

    # -- opening ---------------------------------------------------------------------------
    @classmethod
    def create(cls, path: str | Path, cfg: Config, config_json: dict[str, Json], points_planned: int,
               extra_attrs: dict[str, AttrValue] | None = None, reserve_bytes: float = 0.0,
               journal_bytes: float = JOURNAL_BYTES) -> RunFile:
        """A new run file for ``cfg`` (an InchipConfig or ShakerConfig); refuses to overwrite.

        The file is made aside (``.<name>.partial.<pid>``), with ``reserve_bytes`` set aside
        for it (:func:`reserve_space`) before anything is written, then linked into place
        complete: ``path`` is a valid run file from its first byte on disk. From then on every
        flush goes through its journal (``journal_bytes`` set aside for it).
        """

        path = Path(path)
        if path.exists():
            raise InputError("already exists; use --resume to continue it, or another --out",
                             file=path, key="--out")
        path.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_partials(path)
        tmp = partial_path(path)
        try:
            # the earliest file format on purpose: 1.10's superblock marks a file open for writing, and
            # a killed run's file would then be refused by every reader until someone runs h5clear
            f = open_for_writing(tmp, "w")
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            if exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
                raise DiskFull(f"no room to create the run file ({os.strerror(exc.errno)})", file=path,
                               key="--out") from None
            raise InputError(f"cannot create ({exc})", file=path, key="--out") from None
        try:
            reserve_space(tmp, reserve_bytes)
            cls._lay_out(f, cfg, config_json, points_planned, extra_attrs)
            f.flush()
            _link_into_place(tmp, path)
            f.journal.start_journal(path, journal_bytes)
        except BaseException as exc:
            f.close()
            tmp.unlink(missing_ok=True)
            if isinstance(exc, FileExistsError):
                raise InputError("already exists; use --resume to continue it, or another --out",
                                 file=path, key="--out") from None
            raise
        tmp.unlink(missing_ok=True)
        return cls(f, path)

    @staticmethod
    def _lay_out(f: Any, cfg: Config, config_json: dict[str, Json], points_planned: int,
                 extra_attrs: dict[str, AttrValue] | None) -> None:
        from labkit.experiments import kinds

        kind = kinds.of(cfg)
        stamp(f, kind.file_kind, SCHEMA_VERSION)
        f.attrs["config_toml"] = cfg.text
        f.attrs["config_path"] = str(cfg.path)
        f.attrs["config_json"] = json.dumps(config_json, sort_keys=True)
        put_json(f, "versions_json", versions())
        f.attrs["started_utc"] = utc_now()
        f.attrs["ended_utc"] = ""
        f.attrs["status"] = "running"
        f.attrs["points_planned"] = int(points_planned)
        put_json(f, "resumed_utc_json", [])
        for k, v in (kind.run_attrs(cfg) | (extra_attrs or {})).items():
            f.attrs[k] = v
        f.create_group("instruments")
        point_fields, tables = kind.layout(cfg)
        _make_table(f.create_group("points"), POINT_FIELDS | point_fields)
        _make_table(f.create_group("events"), EVENT_FIELDS, with_index=False)
        for group, fields in tables.items():
            _make_table(f.require_group(group), fields, with_index=False)
        label_dimensions(f)             # coordinates for h5py, xarray and HDFView (schema 2)

    @classmethod
    def resume(cls, path: str | Path, cfg: Config, config_json: dict[str, Json],
               retry_interlocked: bool = False, journal_bytes: float = JOURNAL_BYTES) -> RunFile:
        """Reopen a run file to continue it after its last complete point.

        With ``retry_interlocked``, points an interlock stopped are measured again: their rows
        stay (the record of what happened) with status ``interlock, retried``, and the new
        measurement is appended as a row of its own.

        Raises
        ------
        InputError
            Not a run file of this kind, or written for a different config.
        """

        from labkit.experiments import kinds

        path = Path(path)
        recover_journal(path)           # a flush a kill interrupted is finished first (its journal replayed)
        open_h5(path, "r", kind=kinds.of(cfg).file_kind).close()          # kind and schema checks, clear errors
        try:
            f = open_for_writing(path, "r+")
            f.journal.start_journal(path, journal_bytes)
        except OSError as exc:
            from labkit.h5io import why_unreadable

            raise InputError(f"cannot open for appending: {why_unreadable(path, exc)}", file=path,
                             key="--resume") from None
        stored = json.loads(f.attrs.get("config_json", "{}"))
        if stored != json.loads(json.dumps(config_json, sort_keys=True)):
            diff = sorted(k for k in set(stored) | set(config_json)
                          if json.dumps(stored.get(k), sort_keys=True)
                          != json.dumps(config_json.get(k), sort_keys=True))
            f.close()
            raise InputError("was written with a different config; resume with the run's own config",
                             file=path, key="--resume",
                             expected=f"the same settings (differing: {', '.join(diff) or '?'})")
        # A SIGKILL may have cut a point between its data and its index: trim to the index.
        n = f["points/index"].shape[0]
        _trim(f["points"], n)
        status = f["points/status"].asstr()[...]
        locs = f["points/location"].asstr()[...]
        if "locations" in f:
            for loc, grp in f["locations"].items():
                ok = {int(i) for i, s, where in zip(f["points/index"][...], status, locs)
                      if s == "ok" and where == loc}
                keep = int(np.sum(np.isin(grp["point_index"][...], list(ok)))) if ok else 0
                _trim(grp, keep)
        for name in ("raw", "records"):
            if name in f:
                done = {int(i) for i in f["points/index"][...]}
                for key in list(f[name]):
                    if int(key[1:]) not in done:
                        del f[name][key]
        if retry_interlocked:
            st = f["points/status"]
            values = st.asstr()[...]
            if np.any(values == "interlock"):
                st[...] = _column(np.where(values == "interlock", RETRIED, values), st.dtype)
        f.attrs["status"] = "running"
        f.attrs["ended_utc"] = ""
        resumed = get_json(f, "resumed_utc_json", [])
        put_json(f, "resumed_utc_json", resumed + [utc_now()])
        f.flush()
        return cls(f, path)

    def reserve(self, nbytes: float) -> bool:
        """Set ``nbytes`` aside beyond the file's end for the rest of the run (:func:`reserve_space`)."""
        return reserve_space(self.path, nbytes)

    # -- writing ---------------------------------------------------------------------------
    def set_instrument(self, role: str, model: str, resource: str, snapshot: dict[str, Json]) -> None:
        g = self.f.require_group(f"instruments/{role}")
        g.attrs["model"] = model
        g.attrs["resource"] = resource
        put_json(g, "snapshot_json", snapshot)
        self._flush()

    def _flush(self) -> None:
        """Commit what was written since the last flush (atomically: :mod:`labkit.h5journal`).

        A disk with no room for the journal is :class:`DiskFull`: nothing of this flush reached
        the file, which holds every point flushed before."""
        try:
            self.f.flush()
        except OSError as exc:
            if exc.errno not in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
                raise
            self.full = True
            raise DiskFull(f"no room to write the run file's journal ({os.strerror(exc.errno)}); the file "
                           "holds every completed point; free some space, then continue with --resume",
                           file=self.path, key="--out") from None

    def set_attrs(self, **attrs: Any) -> None:
        for k, v in attrs.items():
            self.f.attrs[k] = v

    def _table(self, name: str) -> _Table:
        if name not in self._tables:
            self._tables[name] = _Table(self.f[name])
        return self._tables[name]

    # -- room on the disk (HDF5 must never meet ENOSPC/EFBIG: it crashes the process) ---------
    def ensure_room(self, need_bytes: float, what: str = "the next point") -> None:
        """Raise :class:`DiskFull` (nothing written) unless ``need_bytes`` fit with a margin.

        The margin (twice the estimate plus :data:`RESERVE_BYTES`) keeps room for
        HDF5's own metadata, the events and the final status of a run that stops here.
        """
        free = headroom_bytes(self.path)
        if free < 2 * need_bytes + RESERVE_BYTES:
            self.full = True
            raise DiskFull(f"not enough room to write {what} safely ({_mb(free)} free on its file system "
                           f"or under the file-size limit; about {_mb(need_bytes)} needed plus "
                           f"{_mb(RESERVE_BYTES)} kept in reserve); the file holds every completed point; "
                           "free some space, then continue with --resume", file=self.path, key="--out")

    def _floor(self, what: str) -> None:
        """Every write into the file needs at least half the reserve (events may use the rest)."""
        if headroom_bytes(self.path) < RESERVE_BYTES / 2:
            self.full = True
            raise DiskFull(f"no room left to write {what}", file=self.path, key="--out")

    def event(self, text: str, t_unix_s: float | None = None) -> None:
        """Append a line to ``/events`` and flush; dropped (and counted) when the disk is nearly full."""
        if headroom_bytes(self.path) < RESERVE_BYTES / 4:
            self.events_dropped += 1
            return
        self._table("events").append({"time_unix_s": time.time() if t_unix_s is None else t_unix_s, "text": text})
        self._flush()

    def add_location_rows(self, location: str, rows: Row) -> None:
        """Append rows to ``/locations/<location>`` (not flushed: :meth:`end_point` flushes)."""
        self._floor("a point's rows")
        self._table(f"locations/{location}").append(rows)

    def add_records(self, group: str, index: int, dt_s: float, arrays: dict[str, tuple[np.ndarray, str]]) -> None:
        """Keep the point's raw records under ``/<group>/p<index>/`` (name -> (data, units))."""
        self._floor("a point's records")
        g = self.f.require_group(f"{group}/p{index:05d}")
        g.attrs["dt_s"] = float(dt_s)
        for name, (data, units) in arrays.items():
            if name in g:
                del g[name]
            ds = g.create_dataset(name, data=np.asarray(data, dtype=np.float32), compression="gzip",
                                  compression_opts=1, shuffle=True, fletcher32=True)
            ds.attrs["units"] = units
        if "t_s" in g:
            del g["t_s"]
        label_dimensions(g)             # t_s (s) from dt_s, a dimension scale

    def end_point(self, index: int, row: Row) -> None:
        """Append the point's row to ``/points`` (index last) and flush: the point is complete."""
        self._floor("a point's row")
        self._table("points").append(dict(row, index=index))
        self._flush()

    def finish(self, status: str) -> None:
        """The final status (and end time); needs a quarter of the reserve (kept for it)."""
        if headroom_bytes(self.path) < RESERVE_BYTES / 8:
            raise DiskFull("no room left to write the run's final status", file=self.path, key="--out")
        self.f.attrs["status"] = status
        self.f.attrs["ended_utc"] = utc_now()
        if self.events_dropped:
            self.f.attrs["events_dropped"] = int(self.events_dropped)
        self._flush()

    def close(self) -> None:
        try:
            self.f.close()
        except Exception as exc:  # pragma: no cover - closing after a failed write
            _log.info("%s: closing the run file: %s: %s", self.path, type(exc).__name__, exc)

    def __enter__(self) -> RunFile:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def write_lab_record(path: str | Path, timeline: list[tuple], truth: Json | None,
                     clock_offset_s: float = 0.0, t0_monotonic_s: float | None = None) -> None:
    """Store the virtual lab's output timeline (and its truth) in a finished run file.

    ``clock_offset_s`` converts the lab's ``t_s`` to Unix time (``time_unix_s = t_s + offset``);
    ``t0_monotonic_s`` is the lab's zero on ``time.monotonic()`` (system-wide on Linux, so
    another process can compare its own monotonic times with the timeline).
    """
    import h5py

    with open_for_writing(path, "r+") as f:
        f.journal.start_journal(path)
        g = f.require_group("virtual_lab")
        for name in list(g):
            del g[name]
        tl = g.create_group("output_timeline")
        t = np.array([float(row[0]) for row in timeline], dtype=float)
        cols = {"t_s": (t, "s"), "time_unix_s": (t + clock_offset_s, "s"),
                "instrument": (np.array([str(r[1]) for r in timeline], dtype=object), "label"),
                "channel": (np.array([str(r[2]) for r in timeline], dtype=object), "label"),
                "on": (np.array([int(bool(r[3])) for r in timeline], dtype=np.int8), "1")}
        for name, (data, units) in cols.items():
            kw = {"dtype": h5py.string_dtype()} if data.dtype == object else {}
            ds = tl.create_dataset(name, data=data, **kw)
            ds.attrs["units"] = units
        label_dimensions(tl)
        if truth is not None:
            put_json(g, "truth_json", truth)
        if t0_monotonic_s is not None:
            g.attrs["t0_monotonic_s"] = float(t0_monotonic_s)


def read_points(path: str | Path) -> dict[str, np.ndarray]:
    """The ``/points`` table of a run file as arrays, complete points only (strings decoded).

    A thin call to :func:`labkit.files.runs.read_run_file`, the one run-file reader.
    """
    from labkit.files.runs import read_run_file

    return read_run_file(path).points


def summary(path: str | Path) -> RunSummary:
    """A short JSON-able summary of a run file (for the CLI's ``--json`` line)."""
    from labkit.files.runs import InchipRun, read_run_file

    run = read_run_file(path)
    st = run.points.get("status", np.array([], dtype=str))
    out: RunSummary = {
        "file": os.fspath(path), "kind": run.kind, "status": run.status, "points_planned": run.points_planned,
        "points_done": int(np.sum(st != RETRIED)) if st.size else run.complete_points,
        "points_ok": int(np.sum(st == "ok")), "points_interlocked": int(np.sum(st == "interlock")),
        "points_retried": int(np.sum(st == RETRIED)),
    }
    if isinstance(run, InchipRun) and run.locations:
        out["locations"] = {loc: int(lg.freq_hz.size) for loc, lg in run.locations.items()}
    return out
