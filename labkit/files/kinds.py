"""Readers of the files labkit writes other than run files: tracks, fits, simulations, parameters, videos."""
from __future__ import annotations

import csv
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, TypedDict

import numpy as np

from labkit.errors import InputError
from labkit.files.base import (
    FileSummary,
    Json,
    LabFile,
    T,
    column,
    json_attr,
    require_xarray,
    root_attrs,
    text,
    units_of,
)

if TYPE_CHECKING:  # pragma: no cover
    import xarray

    from labkit.tomlio import TomlValue


def _columns(g: Any, n: int | None = None) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    import h5py

    cols = {k: column(g[k]) for k in g if isinstance(g[k], h5py.Dataset)}
    return cols, {k: units_of(g[k]) for k in cols}


def _var(dims: tuple[str, ...], v: np.ndarray, units: str) -> tuple[tuple[str, ...], np.ndarray, dict[str, str]]:
    return dims, v, {"units": units}


# --------------------------------------------------------------------------- tracks

class TrackSummary(FileSummary):
    """:meth:`Track.summary` (speed and interval are a sentence for an older CSV that lacks them)."""

    frames: int
    mean_speed_mm_s: float | str
    speed_ci_mm_s: list[float] | str
    source_video: str
    mm_per_px: float | None


@dataclass
class Track(LabFile):
    """A robot track (kind ``track``): per-frame position and heading, the smoothed path, the speed.

    ``columns`` holds the per-frame arrays (``t_s``, ``x_mm``, ``y_mm``, ``heading_rad``,
    ``quality``, ``u_px``, ``v_px``, ``area_px``), ``smoothed`` those of the smoothed path.
    """

    columns: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    smoothed: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    mean_speed_mm_s: float = float("nan")
    speed_ci_mm_s: tuple[float, float] = (float("nan"), float("nan"))
    source_video: str = ""

    @property
    def t_s(self) -> np.ndarray:
        return self.columns["t_s"]

    @property
    def mm_per_px(self) -> float | None:
        """The image scale the positions were converted with (None if the file does not say)."""
        return _number(self.attrs.get("mm_per_px"))

    @property
    def lost_frames(self) -> int:
        """Frames without a position (the file's ``lost_frames``, else the rows with no ``x_mm``)."""
        n = _number(self.attrs.get("lost_frames"))
        if n is not None:
            return int(n)
        x = self.columns.get("x_mm")
        return 0 if x is None else int(np.count_nonzero(~np.isfinite(x)))

    def summary(self) -> TrackSummary:
        speed: float | str = self.mean_speed_mm_s
        ci: list[float] | str = list(self.speed_ci_mm_s)
        if not np.isfinite(self.mean_speed_mm_s) and self.kind == "track_csv":
            speed = ci = "not in this CSV (older labkit; the track's .h5 file holds it)"
        return {**super().summary(), "frames": int(self.t_s.size), "mean_speed_mm_s": speed,
                "speed_ci_mm_s": ci, "source_video": self.source_video,
                "mm_per_px": self.mm_per_px}

    def to_xarray(self) -> xarray.Dataset:
        """Per-frame columns over ``t_s``; the smoothed path as ``smoothed_*`` over ``t_smoothed_s``."""
        xr = require_xarray()
        data = {k: _var(("t_s",), v, self.units.get(k, "")) for k, v in self.columns.items() if k != "t_s"}
        coords = {"t_s": ("t_s", self.t_s, {"units": "s"})}
        if self.smoothed:
            coords["t_smoothed_s"] = ("t_smoothed_s", self.smoothed["t_s"], {"units": "s"})
            data |= {f"smoothed_{k}": _var(("t_smoothed_s",), v, self.units.get(f"smoothed/{k}", ""))
                     for k, v in self.smoothed.items() if k != "t_s"}
        ds = xr.Dataset(data, coords=coords)
        ds.attrs.update(kind=self.kind, file=str(self.path), mean_speed_mm_s=self.mean_speed_mm_s,
                        source_video=self.source_video)
        return ds


