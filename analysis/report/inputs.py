"""Readers for everything a report or a calibration consumes, into plain dicts of arrays.

One reader per file kind (``run_inchip``, ``run_shaker``, ``track``,
``modal_fit``, ``sim_sweep``, ``sim_result``) plus a CSV/HDF5 speed table.
Each raises :class:`labkit.errors.InputError` naming the file (and key) when
a file cannot be read or lacks what is needed, so the CLI exits 2 with one
line. Layouts follow ``interfaces.md``; where a producer's layout allows
alternatives (a dataset at the root or under ``points/``) the readers accept
both, and they never guess a number that is not in the file.
"""
from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from labkit.errors import InputError

LOCATIONS = ("body", "hip", "knee")

# What classified a leg pattern. Two patterns are compared only when the same kind of
# classifier made both: a label written in a run file names what the feet did (as the
# simulator's per-foot contact pattern does); a knee record is classified from the knee's
# vertical velocity (classify_knee_pattern), a different observable.
LABEL = "run-file label (feet)"
KNEE = "knee record (classify_knee_pattern)"
FOOT_CONTACT = "simulated foot contact (dominant over draws and feet)"
PATTERN_BY = {LABEL: "feet", FOOT_CONTACT: "feet", KNEE: "knee"}


def _s(v: Any) -> str:
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)


def file_kind(path: str | Path) -> str:
    """The ``kind`` root attribute of a labkit HDF5 file (InputError if unreadable)."""
    from labkit.h5io import open_h5

    with open_h5(path) as f:
        kind = f.attrs.get("kind")
    if kind is None:
        raise InputError("not a labkit file: no 'kind' attribute", file=path, key="kind")
    return _s(kind)


def _find(f: Any, name: str, groups: tuple[str, ...] = ("", "points", "data")) -> Any:
    for g in groups:
        key = f"{g}/{name}" if g else name
        if key in f:
            return f[key]
    return None


def _need(f: Any, name: str, path: Path, groups: tuple[str, ...] = ("", "points", "data")) -> np.ndarray:
    ds = _find(f, name, groups)
    if ds is None:
        raise InputError("missing dataset", file=path, key=name, expected=f"a '{name}' dataset")
    return ds[()]


# --------------------------------------------------------------------------- in-chip runs

def load_inchip_run(path: str | Path) -> dict[str, Any]:
    """FRFs per location of a ``run_inchip`` file: ``{"file", "status", "locations": {loc: {...}}}``.

    Read through :func:`labkit.files.runs.read_run_file` (complete points only).
    """
    from labkit.files.runs import InchipRun, read_run_file

    path = Path(path)
    run = read_run_file(path)
    if not isinstance(run, InchipRun):
        raise InputError(f"this file holds {run.kind!r}", file=path, key="kind", expected="a 'run_inchip' file")
    out: dict[str, Any] = {"file": str(path), "kind": "run_inchip", "locations": {}, "status": run.status,
                           "method": run.method}
    if not run.locations:
        raise InputError("no measured locations", file=path, key="locations",
                         expected="groups /locations/<body|hip|knee>")
    for loc, lg in run.locations.items():
        if "freq_hz" not in lg.columns or "frf" not in lg.columns:
            raise InputError("missing freq_hz or frf", file=path, key=f"locations/{loc}")
        entry = {"freq_hz": lg.freq_hz.astype(float), "frf": lg.frf.astype(complex)}
        if "coherence" in lg.columns:
            entry["coherence"] = lg.columns["coherence"]
        out["locations"][loc] = entry
    return out


# --------------------------------------------------------------------------- shaker runs and tracks

