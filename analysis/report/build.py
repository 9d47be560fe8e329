"""Build the model-against-measurement report: one self-contained HTML page (figures inline
as SVG), each figure also as PNG (200 dpi) and SVG, ``agreement.json`` (every number, the
tolerances and the headline) and ``figure_data.json`` (what each figure shows).

Sections (paper figure numbers in brackets): FRFs with the fitted model [5/6], stabilisation
diagram, speed against shaker frequency [8], knee motion at every drive with the contact
timeline [10/11], leg-motion patterns, tracked paths with a video frame, and the agreement
table. Every section ends in a verdict against :class:`~labkit.analysis.compare.Tolerances`
and carries its provenance once (input files with SHA-256, software, command). A section
whose inputs were not given says so; an input that cannot be read raises
:class:`labkit.errors.InputError` naming it.
"""
from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any, NotRequired, TypedDict

import numpy as np

from labkit.analysis import compare
from labkit.analysis.compare import Tolerances, verdict
from labkit.analysis.report import figures as figs
from labkit.analysis.report import html as rh
from labkit.analysis.report import inputs as ri
from labkit.analysis.report import provenance as prov
from labkit.analysis.report.numbers import format_uncertain, format_value
from labkit.errors import InputError
from labkit.files.base import Json


class Row(TypedDict):
    """One judged comparison (a row of the agreement table and of ``agreement.json``)."""

    comparison: str
    metric: str
    value: float | None
    units: str
    value_text: str
    tolerance: str
    verdict: str                # "pass", "fail" or "not judged"
    band_statistic: str
    n: int
    section: NotRequired[str]


@dataclass(frozen=True)
class SpeedJudged(compare.Result):
    """One simulated sweep judged against the measured speeds: the nominal robot, the Monte Carlo
    mean, the band's coverage and each measured speed's percentile within the draws."""

    nominal: compare.SpeedAgreement
    monte_carlo_mean: compare.SpeedAgreement
    coverage: compare.Coverage
    percentiles: list[float]


class Details(TypedDict, total=False):
    """The sections' numbers (``agreement.json``: ``details``; the headline is read from them)."""

    speed: dict[str, SpeedJudged]                  # by sweep file
    speed_mc_mean_rms_error_mm_s: float | None     # of the first sweep judged
    speed_nominal: compare.SpeedAgreement          # of the first sweep judged
    speed_coverage: compare.Coverage               # of the first sweep judged
    knee: dict[str, compare.KneeAgreement]         # by drive
    patterns: dict[str, compare.PatternAgreement]  # by what the patterns were compared with


class ReportSummary(TypedDict):
    """What :func:`build_report` returns (``labkit report --json``): the files written, each
    section's status, verdict and message, the headline numbers and every judged comparison."""

    html: str
    figures: list[str]
    svgs: list[str]
    agreement_json: str
    figure_data_json: str
    sections: dict[str, str]
    verdicts: dict[str, str]
    missing: dict[str, str]
    notes: dict[str, str]
    headline: dict[str, HeadlineEntry]
    speed_rms_error_mm_s: float | None
    speed_rms_error_nominal_mm_s: float | int | None
    agreement: list[Row]


class Verdict(TypedDict):
    """A section's verdict (in ``agreement.json`` and on the page)."""

    result: str                 # "pass", "fail", "not judged" or "missing"
    text: str
    passed: NotRequired[int]
    judged: NotRequired[int]


@dataclass
class Section:
    """One section of the page, as data (rendered by :func:`labkit.analysis.report.html.render`)."""

    id: str
    title: str
    status: str = "ok"                  # "ok" or "missing"
    message: str = ""
    figures: list[tuple[figs.FigureFiles, str, str]] = field(default_factory=list)   # files, caption, key
    html: list[str] = field(default_factory=list)
    rows: list[Row] = field(default_factory=list)                                   # judged comparisons
    files: list[str] = field(default_factory=list)                                  # inputs, for provenance
    notes: dict[str, str] = field(default_factory=dict)
    verdict: Verdict = field(default_factory=lambda: Verdict(result="n/a", text=""))
    provenance: prov.SectionProvenance = field(default_factory=lambda: prov.SectionProvenance())
    summarises: list[Row] | None = None    # the agreement section judges other sections' rows
    details: Details = field(default_factory=lambda: Details())   # this section's numbers, for agreement.json
    pairs: list[ri.PatternPair] = field(default_factory=list)   # leg patterns it observed and simulated

    def figure(self, files: figs.FigureFiles, caption: str) -> None:
        self.figures.append((files, caption, files.png.stem))


@dataclass(frozen=True)
class KneeOptions:
    """How the knee section finds and simulates its drives (see :func:`build_report`)."""

    drives: Sequence[tuple[float, float]] | None = None
    simulate: bool = True
    duration_s: float = 0.3
    leg: int = 0
    scheduler: str | None = None
    workers: int | None = None
    quiet: bool = True


@dataclass(frozen=True)
class ReportInputs:
    """Everything the sections read, read once before any is drawn (figures go to ``out``)."""

    out: Path
    inchip: list[ri.InchipData]
    shaker: list[ri.ShakerData]
    tracks: list[ri.TrackData]
    fit: ri.FitData | None
    fit_file: str | None
    params: str | None
    sweeps: list[ri.SweepData]
    results: list[ri.SimRunData]
    tol: Tolerances
    knee: KneeOptions


def _missing(sid: str, title: str, message: str) -> Section:
    return Section(sid, title, status="missing", message=message)


def _fixed(x: float | None, decimals: int) -> str:
    """A number with a fixed count of decimals ("n/a" for None/NaN): table columns that line up."""
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{decimals}f}"


def _row(comparison: str, metric: str, value: float | None, units: str, tolerance: str, result: str, *,
         band: str = "", n: int = 1, text: str | None = None) -> Row:
    """One judged comparison: the metric's value, the tolerance it is judged against, the verdict."""
    return Row(comparison=comparison, metric=metric, value=value, units=units,
               value_text=text if text is not None else format_value(value),
               tolerance=tolerance, verdict=result, band_statistic=band, n=n)