def _number(value: Json) -> float | None:
    """A numeric attribute, or None when it is absent (or not a number)."""
    return value if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def read_track(path: Path, f: Any) -> Track:
    cols, units = _columns(f)
    smoothed: dict[str, np.ndarray] = {}
    if "smoothed" in f:
        smoothed, su = _columns(f["smoothed"])
        units |= {f"smoothed/{k}": u for k, u in su.items()}
    if "t_s" not in cols:
        raise InputError("missing dataset", file=path, key="t_s", expected="a track's frame times")
    ci = np.asarray(f.attrs.get("speed_ci_mm_s", [np.nan, np.nan]), float).ravel()
    return Track(path, "track", int(f.attrs.get("schema_version", 0)), root_attrs(f), units, cols, smoothed,
                 float(f.attrs.get("mean_speed_mm_s", np.nan)),
                 (float(ci[0]), float(ci[-1])) if ci.size else (np.nan, np.nan),
                 text(f.attrs.get("source_video", "")))


def read_track_csv(path: Path) -> Track:
    """The CSV beside a track file (``labkit track --out``): one row per frame."""
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            lines = fh.read().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read ({exc})", file=path) from None
    comments = [ln for ln in lines if ln.startswith("#")]
    rows = list(csv.reader(ln for ln in lines if ln and not ln.startswith("#")))
    if not rows or "t_s" not in rows[0]:
        raise InputError("not a labkit track CSV", file=path, key="t_s", expected="a header row with t_s, x_mm, ...")
    header, body = rows[0], rows[1:]
    try:
        cols = {h: np.array([float(r[i]) if r[i] else np.nan for r in body]) for i, h in enumerate(header)}
    except (ValueError, IndexError) as exc:
        raise InputError(f"bad row ({exc})", file=path) from None
    units = {h: _csv_units(h) for h in header}
    values = _csv_header_values(comments)
    ci = values.get("speed_ci_mm_s", (np.nan, np.nan))
    comment = "\n".join(comments)
    source = re.search(r"labkit track of (.*?);", comment)
    attrs: dict[str, Json] = {"comment": comment}
    attrs |= {k: v[0] if len(v) == 1 else list(v) for k, v in values.items()}
    return Track(path, "track_csv", 0, attrs, units, cols, {}, values.get("mean_speed_mm_s", (np.nan,))[0],
                 (ci[0], ci[-1]), source.group(1) if source else "")


def _csv_header_values(comments: list[str]) -> dict[str, tuple[float, ...]]:
    """``key=value`` pairs of a track CSV's comment lines (``mm_per_px=0.05; speed_ci_mm_s=1.2,1.4``),
    each value as its numbers (non-numeric values are left out)."""
    out: dict[str, tuple[float, ...]] = {}
    for key, value in re.findall(r"(\w+)=([^;\s]+)", "\n".join(comments)):
        try:
            out[key] = tuple(float(v) for v in value.split(","))
        except ValueError:
            continue
    return out


def _csv_units(name: str) -> str:
    for suffix, unit in (("_mm_s", "mm/s"), ("_rad", "rad"), ("_mm", "mm"), ("_px", "px"), ("_s", "s")):
        if name.endswith(suffix):
            return unit
    return "label" if name == "quality" else "1"


# --------------------------------------------------------------------------- modal fits

@dataclass
class FitGroup:
    """One fit group of a modal fit (``inchip``: tethered robot, ``shaker``: released robot)."""

    name: str
    method: str
    quality: float
    locations: dict[str, dict[str, np.ndarray]]       # loc -> freq_hz, frf, model
    modes: dict[str, np.ndarray]                      # freq_hz, damping_ratio, ... (per mode)
    stabilisation: dict[str, np.ndarray] | None
    units: dict[str, str]


class ModeDigest(TypedDict):
    freq_hz: float
    damping_ratio: float


