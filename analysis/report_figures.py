"""The report's figures (matplotlib, Agg, object API: no pyplot state, safe in any process).

Each function takes plain dicts/arrays from :mod:`analysis.report_inputs`
and writes one PNG, returning its path. Figure numbers follow the paper
(Qu, Choi, Oldham 2017): FRFs Fig. 5/6, speed Fig. 8, knee motion Fig. 10/11.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

#: Contact-mode codes of SimResult.contact and their colours in timelines.
CONTACT_NAMES = ("air", "adhesion", "rest")
CONTACT_COLOURS = ("#f4f4f4", "#d95f02", "#1b9e77")
LOC_COLOURS = {"body": "#e7298a", "hip": "#1f78b4", "knee": "#222222"}


def _figure(w: float, h: float):
    from matplotlib.figure import Figure

    return Figure(figsize=(w, h), dpi=100, layout="constrained")


def _save(fig: Any, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    return path


def frf_figure(locations: dict[str, dict[str, Any]], modes: list[dict[str, Any]], path: Path,
               title: str = "", units: str = "(mm/s)/V") -> Path:
    """Magnitude and phase of the measured FRF per location, with the fitted model (Fig. 5/6)."""
    locs = [loc for loc in ("body", "hip", "knee") if loc in locations] + \
           [loc for loc in locations if loc not in ("body", "hip", "knee")]
    fig = _figure(4.0 * max(1, len(locs)), 5.2)
    axes = fig.subplots(2, max(1, len(locs)), squeeze=False, sharex="col")
    for col, loc in enumerate(locs):
        d = locations[loc]
        f = np.asarray(d["freq_hz"], float)
        h = np.asarray(d["frf"], complex)
        am, ap = axes[0, col], axes[1, col]
        colour = LOC_COLOURS.get(loc, "C0")
        am.semilogy(f, np.abs(h), ".", ms=3, color=colour, label="measured")
        ap.plot(f, np.degrees(np.angle(h)), ".", ms=3, color=colour)
        if d.get("model_frf") is not None:
            fm = np.asarray(d.get("model_freq_hz", f), float)
            hm = np.asarray(d["model_frf"], complex)
            am.semilogy(fm, np.abs(hm), "-", color="C3", lw=1.4, label="fitted model")
            ap.plot(fm, np.degrees(np.angle(hm)), "-", color="C3", lw=1.2)
        for m in modes:
            for ax in (am, ap):
                ax.axvline(m["freq_hz"], color="0.6", lw=0.7, ls=":")
        am.set_title(f"{loc}")
        am.set_ylabel(f"|FRF| ({units})" if units != "1" else "|transmissibility|")
        ap.set_ylabel("phase (deg)")
        ap.set_xlabel("frequency (Hz)")
        am.legend(fontsize=8)
        am.grid(True, which="both", alpha=0.3)
        ap.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def stabilisation_figure(stab: dict[str, np.ndarray], path: Path, locations: dict[str, Any] | None = None,
                         title: str = "stabilisation diagram") -> Path:
    """Poles found at each model order against frequency (status codes of analysis.modal_io:
    0 new, 1 stable frequency, 2 stable frequency and damping), with the chosen modes."""
    fig = _figure(7.5, 4.2)
    ax = fig.subplots()
    f = np.asarray(stab["freq_hz"], float).ravel()
    order = np.asarray(stab["order"], float).ravel()
    status = np.asarray(stab.get("status", np.zeros_like(f)), int).ravel()
    for code, marker, colour, name in ((0, "x", "0.6", "new pole"), (1, "^", "C1", "stable frequency"),
                                       (2, "o", "C2", "stable frequency and damping")):
        sel = status == code
        if sel.any():
            ax.plot(f[sel], order[sel], marker, mfc="none", color=colour, ms=5, label=name)
    for k, fc in enumerate(np.atleast_1d(stab.get("chosen_hz", []))):
        ax.axvline(float(fc), color="C3", lw=0.8, ls="--", label="chosen" if k == 0 else None)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("model order")
    ax.grid(True, alpha=0.3)
    if locations:
        twin = ax.twinx()
        for loc, d in locations.items():
            twin.semilogy(d["freq_hz"], np.abs(d["frf"]), "-", lw=0.8, alpha=0.5,
                          color=LOC_COLOURS.get(loc, "C0"))
        twin.set_ylabel("|FRF| (measured, per location)")
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title(title)
    return _save(fig, path)


def speed_figure(measured: dict[str, Any] | None, sims: list[dict[str, Any]], path: Path) -> Path:
    """Speed against shaker frequency: measured with CI, simulated with Monte Carlo band (Fig. 8)."""
    fig = _figure(7.5, 4.5)
    ax = fig.subplots()
    for i, s in enumerate(sims):
        c = f"C{i}"
        ax.fill_between(s["freq_hz"], s["lo_mm_s"], s["hi_mm_s"], color=c, alpha=0.2,
                        label=f"simulated band ({s['label']})")
        ax.plot(s["freq_hz"], s["mean_mm_s"], "--", color=c, lw=1.5, label=f"simulated mean ({s['label']})")
        if "nominal_mm_s" in s:
            ax.plot(s["freq_hz"], s["nominal_mm_s"], ":", color=c, lw=1.2, marker=".",
                    label=f"nominal robot ({s['label']})")
    if measured is not None and measured["freq_hz"].size:
        m = measured
        amps = np.asarray(m.get("amp_um", np.full(m["freq_hz"].size, np.nan)), float)
        keys = np.where(np.isfinite(amps), np.round(amps, 0), -1.0)
        for k, (key, marker) in enumerate(zip(np.unique(keys), "osD^v<>")):
            sel = keys == key
            yerr = np.vstack([m["speed_mm_s"][sel] - m["lo_mm_s"][sel], m["hi_mm_s"][sel] - m["speed_mm_s"][sel]])
            name = "measured (CI)" + (f", {key:g} um" if key >= 0 else "")
            ax.errorbar(m["freq_hz"][sel], m["speed_mm_s"][sel], yerr=np.clip(yerr, 0, None), fmt=marker,
                        color=("C3", "C4", "C5", "C6", "C7", "C8", "C9")[k % 7], ms=4, capsize=3, label=name)
    ax.set_xlabel("shaker frequency (Hz)")
    ax.set_ylabel("speed (mm/s)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("robot speed against shaker frequency")
    return _save(fig, path)


def knee_figure(case: dict[str, Any], path: Path, periods: float = 6.0) -> Path:
    """Knee vertical velocity measured (top) and simulated (middle) with the tray, and the
    simulated contact-mode timeline of every foot (bottom) at one drive (Fig. 10/11)."""
    fig = _figure(7.5, 6.4)
    axes = fig.subplots(3, 1, height_ratios=[2, 2, 1.3])
    f = case["freq_hz"]
    span = periods / f
    meas, sim = case.get("measured"), case.get("simulated")
    if meas is not None:
        t = meas["t_s"] - meas["t_s"][0]
        sel = t <= span
        axes[0].plot(1e3 * t[sel], meas["knee_vz_mm_s"][sel], "--", color="C3", lw=1.2, label="knee (measured)")
        if meas.get("tray_vz_mm_s") is not None:
            axes[0].plot(1e3 * t[sel], meas["tray_vz_mm_s"][sel], "-", color="k", lw=1, label="tray")
        axes[0].set_title(f"measured: {meas.get('pattern', '?')}  ({meas['file']})", fontsize=9)
    else:
        axes[0].text(0.5, 0.5, "no measured knee record at this drive", ha="center", va="center",
                     transform=axes[0].transAxes)
    if sim is not None:
        t = sim["t_s"]
        t0 = t[-1] - span if t[-1] > span else t[0]     # the settled end of the run
        sel = t >= t0
        axes[1].plot(1e3 * (t[sel] - t0), sim["knee_vz_mm_s"][sel], "--", color="C0", lw=1.2,
                     label="knee (simulated)")
        axes[1].plot(1e3 * (t[sel] - t0), sim["tray_vz_mm_s"][sel], "-", color="k", lw=1, label="tray")
        axes[1].set_title(f"simulated: {sim.get('pattern', '?')}", fontsize=9)
        contact = np.asarray(sim["contact"])[sel]
        from matplotlib.colors import ListedColormap

        axes[2].imshow(contact.T, aspect="auto", interpolation="nearest", cmap=ListedColormap(CONTACT_COLOURS),
                       vmin=-0.5, vmax=2.5, extent=(0, 1e3 * (t[sel][-1] - t0), 6.5, 0.5))
        axes[2].set_yticks(range(1, 7))
        axes[2].set_ylabel("foot")
        handles = [__import__("matplotlib.patches", fromlist=["Patch"]).Patch(color=c, label=n)
                   for c, n in zip(CONTACT_COLOURS, CONTACT_NAMES)]
        axes[2].legend(handles=handles, fontsize=7, ncol=3, loc="upper right")
    else:
        axes[1].text(0.5, 0.5, "no simulation at this drive", ha="center", va="center",
                     transform=axes[1].transAxes)
        axes[2].set_axis_off()
    for ax in axes[:2]:
        ax.set_ylabel("v_z (mm/s)")
        ax.grid(True, alpha=0.3)
        if ax.lines:
            ax.legend(fontsize=7, loc="upper right")
    axes[2].set_xlabel("time (ms)")
    fig.suptitle(f"knee vertical motion at {f:.4g} Hz, tray {case.get('tray_amp_um', float('nan')):.3g} um")
    return _save(fig, path)
