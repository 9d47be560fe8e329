"""The report's figures (matplotlib object API, no pyplot state: safe in any process).

Each function takes plain dicts/arrays and writes the figure twice: an SVG (text kept
as text, so the page stays sharp at any zoom and its labels can be selected and
searched) and a PNG at :data:`PNG_DPI` for slides. It returns a :class:`FigureFiles`
with both paths and the numbers it drew (``data``), which the report writes to
``figure_data.json`` so a test, or a reader, can check a figure against its inputs.

Conventions (those of the field, and of the paper, Qu, Choi, Oldham 2017): FRF magnitude
on log-log axes with the phase below (Fig. 5/6), measured lines as markers in one
colour per location that every figure shares, the fitted model as a line on a fine
grid; speed against frequency with intervals and a Monte Carlo band (Fig. 8); knee
velocity measured and simulated overlaid on one time axis (Fig. 10/11).
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, NotRequired, TypeAlias, TypedDict, final

import numpy as np

from labkit.analysis.plotting import (
    PNG_DPI,
    loc_colour,
    log_freq_axis,
    mode_label,
    mode_marks,
    style_frf_axes,
    wrap_x,
    wrapped_phase_deg,
)

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from labkit.analysis.report.inputs import Frf, KneeCase, MeasuredSpeeds, Mode, SimCurve
    from labkit.analysis.report.tracks import TrackPath

#: Contact-mode codes of SimResult.contact and their colours in timelines.
CONTACT_NAMES = ("air", "adhesion", "rest")
CONTACT_COLOURS = ("#f2f2f2", "#e69f00", "#009e73")
#: Leg-motion patterns (labkit.analysis.compare.PATTERNS) and their colours.
PATTERN_COLOURS = {"firm_contact": "#1b9e77", "partial_contact": "#d95f02", "jumping": "#7570b3"}
MEAS_COLOUR = "#c0392b"
SIM_COLOUR = "#1f4e9c"


# The numbers each figure shows (``figure_data.json``, beside its files and caption)

class FrfLines(TypedDict):
    """One location of an FRF figure: its measured lines and, when drawn, the fit's grid."""

    n_lines: int
    fit_grid_points: NotRequired[int]
    fit_min_abs: NotRequired[float]
    # added by the report's FRF section: (freq_hz, |FRF|) of the model's dips and peaks
    fit_minima: NotRequired[list[list[float]]]
    fit_maxima: NotRequired[list[list[float]]]
    lines_model_minima: NotRequired[list[list[float]]]


@final
class FrfData(TypedDict):
    locations: dict[str, FrfLines]
    modes: list[str]


@final
class StabilisationData(TypedDict):
    poles: int
    chosen_hz: list[float]


class SweepDrawn(TypedDict):
    """One simulated sweep of the speed figure: band, nominal curve and dominant patterns."""

    file: str
    freq_hz: list[float]
    draws: int
    p10_mm_s: list[float]
    p90_mm_s: list[float]
    nominal_mm_s: list[float]
    patterns: list[str]


@final
class SpeedData(TypedDict):
    sims: list[SweepDrawn]
    measured_points: int
    measured_freq_hz: NotRequired[list[float]]
    measured_mm_s: NotRequired[list[float]]
    pattern_rows: NotRequired[list[str]]


class DriveDrawn(TypedDict):
    """One panel of the knee figure: the drive, which records it shows and their drawn phases."""

    freq_hz: float
    tray_amp_um: float
    measured: bool
    simulated: bool
    measured_phase_deg: NotRequired[float | None]
    simulated_phase_deg: NotRequired[float | None]


@final
class KneeData(TypedDict):
    drives: list[DriveDrawn]


@final
class TracksData(TypedDict):
    tracks: list[str]
    spacing_mm: float


@final
class FrameData(TypedDict):
    frame_size_px: list[int]
    points: int


