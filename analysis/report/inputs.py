"""Readers for everything a report or a calibration consumes, into frozen dataclasses.

One reader per file kind (``run_inchip``, ``run_shaker``, ``track``,
``modal_fit``, ``sim_sweep``, ``sim_result``) plus a CSV/HDF5 speed table; each
returns a typed record (:class:`InchipData`, :class:`ShakerData`,
:class:`TrackData`, :class:`FitData`, :class:`SweepData`, :class:`SimRunData`),
built on the file kinds of :mod:`labkit.files`; speed tables are :mod:`labkit.files.speeds`.
Each raises :class:`labkit.errors.InputError` naming the file (and key) when
a file cannot be read or lacks what is needed, so the CLI exits 2 with one
line. Layouts follow ``interfaces.md``; where a producer's layout allows
alternatives (a dataset at the root or under ``points/``) the readers accept
both, and they never guess a number that is not in the file.
"""
from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from labkit.errors import InputError
from labkit.files import file_kind as file_kind  # the reader of a file's kind lives in labkit.files

LOCATIONS = ("body", "hip", "knee")

# What classified a leg pattern. Two patterns are compared only when the same kind of
# classifier made both: a label written in a run file names what the feet did (as the
# simulator's per-foot contact pattern does); a knee record is classified from the knee's
# vertical velocity (classify_knee_pattern), a different observable.
LABEL = "run-file label (feet)"
KNEE = "knee record (classify_knee_pattern)"
FOOT_CONTACT = "simulated foot contact (dominant over draws and feet)"
PATTERN_BY = {LABEL: "feet", FOOT_CONTACT: "feet", KNEE: "knee"}


@dataclass(frozen=True)
class Frf:
    """One location's measured FRF (and, in a fit, the model at the same lines)."""

    freq_hz: np.ndarray
    frf: np.ndarray
    coherence: np.ndarray | None = None
    model_frf: np.ndarray | None = None


@dataclass(frozen=True)
class InchipData:
    """A ``run_inchip`` file's FRFs per location (complete points only)."""

    file: str
    status: str
    method: str
    locations: dict[str, Frf]


@dataclass(frozen=True)
class KneeRecord:
    """One vibrometer record of a knee-spot shaker point (mm/s against s)."""

    file: str
    point: int
    t_s: np.ndarray
    knee_vz_mm_s: np.ndarray
    tray_vz_mm_s: np.ndarray | None
    freq_hz: float
    tray_amp_um: float


@dataclass(frozen=True)
class ShakerData:
    """A ``run_shaker`` file's points with status ``ok``, in plan order.

    ``videos`` are absolute paths ("" for a point without video); the speed columns
    are present when the run file holds them; ``patterns`` when a producer labelled
    the points; ``knee`` the knee records (``robot_spot == "knee"``).
    """

    file: str
    status: str
    robot_spot: str
    freq_hz: np.ndarray
    index: np.ndarray
    tray_amp_um: np.ndarray
    videos: list[str]
    speed_mm_s: np.ndarray | None = None
    speed_lo_mm_s: np.ndarray | None = None
    speed_hi_mm_s: np.ndarray | None = None
    speed_std_mm_s: np.ndarray | None = None
    patterns: list[str] | None = None
    knee: list[KneeRecord] = field(default_factory=list)


@dataclass(frozen=True)
class TrackData:
    """A ``track`` file's speed, its interval, its drive (when recorded) and its video."""

    file: str
    mean_speed_mm_s: float
    speed_ci_mm_s: tuple[float, float]
    ci_level: float
    freq_hz: float | None
    tray_amp_um: float
    videos: list[str]


@dataclass(frozen=True)
class MeasuredSpeeds:
    """Measured speed against frequency (and tray amplitude), sorted by frequency.

    ``patterns`` is "" where unknown; ``pattern_by`` names the classifier (:data:`PATTERN_BY`);
    ``sources`` the file (and point) of each row; ``unmatched`` the tracks left out.
    """

    freq_hz: np.ndarray
    amp_um: np.ndarray
    speed_mm_s: np.ndarray
    lo_mm_s: np.ndarray
    hi_mm_s: np.ndarray
    std_mm_s: np.ndarray
    patterns: list[str]
    pattern_by: list[str]
    sources: list[str]
    unmatched: list[str] = field(default_factory=list)

    def select(self, mask: np.ndarray) -> MeasuredSpeeds:
        """The rows where ``mask`` holds."""
        idx = np.flatnonzero(mask)
        return MeasuredSpeeds(self.freq_hz[idx], self.amp_um[idx], self.speed_mm_s[idx], self.lo_mm_s[idx],
                              self.hi_mm_s[idx], self.std_mm_s[idx], [self.patterns[i] for i in idx],
                              [self.pattern_by[i] for i in idx], [self.sources[i] for i in idx],
                              list(self.unmatched))