def load_shaker_run(path: str | Path) -> dict[str, Any]:
    """Per-point data of a ``run_shaker`` file (layout: :mod:`labkit.experiments.runfile`).

    Only complete points with status ``ok`` are kept (read through
    :func:`labkit.files.runs.read_run_file`). Returns ``freq_hz``,
    ``tray_amp_um`` (measured), ``videos`` (absolute paths; "" without video),
    ``index`` (plan indices), optional ``patterns`` (a ``pattern`` label per
    point, if a producer adds one) and ``knee``: the vibrometer records of
    points taken with the laser on the knee (root attribute ``robot_spot``),
    as dicts with ``t_s``, ``knee_vz_mm_s``, ``tray_vz_mm_s``, ``freq_hz``,
    ``tray_amp_um``, ``point``.
    """
    from labkit.files.runs import ShakerRun, read_run_file

    path = Path(path)
    run = read_run_file(path)
    if not isinstance(run, ShakerRun):
        raise InputError(f"this file holds {run.kind!r}", file=path, key="kind", expected="a 'run_shaker' file")
    pts = run.points
    if "freq_hz" not in pts:
        raise InputError("missing dataset", file=path, key="freq_hz", expected="a 'freq_hz' dataset")
    ok = run.ok
    out: dict[str, Any] = {"file": str(path), "kind": "run_shaker", "status": run.status,
                           "robot_spot": run.robot_spot}
    out["freq_hz"] = np.asarray(pts["freq_hz"], float)[ok]
    out["index"] = np.asarray(pts.get("index", np.arange(1, ok.size + 1)))[ok].astype(int)
    amp = pts.get("tray_amp_um")
    out["tray_amp_um"] = np.asarray(amp, float)[ok] if amp is not None else np.full(int(ok.sum()), np.nan)
    videos = pts.get("video")
    out["videos"] = ([str((path.parent / str(v)).resolve()) if v else "" for v in np.asarray(videos)[ok]]
                     if videos is not None else [""] * int(ok.sum()))
    for name in ("speed_mm_s", "speed_lo_mm_s", "speed_hi_mm_s", "speed_std_mm_s"):
        if name in pts:
            out[name] = np.asarray(pts[name], float)[ok]
    if "pattern" in pts:
        out["patterns"] = [str(v) for v in np.asarray(pts["pattern"])[ok]]
    out["knee"] = _knee_records(run, out) if out["robot_spot"] == "knee" else []
    return out


def _knee_records(run: Any, data: dict[str, Any]) -> list[dict[str, Any]]:
    """Velocity records of a knee-spot shaker run (``/records/p<index>/``, complete points only)."""
    records = []
    row_of = {int(i): k for k, i in enumerate(data["index"])}
    for index, rec in sorted(run.records().items()):
        if index not in row_of or "robot_velocity_mm_s" not in rec.signals:
            continue
        k = row_of[index]
        knee = rec.signals["robot_velocity_mm_s"]
        records.append({"point": index, "t_s": np.arange(knee.size) * rec.dt_s,
                        "knee_vz_mm_s": knee, "tray_vz_mm_s": rec.signals.get("tray_velocity_mm_s"),
                        "freq_hz": float(data["freq_hz"][k]), "tray_amp_um": float(data["tray_amp_um"][k]),
                        "spot": "knee"})
    return records


def open_kind(path: str | Path, kinds: tuple[str, ...], expected: str) -> Any:
    """``labkit.open(path)``, refused (InputError naming the file and its kind) unless of ``kinds``."""
    from labkit.files import open_file

    obj = open_file(path)
    if obj.kind not in kinds:
        raise InputError(f"this file holds {obj.kind!r}", file=path, key="kind", expected=expected)
    return obj


def load_track(path: str | Path) -> dict[str, Any]:
    """Speed of a ``track`` file (read by ``labkit.open``; layout: :mod:`labkit.analysis.tracking.output`).

    Returns ``mean_speed_mm_s`` (NaN when the track has no speed), ``speed_ci_mm_s``
    (lo, hi), ``ci_level``, ``freq_hz`` if the track records one, ``path`` (the
    ``labkit.files.Track``) and ``videos``: candidate absolute paths of the tracked video
    (``source_video`` as written, resolved against the working folder and the track's folder).
    """
    path = Path(path)
    t = open_kind(path, ("track",), "a track file (labkit track --out TRACK.h5)")
    a = t.attrs
    if "mean_speed_mm_s" not in a:
        raise InputError("missing root attribute", file=path, key="mean_speed_mm_s")
    speed = float(t.mean_speed_mm_s)
    ci = np.asarray(t.speed_ci_mm_s, float)
    if not np.all(np.isfinite(ci)):
        ci = np.array([speed, speed])
    summ = a.get("summary") if isinstance(a.get("summary"), dict) else {}
    out: dict[str, Any] = {"file": str(path), "kind": "track", "mean_speed_mm_s": speed, "speed_ci_mm_s": ci,
                           "ci_level": float(a.get("speed_ci_level", summ.get("ci_level", 0.95))), "track": t}
    for key in ("freq_hz", "shaker_freq_hz"):
        if key in a:
            out["freq_hz"] = float(a[key])
    out["videos"] = []
    for key in ("source_video", "video", "source"):
        if key in a and _s(a[key]):
            v = Path(_s(a[key]))
            cands = [v] if v.is_absolute() else [Path.cwd() / v, path.parent / v]
            out["videos"] = [str(c.resolve()) for c in cands]
            break
    return out


