"""labkit's fits of pyFRF's impact test against sdypy-EMA's poles picked by hand on its stabilisation chart.

The picks (tests/data/pyfrf_sdypy_picks/picks.csv, made by ``make_picks.py`` beside it, see its README) are
checked to be sdypy-EMA's own poles.  Each |H1| peak's labkit frequency then either lies within 2 standard
uncertainties of the pick, or the difference is settled by an estimate neither fit made: one mode fitted here
to the 11 lines around the peak (the pole at frequency ``f``, damping ratio ``z``, plus a straight background
for the neighbours' tails; least squares, ``f`` and ``z`` found by search).  That estimate is not exact: a
neighbour's tail is curved, not straight.  Its own bias is measured at each peak by making it on labkit's fitted
model of the band, a known FRF, and subtracted (at 824 Hz over 700-1000 Hz it is -0.18 Hz, whichever of the two
frequencies the model holds; elsewhere 0.1 Hz at most).  The estimate the corrected one sits nearer to is the one
the data favour.  Where sdypy-EMA's chart has no column of stable poles at a peak (at
most one order), labkit's fit is compared with that estimate alone.  The outcome of every peak is written
below and explained in docs/fitting.md.
"""
from __future__ import annotations

import csv
import importlib.util
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import minimize
from test_modal_pyfrf import _half_power_band  # the peak's half-power band, as that test takes it

from labkit.analysis.modal.fit import fit_modes
from labkit.analysis.modal.lscf import modal_to_pole
from labkit.analysis.modal.refine import Channel, refine

DATA = Path(__file__).resolve().parents[1] / "data"
PICKS = DATA / "pyfrf_sdypy_picks" / "picks.csv"
#: (band low edge, band high edge, peak): the outcome, see the module docstring and docs/fitting.md
#: "agree": within labkit's 2 sigma; "sdypy off": the local fit is nearer labkit's frequency;
#: "labkit off": nearer sdypy-EMA's; "no column": sdypy-EMA's chart has no stable column at the peak.
OUTCOME: dict[tuple[float, float, int], str] = {
    (700.0, 1000.0, 810): "sdypy off",
    (700.0, 1000.0, 824): "sdypy off",
    (700.0, 1000.0, 851): "sdypy off",
    (700.0, 1000.0, 900): "sdypy off",
    (2900.0, 3300.0, 3008): "sdypy off",
    (2900.0, 3300.0, 3035): "agree",
    (2900.0, 3300.0, 3108): "no column",
    (4900.0, 7300.0, 5031): "sdypy off",
    (4900.0, 7300.0, 5074): "sdypy off",
    (4900.0, 7300.0, 5103): "no column",
    (4900.0, 7300.0, 5969): "sdypy off",
    (4900.0, 7300.0, 6078): "sdypy off",
    (4900.0, 7300.0, 7092): "sdypy off",
    (4900.0, 7300.0, 7158): "no column",
    (700.0, 1600.0, 810): "agree",
    (700.0, 1600.0, 824): "no column",
    (700.0, 1600.0, 851): "sdypy off",
    (700.0, 1600.0, 900): "sdypy off",
    (700.0, 1600.0, 1518): "agree",
    (2500.0, 4600.0, 2640): "agree",
    (2500.0, 4600.0, 3008): "no column",
    (2500.0, 4600.0, 3035): "sdypy off",
    (2500.0, 4600.0, 3108): "sdypy off",
    (2500.0, 4600.0, 3669): "sdypy off",
    (2500.0, 4600.0, 4128): "sdypy off",
    (2500.0, 4600.0, 4164): "sdypy off",
    (2500.0, 4600.0, 4392): "sdypy off",
    (2500.0, 4600.0, 4470): "no column",
}


def _load_h1() -> tuple[np.ndarray, np.ndarray]:
    d = np.load(DATA / "pyfrf_impact" / "h1_five_hits.npz")
    return d["freq_hz"][1:], d["h1"][1:]


