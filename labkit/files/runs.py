"""The one run-file reader (in-chip and shaker runs; layout in :mod:`labkit.experiments.runfile`).

The rule that makes a run file cut short by a crash safe to read lives here,
once: within ``/points`` the ``index`` dataset is written last, so its length
is the number of *complete* points; every other column is read to that
length. A location row (``/locations/<loc>``) or a record group
(``/raw/p<index>``, ``/records/p<index>``) counts only if its point is
complete. Everything else that reads run files (``labkit fit``, the report,
``labkit info``) goes through :func:`read_run_file`.
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from labkit.files.base import FileSummary, Json, LabFile, column, json_attr, require_xarray, root_attrs, text, units_of

if TYPE_CHECKING:  # pragma: no cover
    import xarray

    from labkit.tomlio import TomlValue

#: run-file layouts this reader knows: 1 (no dimension scales), 2 (dimension scales, t_s in records)
READS_SCHEMA = (1, 2)


class RunSummary(FileSummary):
    """:meth:`RunFile.summary`: how far the run got and with which instruments (role -> model)."""

    status: str
    points_planned: int
    points_done: int
    points_ok: int
    points_interlocked: int
    instruments: dict[str, str]
    config_path: str


class InchipSummary(RunSummary):
    """:meth:`InchipRun.summary`: the method and the FRF lines per location."""

    method: str
    locations: dict[str, int]


class ShakerSummary(RunSummary):
    """:meth:`ShakerRun.summary`: where the robot sat and what the amplitude means."""

    robot_spot: str
    amplitude_kind: str


@dataclass
class Instrument:
    """One instrument of a run: its model, its resource and the snapshot of its identity and settings."""

    role: str
    model: str
    resource: str
    snapshot: dict[str, Json]


@dataclass
class Record:
    """The sampled signals of one point (``/raw/p<index>`` or ``/records/p<index>``)."""

    index: int
    dt_s: float
    signals: dict[str, np.ndarray]
    units: dict[str, str]

    @property
    def t_s(self) -> np.ndarray:
        """Sample times from the record's start (s)."""
        n = max((v.size for v in self.signals.values()), default=0)
        return np.arange(n) * self.dt_s


@dataclass
class RunFile(LabFile):
    """An in-chip (``run_inchip``) or shaker (``run_shaker``) run file, complete points only.

    Attributes
    ----------
    status:
        ``complete``, ``interrupted: SIGINT``, ``aborted: ...`` or ``running`` (cut short).
    config_toml, config:
        The experiment config's text and its parsed table.
    instruments:
        Role -> :class:`Instrument` (model, resource, settings snapshot).
    points:
        ``/points`` columns, complete points only (``index``, ``status``, ``freq_hz``, ...).
    events:
        ``time_unix_s`` and ``text`` of the safety events.
    """

    status: str = "?"
    config_toml: str = ""
    config: dict[str, TomlValue] = field(default_factory=dict, repr=False)
    instruments: dict[str, Instrument] = field(default_factory=dict, repr=False)
    points: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    events: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    points_planned: int = 0
    record_group: str = ""

    @property
    def complete_points(self) -> int:
        col = self.points.get("index", next(iter(self.points.values()), None))
        return 0 if col is None else int(np.size(col))

    @property
    def ok(self) -> np.ndarray:
        """Mask of the complete points whose status is ``ok``."""
        st = self.points.get("status")
        return np.ones(self.complete_points, bool) if st is None else np.asarray(st) == "ok"

    def records(self) -> dict[int, Record]:
        """The kept signal records of complete points, by plan index (read on demand)."""
        from labkit.h5io import open_h5

        out: dict[int, Record] = {}
        done = {int(i) for i in self.points.get("index", [])}
        with open_h5(self.path, "r", verify=False) as f:
            grp = f.get(self.record_group) if self.record_group else None
            if grp is None:
                return out
            for name in sorted(grp):
                try:
                    index = int(str(name).lstrip("p"))
                except ValueError:
                    continue
                g = grp[name]
                if index not in done or "dt_s" not in g.attrs:
                    continue
                sig = {k: np.asarray(g[k][()], float) for k in g if k != "t_s"}
                out[index] = Record(index, float(g.attrs["dt_s"]), sig, {k: units_of(g[k]) for k in sig})
        return out

    def summary(self) -> RunSummary:
        st = self.points.get("status", np.array([], str))
        return {**super().summary(),
                "status": self.status, "points_planned": self.points_planned, "points_done": self.complete_points,
                "points_ok": int(np.sum(st == "ok")), "points_interlocked": int(np.sum(st == "interlock")),
                "instruments": {r: i.model for r, i in self.instruments.items()},
                "config_path": text(self.attrs.get("config_path", ""))}


@dataclass
class Location:
    """The FRF lines measured at one location of an in-chip run (complete points only)."""

    name: str
    columns: dict[str, np.ndarray]
    units: dict[str, str]

    @property
    def freq_hz(self) -> np.ndarray:
        return self.columns["freq_hz"]

    @property
    def frf(self) -> np.ndarray:
        """Velocity over drive voltage, complex, ``(mm/s)/V``."""
        return self.columns["frf"]

    @property
    def quality(self) -> np.ndarray:
        q = self.columns.get("quality")
        return np.ones(self.freq_hz.size) if q is None else q