@dataclass(frozen=True)
class Mode:
    """One fitted mode as a fit file stores it (``None``: not in the file)."""

    freq_hz: float
    freq_hz_std: float | None = None
    damping_ratio: float | None = None
    damping_ratio_std: float | None = None
    dominant_location: str = ""


@dataclass(frozen=True)
class FitGroup:
    """One group of a ``modal_fit`` file: ``inchip`` (FRF, (mm/s)/V) or ``shaker`` (transmissibility)."""

    locations: dict[str, Frf]
    modes: list[Mode]
    stabilisation: Mapping[str, np.ndarray] | None
    units: str
    method: str
    quality: float


@dataclass(frozen=True)
class FitData:
    """A ``modal_fit`` file, one :class:`FitGroup` per fit group; ``summary`` as the file stores it."""

    file: str
    groups: dict[str, FitGroup]
    summary: Mapping[str, Any]


@dataclass(frozen=True)
class SweepData:
    """A ``sim_sweep`` file (:class:`labkit.sim.sweep.SweepResult`)."""

    file: str
    sweep: Any


@dataclass(frozen=True)
class SimRunData:
    """The series the knee section needs from a ``sim_result`` file (one run at one drive)."""

    file: str
    t_s: np.ndarray
    knee_vz_mm_s: np.ndarray
    ground_z_um: np.ndarray
    contact: np.ndarray
    scenario: Mapping[str, Any]
    patterns: list[str] | None = None
    summary: Mapping[str, Any] | None = None
    edges: Mapping[str, Any] | None = None      # the run's edge search (labkit.sim.regime), when written
    body_z_um: np.ndarray | None = None         # the body's height: the regime's body motion


def _s(v: Any) -> str:
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)


# --------------------------------------------------------------------------- in-chip runs

def load_inchip_run(path: str | Path) -> InchipData:
    """FRFs per location of a ``run_inchip`` file.

    Read through :func:`labkit.files.runs.read_run_file` (complete points only).
    """
    from labkit.files.runs import InchipRun, read_run_file

    path = Path(path)
    run = read_run_file(path)
    if not isinstance(run, InchipRun):
        raise InputError(f"this file holds {run.kind!r}", file=path, key="kind", expected="a 'run_inchip' file")
    if not run.locations:
        raise InputError("no measured locations", file=path, key="locations",
                         expected="groups /locations/<body|hip|knee>")
    locations = {}
    for loc, lg in run.locations.items():
        if "freq_hz" not in lg.columns or "frf" not in lg.columns:
            raise InputError("missing freq_hz or frf", file=path, key=f"locations/{loc}")
        locations[loc] = Frf(lg.freq_hz.astype(float), lg.frf.astype(complex), lg.columns.get("coherence"))
    return InchipData(str(path), run.status, run.method, locations)


# --------------------------------------------------------------------------- shaker runs and tracks