def _picks() -> list[dict]:
    with open(PICKS) as fh:
        return list(csv.DictReader(fh))


def _make_picks():
    spec = importlib.util.spec_from_file_location("make_picks", DATA / "pyfrf_sdypy_picks" / "make_picks.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _local_rss(f: np.ndarray, h: np.ndarray, freq: float, zeta: float) -> float:
    """Residual sum of squares of one mode plus a straight background, linear in everything but the pole."""
    w = 2 * np.pi * f
    lam = 2 * np.pi * freq * (-zeta + 1j * np.sqrt(1 - zeta ** 2))
    basis = np.column_stack([1 / (1j * w - lam), np.ones_like(w), w - w.mean()])
    coef, *_ = np.linalg.lstsq(basis, h, rcond=None)
    return float(np.sum(np.abs(h - basis @ coef) ** 2))


def local_mode_hz(f: np.ndarray, h: np.ndarray, peak_hz: float, half: int = 5) -> float:
    """One mode fitted to the ``2 half + 1`` lines around ``peak_hz``: grid search, then Nelder-Mead."""
    k = int(np.argmin(np.abs(f - peak_hz)))
    fs, hs = f[k - half:k + half + 1], h[k - half:k + half + 1]
    grid = [(_local_rss(fs, hs, x, z), x, z) for x in np.arange(peak_hz - 2, peak_hz + 2, 0.05)
            for z in np.geomspace(5e-5, 1e-2, 30)]
    _, x0, z0 = min(grid)
    res = minimize(lambda p: _local_rss(fs, hs, p[0], np.exp(p[1])), [x0, np.log(z0)], method="Nelder-Mead",
                   options={"xatol": 1e-4, "fatol": 1e-30})
    return float(res.x[0])


def test_local_mode_fit_recovers_a_known_mode():
    """The independent estimate itself, on one synthetic mode with a neighbour's tail and 1 % noise."""
    f = np.arange(1.0, 2001.0)
    w = 2 * np.pi * f
    rng = np.random.default_rng(0)
    h = sum(a / (1j * w - 2 * np.pi * fr * (-z + 1j * np.sqrt(1 - z * z))) for a, fr, z in
            ((1.0, 810.37, 0.0012), (30.0, 900.0, 0.0015)))
    h = h + 0.01 * np.abs(h).max() * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) / 50
    assert abs(local_mode_hz(f, h, 810.0) - 810.37) < 0.02


@pytest.fixture(scope="module")
def fits() -> dict:
    f, h = _load_h1()
    bands = {(float(p["band_lo_hz"]), float(p["band_hi_hz"])) for p in _picks()}
    return {b: fit_modes(f, h, kind="accelerance", band_hz=b) for b in bands}


def test_the_picks_are_sdypy_emas_poles():
    """Re-running sdypy-EMA's LSCF and its stability test gives the same poles, column by column."""
    mp = _make_picks()
    rows = _picks()
    for band in dict.fromkeys((float(p["band_lo_hz"]), float(p["band_hi_hz"])) for p in rows):
        fn, xi, stable = mp.chart(band)
        for p in (p for p in rows if (float(p["band_lo_hz"]), float(p["band_hi_hz"])) == band):
            got = mp.pick(fn, xi, stable, float(p["peak_hz"]))
            assert got["stable_in_window"] == int(p["stable_in_window"]), p
            assert got["column_orders"] == int(p["column_orders"]), p
            if p["chart_order"]:
                assert got["chart_order"] == int(p["chart_order"]), p
                assert abs(got["freq_hz"] - float(p["freq_hz"])) < 1e-3, p
                assert abs(got["damping_ratio"] - float(p["damping_ratio"])) < 1e-5, p


