"""Plotting conventions shared by every labkit figure (the fit's own PNGs and the report's figures).

One colour per measurement location, the same in every figure; log frequency axes labelled in
plain numbers (300, 500, 1000 Hz, never 3x10^2); phase broken where it wraps, so no line is drawn
across the plot at a +-180 deg jump; mode labels (value +- uncertainty, significant figures set by
the uncertainty) in the margin above the magnitude axes, never on a peak.

Matplotlib's object API only (no pyplot state), so safe in any process.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Protocol

import numpy as np

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["PNG_DPI", "LOC_COLOURS", "loc_colour", "log_freq_axis", "wrapped_phase_deg", "wrap_x",
           "ModeLike", "mode_label", "mode_marks", "style_frf_axes"]

#: PNG resolution (slides, print).
PNG_DPI = 200
#: One colour per measurement location, the same in every figure (Okabe-Ito, colour-blind safe).
LOC_COLOURS = {"body": "#d55e00", "hip": "#0072b2", "knee": "#009e73"}
_EXTRA = ("#cc79a7", "#e69f00", "#56b4e9", "#000000")


def loc_colour(loc: str, k: int = 0) -> str:
    """The colour of location ``loc`` (``k``: its index, for locations without a fixed colour)."""
    return LOC_COLOURS.get(loc, _EXTRA[k % len(_EXTRA)])


def _plain(x: float, decimals: int) -> str:
    return f"{x:.{decimals}f}" if decimals > 0 else f"{x:g}" if abs(x) < 1e6 else f"{x:.0f}"


def text_width_pt(text: str, fontsize: float) -> float:
    """The width of ``text`` set in the default font at ``fontsize`` points, in points (no renderer)."""
    from matplotlib.textpath import TextPath

    return float(TextPath((0, 0), text, size=fontsize).get_extents().width) if text.strip() else 0.0


def axes_width_pt(ax: Axes, shrink: float = 0.8) -> float:
    """The axes' width in points, times ``shrink``: a layout engine (constrained layout, a legend
    outside) may still narrow the axes after this is asked, so estimates stay on the safe side."""
    fig = ax.get_figure()
    assert fig is not None
    return float(ax.bbox.width / fig.dpi * 72.0 * shrink)


def _fontsize_pt(ax: Axes) -> float:
    from matplotlib.font_manager import FontProperties

    ticks = ax.xaxis.get_major_ticks()
    return float(ticks[0].label1.get_fontsize()) if ticks else float(FontProperties(size="medium").get_size_in_points())


#: Major-tick multiples of the powers of ten, finest first, with the smallest gap between two
#: neighbours in decades (4 -> 5: log10(1.25), 2 -> 3: log10(1.5), 1 -> 2: log10(2), one decade).
_LOG_SUBS = (((1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 7.0), math.log10(1.25)), ((1.0, 2.0, 3.0, 5.0), math.log10(1.5)),
             ((1.0, 2.0, 5.0), math.log10(2.0)), ((1.0,), 1.0))


def log_freq_axis(ax: Axes) -> None:
    """A log frequency axis (x) labelled in plain numbers (300, 500, 1000, 2000 Hz, not 3x10^2).

    Major ticks at 1, 1.5, 2, 3, 4, 5, 7 / 1, 2, 3, 5 / 1, 2, 5 / 1 times the powers of ten: the
    finest set whose closest labels do not touch at the axes' width (estimated from the font,
    before layout, with a margin); over a band narrower than 2.5:1, where a decade's
    subdivisions would leave one tick or none, evenly spaced round numbers as on a linear axis.
    Call it after the data are drawn (it reads the axis limits).
    """
    from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator, NullFormatter, NullLocator

    ax.set_xscale("log")
    lo, hi = ax.get_xlim()
    lo = max(lo, 1e-300)
    ratio = hi / lo
    size = _fontsize_pt(ax)
    if ratio < 2.5:
        loc = MaxNLocator(nbins=5, steps=[1, 2, 2.5, 5, 10])
        ticks = np.asarray(loc.tick_values(lo, hi), float)
        step = float(np.min(np.diff(ticks))) if ticks.size > 1 else abs(hi)
        dec = max(0, -math.floor(math.log10(step) + 1e-9)) if step > 0 else 0
        ax.xaxis.set_major_locator(loc)
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _pos: _plain(x, dec)))
        ax.xaxis.set_minor_locator(NullLocator())
        return
    pt_per_decade = axes_width_pt(ax) / math.log10(ratio)
    widest = text_width_pt(_plain(float(10 ** math.floor(math.log10(hi))) * 7.0, 0), size)
    subs = next((s for s, gap in _LOG_SUBS if gap * pt_per_decade >= 1.3 * widest + 4.0), (1.0,))
    ax.xaxis.set_major_locator(LogLocator(base=10.0, subs=subs))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _pos: _plain(x, 0)))
    ax.xaxis.set_minor_locator(LogLocator(base=10.0, subs=tuple(float(k) for k in range(1, 10))))
    ax.xaxis.set_minor_formatter(NullFormatter())


def _wraps(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ph = np.degrees(np.angle(np.asarray(h, complex)))
    return ph, np.flatnonzero(np.abs(np.diff(ph)) > 180.0) + 1


def wrapped_phase_deg(h: np.ndarray) -> np.ndarray:
    """Phase in degrees in (-180, 180], NaN inserted where it wraps so a line is not drawn across
    the plot at a +-180 deg jump. Returns an array one longer per wrap: use with
    :func:`wrap_x` on the frequencies."""
    ph, jumps = _wraps(h)
    return np.insert(ph, jumps, np.nan)


def wrap_x(x: np.ndarray, h: np.ndarray) -> np.ndarray:
    """The abscissae matching :func:`wrapped_phase_deg` (the same NaN-separated breaks)."""
    _, jumps = _wraps(h)
    return np.insert(np.asarray(x, float), jumps, np.nan)


class ModeLike(Protocol):
    """What a mode mark needs: frequency and damping ratio with their standard uncertainties."""

    @property
    def freq_hz(self) -> float: ...
    @property
    def freq_hz_std(self) -> float | None: ...
    @property
    def damping_ratio(self) -> float | None: ...
    @property
    def damping_ratio_std(self) -> float | None: ...


def mode_label(m: ModeLike) -> str:
    """``452.0 ± 0.04 Hz, ζ 0.2200 ± 0.0001`` for a fitted mode (``analysis.modal.fit.Mode`` or a fit file's)."""
    from labkit.analysis.report.numbers import format_uncertain

    text = format_uncertain(m.freq_hz, m.freq_hz_std, "Hz")
    if m.damping_ratio is not None:
        text += ", \u03b6 " + format_uncertain(m.damping_ratio, m.damping_ratio_std)
    return text


def mode_marks(am: Axes, ap: Axes | None, modes: Sequence[ModeLike], *, fontsize: float = 7.0) -> None:
    """Dotted lines at the modes on both axes; labels ``n: f ± sf Hz, ζ ...`` in the margin above
    the magnitude axes ``am`` (never on a peak).

    Each label is centred on its mode (left- or right-aligned at the axes' ends) in the lowest row
    where it does not touch the labels already placed; widths come from the font and the axes'
    width before layout (:func:`axes_width_pt`), so call it after the x limits are set.
    """
    from matplotlib.transforms import blended_transform_factory

    tr = blended_transform_factory(am.transData, am.transAxes)
    lo, hi = (math.log10(max(v, 1e-300)) for v in am.get_xlim())
    log_x = am.get_xscale() == "log"
    xlo, xhi = am.get_xlim()
    width = axes_width_pt(am)
    pad = 0.6 * fontsize / width                     # between two labels, in axes fractions
    rows: list[float] = []                           # per row: right end of its last label (axes fraction)
    for i, m in enumerate(sorted(modes, key=lambda m: m.freq_hz)):
        fx = float(m.freq_hz)
        for ax in (am, ap):
            if ax is not None:
                ax.axvline(fx, color="0.45", lw=0.8, ls=":", zorder=1)
        text = f"{i + 1}: {mode_label(m)}"
        w = text_width_pt(text, fontsize) / width
        u = (math.log10(fx) - lo) / (hi - lo) if log_x else (fx - xlo) / (xhi - xlo)
        ha, left = "center", u - w / 2
        if left < 0.0:
            ha, left = "left", u
        elif u + w / 2 > 1.0:
            ha, left = "right", u - w
        row = next((r for r, end in enumerate(rows) if left >= end + pad), len(rows))
        if row == len(rows):
            rows.append(0.0)
        rows[row] = left + w
        am.text(fx, 1.02 + 0.09 * row, text, transform=tr, fontsize=fontsize, ha=ha, va="bottom",
                color="0.15", clip_on=False)


def style_frf_axes(am: Axes, ap: Axes, ylabel: str) -> None:
    """The FRF pair's axes: magnitude label, phase ticks every 90 deg, plain-number log frequency
    axis (:func:`log_freq_axis`), major and minor grids. Call after the data are drawn."""
    am.set_ylabel(ylabel)
    ap.set_ylabel("phase (deg)")
    ap.set_yticks([-180, -90, 0, 90, 180])
    ap.set_ylim(-190, 190)
    ap.set_xlabel("frequency (Hz)")
    log_freq_axis(ap)
    for ax in (am, ap):
        ax.grid(True, which="major", alpha=0.35)
        ax.grid(True, which="minor", alpha=0.12)