def build_report(out_dir: str | Path, *, runs: Sequence[str] = (), tracks: Sequence[str] = (),
                 fit: str | None = None, sims: Sequence[str] = (), params: str | None = None,
                 knee_drives: Sequence[tuple[float, float]] | None = None, simulate_knee: bool = True,
                 knee_duration_s: float = 0.3, leg: int = 0,
                 tolerances: Tolerances | Mapping[str, float] | None = None, command: str | None = None,
                 scheduler: str | None = None, workers: int | None = None,
                 title: str = "labkit: model against measurement", quiet: bool = True) -> ReportSummary:
    """Read the inputs, compare, draw, and write ``report.html``, the figures, ``agreement.json``
    and ``figure_data.json`` into ``out_dir``.

    Parameters
    ----------
    runs:
        Run files (``run_inchip`` and/or ``run_shaker``).
    tracks:
        Track files (``kind = "track"``).
    fit:
        A ``modal_fit`` file (``robot.fit.h5``).
    sims:
        ``sim_sweep`` files (speed against ``freq_hz``) and/or ``sim_result`` files
        (knee motion at one drive).
    params:
        Robot parameter file for simulating the knee at the drives no ``sim_result`` covers
        (default: the TOML beside the fit, else the first sweep's parameters, else the defaults).
    knee_drives:
        ``(freq_hz, amp_um)`` pairs shown in the knee section in addition to every drive
        with a measured knee record or a ``sim_result``.
    simulate_knee:
        Simulate drives no ``sim_result`` covers (through :func:`labkit.executor.map_tasks`).
    leg:
        Which leg's knee (0..5) the simulated record shows.
    tolerances:
        What each comparison is judged against (:class:`~labkit.analysis.compare.Tolerances`,
        or a mapping of its field names to values; defaults documented there).
    command:
        The command line that made the report, for the provenance (default: this call).
    scheduler, workers:
        Passed to :func:`labkit.executor.map_tasks` for the knee simulations.

    Returns
    -------
    ReportSummary
        Paths written, per-section status and verdict, the headline numbers and every
        judged comparison.
    """
    from labkit import __version__
    from labkit.h5io import utc_now
    from labkit.outputs import staged_dir

    tol = tolerances if isinstance(tolerances, Tolerances) else Tolerances.from_mapping(tolerances)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    typed = command
    command = prov.report_command(out, runs, tracks, fit, sims, params)
    knee = KneeOptions(knee_drives, simulate_knee, knee_duration_s, leg, scheduler, workers, quiet)
    # read everything first: a bad file fails before any figure is drawn
    inchip, shaker, track_data, fit_data, sweeps, results = _read_inputs(runs, tracks, fit, sims)
    read = ReportInputs(out, inchip, shaker, track_data, fit_data, fit, params, sweeps, results, tol, knee)
    names: list[str] = []           # filled below; staged_dir moves them into ``out`` once all are written
    # every file goes to a staging folder first: a failure anywhere leaves an old report whole
    with staged_dir(out, names) as stage:
        sections = run_sections(replace(read, out=stage))
        rows, details, inputs = _judge(sections, tol, out)
        headline = _headline(fit_data, details, sections)
        meta: prov.ReportMeta = {"created_utc": utc_now(), "software": f"labkit {__version__}", "command": command,
                "command_as_given": typed, "input_files": inputs,
                "inputs": {"runs": list(map(str, runs)), "tracks": list(map(str, tracks)), "fit": fit,
                           "sims": list(map(str, sims)), "params": params},
                "tolerances": tol.as_dict()}
        (stage / "report.html").write_text(rh.render(title, sections, meta, headline), encoding="utf-8")
        # from here on, the figures' paths are where they will be
        for s in sections:
            s.figures = [(figs.FigureFiles(out / f.png.name, out / f.svg.name, f.data), cap, key)
                         for f, cap, key in s.figures]
        _write_data(stage, {"meta": meta, "headline": headline, "agreement": rows,
                            "sections": {s.id: {"status": s.status, "verdict": s.verdict, "provenance": s.provenance}
                                         for s in sections},
                            "details": details}, sections)
        names += sorted(p.name for p in stage.iterdir())
    # figures of an earlier report in this folder that this one did not draw would mislead: remove them
    for old in out.glob("fig_*.*"):
        if old.suffix in (".png", ".svg") and old.name not in names:
            old.unlink()
    return _report_summary(out, sections, rows, details, headline)


def _judge(sections: list[Section], tol: Tolerances, out: Path) -> tuple[list[Row], Details, list[prov.InputRecord]]:
    """Add the agreement section, give every section its verdict and provenance; return the judged
    rows, the sections' details merged, and the input files' records (shown relative to ``out``)."""
    rows = [Row(**r, section=s.id) for s in sections for r in s.rows]
    sections.append(_agreement_section(rows, tol, sections))
    details = Details()
    for s in sections:
        details.update(s.details)
    inputs = prov.file_records(f for s in sections if s.status == "ok" for f in s.files)
    for f in inputs:
        f["shown_as"] = prov.display_path(f["path"], out)
    for s in sections:
        s.verdict = _section_verdict(s)
        if s.status == "ok":
            s.provenance = prov.section_provenance(s.files, inputs=inputs, notes=s.notes)
    return rows, details, inputs


def _write_data(stage: Path, payload: Mapping[str, Any], sections: list[Section]) -> None:
    """``agreement.json`` (``payload``) and ``figure_data.json`` (every figure's numbers) into ``stage``."""
    (stage / "agreement.json").write_text(json.dumps(_jsonable(payload), indent=1), encoding="utf-8")
    (stage / "figure_data.json").write_text(
        json.dumps(_jsonable({key: {"png": str(f.png), "svg": str(f.svg), "caption": cap, **f.data}
                              for s in sections for f, cap, key in s.figures}), indent=1), encoding="utf-8")


def _report_summary(out: Path, sections: list[Section], rows: list[Row], details: Details,
                    headline: dict[str, HeadlineEntry]) -> ReportSummary:
    """What :func:`build_report` returns (``labkit report --json``)."""
    mc = details.get("speed_mc_mean_rms_error_mm_s")
    nominal = headline.get("speed_rms_error_nominal_mm_s")
    return {"html": str(out / "report.html"), "figures": [str(f.png) for s in sections for f, _, _ in s.figures],
            "svgs": [str(f.svg) for s in sections for f, _, _ in s.figures],
            "agreement_json": str(out / "agreement.json"), "figure_data_json": str(out / "figure_data.json"),
            "sections": {s.id: s.status for s in sections},
            "verdicts": {s.id: s.verdict["result"] for s in sections},
            "missing": {s.id: s.message for s in sections if s.status != "ok"},
            "notes": {s.id: s.message for s in sections if s.status == "ok" and s.message},
            "headline": headline,
            "speed_rms_error_mm_s": mc,
            "speed_rms_error_nominal_mm_s": nominal["value"] if nominal else None,
            "agreement": [_summary_row(r) for r in rows]}


def _summary_row(r: Row) -> Row:
    """A judged comparison as ``labkit report --json`` lists it (its section first)."""
    return {"section": r.get("section", ""), "comparison": r["comparison"], "metric": r["metric"],
            "value": r["value"], "value_text": r["value_text"], "units": r["units"], "tolerance": r["tolerance"],
            "verdict": r["verdict"], "band_statistic": r["band_statistic"], "n": r["n"]}