class FitSummary(FileSummary):
    """:meth:`ModalFit.summary`: the runs fitted per group and each group's modes."""

    runs: dict[str, list[str]]
    modes: dict[str, list[ModeDigest]]


@dataclass
class ModalFit(LabFile):
    """A resonance fit (kind ``modal_fit``): measured and fitted FRFs, modes with uncertainties."""

    groups: dict[str, FitGroup] = field(default_factory=dict, repr=False)
    runs: dict[str, list[str]] = field(default_factory=dict)

    def summary(self) -> FitSummary:
        return {**super().summary(),
            "runs": self.runs,
            "modes": {g: [{"freq_hz": float(f), "damping_ratio": float(z)} for f, z in
                          zip(fg.modes.get("freq_hz", []), fg.modes.get("damping_ratio", []))]
                      for g, fg in self.groups.items()}}

    def to_xarray(self, group: str | None = None) -> xarray.Dataset:
        """One group (default: the first) as ``frf``/``model`` over ``location`` x ``freq_hz`` and
        the modes over ``mode`` (``mode_freq_hz``, ``damping_ratio``, ..., ``amplitude`` over mode x location)."""
        xr = require_xarray()
        if not self.groups:
            return xr.Dataset()
        name = group or next(iter(self.groups))
        if name not in self.groups:
            raise InputError(f"no fit group {name!r}", file=self.path, key="group",
                             expected=" or ".join(self.groups))
        g = self.groups[name]
        parts = []
        for loc, d in g.locations.items():
            f, keep = np.unique(d["freq_hz"], return_index=True)
            parts.append(xr.Dataset({k: (("freq_hz",), v[keep], {"units": g.units.get(k, "")})
                                     for k, v in d.items() if k != "freq_hz"},
                                    coords={"freq_hz": ("freq_hz", f, {"units": "Hz"})}).expand_dims(location=[loc]))
        ds = xr.concat(parts, dim="location", join="outer") if parts else xr.Dataset()
        nm = g.modes.get("freq_hz", np.array([])).size
        ds = ds.assign_coords(mode=("mode", np.arange(1, nm + 1)))
        for k, v in g.modes.items():
            key = "mode_freq_hz" if k == "freq_hz" else "mode_freq_hz_std" if k == "freq_hz_std" else k
            dims = ("mode",) if v.ndim == 1 else ("mode", "location")
            if v.ndim == 2 and v.shape[1] != ds.sizes.get("location", -1):
                continue
            ds[key] = (dims, v, {"units": g.units.get(f"modes/{k}", "")})
        ds.attrs.update(kind=self.kind, file=str(self.path), group=name, method=g.method, quality=g.quality)
        return ds


def read_fit(path: Path, f: Any) -> ModalFit:
    groups: dict[str, FitGroup] = {}
    for name, g in (f["groups"].items() if "groups" in f else []):
        units: dict[str, str] = {}
        locs: dict[str, dict[str, np.ndarray]] = {}
        for key, lg in (g["locations"].items() if "locations" in g else []):
            cols, u = _columns(lg)
            units |= u
            locs[text(lg.attrs.get("name", key))] = cols
        modes, mu = _columns(g["modes"]) if "modes" in g else ({}, {})
        if "location" in modes and g["modes"]["location"].is_scale:    # the modes x locations arrays' axis
            del modes["location"], mu["location"]
        units |= {f"modes/{k}": v for k, v in mu.items()}
        stab = _columns(g["stabilisation"])[0] if "stabilisation" in g else None
        groups[name] = FitGroup(name, text(g.attrs.get("method", "?")), float(g.attrs.get("quality", np.nan)),
                                locs, modes, stab, units)
    return ModalFit(path, "modal_fit", int(f.attrs.get("schema_version", 0)), root_attrs(f), {}, groups,
                    json_attr(f.attrs, "runs_json", {}) or {})


# --------------------------------------------------------------------------- simulations

