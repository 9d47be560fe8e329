"""labkit.analysis.modal.plots: the fit's own figures, checked on the figure's data, not its pixels.

The FRFs come from a known structure (synthetic_frf: three modes, the body with an
anti-resonance between the first two); the checks read the Line2D data, texts and legend of
the returned matplotlib figure, and the saved PNG's resolution.
"""
from __future__ import annotations

import re
from itertools import combinations

import numpy as np
import pytest

from labkit.analysis.modal.fit import fit_modes
from labkit.analysis.modal.plots import frf_fit_figure, plot_frf_fit, plot_stabilisation
from labkit.analysis.modal.synth import synthetic_frf
from labkit.analysis.plotting import loc_colour, log_freq_axis
from labkit.analysis.report.numbers import format_uncertain

FN = np.array([438.0, 1200.0, 1800.0])
ZETA = np.array([0.02, 0.01, 0.015])
#: body: same-sign residues of modes 1 and 2, so its mobility has a zero (anti-resonance) between them
SHAPES = np.array([[1.0, 1.0, 0.2], [0.3, 1.0, 0.5], [0.2, 0.4, 1.0]]) * 1e7
LOCS = ("body", "hip", "knee")
F = np.geomspace(200.0, 3000.0, 120)          # coarse lines (1.8 % apart), as a quick sweep has


@pytest.fixture(scope="module")
def fit():
    H = synthetic_frf(F, FN, ZETA, SHAPES, noise=0.003, seed=1)
    return fit_modes(F, dict(zip(LOCS, H)), n_modes=3)


@pytest.fixture(scope="module")
def fig(fit, tmp_path_factory):
    path = tmp_path_factory.mktemp("fig") / "robot.fit.inchip.frf.png"
    fig = plot_frf_fit(fit, path, title="inchip: test", units="(mm/s)/V")
    fig.canvas.draw()
    return fig, path


def _line(fig, gid):
    found = [ln for ax in fig.axes for ln in ax.get_lines() if ln.get_gid() == gid]
    assert len(found) == 1, gid
    return found[0]


def _mag_phase_axes(fig):
    am, ap = fig.axes[:2]
    assert am.get_yscale() == "log" and ap.get_ylabel().startswith("phase")
    return am, ap


def test_fit_curve_is_the_model_on_a_fine_grid(fit, fig):
    fig, _ = fig
    for k, loc in enumerate(LOCS):
        ln = _line(fig, f"fit:{loc}")
        x, y = np.asarray(ln.get_xdata(), float), np.asarray(ln.get_ydata(), float)
        assert x.size >= 2000 and x[0] == pytest.approx(F[0]) and x[-1] == pytest.approx(F[-1])
        assert np.all(np.diff(x) > 0) and not np.isin(x[1:-1], F).any()        # not the measured lines
        np.testing.assert_allclose(y, np.abs(fit.model(x, loc)), rtol=1e-12)
        # and it is the structure's law (the generator, without noise) to within the fit's accuracy
        truth = np.abs(synthetic_frf(x, FN, ZETA, SHAPES)[k])
        assert np.max(np.abs(y / truth - 1)) < 0.08
        # phase: the same model, broken (NaN) where it wraps, never a segment across the plot
        ph = _line(fig, f"fit-phase:{loc}")
        px, py = np.asarray(ph.get_xdata(), float), np.asarray(ph.get_ydata(), float)
        ok = np.isfinite(py)
        np.testing.assert_allclose(py[ok], np.degrees(np.angle(fit.model(px[ok], loc))), atol=1e-9)
        both = ok[1:] & ok[:-1]
        assert np.all(np.abs(np.diff(py))[both] < 180.0)
    # the body's anti-resonance between the first two modes: the drawn curve reaches the true dip,
    # which a line through the model at the measured lines would miss
    x = np.asarray(_line(fig, "fit:body").get_xdata(), float)
    y = np.asarray(_line(fig, "fit:body").get_ydata(), float)
    band = (x > 500) & (x < 1150)
    xf = np.geomspace(500, 1150, 200_001)
    true_dip = np.abs(synthetic_frf(xf, FN, ZETA, SHAPES)[0]).min()
    assert y[band].min() == pytest.approx(true_dip, rel=0.02)
    at_lines = np.abs(fit.model(F[(F > 500) & (F < 1150)], "body")).min()
    assert at_lines > 1.05 * y[band].min()


def test_measured_points_are_markers_one_colour_per_location(fit, fig):
    fig, _ = fig
    colours = []
    for k, loc in enumerate(LOCS):
        ln = _line(fig, f"measured:{loc}")
        assert ln.get_linestyle() == "None" and ln.get_marker() == "o"
        np.testing.assert_array_equal(ln.get_xdata(), fit.freq_hz[k])
        np.testing.assert_allclose(ln.get_ydata(), np.abs(fit.frf[k]))
        c = ln.get_markerfacecolor()
        assert c == _line(fig, f"fit:{loc}").get_color() == _line(fig, f"measured-phase:{loc}").get_markerfacecolor()
        assert c == loc_colour(loc)               # the report's colour for that location
        colours.append(c)
    assert len(set(colours)) == len(LOCS)
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    for loc in LOCS:
        assert any(t.startswith(f"{loc}: measured") for t in legend)
        assert any(t.startswith(f"{loc}: fit") for t in legend)


def _visible_ticks(ax, renderer):
    lo, hi = sorted(ax.get_xlim())
    out = []
    for t in ax.xaxis.get_major_ticks():
        if t.label1.get_visible() and t.label1.get_text() and lo <= t.get_loc() <= hi:
            out.append((t.get_loc(), t.label1.get_text(), t.label1.get_window_extent(renderer)))
    return out