def measured_speeds(shaker_runs: list[dict[str, Any]], tracks: list[dict[str, Any]]) -> dict[str, Any]:
    """Measured speed against frequency (and tray amplitude) from shaker runs and tracks.

    A track gets its drive from the shaker run point whose video it tracked
    (frequency and measured tray amplitude), or from its own ``freq_hz``
    attribute (amplitude then unknown: NaN, unless it has ``tray_amp_um``).
    Speeds stored in a run file itself are used for points no track covers.
    The standard deviation is recovered from the confidence interval assuming
    a normal spread. A knee record of the same run point gives the point's
    leg pattern (:func:`labkit.analysis.compare.classify_knee_pattern`).

    Returns
    -------
    dict
        Arrays sorted by frequency: ``freq_hz``, ``amp_um``, ``speed_mm_s``,
        ``lo_mm_s``, ``hi_mm_s``, ``std_mm_s``; lists ``patterns`` ("" when
        unknown) and ``sources`` (file per point); ``unmatched`` (tracks with
        no frequency or no speed).
    """
    from scipy.stats import norm

    from labkit.analysis.compare import classify_knee_pattern

    by_video: dict[str, tuple[dict[str, Any], int]] = {}
    for run in shaker_runs:
        for k, video in enumerate(run["videos"]):
            if video:
                by_video[str(Path(video).resolve())] = (run, k)

    def pattern_of(run: dict[str, Any], k: int) -> tuple[str, str]:
        """The point's leg pattern and what classified it (see :data:`PATTERN_BY`)."""
        if run.get("patterns"):
            return run["patterns"][k], LABEL
        rec = next((r for r in run.get("knee", []) if r["point"] == int(run["index"][k])), None)
        if rec is None:
            return "", ""
        pattern = classify_knee_pattern(rec["t_s"], rec["knee_vz_mm_s"], rec["tray_vz_mm_s"], rec["freq_hz"])
        return pattern["pattern"], KNEE

    rows: list[tuple] = []
    covered: set[tuple[str, int]] = set()
    unmatched = []
    for tr in tracks:
        freq, amp, pattern, src = tr.get("freq_hz"), tr.get("tray_amp_um", np.nan), ("", ""), tr["file"]
        if not np.isfinite(tr["mean_speed_mm_s"]):
            unmatched.append(f"{tr['file']} (no speed)")
            continue
        if freq is None:
            hit = next((by_video[v] for v in tr.get("videos", []) if v in by_video), None)
            if hit:
                run, k = hit
                freq, amp, pattern = float(run["freq_hz"][k]), float(run["tray_amp_um"][k]), pattern_of(run, k)
                src = f"{tr['file']} (video of {run['file']} point {int(run['index'][k])})"
                covered.add((run["file"], k))
        if freq is None:
            unmatched.append(tr["file"])
            continue
        lo, hi = tr["speed_ci_mm_s"]
        z = norm.ppf(0.5 + tr.get("ci_level", 0.95) / 2)
        rows.append((float(freq), float(amp), tr["mean_speed_mm_s"], lo, hi, (hi - lo) / (2 * z), *pattern, src))
    for run in shaker_runs:
        if "speed_mm_s" not in run:
            continue
        for k, fz in enumerate(run["freq_hz"]):
            s = float(run["speed_mm_s"][k])
            if (run["file"], k) in covered or not np.isfinite(s):
                continue
            if "speed_std_mm_s" in run:
                std = float(run["speed_std_mm_s"][k])
                lo, hi = s - 1.96 * std, s + 1.96 * std
            else:
                lo = float(run["speed_lo_mm_s"][k]) if "speed_lo_mm_s" in run else s
                hi = float(run["speed_hi_mm_s"][k]) if "speed_hi_mm_s" in run else s
                std = (hi - lo) / (2 * 1.96)
            rows.append((float(fz), float(run["tray_amp_um"][k]), s, lo, hi, std, *pattern_of(run, k),
                         f"{run['file']} (point {int(run['index'][k])})"))
    rows.sort(key=lambda r: (r[0], r[1]))
    cols: list[Sequence[Any]] = list(zip(*rows)) if rows else [[]] * 9
    return {"freq_hz": np.asarray(cols[0], float), "amp_um": np.asarray(cols[1], float),
            "speed_mm_s": np.asarray(cols[2], float), "lo_mm_s": np.asarray(cols[3], float),
            "hi_mm_s": np.asarray(cols[4], float), "std_mm_s": np.asarray(cols[5], float),
            "patterns": list(cols[6]), "pattern_by": list(cols[7]), "sources": list(cols[8]),
            "unmatched": unmatched}