def _params_from_text(params_toml: str, path: Path) -> Any:
    """The ``RobotParams`` a simulation file was run with (its ``params_toml`` attribute)."""
    import tomllib

    from labkit.sim import RobotParams

    if not params_toml:
        raise InputError("no parameters recorded", file=path, key="params_toml", expected="a labkit simulation file")
    try:
        table = tomllib.loads(params_toml)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not TOML ({exc})", file=path, key="params_toml") from None
    return RobotParams.from_dict(table, file=f"{path}:params_toml")


class SimRunSummary(FileSummary):
    scenario: dict[str, Json]
    mean_speed_mm_s: float
    samples: int


@dataclass
class SimRun(LabFile):
    """One simulator run (kind ``sim_result``): time series of body, feet, contact and knee."""

    columns: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    scenario: dict[str, Json] = field(default_factory=dict)
    params_toml: str = field(default="", repr=False)
    mean_speed_mm_s: float = float("nan")

    @property
    def t_s(self) -> np.ndarray:
        return self.columns["t_s"]

    @property
    def params(self) -> Any:
        """The robot parameters of the run (:class:`labkit.sim.RobotParams`)."""
        return _params_from_text(self.params_toml, self.path)

    def summary(self) -> SimRunSummary:
        return {**super().summary(), "scenario": self.scenario, "mean_speed_mm_s": self.mean_speed_mm_s,
                "samples": int(self.t_s.size)}

    def to_xarray(self) -> xarray.Dataset:
        """Time series over ``t_s`` (per-leg arrays over ``leg``, body angles over ``axis``)."""
        xr = require_xarray()
        n = self.t_s.size
        data = {}
        for k, v in self.columns.items():
            if k == "t_s" or v.ndim == 0:
                continue
            if v.shape[0] == n:
                dims = ("t_s",) + tuple("leg" if s == 6 else "axis" if s == 3 else f"{k}_dim{i}"
                                        for i, s in enumerate(v.shape[1:], 1))
            elif v.ndim == 1 and v.size == 6:
                dims = ("leg",)
            elif v.ndim == 2 and v.shape[0] == 6:
                dims = ("leg", f"{k}_column")
            else:
                dims = tuple(f"{k}_dim{i}" for i in range(v.ndim))
            data[k] = (dims, v, {"units": self.units.get(k, "")})
        ds = xr.Dataset(data, coords={"t_s": ("t_s", self.t_s, {"units": "s"})})
        ds.attrs.update(kind=self.kind, file=str(self.path), mean_speed_mm_s=self.mean_speed_mm_s)
        return ds


def read_sim_result(path: Path, f: Any) -> SimRun:
    cols, units = _columns(f)
    for k in [k for k in cols if k != "t_s" and f[k].is_scale]:        # axis indices (leg, axis, mode, ...)
        cols.pop(k)
    if "t_s" not in cols:
        raise InputError("missing dataset", file=path, key="t_s", expected="a simulation's time axis")
    return SimRun(path, "sim_result", int(f.attrs.get("schema_version", 0)), root_attrs(f), units, cols,
                  json_attr(f.attrs, "scenario_json", {}) or {}, text(f.attrs.get("params_toml", "")),
                  float(f.attrs.get("mean_speed_mm_s", np.nan)))


class SweepSummary(FileSummary):
    """:meth:`SimSweep.summary`: the swept quantity, its points and the Monte Carlo draws (0: nominal only)."""

    quantity: str
    points: int
    draws: int