FigureData: TypeAlias = "FrfData | StabilisationData | SpeedData | KneeData | TracksData | FrameData"


@dataclass
class FigureFiles:
    """One figure as written: ``png`` and ``svg`` paths, and the numbers it shows."""

    png: Path
    svg: Path
    data: FigureData


def _figure(w: float, h: float) -> Figure:
    from matplotlib.figure import Figure

    return Figure(figsize=(w, h), layout="constrained")


def _save(fig: Figure, stem: Path, data: FigureData) -> FigureFiles:
    import matplotlib

    from labkit.outputs import atomic_outputs

    png, svg = stem.with_suffix(".png"), stem.with_suffix(".svg")
    # both or neither (an old pair survives a failed write); text as <text> (selectable, small);
    # a salt per figure keeps element ids unique when several SVGs are inlined in one page
    with atomic_outputs([png, svg]) as (tmp_png, tmp_svg):
        fig.savefig(tmp_png, dpi=PNG_DPI, format="png")
        with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": stem.name}):
            fig.savefig(tmp_svg, format="svg")
    return FigureFiles(png, svg, data)


def _legend_outside(ax: Axes, **kw: Any) -> None:
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7.5,
                  frameon=False, borderaxespad=0.0, **kw)


# --------------------------------------------------------------------------- FRF

def frf_figure(locations: Mapping[str, Frf], modes: Sequence[Mode], stem: Path, *,
               fine: Mapping[str, Frf] | None = None, title: str = "", units: str = "(mm/s)/V") -> FigureFiles:
    """FRF magnitude (log-log) and phase below, every location on the same axes (Fig. 5/6).

    ``fine`` maps a location to its model on a fine grid (``freq_hz``, ``frf``); a location
    without one gets its stored model at the measured lines, drawn dashed and labelled so.
    """
    fine = fine or {}
    fig = _figure(8.0, 6.2)
    am, ap = fig.subplots(2, 1, sharex=True, height_ratios=[2.2, 1])
    data: FrfData = {"locations": {}, "modes": [mode_label(m) for m in modes]}
    for k, (loc, d) in enumerate(locations.items()):
        c = loc_colour(loc, k)
        f = np.asarray(d.freq_hz, float)
        h = np.asarray(d.frf, complex)
        entry: FrfLines = {"n_lines": int(f.size)}
        fm = fine.get(loc)
        if fm is not None:
            am.loglog(fm.freq_hz, np.abs(fm.frf), "-", color=c, lw=1.1, zorder=2, label=f"{loc}: fit")
            ap.semilogx(wrap_x(fm.freq_hz, fm.frf), wrapped_phase_deg(fm.frf), "-", color=c, lw=0.9,
                        zorder=2)
            entry["fit_grid_points"] = int(np.size(fm.freq_hz))
            entry["fit_min_abs"] = float(np.min(np.abs(fm.frf)))
        elif d.model_frf is not None:
            hm = np.asarray(d.model_frf, complex)
            am.loglog(f, np.abs(hm), "--", color=c, lw=1.0, zorder=2, label=f"{loc}: fit (at the lines only)")
            ap.semilogx(wrap_x(f, hm), wrapped_phase_deg(hm), "--", color=c, lw=0.8, zorder=2)
            entry["fit_grid_points"] = int(f.size)
        am.loglog(f, np.abs(h), "o", ms=3.0, mfc=c, mec="white", mew=0.3, color=c, zorder=3,
                  label=f"{loc}: measured")
        ap.semilogx(f, np.degrees(np.angle(h)), "o", ms=2.2, mfc=c, mec="none", color=c, zorder=3)
        data["locations"][loc] = entry
    if modes:
        mode_marks(am, ap, modes)
    style_frf_axes(am, ap, f"|FRF| ({units})" if units != "1" else "|transmissibility|")
    _legend_outside(am)
    if title:
        fig.suptitle(title, fontsize=10)
    return _save(fig, stem, data)