def _read_inputs(runs: Sequence[str], tracks: Sequence[str], fit: str | None, sims: Sequence[str]) -> tuple[
        list[ri.InchipData], list[ri.ShakerData], list[ri.TrackData], ri.FitData | None,
        list[ri.SweepData], list[ri.SimRunData]]:
    """In-chip runs, shaker runs, tracks, the fit, sweeps and single simulations, read (InputError
    naming the first file that cannot be)."""
    inchip: list[ri.InchipData] = []
    shaker: list[ri.ShakerData] = []
    for path in runs:
        kind = ri.file_kind(path)
        if kind == "run_inchip":
            inchip.append(ri.load_inchip_run(path))
        elif kind == "run_shaker":
            shaker.append(ri.load_shaker_run(path))
        else:
            raise InputError(f"this file holds {kind!r}", file=path, key="kind",
                             expected="a 'run_inchip' or 'run_shaker' run file")
    sim_data = [ri.load_sim(p) for p in sims]
    return (inchip, shaker, [ri.load_track(p) for p in tracks], ri.load_fit(fit) if fit else None,
            [s for s in sim_data if isinstance(s, ri.SweepData)], [s for s in sim_data if isinstance(s, ri.SimRunData)])


def _jsonable(x: Any) -> Any:
    if isinstance(x, compare.Result):
        return _jsonable(x.to_dict())
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if np.isfinite(v) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, Path):
        return str(x)
    return x


def _section_verdict(s: Section) -> Verdict:
    if s.status != "ok":
        return Verdict(result="missing", text=f"Verdict: not judged (missing input). {s.message}")
    judged = [r for r in (s.rows if s.summarises is None else s.summarises) if r["verdict"] in ("pass", "fail")]
    if not judged:
        why = s.notes.get("verdict_note", "nothing in this section is judged against a tolerance; shown for "
                                          "inspection")
        return Verdict(result="not judged", text=f"Verdict: not judged ({why}).")
    failed = [r for r in judged if r["verdict"] == "fail"]
    if failed:
        names = "; ".join(f"{r['comparison']}: {r['metric']} {r['value_text']} (tolerance {r['tolerance']})"
                          for r in failed[:4])
        more = f"; and {len(failed) - 4} more" if len(failed) > 4 else ""
        return Verdict(result="fail", passed=len(judged) - len(failed), judged=len(judged),
                       text=f"Verdict: FAIL: {len(failed)} of {len(judged)} comparisons outside tolerance "
                            f"({names}{more}).")
    return Verdict(result="pass", passed=len(judged), judged=len(judged),
                   text="Verdict: PASS: " + ("its one comparison is within tolerance." if len(judged) == 1 else
                                             f"all {len(judged)} comparisons within tolerance."))


# --------------------------------------------------------------------------- FRF and stabilisation

GROUP_TITLES = {"inchip": "tethered robot, in-chip sweep: FRF (paper Fig. 5)",
                "shaker": "released robot on the shaker: transmissibility (paper Fig. 6)"}


def _minima(f: np.ndarray, mag: np.ndarray) -> list[list[float]]:
    """Interior local minima of a curve: ``[[freq_hz, value], ...]``."""
    i = np.flatnonzero((mag[1:-1] < mag[:-2]) & (mag[1:-1] <= mag[2:])) + 1
    return [[float(f[k]), float(mag[k])] for k in i]


def _frf_section(inp: ReportInputs, done: Mapping[str, Section]) -> Section:
    out, inchip, fit, tol = inp.out, inp.inchip, inp.fit, inp.tol
    title = "Frequency responses with the fitted model (paper Fig. 5/6)"
    groups = {k: g for k, g in (fit.groups.items() if fit else []) if g.locations}
    if not groups and not inchip:
        return _missing("frf", title, "No in-chip run file (--runs RUN.h5) or fit (--fit robot.fit.h5) given.")
    sec = Section("frf", title)
    if not groups:
        sec.message = "No fit given (--fit robot.fit.h5): measured FRFs only, no model curve."
        sec.notes["verdict_note"] = "no fit to judge"
        for k, run in enumerate(inchip):
            sec.files.append(run.file)
            ff = figs.frf_figure(run.locations, [], out / f"fig_frf_run{k + 1}", units="(mm/s)/V",
                                 title=GROUP_TITLES["inchip"])
            sec.figure(ff, f"Measured FRF per location (markers) from {run.file}.")
        return sec
    assert fit is not None
    sec.files.append(fit.file)
    sec.files += [r.file for r in inchip]
    for name, g in groups.items():
        modes = g.modes
        fine, lines_only = _fine_models(sec, name, g)
        ff = figs.frf_figure(g.locations, modes, out / f"fig_frf_{name}", fine=fine, units=g.units,
                             title=GROUP_TITLES.get(name, name))
        _mark_extrema(ff, g, fine)
        caption = (f"{GROUP_TITLES.get(name, name)}: measured lines (markers, one colour per location) and the "
                   f"fitted model ({g.method}) on a fine grid (lines); modes marked with frequency and damping "
                   f"ratio, ± one standard uncertainty.")
        if lines_only:
            caption += f" Model at the measured lines only for {', '.join(lines_only)} (could not be rebuilt)."
        sec.figure(ff, caption)
        if modes:
            sec.html.append(f"<h3>Modes ({rh.e(name)})</h3>")
            sec.html.append(rh.table(["mode", "frequency", "damping ratio", "dominant location"],
                                     [[i + 1, format_uncertain(m.freq_hz, m.freq_hz_std, "Hz"),
                                       format_uncertain(m.damping_ratio, m.damping_ratio_std),
                                       m.dominant_location] for i, m in enumerate(modes)],
                                     num_cols={0, 1, 2}))
        q = g.quality
        sec.rows.append(_row(f"fit quality ({name})", "1 - NRMSE² (worst location)", q, "1",
                             f"≥ {tol.fit_quality_min:g}", verdict(q, at_least=tol.fit_quality_min),
                             n=len(g.locations), text=format_value(q, 6)))
    return sec


def _fine_models(sec: Section, name: str, g: ri.FitGroup) -> tuple[dict[str, ri.Frf], list[str]]:
    """The fitted model of each location of group ``name`` rebuilt on a fine grid (noted in ``sec``), and
    the locations whose model could not be rebuilt (shown at the measured lines only)."""
    from labkit.analysis.report.model import rebuild_model

    modes = g.modes
    fine: dict[str, ri.Frf] = {}
    lines_only = []
    for loc, d in g.locations.items():
        fm = (rebuild_model(d.freq_hz, d.model_frf, [m.freq_hz for m in modes],
                            [np.nan if m.damping_ratio is None else m.damping_ratio for m in modes])
              if d.model_frf is not None and modes else None)
        if fm is None:
            lines_only.append(loc)
            continue
        fine[loc] = ri.Frf(fm.freq_hz, fm.frf)
        sec.notes[f"model {name}/{loc}"] = (f"pole-residue model rebuilt on {fm.freq_hz.size} log-spaced lines "
                                            f"(residual powers {list(fm.residual_powers)}, reproduces the stored "
                                            f"model to {fm.rebuild_error:.1e})")
    return fine, lines_only