def local_bias_hz(f: np.ndarray, fit, peak_hz: float, freq_hz: float) -> float:
    """How far :func:`local_mode_hz` misses a known mode: made on ``fit``'s model of its band (a known FRF
    holding the mode at ``freq_hz``), minus ``freq_hz``."""
    s = (f >= fit.band_hz[0]) & (f <= fit.band_hz[1])
    return local_mode_hz(f[s], fit.model(f[s]), peak_hz) - freq_hz


def _outcome(f, h, fit, p: dict) -> tuple[str, dict]:
    peak = float(p["peak_hz"])
    lo, hi = _half_power_band(f, h, peak)
    near = [m for m in fit.modes if m.in_band and lo < m.freq_hz < hi]
    assert near, (p, lo, hi)
    m = min(near, key=lambda m: m.freq_hz_std)
    raw = local_mode_hz(f, h, peak)
    local = raw - local_bias_hz(f, fit, peak, m.freq_hz)
    nums = {"labkit": m.freq_hz, "labkit_std": m.freq_hz_std, "local_raw": raw, "local": local}
    if int(p["column_orders"]) <= 1:
        return "no column", nums
    sd = float(p["freq_hz"])
    nums["sdypy"] = sd
    if abs(m.freq_hz - sd) <= 2 * m.freq_hz_std:
        return "agree", nums
    return ("sdypy off" if abs(m.freq_hz - local) < abs(sd - local) else "labkit off"), nums


def test_every_pick_agrees_or_the_data_settle_the_difference(fits):
    f, h = _load_h1()
    got = {}
    for p in _picks():
        band = (float(p["band_lo_hz"]), float(p["band_hi_hz"]))
        got[band + (int(p["peak_hz"]),)] = _outcome(f, h, fits[band], p)
    for key, (outcome, nums) in got.items():
        print(key, outcome, {k: round(v, 3) for k, v in nums.items()})
    assert {k: v[0] for k, v in got.items()} == OUTCOME
    rows = {(float(p["band_lo_hz"]), float(p["band_hi_hz"]), int(p["peak_hz"])): p for p in _picks()}
    for key, (outcome, nums) in got.items():
        if outcome == "sdypy off":      # sdypy-EMA's own column moves with order by more than labkit's 2 sigma
            span = float(rows[key]["column_max_hz"]) - float(rows[key]["column_min_hz"])
            assert span > 2 * nums["labkit_std"], (key, span, nums)
        if outcome == "no column":      # labkit against the local fit alone (5103 Hz: 1.9 sigma)
            assert abs(nums["labkit"] - nums["local"]) < 2 * nums["labkit_std"], (key, nums)


def test_the_local_fit_s_bias_at_824_hz_is_the_810_hz_tail_s_whoever_is_right(fits):
    """Over 700-1000 Hz the local fit reads 824 Hz 0.16-0.18 Hz low on labkit's model of the band, whether the
    model's 824 Hz mode sits at labkit's frequency or at sdypy-EMA's pick: the correction favours neither.
    Without the 810 Hz mode's tail (curved over the 11 lines, not straight) the bias is under 0.03 Hz.  Corrected,
    the local fit is within labkit's 2 sigma over 7 to 13 lines (823.39-823.41 Hz), not only over 11."""
    f, h = _load_h1()
    fit = fits[(700.0, 1000.0)]
    m = min(fit.modes, key=lambda m: abs(m.freq_hz - 824))
    sdypy = next(float(p["freq_hz"]) for p in _picks() if p["band_lo_hz"] == "700.0" and p["band_hi_hz"] == "1000.0"
                 and p["peak_hz"] == "824")
    labkit_hz = m.freq_hz
    for at in (labkit_hz, sdypy):
        m.freq_hz = at
        try:
            assert -0.2 < local_bias_hz(f, fit, 824.0, at) < -0.12, at
        finally:
            m.freq_hz = labkit_hz
    s = (f >= 700.0) & (f <= 1000.0)
    for half in (3, 4, 5, 6):
        corrected = local_mode_hz(f, h, 824.0, half) - (local_mode_hz(f[s], fit.model(f[s]), 824.0, half) - labkit_hz)
        assert abs(corrected - labkit_hz) < 2 * m.freq_hz_std, (half, corrected)
    tail = min(fit.modes, key=lambda m: abs(m.freq_hz - 810))
    amp = tail.amplitude.copy()
    tail.amplitude = 0 * amp
    try:
        assert abs(local_bias_hz(f, fit, 824.0, labkit_hz)) < 0.03
    finally:
        tail.amplitude = amp