def stabilisation_figure(stab: Mapping[str, np.ndarray], stem: Path, locations: Mapping[str, Frf] | None = None,
                         title: str = "stabilisation diagram") -> FigureFiles:
    """Poles found at each model order (status codes of labkit.analysis.modal.io: 0 new,
    1 stable frequency, 2 stable frequency and damping), the chosen poles marked, and the
    measured |FRF| per location behind them (right axis), all in one legend."""
    fig = _figure(8.0, 4.4)
    ax = fig.subplots()
    f = np.asarray(stab["freq_hz"], float).ravel()
    order = np.asarray(stab["order"], float).ravel()
    status = np.asarray(stab.get("status", np.zeros_like(f)), int).ravel()
    handles = []
    if locations:
        twin = ax.twinx()
        for k, (loc, d) in enumerate(locations.items()):
            (ln,) = twin.semilogy(d.freq_hz, np.abs(d.frf), "-", lw=0.9, alpha=0.55,
                                  color=loc_colour(loc, k), label=f"|FRF| {loc} (right axis)")
            handles.append(ln)
        twin.set_ylabel("|FRF| measured")
        ax.set_zorder(twin.get_zorder() + 1)
        ax.patch.set_visible(False)
    for code, marker, colour, name in ((0, "x", "0.55", "new pole"), (1, "^", "#e69f00", "stable frequency"),
                                       (2, "o", "#009e73", "stable frequency and damping")):
        sel = status == code
        if sel.any():
            (ln,) = ax.plot(f[sel], order[sel], marker, mfc="none", color=colour, ms=5, label=name)
            handles.append(ln)
    chosen = np.atleast_1d(np.asarray(stab.get("chosen_hz", []), float))
    top = float(order.max()) if order.size else 1.0
    for k, fc in enumerate(chosen):
        ln = ax.axvline(float(fc), color="#c0392b", lw=0.9, ls="--", label="chosen pole" if k == 0 else None)
        if k == 0:
            handles.append(ln)
    if chosen.size:
        (ln,) = ax.plot(chosen, np.full(chosen.size, top + 1), "*", color="#c0392b", ms=9,
                        label="chosen poles (freq.)")
    ax.set_xscale("log")
    log_freq_axis(ax)
    ax.set_ylim(0, top + 2.5)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("model order")
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.12 if locations else 1.01, 1.0),
              fontsize=7.5, frameon=False, borderaxespad=0.0)
    ax.set_title(title, fontsize=10)
    return _save(fig, stem, {"poles": int(f.size), "chosen_hz": chosen.tolist()})


# --------------------------------------------------------------------------- speed

def _pattern_strip(ax: Axes, rows: list[tuple[str, np.ndarray, list[str], bool]]) -> None:
    """One row per source: simulated rows as coloured spans between sweep points, measured
    rows as coloured markers at their frequencies."""
    for r, (_name, freq, labels, spans) in enumerate(rows):
        y = len(rows) - 1 - r
        freq = np.asarray(freq, float)
        if spans and freq.size:
            edges = np.concatenate([[freq[0] - 0.5 * (freq[1] - freq[0]) if freq.size > 1 else freq[0] - 5],
                                    0.5 * (freq[1:] + freq[:-1]),
                                    [freq[-1] + 0.5 * (freq[-1] - freq[-2]) if freq.size > 1 else freq[-1] + 5]])
            for i, lab in enumerate(labels):
                ax.broken_barh([(edges[i], edges[i + 1] - edges[i])], (y - 0.35, 0.7),
                               color=PATTERN_COLOURS.get(lab, "0.8"), lw=0)
        else:
            for fx, lab in zip(freq, labels):
                ax.plot(fx, y, "s", ms=7, color=PATTERN_COLOURS.get(lab, "0.8"), mec="k", mew=0.4)
    ax.set_yticks(range(len(rows)), [r[0] for r in rows][::-1], fontsize=7.5)
    ax.set_ylim(-0.6, len(rows) - 0.4)
    from matplotlib.patches import Patch

    ax.legend(handles=[Patch(color=c, label=p.replace("_", " ")) for p, c in PATTERN_COLOURS.items()],
              loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, frameon=False, borderaxespad=0.0,
              title="leg pattern", title_fontsize=7.5)