def _mark_extrema(ff: figs.FigureFiles, g: ri.FitGroup, fine: Mapping[str, ri.Frf]) -> None:
    """Record the model's minima and maxima per location in the FRF figure's data (figure_data.json)."""
    assert "locations" in ff.data       # an FRF figure's data
    for loc, d in g.locations.items():
        entry = ff.data["locations"][loc]
        if loc in fine:
            mag = np.abs(fine[loc].frf)
            entry["fit_minima"] = _minima(fine[loc].freq_hz, mag)
            entry["fit_maxima"] = [[a, -b] for a, b in _minima(fine[loc].freq_hz, -mag)]
        if d.model_frf is not None:
            entry["lines_model_minima"] = _minima(np.asarray(d.freq_hz), np.abs(d.model_frf))


def _stab_section(inp: ReportInputs, done: Mapping[str, Section]) -> Section:
    out, fit = inp.out, inp.fit
    title = "Stabilisation diagram"
    if fit is None:
        return _missing("stabilisation", title, "No fit given (--fit robot.fit.h5).")
    groups = {k: g for k, g in fit.groups.items() if g.stabilisation}
    if not groups:
        return _missing("stabilisation", title, f"{fit.file} holds no stabilisation data.")
    sec = Section("stabilisation", title, files=[fit.file])
    sec.notes["verdict_note"] = "the diagram shows how the poles were chosen; the fit itself is judged above"
    for name, g in groups.items():
        assert g.stabilisation is not None
        ff = figs.stabilisation_figure(g.stabilisation, out / f"fig_stabilisation_{name}", g.locations,
                                       title=f"stabilisation diagram: {name}")
        sec.figure(ff, f"Poles by model order ({name}); the chosen poles marked (red), the measured |FRF| of "
                       f"each location behind them (right axis).")
    return sec


# --------------------------------------------------------------------------- speed

def describe_sweep(sw: Any) -> str:
    """What a sweep covers, e.g. ``freq_hz 150-290 Hz (15 points), tray 25 um, 8 draws of 1 s``
    (the base scenario's own ``freq_hz`` is not what a frequency sweep ran at)."""
    from labkit.sim.sweep import units_of

    v = np.asarray(sw.values, float)
    unit = units_of(sw.quantity)
    scen = {k: x for k, x in (sw.scenario or {}).items() if k not in (sw.quantity, "type")}
    fixed = ", ".join(f"{k} {x:g}" if isinstance(x, (int, float)) else f"{k} {x}" for k, x in scen.items())
    dur = (sw.meta or {}).get("duration_s")
    return (f"{sw.quantity} {v.min():g}\u2013{v.max():g} {unit} ({v.size} points)"
            + (f", {fixed}" if fixed else "")
            + f", {sw.draws} draws" + (f" of {dur:g} s" if isinstance(dur, (int, float)) else ""))


def _sim_curves(sweeps: list[ri.SweepData], tol: Tolerances) -> list[ri.SimCurve]:
    curves = []
    for s in sweeps:
        sw = s.sweep
        if sw.quantity != "freq_hz":
            continue
        # measured speed is unsigned (the paper compares speed, not velocity: the robot turns),
        # the simulator's is signed along +y: compare magnitudes, draw by draw
        draws = np.abs(np.asarray(sw.speeds_mm_s, float))
        order = np.argsort(sw.values)
        p10, p90 = compare.percentile_band(draws, (tol.band_lo_pct, tol.band_hi_pct))
        mean, lo, hi = compare.band_from_draws(draws, k=2.0)
        curves.append(ri.SimCurve(s.file, Path(s.file).name, np.asarray(sw.values)[order], draws[order],
                                  int(sw.draws), p10[order], p90[order], mean[order], lo[order], hi[order],
                                  draws[order, 0], [sw.dominant_pattern(int(i)) for i in order],
                                  describe_sweep(sw), sw))
    return curves


def _speed_section(inp: ReportInputs, done: Mapping[str, Section]) -> Section:
    out, shaker, tracks, sweeps, tol = inp.out, inp.shaker, inp.tracks, inp.sweeps, inp.tol
    title = "Speed against shaker frequency (paper Fig. 8)"
    measured = ri.measured_speeds(shaker, tracks) if (shaker or tracks) else None
    curves = _sim_curves(sweeps, tol)
    have_meas = measured is not None and measured.freq_hz.size > 0
    if not have_meas and not curves:
        return _missing("speed", title, "No measured speeds (--runs SHAKER_RUN.h5 / --tracks TRACK.h5) and no "
                        "simulated frequency sweep (--sim SWEEP.h5) given.")
    sec = Section("speed", title)
    sec.files += [r.file for r in shaker] + [t.file for t in tracks] + [c.file for c in curves]
    band = f"{tol.band_lo_pct:g}\u2013{tol.band_hi_pct:g} %"
    for c in curves:
        sec.notes[f"sweep {c.label}"] = c.describe
    msgs = []
    if not have_meas:
        msgs.append("No measured speeds given: simulation only.")
        sec.notes["verdict_note"] = "no measured speed to judge the simulation against"
    if measured is not None and measured.unmatched:
        msgs.append("Tracks with no known shaker frequency or no speed (left out): "
                    f"{', '.join(measured.unmatched)}.")
    other = [f"{s.file} (over {s.sweep.quantity})" for s in sweeps if s.sweep.quantity != "freq_hz"]
    if other:
        msgs.append(f"Sweeps not over freq_hz are not drawn here: {', '.join(other)}.")
    if not curves:
        msgs.append("No simulated frequency sweep (--sim SWEEP.h5): no model curve.")
        sec.notes["verdict_note"] = "no simulated sweep to judge"
    if have_meas and curves:
        assert measured is not None
        msgs += _judge_curves(sec, measured, curves, tol, band)
    ff = figs.speed_figure(measured if have_meas else None, curves, out / "fig_speed", note=_speed_note(sec, tol, band))
    sec.figure(ff, f"Measured speed (markers, 95 % confidence interval) against the simulated nominal robot "
                   f"(line) and the Monte Carlo {band} band over draws; below, the leg pattern (simulated: the "
                   f"dominant one over draws and feet; measured: where a knee record or label gives it).")
    sec.message = " ".join(msgs)
    return sec


def _judge_curves(sec: Section, measured: ri.MeasuredSpeeds, curves: list[ri.SimCurve], tol: Tolerances,
                  band: str) -> list[str]:
    """Judge the measured speeds against each simulated sweep, only the points measured at the sweep's tray
    amplitude (or of unknown amplitude); the messages for sweeps no point was measured for."""
    msgs = []
    for c in curves:
        amp = float(c.sweep.scenario.get("amp_um", np.nan))
        mask = ~np.isfinite(measured.amp_um) | ~np.isfinite(amp) | (np.abs(measured.amp_um - amp) <= 0.1 * abs(amp))
        m = measured.select(mask)
        if not m.freq_hz.size:
            msgs.append(f"No measured point at the tray amplitude of {c.file} ({amp:.3g} um).")
            continue
        _judge_speed(sec, m, c, tol, band)
        sec.pairs += _sweep_pattern_pairs(m, c)
    return msgs