def test_the_weak_pole_beside_824_hz_is_the_data_s_and_barely_correlated(fits):
    """Over 700-1000 Hz labkit also fits a pole at 830.9 Hz, 7 Hz above the 824 Hz mode.  The data show it: the
    831 Hz line stands out of |H1| (2.6 and 1.7 times its neighbours, the phase turning by 124 degrees from 830 Hz,
    coherence 0.998), and with every other pole held, taking it out raises the band's residual sum of squares by
    47 % (F = 67 on its 4 parameters and 566 degrees of freedom: p = 3e-46).  Its frequency is correlated with the
    824 Hz one by under 0.1, so the sandwich covariance misses no correlation there; refitted freely without it, the
    824 Hz mode moves by 0.13 Hz and its standard uncertainty grows from 0.108 to 0.157 Hz, not to a size that
    would reach the local fit."""
    from scipy.stats import f as f_dist

    f, h = _load_h1()
    coh = np.load(DATA / "pyfrf_impact" / "h1_five_hits.npz")["coherence"][1:]
    k = int(np.argmin(np.abs(f - 831)))
    assert abs(h[k]) > 1.5 * max(abs(h[k - 1]), abs(h[k + 1])) and coh[k - 2:k + 3].min() > 0.99
    band = (700.0, 1000.0)
    fit = fits[band]
    i = int(np.argmin([abs(m.freq_hz - 830.9) for m in fit.modes]))
    j = int(np.argmin([abs(m.freq_hz - 823.5) for m in fit.modes]))
    assert abs(fit.modes[i].freq_hz - 830.9) < 0.5
    s = (f >= band[0]) & (f <= band[1])
    pairs = [(m.freq_hz, m.damping_ratio) for m in fit.modes]
    ssr = [float(np.sum(np.abs(g.model(f[s]) - h[s]) ** 2))
           for g in (fit_modes(f, h, kind="accelerance", band_hz=band, poles_hz=p)
                     for p in (pairs, pairs[:i] + pairs[i + 1:]))]
    dof = 2 * int(s.sum()) - fit.covariance.shape[0]
    F = (ssr[1] - ssr[0]) / 4 / (ssr[0] / dof)
    assert f_dist.sf(F, 4, dof) < 1e-9, (ssr, F)
    c = fit.covariance
    assert abs(c[2 * i, 2 * j]) < 0.1 * np.sqrt(c[2 * i, 2 * i] * c[2 * j, 2 * j])
    fr = sum(band) / 2                                   # refined in units of the band's centre, as fit_modes does
    ch = [Channel("h1", 2 * np.pi * f[s] / fr, h[s], np.ones(int(s.sum())))]
    for m in (fit.modes[:i] + fit.modes[i + 1:], fit.modes):
        r = refine(ch, modal_to_pole(np.array([x.freq_hz for x in m]) / fr, np.array([x.damping_ratio for x in m])),
                   fit.residual_powers, band_hz=(band[0] / fr, band[1] / fr), covariance="sandwich")
        k = int(np.argmin(np.abs(r.freq_hz * fr - 823.5)))
        if len(m) < len(fit.modes):
            without = (r.freq_hz[k] * fr, np.sqrt(r.cov[2 * k, 2 * k]) * fr)
    assert abs(r.freq_hz[k] * fr - fit.modes[j].freq_hz) < 1e-4           # the same fit as fit_modes'
    assert abs(without[0] - fit.modes[j].freq_hz) < 0.15 and without[1] < 1.5 * fit.modes[j].freq_hz_std, without