def speed_figure(measured: MeasuredSpeeds | None, sims: Sequence[SimCurve], stem: Path,
                 note: str = "") -> FigureFiles:
    """Speed against shaker frequency (Fig. 8): measured points with their intervals, the
    nominal robot as a line, the Monte Carlo 10-90 % band (with its draws count), and the
    leg patterns as a strip below (simulated dominant pattern; measured where known).
    ``note`` (e.g. the nominal robot's RMS error and the band coverage) is written in the plot."""
    rows: list[tuple[str, np.ndarray, list[str], bool]] = []
    for s in sims:
        tag = f" ({s.label})" if len(sims) > 1 else ""
        rows.append((f"simulated{tag}", s.freq_hz, list(s.patterns), True))
    if measured is not None and measured.freq_hz.size:
        pats = list(measured.patterns)
        known = [i for i, p in enumerate(pats) if p in PATTERN_COLOURS]
        if known:
            rows.append(("measured", measured.freq_hz[known], [pats[i] for i in known], False))
    fig = _figure(8.0, 5.4 if rows else 4.4)
    if rows:
        ax, strip = fig.subplots(2, 1, sharex=True, height_ratios=[4, max(1, len(rows)) * 0.6])
    else:
        ax, strip = fig.subplots(), None
    data: SpeedData = {"sims": [], "measured_points": 0}
    xs: list[float] = []
    top = 0.0
    for i, s in enumerate(sims):
        c = SIM_COLOUR if i == 0 else f"C{i + 1}"
        tag = f" ({s.label})" if len(sims) > 1 else ""
        ax.fill_between(s.freq_hz, s.p10_mm_s, s.p90_mm_s, color=c, alpha=0.18, lw=0,
                        label=f"Monte Carlo 10\u201390 % ({s.draws} draws){tag}")
        ax.plot(s.freq_hz, s.nominal_mm_s, "-", color=c, lw=1.6, marker=".", ms=4,
                label=f"simulated, nominal robot{tag}")
        data["sims"].append({"file": s.file, "freq_hz": np.asarray(s.freq_hz).tolist(), "draws": s.draws,
                             "p10_mm_s": np.asarray(s.p10_mm_s).tolist(),
                             "p90_mm_s": np.asarray(s.p90_mm_s).tolist(),
                             "nominal_mm_s": np.asarray(s.nominal_mm_s).tolist(),
                             "patterns": list(s.patterns)})
        xs += [float(np.min(s.freq_hz)), float(np.max(s.freq_hz))]
        top = max(top, float(np.nanmax(s.p90_mm_s)), float(np.nanmax(s.nominal_mm_s)))
    if measured is not None and measured.freq_hz.size:
        m = measured
        amps = np.asarray(m.amp_um, float)
        keys = np.where(np.isfinite(amps), np.round(amps, 0), -1.0)
        for k, (key, marker) in enumerate(zip(np.unique(keys), "osD^v<>")):
            sel = keys == key
            yerr = np.vstack([m.speed_mm_s[sel] - m.lo_mm_s[sel], m.hi_mm_s[sel] - m.speed_mm_s[sel]])
            name = "measured (95 % CI)" + (f", tray {key:g} um" if key >= 0 else "")
            ax.errorbar(m.freq_hz[sel], m.speed_mm_s[sel], yerr=np.clip(yerr, 0, None), fmt=marker,
                        color=(MEAS_COLOUR, "#8e44ad", "#16a085", "#7f8c8d")[k % 4], ms=5, capsize=3,
                        zorder=4, label=name)
        data["measured_points"] = int(m.freq_hz.size)
        data["measured_freq_hz"] = np.asarray(m.freq_hz, float).tolist()
        data["measured_mm_s"] = np.asarray(m.speed_mm_s, float).tolist()
        xs += [float(np.min(m.freq_hz)), float(np.max(m.freq_hz))]
        top = max(top, float(np.nanmax(np.fmax(m.hi_mm_s, m.speed_mm_s))))
    if xs:
        lo, hi = min(xs), max(xs)
        pad = 0.04 * (hi - lo) if hi > lo else 0.1 * abs(lo) + 1.0
        ax.set_xlim(lo - pad, hi + pad)
    ax.set_ylabel("speed (mm/s)")
    ax.set_ylim(0, (top if np.isfinite(top) and top > 0 else 1.0) * (1.25 if note else 1.08))
    ax.grid(True, alpha=0.3)
    if note:
        ax.text(0.01, 0.98, note, transform=ax.transAxes, fontsize=7.5, va="top", ha="left",
                bbox={"boxstyle": "round,pad=0.3", "fc": "white", "ec": "0.75", "alpha": 0.9})
    _legend_outside(ax)
    if strip is not None:
        _pattern_strip(strip, rows)
        strip.set_xlabel("shaker frequency (Hz)")
        strip.grid(True, axis="x", alpha=0.3)
    else:
        ax.set_xlabel("shaker frequency (Hz)")
    ax.set_title("robot speed against shaker frequency", fontsize=10)
    data["pattern_rows"] = [r[0] for r in rows]
    return _save(fig, stem, data)