def _speed_note(sec: Section, tol: Tolerances, band: str) -> str:
    """The speed figure's note: the first judged sweep's nominal RMS error and band coverage ("" if none)."""
    judged = sec.details.get("speed", {})
    if not judged:
        return ""
    first = next(iter(judged.values()))
    nom, cov = first.nominal, first.coverage
    return (f"nominal robot: RMS error {format_value(nom.rms_error_mm_s, 3)} mm/s "
            f"(relative {format_value(nom.relative_rms_error, 2)}, tolerance "
            f"\u2264 {tol.speed_relative_rms_max:g})\n"
            f"{band} band holds {sum(q.inside_band for q in nom.points)} of {cov.n} measured points; "
            f"median percentile in the draws {format_value(cov.median_percentile, 3)} (50 if unbiased)")


def _judge_speed(sec: Section, m: ri.MeasuredSpeeds, c: ri.SimCurve, tol: Tolerances, band: str) -> None:
    p: dict[str, Json] = {"measured": [*sorted(set(m.sources))], "simulated": c.file, "sweep": c.describe}
    a_nom = compare.speed_agreement(m.freq_hz, m.speed_mm_s, m.lo_mm_s, m.hi_mm_s, c.freq_hz,
                                    c.nominal_mm_s, c.p10_mm_s, c.p90_mm_s, provenance=p)
    a_mc = compare.speed_agreement(m.freq_hz, m.speed_mm_s, m.lo_mm_s, m.hi_mm_s, c.freq_hz,
                                   c.mean_mm_s, c.p10_mm_s, c.p90_mm_s, provenance=p)
    pct = compare.draw_percentiles(m.freq_hz, m.speed_mm_s, c.freq_hz, c.draws_mm_s)
    cov = compare.coverage(pct.tolist(), [q.inside_band for q in a_nom.points], (tol.band_lo_pct, tol.band_hi_pct))
    details = sec.details
    details.setdefault("speed", {})[c.file] = SpeedJudged(a_nom, a_mc, cov, pct.tolist())
    if "speed_nominal" not in details:                  # the headline reads the first sweep judged
        details["speed_mc_mean_rms_error_mm_s"] = a_mc.rms_error_mm_s
        details["speed_nominal"] = a_nom
        details["speed_coverage"] = cov
    rel = a_nom.relative_rms_error
    tag = f" vs {c.label}"
    med = cov.median_percentile
    band_text = (f"median percentile of the measured speeds within the draws: {format_value(med, 3)} "
                 f"(50 if unbiased; {c.draws} draws)")
    sec.rows.append(_row(f"speed, nominal robot{tag}", "relative RMS error (RMS error / RMS measured)", rel, "1",
                         f"≤ {tol.speed_relative_rms_max:g}", verdict(rel, at_most=tol.speed_relative_rms_max),
                         band=band_text, n=a_nom.n_points,
                         text=f"{format_value(rel, 3)} (RMS error {format_value(a_nom.rms_error_mm_s, 3)} mm/s)"))
    fr = cov.fraction_inside
    sec.rows.append(_row(f"speed, Monte Carlo band{tag}", f"fraction of measured speeds inside the {band} band",
                         fr, "1", f"≥ {tol.speed_coverage_min:g} (expected {cov.expected_fraction:g})",
                         verdict(fr, at_least=tol.speed_coverage_min), band=band_text, n=cov.n))
    sec.html.append(f"<h3>Measured against {rh.e(c.label)}: {rh.e(c.describe)}</h3>")
    table_rows = []
    for q, pc in zip(a_nom.points, pct):
        std = None
        if q.measured_lo_mm_s is not None and q.measured_hi_mm_s is not None:
            std = (q.measured_hi_mm_s - q.measured_lo_mm_s) / (2 * 1.96)
        table_rows.append([q.freq_hz, format_uncertain(q.measured_mm_s, std), format_value(q.simulated_mm_s, 3),
                           f"{format_value(q.band_lo_mm_s, 3)} \u2013 {format_value(q.band_hi_mm_s, 3)}",
                           format_value(float(pc), 3), "yes" if q.inside_band else "no"])
    sec.html.append(rh.table(["freq_hz", "measured (mm/s, ± std)", "nominal robot (mm/s)", f"band {band} (mm/s)",
                              "percentile in draws", "inside band"], table_rows, num_cols={0, 1, 2, 3, 4}))


def _sweep_pattern_pairs(measured: ri.MeasuredSpeeds, c: ri.SimCurve) -> list[ri.PatternPair]:
    """Leg patterns of the measured points (labels in the run, or classified from knee records)
    against the sweep's dominant pattern at the nearest frequency (within 2 %)."""
    pairs = []
    values = np.asarray(c.freq_hz, float)
    for fz, lab, by, src in zip(measured.freq_hz, measured.patterns, measured.pattern_by, measured.sources):
        if lab not in compare.PATTERNS:
            continue
        i = int(np.argmin(np.abs(values - fz)))
        if abs(values[i] - fz) > 0.02 * fz:
            continue
        pairs.append(ri.PatternPair("sweep", f"{fz:.4g} Hz", lab, c.patterns[i], by, ri.FOOT_CONTACT, src, c.file))
    return pairs


# --------------------------------------------------------------------------- knee motion

def _sim_knee_task(task: tuple) -> ri.SimRunData:
    """Simulate one shaker drive and keep what the knee figure needs (module-level: picklable)."""
    from labkit.sim import Shaker, simulate

    params, freq_hz, amp_um, duration_s, seed = task
    r = simulate(params, Shaker(freq_hz=freq_hz, amp_um=amp_um), duration_s=duration_s, seed=seed)
    return ri.SimRunData(f"simulated here ({freq_hz:.4g} Hz, {amp_um:.3g} um)", np.asarray(r.t_s),
                         np.asarray(r.knee_vz_mm_s), np.asarray(r.ground_z_um), np.asarray(r.contact),
                         {"freq_hz": freq_hz, "amp_um": amp_um}, [str(p) for p in r.patterns])


def _knee_params(fit: str | None, params: str | None, sweeps: list[ri.SweepData]) -> tuple[Any, str]:
    from labkit.sim import RobotParams

    if params:
        return RobotParams.from_toml(params), params
    if fit:
        sibling = Path(fit).with_name(Path(fit).name.replace(".fit.h5", ".toml"))
        if sibling.is_file() and sibling != Path(fit):
            return RobotParams.from_toml(sibling), str(sibling)
    if sweeps and sweeps[0].sweep.params_toml:
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            p = Path(tmp) / "robot.toml"
            p.write_text(sweeps[0].sweep.params_toml)
            return RobotParams.from_toml(p), f"parameters of {sweeps[0].file}"
    return RobotParams(), "RobotParams() defaults (paper Tables 1-2)"


