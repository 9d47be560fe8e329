"""Make ``picks.csv`` and the stabilisation charts from sdypy-EMA's LSCF on pyFRF's H1 (see README.md).

Run from the repository root: ``python tests/data/pyfrf_sdypy_picks/make_picks.py [chart_dir]``.
"""
from __future__ import annotations

import contextlib
import csv
import io
import sys
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DATA = HERE.parent / "pyfrf_impact" / "h1_five_hits.npz"
ORDER_HIGH = 120
#: the |H1| peaks of tests/analysis/test_modal_pyfrf.py
PEAKS_HZ = {(700.0, 1000.0): [810, 824, 851, 900],
            (2900.0, 3300.0): [3008, 3035, 3108],
            (4900.0, 7300.0): [5031, 5074, 5103, 5969, 6078, 7092, 7158],
            (700.0, 1600.0): [810, 824, 851, 900, 1518],
            (2500.0, 4600.0): [2640, 3008, 3035, 3108, 3669, 4128, 4164, 4392, 4470]}


def window_hz(peak: float) -> float:
    """Half-width of the window searched around a peak: 3 Hz below 2 kHz, 5 Hz above."""
    return 3.0 if peak < 2000 else 5.0


def chart(band: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """sdypy-EMA's stabilisation chart of one band: frequency, damping and stable flag, (pole, chart order - 1).

    Stable is sdypy-EMA's own test (``select_closest_poles``' defaults: 0.1 % in frequency, 5 % in damping).
    """
    import sdypy.EMA as ema
    from sdypy.EMA import stabilization

    d = np.load(DATA)
    with warnings.catch_warnings(), contextlib.redirect_stderr(io.StringIO()):
        warnings.simplefilter("ignore")
        m = ema.Model(frf=d["h1"][1:], freq=d["freq_hz"][1:], lower=band[0], upper=band[1],
                      pol_order_high=ORDER_HIGH, frf_form="accelerance")
        m.get_poles(show_progress=False)
        fn, xi, test_fn, test_xi = stabilization._stabilization(m.all_poles, ORDER_HIGH, err_fn=0.001, err_xi=0.05)
    return fn, xi, (test_fn > 0) & (test_xi > 0) & (xi > 0)


def pick(fn: np.ndarray, xi: np.ndarray, stable: np.ndarray, peak: float) -> dict:
    """The densest column of stable poles near ``peak`` (most orders within a strip 1 Hz wide, 2 Hz
    above 2 kHz), and its pole nearest the column's median frequency."""
    w = window_hz(peak)
    r, c = np.nonzero(stable & (np.abs(fn - peak) <= w))
    row = {"band_lo_hz": None, "peak_hz": peak, "chart_order": "", "freq_hz": "", "damping_ratio": "",
           "column_orders": 0, "column_min_hz": "", "column_max_hz": "", "stable_in_window": int(r.size)}
    if r.size == 0:
        return row
    freq, order, damp = fn[r, c], c + 1, xi[r, c]
    strip = 1.0 if peak < 2000 else 2.0
    starts = np.arange(peak - w, peak + w, 0.05)
    counts = [np.unique(order[(freq >= x) & (freq < x + strip)]).size for x in starts]
    x = starts[int(np.argmax(counts))]
    s = (freq >= x) & (freq < x + strip)
    k = np.flatnonzero(s)[int(np.argmin(np.abs(freq[s] - np.median(freq[s]))))]
    row.update(chart_order=int(order[k]), freq_hz=round(float(freq[k]), 4), damping_ratio=round(float(damp[k]), 6),
               column_orders=int(np.unique(order[s]).size), column_min_hz=round(float(freq[s].min()), 3),
               column_max_hz=round(float(freq[s].max()), 3))
    return row


def plot(path: Path, band, fn, xi, stable) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = np.load(DATA)
    f, h = d["freq_hz"], np.abs(d["h1"])
    peaks = PEAKS_HZ[band]
    fig, axs = plt.subplots(-(-len(peaks) // 3), 3, figsize=(18, 4.5 * -(-len(peaks) // 3)), squeeze=False)
    for ax, pk in zip(axs.flat, peaks):
        w = 4 * window_hz(pk)
        for mask, style in ((~stable & (xi > 0), "r."), (stable, "gX")):
            r, c = np.nonzero(mask & (np.abs(fn - pk) < w))
            ax.plot(fn[r, c], c + 1, style, ms=4)
        s = np.abs(f - pk) < w
        ax.twinx().semilogy(f[s], h[s], "k-", lw=0.8)
        ax.set(xlim=(pk - w, pk + w), ylim=(0, ORDER_HIGH + 2), title=f"{band[0]:g}-{band[1]:g} Hz, peak {pk} Hz",
               ylabel="sdypy-EMA chart order")
    fig.tight_layout()
    fig.savefig(path, dpi=70)
    plt.close(fig)


def main(chart_dir: Path | None = None) -> None:
    rows = []
    for band, peaks in PEAKS_HZ.items():
        fn, xi, stable = chart(band)
        if chart_dir is not None:
            plot(chart_dir / f"chart_{band[0]:g}_{band[1]:g}.png", band, fn, xi, stable)
        for peak in peaks:
            row = pick(fn, xi, stable, peak)
            row.update(band_lo_hz=band[0], band_hi_hz=band[1])
            rows.append(row)
    keys = ["band_lo_hz", "band_hi_hz", "peak_hz", "chart_order", "freq_hz", "damping_ratio", "column_orders",
            "column_min_hz", "column_max_hz", "stable_in_window"]
    with open(HERE / "picks.csv", "w", newline="") as fh:
        out = csv.DictWriter(fh, keys, extrasaction="ignore")
        out.writeheader()
        out.writerows(rows)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else None)