@dataclass
class SimSweep(LabFile):
    """A simulated sweep (kind ``sim_sweep``, or ``sim_points`` for a scenario's set of drive points):
    speeds over the swept quantity and Monte Carlo draws."""

    quantity: str = "?"
    values: np.ndarray = field(default_factory=lambda: np.array([]))
    columns: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    params_toml: str = field(default="", repr=False)

    @property
    def params(self) -> Any:
        """The nominal robot parameters of the sweep (:class:`labkit.sim.RobotParams`)."""
        return _params_from_text(self.params_toml, self.path)

    def summary(self) -> SweepSummary:
        speeds = self.columns.get("speeds_mm_s")
        return {**super().summary(), "quantity": self.quantity, "points": int(self.values.size),
                "draws": int(speeds.shape[1]) if speeds is not None and speeds.ndim == 2 else 0}

    def to_xarray(self) -> xarray.Dataset:
        """Over the swept quantity (``freq_hz``, ``amp_um``, ...) x ``draw`` (0 = nominal) x ``foot`` x ``mode``."""
        xr = require_xarray()
        q = self.quantity
        names = (q, "draw", "foot", "contact_mode")
        data = {}
        for k, v in self.columns.items():
            if k in ("values", q) or v.ndim == 0 or v.shape[0] != self.values.size:
                continue
            data[k] = (names[:v.ndim], v, {"units": self.units.get(k, "")})
        ds = xr.Dataset(data, coords={q: (q, self.values, {"units": self.units.get("values", "")})})
        ds.attrs.update(kind=self.kind, file=str(self.path), quantity=q)
        return ds


def read_sim_sweep(path: Path, f: Any, group: Any = None, version: int | None = None) -> SimSweep:
    """A sweep written by :meth:`labkit.sim.SweepResult.to_h5` (``group``: one sweep of a set)."""
    g = f if group is None else group
    cols, units = _columns(g)
    q = text(g.attrs.get("quantity", g["values"].attrs.get("quantity", "?") if "values" in g else "?"))
    for k in [k for k in cols if k not in ("values", q) and g[k].is_scale]:   # axis indices (draw, foot, mode)
        cols.pop(k)
    if "values" not in cols:
        raise InputError("missing dataset", file=path, key=f"{g.name.rstrip('/')}/values",
                         expected="the swept values")
    version = int(f.attrs.get("schema_version", 0)) if version is None else version
    kind = text(f.attrs.get("kind", "sim_sweep")) if group is None else "sim_sweep"
    return SimSweep(path, kind, version, root_attrs(g), units,
                    q, cols["values"], cols, text(g.attrs.get("params_toml", "")))


class SweepSetSummary(FileSummary):
    sweeps: dict[str, SweepSummary]


@dataclass
class SimSweepSet(LabFile):
    """Several simulated sweeps in one file (kind ``sim_sweep_set``, from ``labkit simulate scenario``):
    ``sweeps[label]`` is a :class:`SimSweep` (labels are the groups' paths, e.g. ``capped/50_uN``)."""

    sweeps: dict[str, SimSweep] = field(default_factory=dict, repr=False)

    def summary(self) -> SweepSetSummary:
        return {**super().summary(), "sweeps": {k: {**s.summary(), "file": None} for k, s in self.sweeps.items()}}

    def to_xarray(self, label: str | None = None) -> xarray.Dataset:
        """One sweep (default: the first) as :meth:`SimSweep.to_xarray`."""
        return _pick(self.sweeps, label, self.path).to_xarray()


def read_sim_sweep_set(path: Path, f: Any) -> SimSweepSet:
    import h5py

    version = int(f.attrs.get("schema_version", 0))
    sweeps: dict[str, SimSweep] = {}

    def visit(name: str, obj: Any) -> None:
        if isinstance(obj, h5py.Group) and "values" in obj:
            sweeps[name] = read_sim_sweep(path, f, obj, version)

    f.visititems(visit)
    return SimSweepSet(path, "sim_sweep_set", version, root_attrs(f), {}, sweeps)


class RunDigest(TypedDict):
    samples: int
    mean_speed_mm_s: float


class RunSetSummary(FileSummary):
    """:meth:`SimRunSet.summary`: each run's length and speed, and the file's own summary (``info``)."""

    runs: dict[str, RunDigest]
    info: Json


