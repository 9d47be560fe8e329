"""Figures of a modal fit: FRF magnitude and phase with the fitted model, the stabilisation diagram.

Uses ``matplotlib.figure.Figure`` with the Agg canvas directly, so no global
backend is chosen and nothing needs a display.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["plot_frf_fit", "plot_stabilisation"]


def _figure(w_in: float, h_in: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w_in, h_in), dpi=110)
    FigureCanvasAgg(fig)
    return fig


def plot_frf_fit(fit: Any, path: str | Path, *, title: str = "", units: str = "") -> Path:
    """Magnitude (log) and phase per location: measured points, fitted model, mode markers."""
    n = len(fit.locations)
    fig = _figure(4.2 * n + 0.6, 6.0)
    axes = fig.subplots(2, n, sharex="col", squeeze=False)
    for k, loc in enumerate(fit.locations):
        f, H = fit.freq_hz[k], fit.frf[k]
        logx = f.max() / f.min() > 5
        fm = (np.geomspace if logx else np.linspace)(f.min(), f.max(), max(2000, 4 * f.size))
        Hm = fit.model(fm, k)
        am, ap = axes[0, k], axes[1, k]
        am.semilogy(f, np.abs(H), ".", ms=2.5, color="0.45", label="measured")
        am.semilogy(fm, np.abs(Hm), "-", lw=1.2, color="C3", label=f"fit ({fit.method})")
        ap.plot(f, np.degrees(np.angle(H)), ".", ms=2.5, color="0.45")
        ap.plot(fm, np.degrees(np.angle(Hm)), "-", lw=1.2, color="C3")
        for i, m in enumerate(fit.modes):
            for ax in (am, ap):
                ax.axvline(m.freq_hz, color="C0", lw=0.6, ls=":")
            am.annotate(f"{m.freq_hz:.4g} Hz\nzeta {m.damping_ratio:.3g}", (m.freq_hz, 1.0 - 0.1 * (i % 3)),
                        xycoords=("data", "axes fraction"), xytext=(2, -2), textcoords="offset points",
                        fontsize=6.5, va="top", color="C0")
        am.set_title(f"{loc}  (nrmse {fit.nrmse.get(loc, float('nan')):.3g})", fontsize=9)
        am.set_ylabel(f"|H| {units}".strip(), fontsize=8)
        ap.set_ylabel("phase (deg)", fontsize=8)
        ap.set_xlabel("frequency (Hz)", fontsize=8)
        ap.set_ylim(-190, 190)
        if logx:
            ap.set_xscale("log")
        ap.set_yticks([-180, -90, 0, 90, 180])
        for ax in (am, ap):
            ax.tick_params(which="both", labelsize=7)
            ax.grid(True, lw=0.3, alpha=0.5)
        if k == 0:
            am.legend(fontsize=7, loc="lower left")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    return path


def plot_stabilisation(stab: Any, path: str | Path, *, fit: Any = None, title: str = "") -> Path:
    """Stabilisation diagram: poles per model order, marked by stability, over the FRFs' magnitude."""
    fig = _figure(7.5, 4.5)
    ax = fig.subplots()
    styles = {0: ("x", "0.6", "new"), 1: ("o", "C1", "stable frequency"),
              2: ("o", "C2", "stable frequency + damping")}
    for st, (mk, col, lab) in styles.items():
        sel = stab.status == st
        if mk == "o":
            ax.scatter(stab.freq_hz[sel], stab.order[sel], marker=mk, s=12, facecolors="none",
                       edgecolors=col, lw=0.8, label=lab)
        else:
            ax.scatter(stab.freq_hz[sel], stab.order[sel], marker=mk, s=8, color=col, lw=0.8, label=lab)
    for f0 in np.atleast_1d(stab.chosen_hz):
        ax.axvline(f0, color="C3", lw=0.8, ls="--")
    ax.set_xlabel("frequency (Hz)", fontsize=8)
    ax.set_ylabel("model order", fontsize=8)
    ax.tick_params(labelsize=7)
    if fit is not None:
        ax2 = ax.twinx()
        for k, loc in enumerate(fit.locations):
            ax2.semilogy(fit.freq_hz[k], np.abs(fit.frf[k]), lw=0.7, alpha=0.6, label=f"|H| {loc}")
        ax2.set_ylabel("|H|", fontsize=8)
        ax2.tick_params(labelsize=7)
        ax2.legend(fontsize=6.5, loc="upper right")
    ax.legend(fontsize=6.5, loc="upper left")
    ax.set_title(title or "stabilisation diagram (dashed: chosen poles)", fontsize=9)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    return path