@dataclass
class InchipRun(RunFile):
    """An in-chip swept-sine run: FRFs per location (``run.locations["knee"].frf``)."""

    method: str = "?"
    locations: dict[str, Location] = field(default_factory=dict, repr=False)

    def summary(self) -> InchipSummary:
        return {**super().summary(), "method": self.method,
                "locations": {k: int(v.freq_hz.size) for k, v in self.locations.items()}}

    def to_xarray(self) -> xarray.Dataset:
        """``frf``, ``quality`` (and the stepped sine's ``drive_v``, ``velocity_mm_s``) over
        ``location`` x ``freq_hz`` (the union of the locations' lines; NaN where a location has none)."""
        xr = require_xarray()
        parts = []
        for name, loc in self.locations.items():
            f, keep = np.unique(loc.freq_hz, return_index=True)      # last-resort: one value per line
            data = {k: (("freq_hz",), v[keep], {"units": loc.units.get(k, "")})
                    for k, v in loc.columns.items() if k != "freq_hz"}
            parts.append(xr.Dataset(data, coords={"freq_hz": ("freq_hz", f, {"units": "Hz"})})
                         .expand_dims(location=[name]))
        ds = xr.concat(parts, dim="location", join="outer") if parts else xr.Dataset()
        ds.attrs.update(kind=self.kind, file=str(self.path), status=self.status, method=self.method,
                        config_toml=self.config_toml)
        return ds


@dataclass
class ShakerRun(RunFile):
    """A shaker run: one row per grid point (``run.points["transmissibility"]``) and velocity records."""

    robot_spot: str = "?"
    amplitude_kind: str = "?"

    def video_paths(self) -> list[Path | None]:
        """The video of each complete point as an absolute path (None without video)."""
        return [(self.path.parent / v).resolve() if v else None for v in self.points.get("video", [])]

    def summary(self) -> ShakerSummary:
        return {**super().summary(), "robot_spot": self.robot_spot, "amplitude_kind": self.amplitude_kind}

    def to_xarray(self) -> xarray.Dataset:
        """Every ``/points`` column over the ``point`` dimension (coordinate: plan ``index``;
        ``freq_hz`` and ``tray_amp_um`` are coordinates too)."""
        xr = require_xarray()
        data = {k: (("point",), v, {"units": self.units.get(k, "")}) for k, v in self.points.items()
                if k not in ("index", "freq_hz", "tray_amp_um")}
        coords = {"point": ("point", self.points["index"], {"units": "1"})}
        for k in ("freq_hz", "tray_amp_um"):
            if k in self.points:
                coords[k] = ("point", self.points[k], {"units": self.units.get(k, "")})
        ds = xr.Dataset(data, coords=coords)
        ds.attrs.update(kind=self.kind, file=str(self.path), status=self.status, robot_spot=self.robot_spot,
                        config_toml=self.config_toml)
        return ds


def read_run_file(path: str | Path) -> InchipRun | ShakerRun:
    """Read a run file's complete points (the reader behind :func:`labkit.open` for run files).

    Raises
    ------
    InputError
        Not a run file, written by a newer labkit, or missing its ``/points`` table.
    """
    from labkit.h5io import open_h5

    path = Path(path)
    with open_h5(path, "r", kind="run") as f:
        kind = text(f.attrs["kind"])
        version = int(f.attrs.get("schema_version", 0))
        attrs = root_attrs(f)
        cfg_text = text(f.attrs.get("config_toml", ""))
        try:
            cfg = tomllib.loads(cfg_text) if cfg_text else {}
        except tomllib.TOMLDecodeError:
            cfg = {}
        instruments = {
            role: Instrument(role, text(g.attrs.get("model", "")), text(g.attrs.get("resource", "")),
                             json_attr(g.attrs, "snapshot_json", {}) or {})
            for role, g in (f["instruments"].items() if "instruments" in f else [])}
        # (a file another tool assembled may lack /points: its rows are then taken as they are)
        pts = f["points"] if "points" in f else {}
        # THE rule: index is written last, so its length counts the complete points; a file torn
        # another way (another writer, a damaged copy) is read up to its shortest column
        n = min((d.shape[0] for d in pts.values() if d.ndim == 1), default=0)
        points = {k: column(pts[k], n) for k in pts if pts[k].ndim == 1}
        units = {k: units_of(pts[k]) for k in pts}
        ev = f.get("events")
        events = {k: column(ev[k]) for k in ev} if ev is not None else {}
        # the fields every run file has, read once; each kind adds its own below
        header = RunFile(path, kind, version, attrs, units, status=text(f.attrs.get("status", "?")),
                         config_toml=cfg_text, config=cfg, instruments=instruments, points=points, events=events,
                         points_planned=int(f.attrs.get("points_planned", 0)),
                         record_group="raw" if kind == "run_inchip" else "records")
        if kind == "run_inchip":
            locs = _locations(f, points)
            for loc in locs.values():
                units.update(loc.units)
            return InchipRun(**vars(header), method=text(f.attrs.get("method", "?")),
                             locations=locs)
        return ShakerRun(**vars(header),
                         robot_spot=text(f.attrs.get("robot_spot", "?")),
                         amplitude_kind=text(f.attrs.get("amplitude_kind", "?")))


def _locations(f: Any, points: dict[str, np.ndarray]) -> dict[str, Location]:
    """Rows of ``/locations/<loc>`` whose point is complete and ok at that location."""
    out: dict[str, Location] = {}
    if "locations" not in f:
        return out
    idx = points.get("index", np.array([], int))
    st = points.get("status", np.full(idx.size, "ok"))
    where = points.get("location", np.full(idx.size, ""))
    for name, g in f["locations"].items():
        lengths = [d.shape[0] for d in g.values() if d.ndim == 1]
        m = min(lengths) if lengths else 0
        cols = {k: column(g[k], m) for k in g if g[k].ndim == 1}
        if "point_index" in cols and "index" in points:
            done = idx[(st == "ok") & ((where == name) | (where == ""))]
            keep = np.isin(cols["point_index"], done)
            cols = {k: v[keep] for k, v in cols.items()}
        out[name] = Location(name, cols, {k: units_of(g[k]) for k in g})
    return out