def _same(d: tuple[float, float], f: float, a: float) -> bool:
    return bool(abs(d[0] - f) <= 0.01 * abs(f) and (not np.isfinite(a) or not np.isfinite(d[1])
                                                    or abs(d[1] - a) <= 0.1 * abs(a) + 1e-9))


def _drive_of(run: ri.SimRunData) -> tuple[float, float]:
    return float(run.scenario.get("freq_hz", np.nan)), float(run.scenario.get("amp_um", np.nan))


def knee_drives_of(records: list[ri.KneeRecord], results: list[ri.SimRunData],
                   extra: Sequence[tuple[float, float]] | None) -> list[tuple[float, float]]:
    """Every drive to show: each measured knee record's, each sim_result's and the extra ones,
    once each (same frequency within 1 %, amplitude within 10 %), sorted by frequency."""
    drives: list[tuple[float, float]] = []
    cands = [(float(r.freq_hz), float(r.tray_amp_um)) for r in records]
    cands += [_drive_of(s) for s in results]
    cands += [(float(f), float(a)) for f, a in (extra or [])]
    for d in cands:
        if np.isfinite(d[0]) and not any(_same(x, *d) for x in drives):
            drives.append(d)
    return sorted(drives)


def _knee_sims(inp: ReportInputs, drives: list[tuple[float, float]], sec: Section) -> dict[int, ri.SimRunData]:
    """The simulated run of each drive: a given sim_result, else one simulated here (when allowed)."""
    opt = inp.knee
    sims: dict[int, ri.SimRunData] = {}
    for i, d in enumerate(drives):
        hit = next((s for s in inp.results if _same(d, *_drive_of(s))), None)
        if hit is not None:
            sims[i] = hit
    todo = [i for i, d in enumerate(drives) if i not in sims and np.isfinite(d[1])]
    if opt.simulate and todo:
        from labkit.executor import map_tasks

        p, param_src = _knee_params(inp.fit_file, inp.params, inp.sweeps)
        sec.files.append(param_src)
        sec.notes["simulated here"] = (f"simulate({Path(param_src).name}, Shaker(freq_hz, amp_um), "
                                       f"duration_s={opt.duration_s:g}, "
                                       f"seed=0) at {len(todo)} drive(s); the settled second half is compared")
        outs = map_tasks(_sim_knee_task, [(p, drives[i][0], drives[i][1], opt.duration_s, 0) for i in todo],
                         scheduler=opt.scheduler, workers=opt.workers, desc="knee sims", quiet=opt.quiet)
        sims.update(zip(todo, outs))
    return sims


def _settled_knee(sim: ri.SimRunData, freq: float, leg: int) -> ri.SimKnee:
    """The settled second half of a simulated run, labelled with the measured records' classifier
    (the same observable on both sides; the simulator's own per-foot label is kept beside it)."""
    t = np.asarray(sim.t_s)
    tray_v = np.gradient(np.asarray(sim.ground_z_um), t) * 1e-3        # um/s -> mm/s
    knee = np.asarray(sim.knee_vz_mm_s)
    knee = knee[:, leg] if knee.ndim == 2 else knee
    pats = sim.patterns or []
    settle = t >= t[0] + 0.5 * (t[-1] - t[0])
    knee_label = compare.classify_knee_pattern(t[settle], knee[settle], tray_v[settle], freq)["pattern"]
    return ri.SimKnee(t[settle], knee[settle], tray_v[settle], np.asarray(sim.contact)[settle], knee_label,
                      pats[leg] if len(pats) > leg else "?", sim.file)


def _knee_case(freq: float, amp: float, records: list[ri.KneeRecord], sim: ri.SimRunData | None,
               leg: int) -> ri.KneeCase:
    meas = next((r for r in records if _same((freq, amp), r.freq_hz, r.tray_amp_um)), None)
    pattern = (compare.classify_knee_pattern(meas.t_s, meas.knee_vz_mm_s, meas.tray_vz_mm_s, freq)["pattern"]
               if meas is not None else "?")
    return ri.KneeCase(freq, amp, meas, pattern, _settled_knee(sim, freq, leg) if sim is not None else None)


def _knee_rows(sec: Section, case: ri.KneeCase, tol: Tolerances, leg: int) -> list[Any]:
    """Judge one drive with both records: rows, details, the pattern pair; the table's row."""
    meas, s, freq, amp = case.measured, case.simulated, case.freq_hz, case.tray_amp_um
    assert meas is not None and s is not None
    pv: dict[str, Json] = {"measured": meas.file, "measured_point": meas.point, "simulated": s.source, "leg": leg + 1}
    a = compare.knee_motion_agreement(meas.t_s, meas.knee_vz_mm_s, s.t_s, s.knee_vz_mm_s, freq,
                                      ref_meas=meas.tray_vz_mm_s, ref_sim=s.tray_vz_mm_s, provenance=pv)
    sec.details.setdefault("knee", {})[f"{freq:.4g}Hz_{amp:.3g}um"] = a
    drive = f"{freq:.4g} Hz, {amp:.3g} um"
    r_lo, r_hi = 1.0 / tol.knee_amplitude_ratio_max, tol.knee_amplitude_ratio_max
    ratio, phase, corr = a.amplitude_ratio, a.phase_diff_deg, a.correlation
    sec.rows.append(_row(f"knee @ {drive}", "amplitude ratio (sim/meas)", ratio, "1",
                         f"{r_lo:.2f}\u2013{r_hi:.2f}", verdict(ratio, at_least=r_lo, at_most=r_hi),
                         text=_fixed(ratio, 2)))
    sec.rows.append(_row(f"knee @ {drive}", "phase difference (sim - meas)", phase, "deg",
                         f"|Δφ| ≤ {tol.knee_phase_deg_max:g} deg",
                         verdict(abs(phase) if phase is not None else None, at_most=tol.knee_phase_deg_max),
                         text=_fixed(phase, 1)))
    sec.rows.append(_row(f"knee @ {drive}", "waveform correlation (one folded period)", corr, "1",
                         f"≥ {tol.knee_correlation_min:g}", verdict(corr, at_least=tol.knee_correlation_min),
                         text=_fixed(corr, 3)))
    if case.measured_pattern in compare.PATTERNS:
        sec.pairs.append(ri.PatternPair("knee record", drive, case.measured_pattern, s.knee_pattern, ri.KNEE,
                                        ri.KNEE, meas.file, s.source))
    return [freq, amp, format_value(a.amplitude_meas_mm_s, 3), format_value(a.amplitude_sim_mm_s, 3),
            _fixed(ratio, 2), _fixed(phase, 1), _fixed(corr, 3), case.measured_pattern, s.knee_pattern,
            s.foot_pattern]