@dataclass
class SimRunSet(LabFile):
    """Several simulator runs in one file (kind ``sim_ablations``, from ``labkit simulate scenario
    ablation-shaker``): ``runs[label]`` holds each run's time series (``t_s``, ``foot_z_um``, ...)."""

    runs: dict[str, dict[str, np.ndarray]] = field(default_factory=dict, repr=False)

    def summary(self) -> RunSetSummary:
        return {**super().summary(),
            "runs": {k: {"samples": int(v["t_s"].size), "mean_speed_mm_s": float(np.ravel(v.get(
                "mean_speed_mm_s", np.nan))[0])} for k, v in self.runs.items()},
            "info": self.attrs.get("summary", {})}

    def to_xarray(self, label: str | None = None) -> xarray.Dataset:
        """One run (default: the first): time series over ``t_s`` (per-leg arrays over ``leg``)."""
        xr = require_xarray()
        name = next(iter(self.runs), "") if label is None else label
        cols = _pick(self.runs, name, self.path)
        data: dict[str, tuple[tuple[str, ...], np.ndarray, dict[str, str]]] = {}
        for k, v in cols.items():
            if k == "t_s" or v.ndim == 0:
                continue
            dims = ("t_s", "leg")[:v.ndim] if v.shape[0] == cols["t_s"].size else \
                tuple(f"{k}_dim{i}" for i in range(v.ndim))
            data[k] = (dims, v, {"units": self.units.get(f"{name}/{k}", "")})
        ds = xr.Dataset(data, coords={"t_s": ("t_s", cols["t_s"], {"units": "s"})})
        ds.attrs.update(kind=self.kind, file=str(self.path), run=name)
        return ds


def read_sim_run_set(path: Path, f: Any) -> SimRunSet:
    runs: dict[str, dict[str, np.ndarray]] = {}
    units: dict[str, str] = {}
    for label, g in (f["runs"].items() if "runs" in f else []):
        cols, u = _columns(g)
        if "t_s" not in cols:
            raise InputError("missing dataset", file=path, key=f"runs/{label}/t_s", expected="a run's time axis")
        runs[label] = cols
        units |= {f"{label}/{k}": v for k, v in u.items()}
    return SimRunSet(path, text(f.attrs.get("kind", "sim_ablations")), int(f.attrs.get("schema_version", 0)),
                     root_attrs(f), units, runs)


def _pick(items: dict[str, T], label: str | None, path: Path) -> T:
    if not items:
        raise InputError("holds no data", file=path)
    name = next(iter(items)) if label is None else label
    if name not in items:
        raise InputError(f"no {name!r} in the file", file=path, key="label", expected=" or ".join(items))
    return items[name]


# --------------------------------------------------------------------------- parameter files, videos

class ParamsSummary(FileSummary):
    """:meth:`RobotParameters.summary`: the modes and where each came from (:func:`provenance_digest`)."""

    modal_freq_hz: list[float]
    modal_damping_ratio: list[float]
    provenance: dict[str, Json]


@dataclass
class RobotParameters(LabFile):
    """A robot parameter file (TOML): ``params`` (:class:`labkit.sim.RobotParams`) and its ``provenance``."""

    params: Any = None
    provenance: dict[str, Json] = field(default_factory=dict)

    def summary(self) -> ParamsSummary:
        p = self.params
        return {**super().summary(), "modal_freq_hz": list(p.modal_freq_hz),
                "modal_damping_ratio": list(p.modal_damping_ratio), "provenance": provenance_digest(self.provenance)}

    def to_xarray(self) -> xarray.Dataset:
        """Scalars as 0-d variables, per-mode triples over ``mode`` (1, 2, 3); units on each."""
        xr = require_xarray()
        from labkit.sim.params import UNITS  # the parameter table: units of every key

        data = {}
        for k, v in self.params.to_dict().items():
            arr = np.asarray(v)
            data[k] = (("mode",) if arr.ndim == 1 else (), arr, {"units": UNITS.get(k, "")})
        ds = xr.Dataset(data, coords={"mode": ("mode", np.arange(1, 4))})
        ds.attrs.update(kind=self.kind, file=str(self.path))
        return ds