def select(measured: dict[str, Any], mask: np.ndarray) -> dict[str, Any]:
    """The rows of :func:`measured_speeds` where ``mask`` holds."""
    idx = np.flatnonzero(mask)
    lists = ("patterns", "pattern_by", "sources")
    return {k: (v[idx] if isinstance(v, np.ndarray) else [v[i] for i in idx] if k in lists else v)
            for k, v in measured.items()}


def load_speed_table(path: str | Path) -> dict[str, Any]:
    """A table of measured speeds: CSV with header ``freq_hz,speed_mm_s[,speed_std_mm_s][,pattern]``
    or an HDF5 file with those datasets (any ``kind``).

    ``speed_std`` is accepted as an alias of ``speed_std_mm_s``.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("no such file", file=path)
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
    else:
        import h5py

        try:
            with h5py.File(path, "r") as f:
                for k in ("freq_hz", "speed_mm_s", "speed_std_mm_s", "speed_std", "pattern"):
                    ds = _find(f, k)
                    if ds is not None:
                        cols[k] = [_s(v) if isinstance(v, bytes) else v for v in ds[()]]
        except OSError as exc:
            raise InputError(f"not a readable HDF5 or CSV file ({exc})", file=path) from None
    if "speed_std" in cols and "speed_std_mm_s" not in cols:
        cols["speed_std_mm_s"] = cols.pop("speed_std")
    out: dict[str, Any] = {"file": str(path)}
    for key in ("freq_hz", "speed_mm_s", "speed_std_mm_s"):
        if key not in cols:
            if key == "speed_std_mm_s":
                continue
            raise InputError("missing column", file=path, key=key,
                             expected="columns freq_hz, speed_mm_s[, speed_std_mm_s][, pattern]")
        try:
            out[key] = np.asarray([float(v) for v in cols[key]], float)
        except ValueError as exc:
            raise InputError(f"not a number: {exc}", file=path, key=key) from None
    if out["freq_hz"].size == 0:
        raise InputError("no rows", file=path, expected="at least one measured speed")
    if "pattern" in cols and any(cols["pattern"]):
        out["pattern"] = [str(v) for v in cols["pattern"]]
    return out


# --------------------------------------------------------------------------- fits and simulations

def load_fit(path: str | Path) -> dict[str, Any]:
    """A ``modal_fit`` file (read by ``labkit.open``; layout: :mod:`labkit.analysis.modal.io`),
    one entry per fit group.

    Returns ``{"file", "groups": {group: {"locations": {loc: {"freq_hz", "frf", "model_frf"}},
    "modes": [{"freq_hz", "freq_hz_std", "damping_ratio", ...}], "stabilisation": {...} | None,
    "units", "method", "quality"}}, "summary": {...}}``; group is ``inchip`` (tethered robot,
    FRF in (mm/s)/V) or ``shaker`` (released robot, transmissibility).
    """
    path = Path(path)
    fit = open_kind(path, ("modal_fit",), "a 'modal_fit' file (labkit fit ... --out ROBOT.toml writes ROBOT.fit.h5)")
    if not fit.groups:
        raise InputError("no fit groups", file=path, key="groups", expected="/groups/<inchip|shaker>")
    out: dict[str, Any] = {"file": str(path), "kind": "modal_fit", "groups": {},
                           "summary": fit.attrs.get("summary") or {}}
    for name, g in fit.groups.items():
        entry: dict[str, Any] = {"locations": {}, "method": g.method, "quality": float(g.quality),
                                 "units": g.units.get("frf", "(mm/s)/V" if name == "inchip" else "1")}
        for loc, cols in g.locations.items():
            if "freq_hz" not in cols or "frf" not in cols:
                raise InputError("missing freq_hz or frf", file=path, key=f"groups/{name}/locations/{loc}")
            d = {"freq_hz": np.asarray(cols["freq_hz"], float), "frf": np.asarray(cols["frf"], complex)}
            if "model" in cols:
                d["model_frf"] = np.asarray(cols["model"], complex)
            entry["locations"][loc] = d
        entry["modes"] = _modes_of(g.modes)
        st = g.stabilisation
        entry["stabilisation"] = st if st is not None and "freq_hz" in st and "order" in st else None
        out["groups"][name] = entry
    return out


def _modes_of(cols: dict[str, np.ndarray]) -> list[dict[str, Any]]:
    """One dict per mode from the 1-D mode columns (2-D per-location arrays are left out)."""
    if "freq_hz" not in cols:
        return []
    freq = np.asarray(cols["freq_hz"], float).ravel()
    modes: list[dict[str, Any]] = [{"freq_hz": float(x)} for x in freq]
    for k, v in cols.items():
        v = np.asarray(v)
        if k == "freq_hz" or v.ndim != 1 or v.size != freq.size:
            continue
        for i, x in enumerate(v):
            if isinstance(x, (bytes, str, np.str_)):
                modes[i][k] = _s(x)
            elif np.isrealobj(x):
                modes[i][k] = float(x)
    return modes


def load_sim(path: str | Path) -> dict[str, Any]:
    """A simulation file: ``sim_sweep`` (SweepResult) or ``sim_result`` (one run's time series)."""
    path = Path(path)
    kind = file_kind(path)
    if kind == "sim_sweep":
        from labkit.sim.sweep import SweepResult

        try:
            s = SweepResult.from_h5(path)
        except KeyError as exc:
            raise InputError(f"incomplete sweep file: {exc}", file=path) from None
        return {"file": str(path), "kind": kind, "sweep": s}
    if kind == "sim_result":
        return {"file": str(path), "kind": kind, **_load_sim_result(path)}
    raise InputError(f"this file holds {kind!r}", file=path, key="kind",
                     expected="a 'sim_sweep' or 'sim_result' file")


def _load_sim_result(path: Path) -> dict[str, Any]:
    """The series the knee section needs from a ``sim_result`` file (read by ``labkit.open``)."""
    run = open_kind(path, ("sim_result",), "a 'sim_result' file (labkit simulate shaker --out RUN.h5)")
    cols = run.columns
    out: dict[str, Any] = {}
    for key in ("t_s", "knee_vz_mm_s", "ground_z_um", "contact"):
        if key not in cols:
            raise InputError("missing dataset", file=path, key=key, expected="a simulated run's time series")
        out[key] = np.asarray(cols[key]) if key == "contact" else np.asarray(cols[key], float)
    out["scenario"] = dict(run.scenario)
    pats = cols.get("patterns")
    if pats is None:
        pats = run.attrs.get("patterns")       # SimResult.to_h5 stores the six labels as a JSON list
        if isinstance(pats, str):
            pats = json.loads(pats) if pats.startswith("[") else [pats]
    if pats is not None:
        out["patterns"] = [_s(v) for v in np.atleast_1d(np.asarray(pats, dtype=object))]
    if isinstance(run.attrs.get("summary"), dict):
        out["summary"] = run.attrs["summary"]
    if isinstance(run.attrs.get("edges"), dict):         # labkit simulate ... --edges --out RUN.h5
        out["edges"] = run.attrs["edges"]
    if "body_z_um" in cols:                              # the regime's body motion (labkit.sim.regime)
        out["body_z_um"] = np.asarray(cols["body_z_um"], float)
    return out


def classify_inputs(paths: list[str]) -> dict[str, list[str]]:
    """Sort files by their ``kind`` (unknown kinds -> InputError naming the file)."""
    groups: dict[str, list[str]] = {}
    for p in paths:
        kind = file_kind(p)
        groups.setdefault(kind, []).append(p)
    return groups