def _knee_section(inp: ReportInputs, done: Mapping[str, Section]) -> Section:
    out, tol, leg = inp.out, inp.tol, inp.knee.leg
    title = "Knee vertical motion, measured against simulated (paper Fig. 10/11)"
    records = [r for run in inp.shaker for r in run.knee]
    drives = knee_drives_of(records, inp.results, inp.knee.drives)
    if not drives:
        return _missing("knee", title, "No measured knee records (shaker run files with waveforms), no "
                        "sim_result files (--sim) and no --knee-drive given.")
    sec = Section("knee", title)
    sec.files += sorted({r.file for r in records}) + [s.file for s in inp.results]
    sims = _knee_sims(inp, drives, sec)
    sec.notes["leg"] = f"simulated knee of leg {leg + 1}"
    cases, table_rows, msgs = [], [], []
    for i, (freq, amp) in enumerate(drives):
        case = _knee_case(freq, amp, records, sims.get(i), leg)
        cases.append(case)
        if case.measured is not None and case.simulated is not None:
            table_rows.append(_knee_rows(sec, case, tol, leg))
        elif case.measured is None:
            msgs.append(f"No measured knee record at {freq:.4g} Hz, {amp:.3g} um.")
        else:
            msgs.append(f"No simulation at {freq:.4g} Hz, {amp:.3g} um (give --sim SIM_RESULT.h5 or allow simulation).")
    ff = figs.knee_figure(cases, out / "fig_knee")
    sec.figure(ff, f"Knee vertical velocity at all {len(cases)} drives: measured (solid) and simulated (dashed, "
                   f"leg {leg + 1}, settled part) on one time axis whose zero is the tray's phase zero, the tray "
                   f"behind them (grey); below each, the simulated contact mode of the six feet.")
    if table_rows:
        sec.html.append(rh.table(["freq_hz", "tray_amp_um", "measured amp (mm/s)", "simulated amp (mm/s)",
                                  "ratio", "phase diff (deg)", "correlation", "measured pattern (knee)",
                                  "simulated pattern (knee)", f"simulated foot contact (leg {leg + 1})"],
                                 table_rows, num_cols={0, 1, 2, 3, 4, 5, 6}))
    if not table_rows:
        sec.notes["verdict_note"] = "no drive has both a measured and a simulated knee record"
    from labkit.analysis.report.regime import regime_html

    sec.html += regime_html(inp.results, msgs)       # each sim_result's gait regime and edges
    sec.message = " ".join(msgs)
    return sec


# --------------------------------------------------------------------------- leg patterns

def _pattern_section(inp: ReportInputs, done: Mapping[str, Section]) -> Section:
    tol = inp.tol
    # the observed and simulated patterns the speed and knee sections met, copied: theirs stay as they are
    pairs = [p for sid in ("speed", "knee") if sid in done for p in done[sid].pairs]
    title = "Leg-motion patterns, observed against simulated (paper Fig. 9-11)"
    if not pairs:
        return _missing("patterns", title, "No drive with both an observed leg pattern (a knee record or a "
                        "pattern label in the run file) and a simulated one.")
    sec = Section("patterns", title)
    sources = sorted({p.measured_file.split(" (")[0] for p in pairs} | {p.simulated_file for p in pairs})
    sec.files += [f for f in sources if Path(f).is_file()]
    here = [f for f in sources if not Path(f).is_file()]
    if here:
        sec.notes["simulated here"] = f"{len(here)} knee simulation(s) run by this report (see the knee section)"
    sec.notes["compared"] = ("a pattern is compared only with one classified the same way: knee record "
                             "against simulated knee record (classify_knee_pattern on both), run-file labels of "
                             "the feet against the simulated feet's dominant contact pattern")
    for source in ("knee record", "sweep"):
        ps = [p for p in pairs if p.source == source and p.comparable]
        if not ps:
            continue
        a = compare.pattern_agreement([p.measured for p in ps], [p.simulated for p in ps],
                                      keys=[p.drive for p in ps])
        sec.details.setdefault("patterns", {})[source] = a
        fr = a.fraction_agree
        agree = sum(q.agree for q in a.pairs)
        sec.rows.append(_row(f"leg pattern ({source}s)", "fraction of drives with the same pattern", fr, "1",
                             f"≥ {tol.pattern_agreement_min:g}", verdict(fr, at_least=tol.pattern_agreement_min),
                             n=a.n, text=f"{format_value(fr, 3)} ({agree} of {a.n})"))
    apart = [p for p in pairs if not p.comparable]
    if apart:
        sec.message = (f"{len(apart)} pair(s) not compared: the observed pattern was classified from a knee "
                       "record, the simulated one from the feet's contact (different observables; see the "
                       "knee record rows for the like-with-like comparison).")
    if not sec.rows:
        sec.notes["verdict_note"] = "no drive has an observed and a simulated pattern from the same classifier"
    sec.html.append(rh.table(["compared with", "drive", "observed", "observed by", "simulated", "simulated by",
                              "same"],
                             [[p.source, p.drive, p.measured.replace("_", " "), p.measured_by,
                               p.simulated.replace("_", " "), p.simulated_by, _same_text(p)]
                              for p in pairs]))
    return sec


def _same_text(pair: ri.PatternPair) -> str:
    if not pair.comparable:
        return "not compared (different classifiers)"
    return "yes" if pair.measured == pair.simulated else "no"


# --------------------------------------------------------------------------- tracks

def _tracks_section(inp: ReportInputs, done: Mapping[str, Section]) -> Section:
    from labkit.analysis.report.tracks import load_track_path, read_frame_at

    out, tracks = inp.out, inp.tracks
    title = "Tracked paths and a video frame"
    if not tracks:
        return _missing("tracks", title, "No track files (--tracks TRACK.h5) given.")
    sec = Section("tracks", title, files=[t.file for t in tracks])
    sec.notes["verdict_note"] = "the tracked speeds are judged in the speed section"
    paths, labels, names = [], [], []
    for k, t in enumerate(tracks, 1):
        paths.append(load_track_path(t.file))
        lo, hi = t.speed_ci_mm_s
        drive = f"{t.freq_hz:.4g} Hz: " if t.freq_hz is not None else ""
        labels.append(f"{drive}{format_value(t.mean_speed_mm_s, 3)} mm/s")
        names.append(f"{k}: {Path(t.file).name} ({format_value(t.mean_speed_mm_s, 3)} mm/s, interval "
                     f"{format_value(float(lo), 3)}\u2013{format_value(float(hi), 3)})")
    ff = figs.tracks_figure(paths, labels, out / "fig_tracks")
    sec.figure(ff, f"Paths of all {len(paths)} tracks (mm), each from its own start, side by side, labelled with "
                   f"its mean speed. Tracks: {'; '.join(names)}.")
    # the frame shows the track that moved furthest in the image (the most visible one)
    cands = [(float(np.nansum(np.hypot(np.diff(p.u_px), np.diff(p.v_px)))), k, p, v)
             for k, (p, t) in enumerate(zip(paths, tracks)) if p.u_px is not None and p.v_px is not None
             and p.u_px.size for v in [next((x for x in t.videos if Path(x).is_file()), None)] if v]
    framed = max(cands, key=lambda c: (c[0], -c[1]))[2:] if cands else None
    if framed is None:
        sec.message = "No track's video was found (or no track holds pixel coordinates): no frame drawn."
        return sec
    p, video = framed
    assert p.u_px is not None and p.v_px is not None
    frame = read_frame_at(video, float(p.t_s[-1]))
    sec.files.append(video)
    ff = figs.frame_figure(frame, p.u_px, p.v_px, out / "fig_frame",
                           title=f"{Path(video).name} at t = {float(p.t_s[-1]):.2f} s, with the track")
    sec.figure(ff, f"The last tracked frame of {Path(video).name} with the track of {Path(p.file).name} drawn on it "
                   f"(of the tracks whose video was found, the one that moved furthest in the image).")
    return sec