# --------------------------------------------------------------------------- knee motion

def tray_aligned_window(t_s: np.ndarray, x: np.ndarray, tray: np.ndarray | None, freq_hz: float,
                        periods: float, *, settled_end: bool) -> tuple[np.ndarray, np.ndarray, float]:
    """A window of ``periods`` drive periods, on a time axis whose zero is the tray's phase zero.

    The tray's drive-frequency component is ``A sin(2 pi f t')`` on the returned axis ``t'``,
    so a measured and a simulated record, each aligned to its own tray, share one time axis
    whatever their start times (without a tray record, ``t = 0`` is taken as phase zero, as
    :func:`labkit.analysis.compare.knee_motion_agreement` does). The window starts on a whole
    period: the first one in the record, or with ``settled_end`` the last ones.
    Returns ``(t_window_s, x_window, shift_s)``.
    """
    from labkit.sim.knee_patterns import fundamental

    t = np.asarray(t_s, float)
    period = 1.0 / freq_hz
    phi = fundamental(t, tray, freq_hz)["phase_rad"] if tray is not None else 0.0
    tp = t + phi / (2 * np.pi * freq_hz)
    span = periods * period
    if settled_end:
        k0 = math.floor((tp[-1] - span) / period) * period
        k0 = max(k0, math.ceil(tp[0] / period) * period)
    else:
        k0 = math.ceil(tp[0] / period) * period
    sel = (tp >= k0) & (tp <= k0 + span)
    return tp[sel] - k0, np.asarray(x)[sel], float(phi / (2 * np.pi * freq_hz) - k0)


def _drawn_phase_deg(t_s: np.ndarray, x: np.ndarray, freq_hz: float) -> float | None:
    """Phase (deg) of the drive-frequency component of a trace as drawn (on the drawn time axis)."""
    from labkit.sim.knee_patterns import fundamental

    if np.size(t_s) < 4:
        return None
    return float(np.degrees(fundamental(np.asarray(t_s), np.asarray(x), freq_hz)["phase_rad"]))


