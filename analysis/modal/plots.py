"""Figures of a modal fit: FRF magnitude and phase with the fitted model, the stabilisation diagram.

The conventions are the report's (:mod:`labkit.analysis.plotting`): magnitude on log-log axes
with the phase below (broken where it wraps), measured lines as markers in one colour per
location, the fitted model as a line on a fine grid (so an anti-resonance between measured lines
is drawn as the model has it), plain-number log frequency ticks, modes labelled with frequency
and damping +- their uncertainty in the margin above the axes, PNG at
:data:`~labkit.analysis.plotting.PNG_DPI`.

Each ``*_figure`` function returns the ``matplotlib.figure.Figure`` (Agg canvas attached, no
pyplot state, no display needed); each ``plot_*`` function also saves it as PNG to the path
given (``labkit fit`` hands a temporary name of its all-or-nothing output set) and returns the
figure.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from labkit.analysis.plotting import (
    PNG_DPI,
    loc_colour,
    log_freq_axis,
    mode_marks,
    style_frf_axes,
    wrap_x,
    wrapped_phase_deg,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["FINE_POINTS", "fine_grid", "frf_fit_figure", "plot_frf_fit", "stabilisation_figure",
           "plot_stabilisation"]

#: Least number of points of the fine grid the model is drawn on.
FINE_POINTS = 2000
#: Locations named in the legend at most (a scan's other locations are drawn, not listed).
LEGEND_LOCATIONS = 8


def _figure(w_in: float, h_in: float) -> Figure:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w_in, h_in), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: str | Path) -> None:
    fig.savefig(Path(path), dpi=PNG_DPI, format="png")


def fine_grid(freq_hz: np.ndarray, n: int = FINE_POINTS) -> np.ndarray:
    """Log-spaced frequencies over the measured band: at least ``n`` points and 4 per measured line."""
    f = np.asarray(freq_hz, float)
    return np.geomspace(f.min(), f.max(), max(n, 4 * f.size))


def _loc_colours(locations: list[str]) -> list[Any]:
    if len(locations) <= 7:
        return [loc_colour(loc, k) for k, loc in enumerate(locations)]
    from matplotlib import colormaps

    return [colormaps["viridis"](x) for x in np.linspace(0.0, 0.9, len(locations))]


def _legend_outside(ax: Any, handles: list[Any]) -> None:
    if handles:
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7,
                  frameon=False, borderaxespad=0.0)


def frf_fit_figure(fit: Any, *, title: str = "", units: str = "") -> Figure:
    """Magnitude (log-log) and phase below, every location on the same axes.

    Measured lines: markers, one colour per location (gid ``measured:<loc>``); the model
    ``fit.model`` on :func:`fine_grid` over each location's lines: a line in the same colour
    (gid ``fit:<loc>``; its phase ``fit-phase:<loc>``, NaN where it wraps); dotted lines at the
    modes and their labels (``n: f ± sf Hz, ζ z ± sz``) above the magnitude axes.
    """
    fig = _figure(8.0, 6.4)
    am, ap = fig.subplots(2, 1, sharex=True, height_ratios=[2.2, 1])
    colours = _loc_colours(list(fit.locations))
    handles: list[Any] = []
    for k, loc in enumerate(fit.locations):
        c = colours[k]
        f, h = np.asarray(fit.freq_hz[k], float), np.asarray(fit.frf[k], complex)
        fm = fine_grid(f)
        hm = np.asarray(fit.model(fm, k), complex)
        named = k < LEGEND_LOCATIONS
        (fl,) = am.loglog(fm, np.abs(hm), "-", color=c, lw=1.1, zorder=2, gid=f"fit:{loc}",
                          label=f"{loc}: fit ({fit.method})")
        ap.semilogx(wrap_x(fm, hm), wrapped_phase_deg(hm), "-", color=c, lw=0.9, zorder=2, gid=f"fit-phase:{loc}")
        nrmse = fit.nrmse.get(loc, float("nan"))
        (ml,) = am.loglog(f, np.abs(h), "o", ms=3.0, mfc=c, mec="white", mew=0.3, color=c, zorder=3,
                          gid=f"measured:{loc}", label=f"{loc}: measured (nrmse {nrmse:.2g})")
        ap.semilogx(f, np.degrees(np.angle(h)), "o", ms=2.2, mfc=c, mec="none", color=c, zorder=3,
                    gid=f"measured-phase:{loc}")
        if named:
            handles += [ml, fl]
    if len(fit.locations) > LEGEND_LOCATIONS:
        from matplotlib.lines import Line2D

        handles.append(Line2D([], [], ls="none", label=f"... {len(fit.locations) - LEGEND_LOCATIONS} more locations"))
    if fit.modes:
        mode_marks(am, ap, fit.modes)
    style_frf_axes(am, ap, f"|H| ({units})" if units and units != "1" else "|H|")
    _legend_outside(am, handles)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def plot_frf_fit(fit: Any, path: str | Path, *, title: str = "", units: str = "") -> Figure:
    """:func:`frf_fit_figure`, saved as PNG at ``path``."""
    fig = frf_fit_figure(fit, title=title, units=units)
    _save(fig, path)
    return fig


#: Stabilisation status code -> (marker, colour, legend text), as in the report.
STATUS_STYLE = {0: ("x", "0.55", "new pole"), 1: ("^", "#e69f00", "stable frequency"),
                2: ("o", "#009e73", "stable frequency and damping")}
CHOSEN_COLOUR = "#c0392b"


def stabilisation_figure(stab: Any, *, fit: Any = None, title: str = "stabilisation diagram") -> Figure:
    """Poles per model order marked by stability, the chosen poles marked (dashed line and a star
    above the highest order, gid ``chosen``), the measured |H| per location behind them (right
    axis, location colours), all in one legend."""
    fig = _figure(8.0, 4.6)
    ax = fig.subplots()
    f = np.asarray(stab.freq_hz, float).ravel()
    order = np.asarray(stab.order, float).ravel()
    status = np.asarray(stab.status, int).ravel()
    handles: list[Any] = []
    if fit is not None:
        twin = ax.twinx()
        colours = _loc_colours(list(fit.locations))
        for k, loc in enumerate(fit.locations):
            (ln,) = twin.semilogy(fit.freq_hz[k], np.abs(fit.frf[k]), "-", lw=0.9, alpha=0.55, color=colours[k],
                                  label=f"|H| {loc} (right axis)")
            if k < LEGEND_LOCATIONS:
                handles.append(ln)
        twin.set_ylabel("|H| measured")
        ax.set_zorder(twin.get_zorder() + 1)
        ax.patch.set_visible(False)
    for code, (marker, colour, name) in STATUS_STYLE.items():
        sel = status == code
        if sel.any():
            (ln,) = ax.plot(f[sel], order[sel], marker, mfc="none", color=colour, ms=4.5, ls="none",
                            label=name, gid=f"status:{code}")
            handles.append(ln)
    chosen = np.atleast_1d(np.asarray(stab.chosen_hz, float))
    top = float(order.max()) if order.size else 1.0
    for fc in chosen:
        ax.axvline(float(fc), color=CHOSEN_COLOUR, lw=0.9, ls="--", zorder=1)
    if chosen.size:
        (ln,) = ax.plot(chosen, np.full(chosen.size, top + 1), "*", color=CHOSEN_COLOUR, ms=9, ls="none",
                        gid="chosen", label=f"chosen poles ({chosen.size}, dashed)")
        handles.append(ln)
    log_freq_axis(ax)
    ax.set_ylim(0, top + 2.5)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("model order")
    ax.grid(True, which="major", alpha=0.25)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.12 if fit is not None else 1.01, 1.0),
              fontsize=7, frameon=False, borderaxespad=0.0)
    ax.set_title(title, fontsize=10)
    return fig


def plot_stabilisation(stab: Any, path: str | Path, *, fit: Any = None, title: str = "stabilisation diagram") -> Figure:
    """:func:`stabilisation_figure`, saved as PNG at ``path``."""
    fig = stabilisation_figure(stab, fit=fit, title=title)
    _save(fig, path)
    return fig