def load_shaker_run(path: str | Path) -> ShakerData:
    """Per-point data of a ``run_shaker`` file (layout: :mod:`labkit.experiments.runfile`).

    Only complete points with status ``ok`` are kept (read through
    :func:`labkit.files.runs.read_run_file`); the knee records are those of points
    taken with the laser on the knee (root attribute ``robot_spot``).
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
    n = int(ok.sum())
    amp = pts.get("tray_amp_um")
    videos = pts.get("video")

    def column(name: str) -> np.ndarray | None:
        return np.asarray(pts[name], float)[ok] if name in pts else None

    data = ShakerData(
        file=str(path), status=run.status, robot_spot=run.robot_spot,
        freq_hz=np.asarray(pts["freq_hz"], float)[ok],
        index=np.asarray(pts.get("index", np.arange(1, ok.size + 1)))[ok].astype(int),
        tray_amp_um=np.asarray(amp, float)[ok] if amp is not None else np.full(n, np.nan),
        videos=([str((path.parent / str(v)).resolve()) if v else "" for v in np.asarray(videos)[ok]]
                if videos is not None else [""] * n),
        speed_mm_s=column("speed_mm_s"), speed_lo_mm_s=column("speed_lo_mm_s"),
        speed_hi_mm_s=column("speed_hi_mm_s"), speed_std_mm_s=column("speed_std_mm_s"),
        patterns=[str(v) for v in np.asarray(pts["pattern"])[ok]] if "pattern" in pts else None)
    if data.robot_spot != "knee":
        return data
    return ShakerData(**{**data.__dict__, "knee": _knee_records(run, data)})


def _knee_records(run: Any, data: ShakerData) -> list[KneeRecord]:
    """Velocity records of a knee-spot shaker run (``/records/p<index>/``, complete points only)."""
    records = []
    row_of = {int(i): k for k, i in enumerate(data.index)}
    for index, rec in sorted(run.records().items()):
        if index not in row_of or "robot_velocity_mm_s" not in rec.signals:
            continue
        k = row_of[index]
        knee = rec.signals["robot_velocity_mm_s"]
        records.append(KneeRecord(data.file, index, np.arange(knee.size) * rec.dt_s, knee,
                                  rec.signals.get("tray_velocity_mm_s"), float(data.freq_hz[k]),
                                  float(data.tray_amp_um[k])))
    return records


def open_kind(path: str | Path, kinds: tuple[str, ...], expected: str) -> Any:
    """``labkit.open(path)``, refused (InputError naming the file and its kind) unless of ``kinds``."""
    from labkit.files import open_file

    obj = open_file(path)
    if obj.kind not in kinds:
        raise InputError(f"this file holds {obj.kind!r}", file=path, key="kind", expected=expected)
    return obj


def load_track(path: str | Path) -> TrackData:
    """Speed of a ``track`` file (read by ``labkit.open``; layout: :mod:`labkit.analysis.tracking.output`).

    ``mean_speed_mm_s`` is NaN when the track has no speed; ``freq_hz`` is the drive the
    track records, if any; ``videos`` are candidate absolute paths of the tracked video
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
    freq = next((float(a[k]) for k in ("freq_hz", "shaker_freq_hz") if k in a), None)
    videos: list[str] = []
    for key in ("source_video", "video", "source"):
        if key in a and _s(a[key]):
            v = Path(_s(a[key]))
            cands = [v] if v.is_absolute() else [Path.cwd() / v, path.parent / v]
            videos = [str(c.resolve()) for c in cands]
            break
    return TrackData(str(path), speed, (float(ci[0]), float(ci[1])),
                     float(a.get("speed_ci_level", summ.get("ci_level", 0.95))), freq,
                     float(a.get("tray_amp_um", np.nan)), videos)


def _pattern_of(run: ShakerData, k: int) -> tuple[str, str]:
    """A shaker point's leg pattern and what classified it (see :data:`PATTERN_BY`)."""
    from labkit.analysis.compare import classify_knee_pattern

    if run.patterns:
        return run.patterns[k], LABEL
    rec = next((r for r in run.knee if r.point == int(run.index[k])), None)
    if rec is None:
        return "", ""
    return classify_knee_pattern(rec.t_s, rec.knee_vz_mm_s, rec.tray_vz_mm_s, rec.freq_hz)["pattern"], KNEE


def _run_speed_rows(run: ShakerData, covered: set[tuple[str, int]]) -> list[tuple]:
    """Rows of the speeds a run file stores itself, for points no track covers."""
    if run.speed_mm_s is None:
        return []
    rows = []
    for k, fz in enumerate(run.freq_hz):
        s = float(run.speed_mm_s[k])
        if (run.file, k) in covered or not np.isfinite(s):
            continue
        if run.speed_std_mm_s is not None:
            std = float(run.speed_std_mm_s[k])
            lo, hi = s - 1.96 * std, s + 1.96 * std
        else:
            lo = float(run.speed_lo_mm_s[k]) if run.speed_lo_mm_s is not None else s
            hi = float(run.speed_hi_mm_s[k]) if run.speed_hi_mm_s is not None else s
            std = (hi - lo) / (2 * 1.96)
        rows.append((float(fz), float(run.tray_amp_um[k]), s, lo, hi, std, *_pattern_of(run, k),
                     f"{run.file} (point {int(run.index[k])})"))
    return rows


