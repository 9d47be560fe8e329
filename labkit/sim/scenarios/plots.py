"""Figures of the scenarios: speed curves with Monte Carlo spread, foot traces."""
from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from labkit.sim.result import SimResult

#: A figure-drawing function: gets an empty matplotlib Figure and fills it.
Plot = Callable[[Any], None]


def save_figure(plot: Plot, path: Path, size_in: tuple[float, float] = (7.0, 4.6)) -> Path:
    """Draw ``plot`` on a new Agg figure and write it as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=size_in, dpi=100)
    try:
        plot(fig)
        fig.savefig(path, dpi=100)
    finally:
        plt.close(fig)
    return path


def curve_axes(ax: Any, s: Any, label: str = "", color: str = "k") -> None:
    """One speed curve on an axis: every draw in grey, mean +- 1 sd, the nominal robot dashed.

    ``s`` has ``values``, ``speeds_mm_s`` (points x draws), ``mean_speed_mm_s``,
    ``std_speed_mm_s``, ``nominal_speed_mm_s`` and ``draws`` (a SweepResult or a PointSet).
    """
    x = s.values
    for d in range(1, s.draws):
        ax.plot(x, s.speeds_mm_s[:, d], color="0.85", lw=0.6, zorder=1)
    pre = f"{label}: " if label else ""
    ax.errorbar(x, s.mean_speed_mm_s, yerr=s.std_speed_mm_s, fmt="o-", ms=3, lw=1.2, capsize=2,
                color=color, label=f"{pre}mean +- 1 sd, {s.draws} draw(s)", zorder=3)
    ax.plot(x, s.nominal_speed_mm_s, "--", color=color, lw=0.8, alpha=0.7, zorder=2, label=f"{pre}nominal robot")


def sweep_plot(s: Any, xlabel: str, title: str, marks: Sequence[tuple[float, float, str]] = (),
               xscale: str = "linear", others: Sequence[tuple[Any, str]] = (), label: str = "") -> Plot:
    """Mean +- 1 sd over draws (and the nominal robot, and every draw in grey) of one or more curves."""
    def plot(fig: Any) -> None:
        ax = fig.add_subplot(111)
        series = [(s, label, "k")] + [(o, lab, c) for (o, lab), c in zip(others, ("tab:blue", "tab:green"))]
        for sw, lab, color in series:
            curve_axes(ax, sw, lab, color)
        for lo, hi, text in marks:
            ax.axvspan(lo, hi, color="tab:blue", alpha=0.08)
            ax.text((lo + hi) / 2, 0.97, text, transform=ax.get_xaxis_transform(), ha="center", va="top",
                    fontsize=7, color="tab:blue")
        ax.set_xscale(xscale)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("mean forward speed (mm/s)")
        ax.set_title(title, fontsize=9)
        ax.axhline(0, color="0.5", lw=0.5)
        ax.legend(fontsize=6, loc="upper right")
        fig.tight_layout()
    return plot


def trace_axes(ax: Any, label: str, r: SimResult, freq_hz: float, foot: int = 0, cycles: int = 6,
               legend: bool = False) -> None:
    """Foot height and tray height over the last ``cycles`` periods, with a contact-mode strip."""
    t = np.asarray(r.t_s)
    m = t >= t[-1] - cycles / freq_hz
    tm = (t[m] - t[m][0]) * 1e3
    ax.plot(tm, np.asarray(r.foot_z_um)[m, foot], "k", lw=0.9, label=f"foot {foot + 1}")
    ax.plot(tm, np.asarray(r.ground_z_um)[m], "--", color="tab:red", lw=0.8, label="tray")
    mode = np.asarray(r.contact)[m, foot]
    for code, color in ((0, "tab:blue"), (1, "tab:orange"), (2, "tab:green")):
        ax.fill_between(tm, 0, 0.06, where=mode == code, color=color, lw=0, transform=ax.get_xaxis_transform(),
                        step="mid", label=("air", "adhesion", "rest")[code] if legend else None)
    ax.set_title(f"{label}: {r.patterns[foot]} (air {np.mean(mode == 0):.0%})", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.set_ylabel("z (um)", fontsize=7)
    if legend:
        ax.legend(fontsize=5, loc="upper right", ncol=2)


def trace_plot(runs: Sequence[tuple[str, SimResult]], freq_hz: float, foot: int = 0, cycles: int = 6,
               extra: Callable[[Any, Any], None] | None = None) -> Plot:
    """Foot height and tray height over the last ``cycles`` periods, one panel per run."""
    def plot(fig: Any) -> None:
        n = len(runs) + (1 if extra else 0)
        cols = 2 if n > 3 else 1
        if extra and n % 2 == 0 and cols == 2:
            n += 1  # keep the map in its own row
        rows = int(np.ceil(n / cols))
        for i, (label, r) in enumerate(runs):
            ax = fig.add_subplot(rows, cols, i + 1)
            trace_axes(ax, label, r, freq_hz, foot, cycles, legend=i == 0)
            if i >= len(runs) - cols:
                ax.set_xlabel("t (ms)", fontsize=7)
        if extra:
            extra(fig, fig.add_subplot(rows, 1, rows) if cols == 2 else fig.add_subplot(rows, cols, n))
        fig.tight_layout()
    return plot