# --------------------------------------------------------------------------- the registry

SectionFunction = Callable[[ReportInputs, Mapping[str, Section]], Section]

#: The report's sections in page order: each is a function of the inputs and of the sections
#: before it (read-only; the leg-pattern section reads the pairs the speed and knee sections
#: met). A new section is one function and one line here.
SECTIONS: tuple[tuple[str, SectionFunction], ...] = (
    ("frf", _frf_section),
    ("stabilisation", _stab_section),
    ("speed", _speed_section),
    ("knee", _knee_section),
    ("patterns", _pattern_section),
    ("tracks", _tracks_section),
)


def run_sections(inp: ReportInputs) -> list[Section]:
    """Every section of :data:`SECTIONS`, in order (the agreement table is added by the caller)."""
    done: dict[str, Section] = {}
    for sid, make in SECTIONS:
        sec = make(inp, MappingProxyType(done))
        assert sec.id == sid, (sid, sec.id)
        done[sid] = sec
    return list(done.values())


# --------------------------------------------------------------------------- agreement table

def _agreement_section(rows: list[Row], tol: Tolerances, sections: list[Section]) -> Section:
    title = "Agreement between model and measurement"
    if not rows:
        return _missing("agreement", title, "Nothing to compare: needs measured and simulated data of the same "
                        "kind (speeds and a frequency sweep, knee records and simulations) or a fit.")
    sec = Section("agreement", title)
    # its inputs are the other sections' (numbered in the report's provenance): not repeated here
    sec.notes["inputs"] = "those of the sections above"
    sec.summarises = rows          # the rows belong to their sections; this one summarises them
    judged = [r for r in rows if r["verdict"] in ("pass", "fail")]
    failed = [r for r in judged if r["verdict"] == "fail"]
    sec.html.append(rh.table(["section", "comparison", "metric", "value", "tolerance", "verdict",
                              "band statistic", "n"],
                             [[r["section"], r["comparison"], r["metric"], r["value_text"], r["tolerance"],
                               ("html", rh.verdict_badge(r["verdict"])), r["band_statistic"], r["n"]]
                              for r in rows], num_cols={3, 7}))
    sec.html.append(f"<p>{len(judged) - len(failed)} of {len(judged)} judged comparisons within tolerance. "
                    "Tolerances (change with <code>--tolerance KEY=VALUE</code>): "
                    + ", ".join(f"<code>{rh.e(k)}={v:g}</code>" for k, v in tol.as_dict().items())
                    + ". The defaults and the reason for each are documented in "
                      "<code>labkit.analysis.compare.Tolerances</code>. Band statistic: each measured speed's "
                      "percentile within the Monte Carlo draws at its frequency (mid-rank); their median is 50 "
                      "for a model without bias, near 0 or 100 when the draws miss on one side. "
                      "Every number is also in <code>agreement.json</code> beside this page.</p>")
    return sec


# --------------------------------------------------------------------------- headline numbers

class _Headline(TypedDict):
    label: str
    value: float | int | None
    units: str


class _HeadlineExtra(TypedDict, total=False):
    std: float | None
    of: int
    digits: int


class HeadlineEntry(_Headline, _HeadlineExtra):
    """One headline number (``agreement.json``: ``headline``): with its standard deviation, the
    count it is out of (``of``), or the digits to show."""


def _headline(fit: ri.FitData | None, details: Details, sections: list[Section]) -> dict[str, HeadlineEntry]:
    """The numbers two reports are compared by (``labkit report --compare``)."""
    h: dict[str, HeadlineEntry] = {}

    def put(key: str, label: str, value: float | int | None, units: str, extra: _HeadlineExtra | None = None) -> None:
        h[key] = {"label": label, "value": value, "units": units, **(extra or {})}

    if fit:
        for name, g in fit.groups.items():
            for i, m in enumerate(g.modes):
                put(f"{name}_mode{i + 1}_freq_hz", f"{name} mode {i + 1} frequency", m.freq_hz, "Hz",
                    {"std": m.freq_hz_std})
                put(f"{name}_mode{i + 1}_damping_ratio", f"{name} mode {i + 1} damping ratio",
                    m.damping_ratio, "1", {"std": m.damping_ratio_std})
            put(f"{name}_fit_quality", f"{name} fit quality (1 - NRMSE\u00b2)", g.quality, "1", {"digits": 6})
    nom, cov = details.get("speed_nominal"), details.get("speed_coverage")
    speed = [("speed_rms_error_nominal_mm_s", "speed RMS error, nominal robot",
              nom.rms_error_mm_s if nom else None, "mm/s"),
             ("speed_relative_rms_error_nominal", "speed relative RMS error, nominal robot",
              nom.relative_rms_error if nom else None, "1"),
             ("speed_rms_error_mc_mean_mm_s", "speed RMS error, Monte Carlo mean",
              details.get("speed_mc_mean_rms_error_mm_s"), "mm/s"),
             ("speed_band_coverage", "measured speeds inside the Monte Carlo band",
              cov.fraction_inside if cov else None, "1"),
             ("speed_median_percentile", "median percentile of measured speeds in the draws",
              cov.median_percentile if cov else None, "%")]
    for key, label, value, units in speed:
        if value is not None:
            put(key, label, value, units)
    knee = list(details.get("knee", {}).values())
    for key, label, field_, reduce, units in (
            ("knee_amplitude_ratio_median", "knee amplitude ratio (median over drives)", "amplitude_ratio",
             lambda v: float(np.median(v)), "1"),
            ("knee_phase_diff_max_deg", "knee |phase difference| (largest)", "phase_diff_deg",
             lambda v: max(abs(x) for x in v), "deg"),
            ("knee_correlation_min", "knee waveform correlation (smallest)", "correlation", min, "1")):
        values = [getattr(a, field_) for a in knee if getattr(a, field_) is not None]
        if values:
            put(key, label, reduce(values), units)
    for source, a in details.get("patterns", {}).items():
        put(f"pattern_agreement_{source.replace(' ', '_')}", f"leg-pattern agreement ({source}s)",
            a.fraction_agree, "1")
    rows = [r for s in sections for r in s.rows if r["verdict"] in ("pass", "fail")]
    put("comparisons_passed", "comparisons within tolerance", sum(r["verdict"] == "pass" for r in rows), "",
        {"of": len(rows)})
    return h