def measured_speeds(shaker_runs: Sequence[ShakerData], tracks: Sequence[TrackData]) -> MeasuredSpeeds:
    """Measured speed against frequency (and tray amplitude) from shaker runs and tracks.

    A track gets its drive from the shaker run point whose video it tracked
    (frequency and measured tray amplitude), or from its own ``freq_hz``
    attribute (amplitude then unknown: NaN, unless it has ``tray_amp_um``).
    Speeds stored in a run file itself are used for points no track covers.
    The standard deviation is recovered from the confidence interval assuming
    a normal spread. A knee record of the same run point gives the point's
    leg pattern (:func:`labkit.analysis.compare.classify_knee_pattern`).
    """
    from scipy.stats import norm

    by_video: dict[str, tuple[ShakerData, int]] = {}
    for run in shaker_runs:
        for k, video in enumerate(run.videos):
            if video:
                by_video[str(Path(video).resolve())] = (run, k)
    rows: list[tuple] = []
    covered: set[tuple[str, int]] = set()
    unmatched = []
    for tr in tracks:
        freq, amp, pattern, src = tr.freq_hz, tr.tray_amp_um, ("", ""), tr.file
        if not np.isfinite(tr.mean_speed_mm_s):
            unmatched.append(f"{tr.file} (no speed)")
            continue
        if freq is None:
            hit = next((by_video[v] for v in tr.videos if v in by_video), None)
            if hit:
                run, k = hit
                freq, amp, pattern = float(run.freq_hz[k]), float(run.tray_amp_um[k]), _pattern_of(run, k)
                src = f"{tr.file} (video of {run.file} point {int(run.index[k])})"
                covered.add((run.file, k))
        if freq is None:
            unmatched.append(tr.file)
            continue
        lo, hi = tr.speed_ci_mm_s
        z = norm.ppf(0.5 + tr.ci_level / 2)
        rows.append((float(freq), float(amp), tr.mean_speed_mm_s, lo, hi, (hi - lo) / (2 * z), *pattern, src))
    for run in shaker_runs:
        rows += _run_speed_rows(run, covered)
    rows.sort(key=lambda r: (r[0], r[1]))
    cols: list[Sequence[Any]] = list(zip(*rows)) if rows else [[]] * 9
    num = [np.asarray(c, float) for c in cols[:6]]
    return MeasuredSpeeds(num[0], num[1], num[2], num[3], num[4], num[5], [str(x) for x in cols[6]],
                          [str(x) for x in cols[7]], [str(x) for x in cols[8]], unmatched)


# --------------------------------------------------------------------------- fits and simulations

def load_fit(path: str | Path) -> FitData:
    """A ``modal_fit`` file (read by ``labkit.open``; layout: :mod:`labkit.analysis.modal.io`),
    one :class:`FitGroup` per fit group: ``inchip`` (tethered robot, FRF in (mm/s)/V) or
    ``shaker`` (released robot, transmissibility).
    """
    path = Path(path)
    fit = open_kind(path, ("modal_fit",), "a 'modal_fit' file (labkit fit ... --out ROBOT.toml writes ROBOT.fit.h5)")
    if not fit.groups:
        raise InputError("no fit groups", file=path, key="groups", expected="/groups/<inchip|shaker>")
    groups = {}
    for name, g in fit.groups.items():
        locations = {}
        for loc, cols in g.locations.items():
            if "freq_hz" not in cols or "frf" not in cols:
                raise InputError("missing freq_hz or frf", file=path, key=f"groups/{name}/locations/{loc}")
            locations[loc] = Frf(np.asarray(cols["freq_hz"], float), np.asarray(cols["frf"], complex),
                                 model_frf=np.asarray(cols["model"], complex) if "model" in cols else None)
        st = g.stabilisation
        groups[name] = FitGroup(locations, _modes_of(g.modes),
                                st if st is not None and "freq_hz" in st and "order" in st else None,
                                g.units.get("frf", "(mm/s)/V" if name == "inchip" else "1"), g.method,
                                float(g.quality))
    return FitData(str(path), groups, fit.attrs.get("summary") or {})


def _modes_of(cols: Mapping[str, np.ndarray]) -> list[Mode]:
    """One :class:`Mode` per entry of the 1-D mode columns (absent columns: ``None``)."""
    if "freq_hz" not in cols:
        return []
    freq = np.asarray(cols["freq_hz"], float).ravel()

    def column(key: str) -> list[float | None]:
        v = np.asarray(cols[key]).ravel() if key in cols else np.array([])
        return [float(x) for x in v] if v.size == freq.size and np.isrealobj(v) else [None] * freq.size

    where = np.asarray(cols.get("dominant_location", [""] * freq.size)).ravel()
    where = where if where.size == freq.size else np.array([""] * freq.size)
    return [Mode(float(f), fs, d, ds, _s(w)) for f, fs, d, ds, w in
            zip(freq, column("freq_hz_std"), column("damping_ratio"), column("damping_ratio_std"), where)]