def _assert_plain_and_apart(ticks):
    assert len(ticks) >= 3, [t[1] for t in ticks]
    for loc, text, _ in ticks:
        assert re.fullmatch(r"\d+(\.\d+)?", text), text                 # 300, 1000; not 3x10^2
        assert float(text) == pytest.approx(loc, rel=1e-6)
    for (_, a, ba), (_, b, bb) in combinations(ticks, 2):
        assert not ba.overlaps(bb), (a, b)


def test_frequency_ticks_are_plain_numbers_that_do_not_overlap(fig):
    fig, _ = fig
    renderer = fig.canvas.get_renderer()
    am, ap = _mag_phase_axes(fig)
    ticks = _visible_ticks(ap, renderer)
    _assert_plain_and_apart(ticks)
    assert {"300", "500", "1000", "2000"} <= {t[1] for t in ticks}


@pytest.mark.parametrize("band", [(10.0, 1e5), (400.0, 1300.0), (440.0, 470.0), (999e6, 1001e6)])
def test_log_frequency_axis_over_wide_and_narrow_bands(band):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    f = Figure(figsize=(8, 3))
    FigureCanvasAgg(f)
    ax = f.subplots()
    ax.loglog(np.geomspace(*band, 50), np.ones(50))
    log_freq_axis(ax)
    f.canvas.draw()
    _assert_plain_and_apart(_visible_ticks(ax, f.canvas.get_renderer()))


def test_mode_labels_sit_above_the_axes_with_their_uncertainty(fit, fig):
    fig, _ = fig
    renderer = fig.canvas.get_renderer()
    am, _ = _mag_phase_axes(fig)
    texts = [t for t in am.texts if t.get_text()]
    assert len(texts) == len(fit.modes) == 3
    box = am.get_window_extent(renderer)
    for t, m in zip(sorted(texts, key=lambda t: t.get_position()[0]), sorted(fit.modes, key=lambda m: m.freq_hz)):
        x, y = t.get_position()
        assert x == pytest.approx(m.freq_hz) and y > 1.0                       # axes fraction: above
        assert t.get_window_extent(renderer).y0 >= box.y1 - 0.5               # drawn above the axes' top
        assert (f"{format_uncertain(m.freq_hz, m.freq_hz_std, 'Hz')}, \u03b6 "
                f"{format_uncertain(m.damping_ratio, m.damping_ratio_std)}") in t.get_text()
    extents = [t.get_window_extent(renderer) for t in texts]
    for a, b in combinations(extents, 2):
        assert not a.overlaps(b)
    title = fig.get_suptitle() and fig._suptitle.get_window_extent(renderer)
    assert title and not any(title.overlaps(e) for e in extents)


def test_png_is_200_dpi(fig):
    from PIL import Image

    fig, path = fig
    with Image.open(path) as im:
        assert im.info["dpi"] == pytest.approx((200, 200), abs=0.01)
        assert im.size == (round(fig.get_figwidth() * 200), round(fig.get_figheight() * 200))


def test_stabilisation_diagram_has_a_legend_and_the_chosen_poles(fit, tmp_path):
    from PIL import Image

    stab = fit.stabilisation
    fig = plot_stabilisation(stab, tmp_path / "s.png", fit=fit)
    ax = next(a for a in fig.axes if a.get_legend() is not None)
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    for name in ("stable frequency and damping", "chosen poles (3, dashed)"):
        assert name in legend
    assert all(f"|H| {loc} (right axis)" in legend for loc in LOCS)
    chosen = _line(fig, "chosen")
    np.testing.assert_allclose(chosen.get_xdata(), stab.chosen_hz)
    np.testing.assert_allclose(np.sort(chosen.get_xdata()), FN, rtol=0.002)     # the structure's modes
    assert np.all(np.asarray(chosen.get_ydata()) > stab.order.max())           # above every order
    stable = _line(fig, "status:2")
    sel = stab.status == 2
    np.testing.assert_array_equal(stable.get_xdata(), stab.freq_hz[sel])
    with Image.open(tmp_path / "s.png") as im:
        assert im.info["dpi"] == pytest.approx((200, 200), abs=0.01)


def test_many_locations_stay_readable(tmp_path):
    # a 12-location scan: one pair of axes, a bounded legend, distinct colours
    f = np.geomspace(300.0, 2500.0, 80)
    shapes = np.outer(np.linspace(0.3, 1.0, 12), [1.0, 0.6, 0.3]) * 1e7
    H = synthetic_frf(f, FN, ZETA, shapes, noise=0.003, seed=2)
    scan = fit_modes(f, {f"p{i:02d}": h for i, h in enumerate(H)}, n_modes=3)
    fig = frf_fit_figure(scan)
    assert len(fig.axes) == 2
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert len(legend) == 2 * 8 + 1 and legend[-1] == "... 4 more locations"
    colours = {tuple(_line(fig, f"measured:p{i:02d}").get_markerfacecolor()) for i in range(12)}
    assert len(colours) == 12


def test_labkit_fit_writes_its_figures_at_200_dpi(tmp_path, capsys):
    from fit_runfiles import write_inchip
    from PIL import Image

    from labkit.cli import main

    run = write_inchip(tmp_path / "inchip.h5", np.geomspace(200, 5000, 300), seed=3)
    assert main(["fit", str(run), "--out", str(tmp_path / "robot.toml")]) == 0, capsys.readouterr().err
    for what in ("frf", "stabilisation"):
        with Image.open(tmp_path / f"robot.fit.inchip.{what}.png") as im:
            assert im.info["dpi"] == pytest.approx((200, 200), abs=0.01)
    assert not list(tmp_path.glob("*.svg"))          # PNG only: the fit's output set lists no SVG