def provenance_digest(prov: Mapping[str, Json]) -> dict[str, Json]:
    """What ``labkit info`` shows of a ``[provenance]`` table: source, runs, fit file, and per mode
    where its value came from (fit with uncertainty, or the base file)."""
    keep = ("source", "created_utc", "runs", "fit_file", "method", "generated_by", "calibration")
    out: dict[str, Json] = {k: prov[k] for k in keep if k in prov}
    modes = prov.get("modes")
    if isinstance(modes, dict):
        where: dict[str, Json] = {}
        out["modes"] = where
        for m, d in modes.items():
            if not isinstance(d, dict):
                continue
            if d.get("source") == "fit":
                nan = float("nan")
                where[m] = (f"fit ({d.get('method', '?')}, {d.get('group', '?')}): "
                                   f"{d.get('freq_hz', nan):.6g} +- {d.get('freq_hz_std', nan):.2g} Hz, "
                                   f"zeta {d.get('damping_ratio', nan):.4g} +- {d.get('damping_ratio_std', nan):.2g}")
            else:
                where[m] = f"{d.get('source', '?')}: {d.get('base', '')}".rstrip(": ")
    others = sorted(k for k in prov if k not in keep and k != "modes")
    if others:
        out["other_keys"] = list(others)
    return out


def read_params(path: Path) -> RobotParameters:
    from labkit.sim import RobotParams

    p = RobotParams.from_toml(path)
    return RobotParameters(path, "robot_params", 0, {}, {}, p, dict(p.provenance))


#: top-level tables that mark a TOML file as an experiment config (not a robot parameter file)
CONFIG_TABLES = ("run", "instruments")


ConfigTable = Literal["drive", "frequencies", "grid", "method"]
#: the tables of a config that ``labkit info`` shows key by key
SHOWN_TABLES: tuple[ConfigTable, ...] = ("drive", "frequencies", "grid", "method")


class _ShownTables(TypedDict, total=False):
    drive: dict[str, Json]
    frequencies: dict[str, Json]
    grid: dict[str, Json]
    method: dict[str, Json]


class ConfigSummary(FileSummary, _ShownTables):
    """:meth:`ExperimentConfig.summary`: the experiment, its instruments (role -> model), its tables
    and the contents of those it has of ``drive``, ``frequencies``, ``grid``, ``method``."""

    experiment: str
    instruments: dict[str, str]
    tables: list[str]


@dataclass
class ExperimentConfig(LabFile):
    """An experiment config (TOML; kind ``config_inchip`` or ``config_shaker``): its text and tables.

    Read, not validated: ``labkit sweep inchip`` / ``labkit shaker`` validate a config (every
    error naming the file and key) before they touch an instrument. ``frequencies_hz`` is the
    in-chip plan's frequency list when the config gives one (``list_hz``) or a linear/log range.
    """

    experiment: str = "?"
    text: str = field(default="", repr=False)
    table: dict[str, TomlValue] = field(default_factory=dict, repr=False)

    @property
    def instruments(self) -> dict[str, str]:
        """Role -> model of the ``[instruments.<role>]`` tables."""
        inst = self.table.get("instruments")
        if not isinstance(inst, dict):
            return {}
        return {k: str(v.get("model", "?")) for k, v in inst.items() if isinstance(v, dict)}

    def summary(self) -> ConfigSummary:
        out: ConfigSummary = {**super().summary(), "experiment": self.experiment, "instruments": self.instruments,
                              "tables": sorted(k for k, v in self.table.items() if isinstance(v, dict))}
        for key in SHOWN_TABLES:
            if isinstance(shown := self.table.get(key), dict):
                from labkit.jsonutil import to_jsonable

                out[key] = to_jsonable(shown)
        return out

    def to_xarray(self) -> xarray.Dataset:
        """No arrays: an empty Dataset whose attributes hold the config's text and kind."""
        xr = require_xarray()
        return xr.Dataset(attrs={"kind": self.kind, "file": str(self.path), "config_toml": self.text})


