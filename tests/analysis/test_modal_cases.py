"""labkit.analysis.modal.fit on the hard cases of issue 12: zoomed bands, units, close modes,
mode counts, dips over a background, single-mode methods at their limits, poles by hand, and
the coverage of the stated uncertainty in repeated noisy trials of each."""
from __future__ import annotations

import numpy as np
import pytest

from labkit.analysis.modal.fit import MISFIT_WARN, fit_modes
from labkit.analysis.modal.lscf import modal_to_pole
from labkit.analysis.modal.synth import synthetic_frf
from labkit.errors import InputError


def _one_mode(f: np.ndarray, fn: float, z: float, R: complex) -> np.ndarray:
    """``R / (j w - lam) + conj(R) / (j w - conj(lam))``: one mode of the pole-residue model."""
    lam = modal_to_pole(np.array([fn]), np.array([z]))[0]
    jw = 2j * np.pi * f
    return R / (jw - lam) + np.conj(R) / (jw - np.conj(lam))


def _noise(n: int, sd: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return sd * (rng.standard_normal(n) + 1j * rng.standard_normal(n)) / np.sqrt(2)


def _narrow(seed: int | None, noise: float = 0.01):
    f = np.linspace(990, 1010, 201)
    return f, synthetic_frf(f, [1000.0], [0.001], noise=noise, seed=seed)[0]


def _pair(seed: int):
    f = np.linspace(200, 2500, 1500)
    return f, synthetic_frf(f, [1000.0, 1020.0], [0.01, 0.01], noise=0.005, seed=seed)[0]


def _dip(seed: int):
    """A mobility resonance seen as a dip under a sloping complex background."""
    f = np.linspace(900, 1100, 400)
    H = 1.0 + 0.2 * (f - 1000) / 100 + 0.1j - _one_mode(f, 1000.0, 0.005, 2 * np.pi * 1000 * 0.005 * 0.8)
    return f, H + _noise(f.size, 0.002, seed)


def _fz(fit) -> np.ndarray:
    return np.array([[m.freq_hz, m.freq_hz_std, m.damping_ratio, m.damping_ratio_std] for m in fit.modes])


@pytest.mark.parametrize("method", ["lscf", "peak", "circle"])
def test_plus_minus_one_percent_band_fits_without_noise(method):
    f, H = _narrow(None, noise=0.0)
    fit = fit_modes(f, H, method=method)
    assert len(fit.modes) == 1
    assert fit.modes[0].freq_hz == pytest.approx(1000.0, rel=1e-7)
    assert fit.modes[0].damping_ratio == pytest.approx(0.001, rel=1e-3)


@pytest.mark.parametrize("method", ["lscf", "peak", "circle"])
def test_same_result_in_hz_khz_and_ghz(method):
    f = np.linspace(9e6, 11e6, 400)
    H = synthetic_frf(f, [1e7], [0.002], noise=0.001, seed=1)[0]
    got = []
    for scale in (1.0, 1e-3, 1e-9):
        fit = fit_modes(f * scale, H, method=method, n_boot=20)
        r = _fz(fit)
        r[:, :2] /= scale
        got.append(r)
        assert not any("neighbouring" in w for w in fit.warnings), fit.warnings
    for r in got[1:]:
        np.testing.assert_allclose(r, got[0], rtol=1e-9)
    assert abs(got[0][0, 0] / 1e7 - 1) < 1e-4


def test_close_pair_honours_n_modes_and_one_mode_is_flagged():
    f, H = _pair(2)
    fit = fit_modes(f, H, n_modes=2)
    r = _fz(fit)
    assert r.shape[0] == 2
    np.testing.assert_array_less(np.abs(r[:, 0] / [1000, 1020] - 1), 1e-3)
    np.testing.assert_array_less(np.abs(r[:, 2] / 0.01 - 1), 0.1)
    assert max(fit.misfit_to_noise.values()) < MISFIT_WARN and not fit.warnings
    one = fit_modes(f, H, n_modes=1)
    assert len(one.modes) == 1
    assert max(one.misfit_to_noise.values()) > 10
    assert one.quality < 0.1                       # never "0.97" for a fit that misses a mode
    assert any("misfit" in w and "noise" in w for w in one.warnings)


def test_n_modes_that_cannot_be_given_is_a_clear_error():
    f = np.linspace(500, 1500, 30)
    H = synthetic_frf(f, [1000.0], [0.02])[0]
    with pytest.raises(InputError, match="modes"):
        fit_modes(f, H, n_modes=20)                     # 30 lines cannot hold 20 modes
    eight = fit_modes(f, H, n_modes=8)                  # they can hold 8: exactly 8, and said which are weak
    assert len(eight.modes) == 8
    assert any("kept the mode" in w and "n_modes = 8" in w for w in eight.warnings)
    f2, H2 = _pair(3)
    with pytest.raises(InputError, match="n_modes"):
        fit_modes(f2, H2, n_modes=3, method="peak")   # two peaks only: not silently two


@pytest.mark.parametrize("method", ["lscf", "peak", "circle"])
def test_dip_over_a_background(method):
    f, H = _dip(0)
    fit = fit_modes(f, H, method=method, background="linear", n_boot=30)
    assert len(fit.modes) == 1, fit.warnings
    m = fit.modes[0]
    assert abs(m.freq_hz - 1000.0) < 4 * m.freq_hz_std + 1e-4 * 1000
    assert m.damping_ratio == pytest.approx(0.005, rel=0.05)
    assert max(fit.misfit_to_noise.values()) < MISFIT_WARN
    assert not any("neighbouring" in w for w in fit.warnings)   # the background is no neighbour


def test_dip_without_background_says_what_to_try():
    f, H = _dip(1)
    with pytest.raises(InputError, match="background"):
        fit_modes(f, H, method="peak")


def test_reflection_with_a_line_delay():
    f = np.linspace(900e6, 1100e6, 400)
    tau = 3e-9
    S = (0.9 - _one_mode(f, 1e9, 0.005, 2 * np.pi * 1e9 * 0.005 * 0.8)) * np.exp(-2j * np.pi * f * tau)
    S = S + _noise(f.size, 0.002, 4)
    plain = fit_modes(f, S, kind="scattering", background="linear")
    assert max(plain.misfit_to_noise.values()) > MISFIT_WARN and plain.warnings   # a delay is missing: said
    fit = fit_modes(f, S, kind="scattering", background="linear+delay")
    assert len(fit.modes) == 1 and fit.delay_s == pytest.approx(tau, rel=0.05)
    assert fit.modes[0].freq_hz == pytest.approx(1e9, rel=2e-5)
    assert fit.modes[0].damping_ratio == pytest.approx(0.005, rel=0.01)
    assert max(fit.misfit_to_noise.values()) < 1.5


def test_peak_method_warns_when_modes_are_narrower_than_the_line_spacing():
    f = np.linspace(800, 1200, 201)                      # 2 Hz lines, half-power band 1 Hz
    H = synthetic_frf(f, [1000.0], [0.0005])[0]
    fit = fit_modes(f, H, method="peak", n_boot=10)
    assert any("line spacing" in w and "cannot resolve" in w for w in fit.warnings)
    wide = fit_modes(*_narrow(0), method="peak", n_boot=10)
    assert not any("line spacing" in w for w in wide.warnings)


def test_poles_chosen_by_hand():
    f = np.linspace(100, 3000, 1200)
    H = synthetic_frf(f, [438.0, 1200.0], [0.03, 0.02], noise=0.005, seed=5)[0]
    fit = fit_modes(f, H, poles_hz=[438.0, 1200.0])
    assert [m.freq_hz for m in fit.modes] == [438.0, 1200.0]
    assert all(m.given and m.freq_hz_std == 0.0 for m in fit.modes)
    np.testing.assert_allclose([m.damping_ratio for m in fit.modes], [0.03, 0.02], rtol=0.02)
    held = fit_modes(f, H, poles_hz=[(438.0, 0.03), 1200.0])
    assert held.modes[0].damping_ratio == 0.03 and held.modes[0].damping_ratio_std == 0.0
    assert any("by hand" in w for w in fit.warnings)
    with pytest.raises(InputError, match="outside the band"):
        fit_modes(f, H, poles_hz=[5000.0])


def test_a_clean_fit_has_no_warnings_and_nothing_said_to_be_dropped():
    f = np.linspace(100, 4000, 1500)
    H = synthetic_frf(f, [438.0, 1200.0, 1800.0], [0.05, 0.02, 0.03], noise=0.01, seed=7)[0]
    fit = fit_modes(f, H)
    assert len(fit.modes) == 3 and fit.warnings == []
    assert not any("dropped" in w for w in fit.warnings)


# ------------------------------------------------------------------------------ coverage
def _coverage(make, truth_f, truth_z, trials: int, **kw) -> tuple[float, float]:
    inf, inz = [], []
    for s in range(trials):
        f, H = make(s)
        r = _fz(fit_modes(f, H, **kw))
        assert r.shape[0] == len(truth_f)
        inf += list(np.abs(r[:, 0] - truth_f) <= 2 * r[:, 1])
        inz += list(np.abs(r[:, 2] - truth_z) <= 2 * r[:, 3])
    return float(np.mean(inf)), float(np.mean(inz))


@pytest.mark.parametrize("case", ["narrow_hz", "narrow_ghz", "pair", "dip"])
def test_stated_uncertainty_covers_the_truth_in_repeated_noisy_trials(case):
    """The truth lies within 2 standard uncertainties in >= 90 % of trials (expected ~95 %)."""
    if case.startswith("narrow"):
        s = 1.0 if case == "narrow_hz" else 1e6          # 990-1010 Hz or 0.99-1.01 GHz
        cf, cz = _coverage(lambda k: (_narrow(100 + k)[0] * s, _narrow(100 + k)[1]), [1000.0 * s], [0.001], 100)
    elif case == "pair":
        cf, cz = _coverage(_pair, [1000.0, 1020.0], [0.01, 0.01], 40, n_modes=2)
    else:
        cf, cz = _coverage(_dip, [1000.0], [0.005], 40, background="linear")
    assert cf >= 0.9 and cz >= 0.9, (cf, cz)


def test_automatic_order_adds_a_mode_the_diagram_missed_while_the_misfit_is_above_the_noise(monkeypatch):
    """With n_modes=None the order rests on the stabilisation diagram *and* on the misfit against the
    noise level estimated from the data: a mode the diagram's choice misses is added, and said."""
    import labkit.analysis.modal.fit as modal_fit

    f = np.linspace(200, 2500, 1500)
    H = synthetic_frf(f, [1000.0, 1600.0], [0.01, 0.01], [[1e6, 0.1e6]], noise=0.002, seed=3)[0]
    choose = modal_fit.choose_poles
    monkeypatch.setattr(modal_fit, "choose_poles", lambda stab, n, band_hz=None: choose(stab, n, band_hz=band_hz)[:1])
    fit = fit_modes(f, H)
    r = _fz(fit)
    assert r.shape[0] == 2
    np.testing.assert_allclose(r[:, 0], [1000.0, 1600.0], rtol=1e-4)
    assert max(fit.misfit_to_noise.values()) < MISFIT_WARN
    assert any(w.startswith("added a mode at 1600 Hz") for w in fit.warnings), fit.warnings


@pytest.mark.parametrize("zeta", [1e-5, 1e-7])
def test_very_high_q_resonator_over_a_band_of_a_few_bandwidths(zeta):
    """A GHz resonator with Q up to 5e6 (no lower limit on the damping ratio short of 1e-12)."""
    fn = 1e9
    f = np.linspace(fn * (1 - 8 * zeta), fn * (1 + 8 * zeta), 401)
    S = 0.01 + 0.002j + _one_mode(f, fn, zeta, 2 * np.pi * fn * zeta * 0.5) + _noise(f.size, 1.4e-3, 11)
    fit = fit_modes(f, S, kind="scattering")
    assert len(fit.modes) == 1
    m = fit.modes[0]
    assert abs(m.freq_hz - fn) < 3 * m.freq_hz_std
    assert m.damping_ratio == pytest.approx(zeta, rel=0.005)
    assert abs(m.damping_ratio - zeta) < 3 * m.damping_ratio_std