def knee_figure(cases: Sequence[KneeCase], stem: Path, periods: float = 4.0, ncols: int = 3) -> FigureFiles:
    """Small multiples, one panel per drive: the knee's vertical velocity measured and simulated
    overlaid on one tray-aligned time axis, the tray's velocity behind them, and the simulated
    contact modes of the six feet as a timeline below (Fig. 10/11). One legend for all panels."""
    from matplotlib.colors import ListedColormap
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch
    from matplotlib.ticker import MaxNLocator

    n = len(cases)
    ncols = max(1, min(ncols, n))
    nrows = math.ceil(n / ncols)
    fig = _figure(max(3.8 * ncols + 0.4, 5.6), 3.1 * nrows + 0.9)
    grid = fig.subfigures(nrows, ncols, wspace=0.02, hspace=0.03, squeeze=False)
    subs = list(np.asarray(grid, dtype=object).ravel())
    cmap = ListedColormap(CONTACT_COLOURS)
    data: KneeData = {"drives": []}
    for k, sub in enumerate(subs):
        if k >= n:
            sub.set_facecolor("none")
            continue
        case = cases[k]
        f = float(case.freq_hz)
        ax, tl = sub.subplots(2, 1, sharex=True, height_ratios=[3, 1])
        meas, sim = case.measured, case.simulated
        drawn: DriveDrawn = {"freq_hz": f, "tray_amp_um": case.tray_amp_um, "measured": meas is not None,
                 "simulated": sim is not None}
        if meas is not None:
            tray = meas.tray_vz_mm_s
            tm, xm, _ = tray_aligned_window(meas.t_s, meas.knee_vz_mm_s, tray, f, periods, settled_end=False)
            ax.plot(1e3 * tm, xm, "-", color=MEAS_COLOUR, lw=1.3, zorder=3)
            drawn["measured_phase_deg"] = _drawn_phase_deg(tm, xm, f)
            if tray is not None:
                tt, xt, _ = tray_aligned_window(meas.t_s, tray, tray, f, periods, settled_end=False)
                ax.plot(1e3 * tt, xt, "-", color="0.6", lw=0.8, zorder=1)
        if sim is not None:
            ts, xs, shift = tray_aligned_window(sim.t_s, sim.knee_vz_mm_s, sim.tray_vz_mm_s, f, periods,
                                                settled_end=True)
            ax.plot(1e3 * ts, xs, "--", color=SIM_COLOUR, lw=1.3, zorder=4)
            drawn["simulated_phase_deg"] = _drawn_phase_deg(ts, xs, f)
            if meas is None or meas.tray_vz_mm_s is None:
                tt, xt, _ = tray_aligned_window(sim.t_s, sim.tray_vz_mm_s, sim.tray_vz_mm_s, f, periods,
                                                settled_end=True)
                ax.plot(1e3 * tt, xt, "-", color="0.6", lw=0.8, zorder=1)
            t_all = np.asarray(sim.t_s, float) + shift
            sel = (t_all >= 0) & (t_all <= periods / f)
            contact = np.asarray(sim.contact)[sel]
            if contact.size:
                if contact.ndim == 1:
                    contact = contact[:, None]
                tl.imshow(contact.T, aspect="auto", interpolation="nearest", cmap=cmap, vmin=-0.5, vmax=2.5,
                          extent=(1e3 * t_all[sel][0], 1e3 * t_all[sel][-1], contact.shape[1] + 0.5, 0.5))
                tl.set_yticks([1, contact.shape[1]])
        else:
            tl.text(0.5, 0.5, "no simulation", ha="center", va="center", fontsize=7, transform=tl.transAxes)
            tl.set_yticks([])
        if meas is None:
            ax.text(0.02, 0.96, "no measured record", fontsize=7, va="top", transform=ax.transAxes)
        ax.set_xlim(0, 1e3 * periods / f)
        ax.grid(True, alpha=0.3)
        # few, large tick labels: the panels are read on a projector too
        ax.yaxis.set_major_locator(MaxNLocator(4))
        tl.xaxis.set_major_locator(MaxNLocator(4))
        ax.tick_params(labelsize=9)
        tl.tick_params(labelsize=9)
        tl.set_ylabel("foot", fontsize=9)
        tl.set_xlabel("time from tray phase 0 (ms)", fontsize=9)
        ax.set_ylabel("v_z (mm/s)", fontsize=9)
        pm = case.measured_pattern if meas is not None else "-"
        ps = sim.knee_pattern if sim is not None else "-"
        ax.set_title(f"{f:.4g} Hz, tray {case.tray_amp_um:.3g} um\n"
                     f"meas. {pm.replace('_', ' ')} | sim. {ps.replace('_', ' ')}", fontsize=8.5)
        data["drives"].append(drawn)
    handles: list[Artist] = [Line2D([], [], color=MEAS_COLOUR, lw=1.3, label="knee, measured"),
                             Line2D([], [], color=SIM_COLOUR, lw=1.3, ls="--", label="knee, simulated"),
                             Line2D([], [], color="0.6", lw=0.8, label="tray")]
    handles += [Patch(color=c, label=f"contact: {nm}") for c, nm in zip(CONTACT_COLOURS, CONTACT_NAMES)]
    fig.legend(handles=handles, loc="outside upper center", ncol=6 if ncols >= 2 else 3, fontsize=8,
               frameon=False)
    return _save(fig, stem, data)