def read_config(path: Path, table: dict[str, TomlValue], raw: str) -> ExperimentConfig:
    shaker = any(k in table for k in ("grid", "shaker", "amplifier", "tray_control"))
    experiment = "shaker" if shaker else "inchip"
    return ExperimentConfig(path, f"config_{experiment}", 0, {}, {}, experiment, raw, table)


def read_toml(path: Path) -> RobotParameters | ExperimentConfig:
    """A robot parameter file, or an experiment config (a file with a ``[run]`` or ``[instruments]`` table)."""
    from labkit.tomlio import load_toml

    table, raw = load_toml(path)
    if any(isinstance(table.get(k), dict) for k in CONFIG_TABLES):
        return read_config(path, table, raw)
    return read_params(path)


class VideoSummary(FileSummary):
    """:meth:`Video.summary`: the measured frame rate, and the container's rate field where it differs."""

    width_px: int
    height_px: int
    frames: int
    fps: float
    fps_container: float | str
    codec: str
    duration_s: float | None


@dataclass
class Video(LabFile):
    """A video labkit recorded or drew (``.mkv`` with per-frame timestamps, ``.avi``)."""

    width: int = 0
    height: int = 0
    frames: int = 0
    fps_nominal: float = 0.0
    codec: str = ""
    t_s: np.ndarray = field(default_factory=lambda: np.array([]), repr=False)

    @property
    def fps_measured(self) -> float:
        """The frame rate the frames' timestamps give (median interval); NaN for fewer than 2 frames."""
        dt = np.diff(self.t_s)
        dt = dt[dt > 0]
        return float(1.0 / np.median(dt)) if dt.size else float("nan")

    def summary(self) -> VideoSummary:
        d = float(self.t_s[-1] - self.t_s[0]) if self.t_s.size > 1 else None
        fps = self.fps_measured
        container: float | str = self.fps_nominal
        if np.isfinite(fps) and abs(self.fps_nominal - fps) > 0.01 * fps:
            # e.g. Matroska's 1 ms time base read back as "1000 fps": not the frame rate
            container = f"{self.fps_nominal:g} (the container's rate field; the timestamps give {fps:.4g})"
        return {**super().summary(), "width_px": self.width, "height_px": self.height, "frames": self.frames,
                "fps": fps, "fps_container": container, "codec": self.codec, "duration_s": d}

    def to_xarray(self) -> xarray.Dataset:
        """The frame times (``t_s`` coordinate over ``frame``); pixels are read with ``labkit.analysis.tracking``."""
        xr = require_xarray()
        ds = xr.Dataset(coords={"frame": ("frame", np.arange(self.t_s.size)),
                                "t_s": ("frame", self.t_s, {"units": "s"})})
        ds.attrs.update(kind=self.kind, file=str(self.path), width_px=self.width, height_px=self.height)
        return ds


def read_video(path: Path) -> Video:
    """Frame size, count, codec and every frame's container timestamp (OpenCV's FFmpeg backend).

    Read here rather than through ``labkit.analysis.tracking`` so that this package stays
    below the analysis layer (analysis reads files through it).
    """
    import cv2

    cap = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
    try:
        if not cap.isOpened():
            raise InputError("not a readable video", file=path)
        code = int(cap.get(cv2.CAP_PROP_FOURCC))
        fourcc = "".join(chr((code >> (8 * i)) & 0xFF) for i in range(4)).strip("\x00")
        width, height = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
        times = []
        while cap.grab():                      # no decoding: only the timestamps are wanted
            times.append(cap.get(cv2.CAP_PROP_POS_MSEC) / 1000.0)
    finally:
        cap.release()
    t = np.asarray(times, float)
    if t.size == 0:
        raise InputError("the video has no frames", file=path)
    if t.size > 1 and np.all(t == t[0]) and fps > 0:      # no timestamps in the container: nominal rate
        t = np.arange(t.size) / fps
    return Video(path, "video", 0, {}, {"t_s": "s"}, width, height, int(t.size), fps, fourcc, t)