def load_sim(path: str | Path) -> SweepData | SimRunData:
    """A simulation file: ``sim_sweep`` (:class:`SweepData`) or ``sim_result`` (:class:`SimRunData`)."""
    path = Path(path)
    kind = file_kind(path)
    if kind == "sim_sweep":
        from labkit.files import read_sweep_result

        return SweepData(str(path), read_sweep_result(path))
    if kind == "sim_result":
        return _load_sim_result(path)
    raise InputError(f"this file holds {kind!r}", file=path, key="kind",
                     expected="a 'sim_sweep' or 'sim_result' file")


def _load_sim_result(path: Path) -> SimRunData:
    """The series the knee section needs from a ``sim_result`` file (read by ``labkit.open``)."""
    run = open_kind(path, ("sim_result",), "a 'sim_result' file (labkit simulate shaker --out RUN.h5)")
    cols = run.columns
    for key in ("t_s", "knee_vz_mm_s", "ground_z_um", "contact"):
        if key not in cols:
            raise InputError("missing dataset", file=path, key=key, expected="a simulated run's time series")
    pats = cols.get("patterns")
    if pats is None:
        pats = run.attrs.get("patterns")       # SimResult.to_h5 stores the six labels as a JSON list
        if isinstance(pats, str):
            pats = json.loads(pats) if pats.startswith("[") else [pats]
    summary, edges = run.attrs.get("summary"), run.attrs.get("edges")
    return SimRunData(str(path), np.asarray(cols["t_s"], float), np.asarray(cols["knee_vz_mm_s"], float),
                      np.asarray(cols["ground_z_um"], float), np.asarray(cols["contact"]), dict(run.scenario),
                      [_s(v) for v in np.atleast_1d(np.asarray(pats, dtype=object))] if pats is not None else None,
                      summary if isinstance(summary, dict) else None,
                      edges if isinstance(edges, dict) else None,       # labkit simulate ... --edges --out RUN.h5
                      np.asarray(cols["body_z_um"], float) if "body_z_um" in cols else None)


def classify_inputs(paths: list[str]) -> dict[str, list[str]]:
    """Sort files by their ``kind`` (unknown kinds -> InputError naming the file)."""
    groups: dict[str, list[str]] = {}
    for p in paths:
        kind = file_kind(p)
        groups.setdefault(kind, []).append(p)
    return groups


# --------------------------------------------------------------------------- what the sections derive

@dataclass(frozen=True)
class SimCurve:
    """A frequency sweep as the speed section draws it: magnitudes, sorted by frequency."""

    file: str
    label: str
    freq_hz: np.ndarray
    draws_mm_s: np.ndarray          # (points, draws); draw 0 is the nominal robot
    draws: int
    p10_mm_s: np.ndarray
    p90_mm_s: np.ndarray
    mean_mm_s: np.ndarray
    lo_mm_s: np.ndarray
    hi_mm_s: np.ndarray
    nominal_mm_s: np.ndarray
    patterns: list[str]
    describe: str
    sweep: Any


@dataclass(frozen=True)
class SimKnee:
    """The settled part of a simulated knee record at one drive, tray velocity derived."""

    t_s: np.ndarray
    knee_vz_mm_s: np.ndarray
    tray_vz_mm_s: np.ndarray
    contact: np.ndarray
    knee_pattern: str
    foot_pattern: str
    source: str


@dataclass(frozen=True)
class KneeCase:
    """One drive of the knee section: the measured record (and its pattern) and the simulated one."""

    freq_hz: float
    tray_amp_um: float
    measured: KneeRecord | None = None
    measured_pattern: str = "?"
    simulated: SimKnee | None = None


@dataclass(frozen=True)
class PatternPair:
    """An observed leg pattern and a simulated one at the same drive, and what classified each."""

    source: str                # "knee record" or "sweep"
    drive: str
    measured: str
    simulated: str
    measured_by: str
    simulated_by: str
    measured_file: str
    simulated_file: str

    @property
    def comparable(self) -> bool:
        """Both classified from the same observable (:data:`PATTERN_BY`)."""
        return PATTERN_BY.get(self.measured_by) == PATTERN_BY.get(self.simulated_by)