# --------------------------------------------------------------------------- tracks and video

def tracks_figure(paths: Sequence[TrackPath], labels: Sequence[str], stem: Path) -> FigureFiles:
    """Tracked paths side by side: each drawn from its own start (displacement in mm), the paths
    spread along x so that none hides another, each labelled at its start with its speed."""
    fig = _figure(7.0, 5.0)
    ax = fig.subplots()
    spans = [float(np.nanmax(np.abs(p.x_mm - p.x_mm[0]))) if np.size(p.x_mm) else 0.0 for p in paths]
    step = max(2.0 * max(spans, default=0.0) + 1.0, 2.0)
    for k, (p, label) in enumerate(zip(paths, labels)):
        c = f"C{k % 10}"
        x, y = p.x_mm - p.x_mm[0] + k * step, p.y_mm - p.y_mm[0]
        ax.plot(x, y, "-", color=c, lw=1.3)
        ax.plot(x[0], y[0], "o", color=c, ms=5)
        ax.plot(x[-1], y[-1], ">", color=c, ms=5)
        ax.annotate(label, (x[-1], y[-1]), textcoords="offset points", xytext=(0, 6), rotation=90,
                    ha="center", va="bottom", fontsize=8, color=c)
    ax.margins(y=0.35)
    ax.set_xticks([k * step for k in range(len(paths))], [str(k + 1) for k in range(len(paths))])
    ax.set_xlabel("track (each drawn from its own start, side by side)")
    ax.set_ylabel("displacement along y (mm)")
    ax.grid(True, axis="y", alpha=0.3)
    ax.set_title("tracked paths (o start, > end)", fontsize=10)
    return _save(fig, stem, {"tracks": list(labels), "spacing_mm": step})


def frame_figure(frame: np.ndarray, u_px: np.ndarray, v_px: np.ndarray, stem: Path, title: str) -> FigureFiles:
    """A video frame with the track drawn on it, in pixels (image coordinates)."""
    h, w = frame.shape[:2]
    fig = _figure(6.4, 6.4 * h / w + 0.5)
    ax = fig.subplots()
    ax.imshow(frame, cmap="gray", interpolation="nearest", vmin=0, vmax=255)
    ax.plot(u_px, v_px, "-", color="#ff3b30", lw=1.4, label="track")
    ax.plot(u_px[-1], v_px[-1], "o", mfc="none", mec="#ffd60a", ms=10, mew=1.5, label="position in this frame")
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    ax.legend(loc="lower right", fontsize=7.5)
    ax.set_title(title, fontsize=9)
    return _save(fig, stem, {"frame_size_px": [w, h], "points": int(np.size(u_px))})

