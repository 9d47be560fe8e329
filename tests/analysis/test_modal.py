"""labkit.analysis.modal.fit: accuracy, overlapping modes, honest uncertainties, common poles, bad input."""
from __future__ import annotations

import numpy as np
import pytest

from labkit.analysis.frf import sdof_transmissibility
from labkit.analysis.modal.fit import fit_modes
from labkit.analysis.modal.synth import synthetic_frf
from labkit.errors import InputError

FN = np.array([438.0, 1200.0, 1800.0])
ZETA = np.array([0.05, 0.02, 0.03])
#: three locations (body, hip, knee), each dominated by a different mode
SHAPES = np.array([[1.0, 0.5, 0.2], [0.3, 1.0, 0.5], [0.2, 0.4, 1.0]]) * 1e7


def _check(fit, fn, zeta, f_tol, z_tol):
    got_f = np.array([m.freq_hz for m in fit.modes])
    got_z = np.array([m.damping_ratio for m in fit.modes])
    assert got_f.size == len(fn), got_f
    np.testing.assert_array_less(np.abs(got_f / fn - 1), f_tol)
    np.testing.assert_array_less(np.abs(got_z / zeta - 1), z_tol)


def test_three_modes_one_percent_noise_three_locations():
    f = np.linspace(100, 4000, 2000)
    H = synthetic_frf(f, FN, ZETA, SHAPES, noise=0.01, seed=3)
    fit = fit_modes(f, {"body": H[0], "hip": H[1], "knee": H[2]})
    _check(fit, FN, ZETA, 0.001, 0.05)
    assert fit.locations == ["body", "hip", "knee"]
    # which mode dominates where: mode i moves location i most
    assert [m.dominant_location for m in fit.modes] == ["body", "hip", "knee"]
    assert fit.dominant_mode == {"body": 0, "hip": 1, "knee": 2}
    # the model follows the data to the noise level (1 %)
    for loc in fit.locations:
        assert 0.005 < fit.nrmse[loc] < 0.02
    assert fit.quality > 0.999
    k = fit.locations.index("knee")
    assert np.allclose(fit.model(f, "knee"), fit.model(f, k))
    assert fit.stabilisation is not None and fit.stabilisation.chosen_hz.size == 3
    # residues: the fitted modal contribution peaks at the true |H| peak of that mode
    wn = 2 * np.pi * FN
    true_peak = SHAPES / (2 * ZETA * wn ** 2)[None, :] * wn[None, :]     # mobility peak A/(2 zeta wn)
    got_peak = np.array([m.peak for m in fit.modes]).T
    np.testing.assert_allclose(got_peak, true_peak, rtol=0.03)


@pytest.mark.parametrize("kind", ["receptance", "accelerance"])
def test_three_modes_other_frf_kinds(kind):
    f = np.linspace(100, 4000, 1500)
    H = synthetic_frf(f, FN, ZETA, SHAPES[:1], kind=kind, noise=0.01, seed=4)[0]
    _check(fit_modes(f, H, kind=kind), FN, ZETA, 0.001, 0.05)


def test_two_modes_two_percent_apart_are_resolved():
    f = np.linspace(800, 1250, 900)
    fn, z = np.array([1000.0, 1020.0]), np.array([0.01, 0.01])
    H = synthetic_frf(f, fn, z, [[1e6, -0.8e6], [0.5e6, 1e6]], noise=0.01, seed=0)
    for n in (None, 2):
        fit = fit_modes(f, H, n_modes=n)
        _check(fit, fn, z, 0.001, 0.05)
    # a single-mode method cannot split them, and says so
    peak = fit_modes(f, H, method="peak")
    assert len(peak.modes) < 2 or any("neighbouring modes" in w for w in peak.warnings)
    assert any("neighbouring modes" in w for w in peak.warnings)


def test_heavily_damped_modes_like_the_released_robot():
    f = np.linspace(50, 4000, 1500)
    z = np.array([0.25, 0.12, 0.13])
    H = synthetic_frf(f, FN, z, SHAPES, noise=0.01, seed=5)
    _check(fit_modes(f, H), FN, z, 0.002, 0.05)
    circle = fit_modes(f, H, method="circle")
    assert any("neighbouring modes" in w for w in circle.warnings)


def _coverage(noise_model: str, covariance: str, trials: int, seed0: int) -> tuple[float, float]:
    f = np.linspace(200, 2600, 500)
    inside_f, inside_z = [], []
    for s in range(trials):
        H = synthetic_frf(f, FN, ZETA, SHAPES[:1] * [[1, 1, 1]], noise=0.01, noise_model=noise_model,
                          seed=seed0 + s)[0]
        fit = fit_modes(f, H, n_modes=3, covariance=covariance)
        got = np.array([[m.freq_hz, m.freq_hz_std, m.damping_ratio, m.damping_ratio_std] for m in fit.modes])
        assert got.shape == (3, 4)
        inside_f += list(np.abs(got[:, 0] - FN) <= 2 * got[:, 1])
        inside_z += list(np.abs(got[:, 2] - ZETA) <= 2 * got[:, 3])
    return float(np.mean(inside_f)), float(np.mean(inside_z))


@pytest.mark.slow
def test_uncertainty_is_honest_in_repeated_noisy_trials():
    """The true value lies within 2 standard uncertainties >= 90 % of the time (expected ~95 %)."""
    # noise proportional to |H| (varies along the sweep): the default sandwich covariance
    cf, cz = _coverage("relative", "sandwich", 40, 100)
    assert cf >= 0.90 and cz >= 0.90, (cf, cz)
    # white noise of constant level: the residual-variance-scaled covariance
    cf, cz = _coverage("additive", "residual", 40, 200)
    assert cf >= 0.90 and cz >= 0.90, (cf, cz)
    # and the uncertainty is not inflated to get there: a 2-sigma band that also holds at 0.5 sigma
    # would be useless; at 1 sigma about 68 % should fall inside, not ~100 %
    f = np.linspace(200, 2600, 500)
    z1 = []
    for s in range(20):
        H = synthetic_frf(f, FN, ZETA, SHAPES[:1], noise=0.01, seed=300 + s)[0]
        fit = fit_modes(f, H, n_modes=3)
        z1 += [abs(m.freq_hz - t) / m.freq_hz_std for m, t in zip(fit.modes, FN)]
    assert 0.45 < np.mean(np.array(z1) <= 1.0) < 0.9


def test_single_mode_methods_on_separated_light_modes():
    f = np.linspace(100, 4000, 3000)
    z = np.array([0.01, 0.01, 0.01])
    H = synthetic_frf(f, FN, z, SHAPES, noise=0.005, seed=6)
    for method, f_tol, z_tol in (("peak", 0.002, 0.10), ("circle", 0.001, 0.05)):
        fit = fit_modes(f, H, method=method, n_boot=30)
        _check(fit, FN, z, f_tol, z_tol)
        for m in fit.modes:
            assert 0 < m.freq_hz_std < 0.01 * m.freq_hz and 0 < m.damping_ratio_std < 0.5 * m.damping_ratio
        assert fit.stabilisation is None and fit.method == method
        assert not any("neighbouring modes" in w for w in fit.warnings)


def test_transmissibility_of_a_base_excited_robot():
    f = np.linspace(100, 600, 120)
    rng = np.random.default_rng(7)
    T = sdof_transmissibility(f, 240.0, 0.1) * (1 + 0.005 * rng.standard_normal(f.size))
    fit = fit_modes(f, T, kind="transmissibility")
    assert len(fit.modes) == 1
    assert fit.modes[0].freq_hz == pytest.approx(240.0, rel=2e-3)
    assert fit.modes[0].damping_ratio == pytest.approx(0.1, rel=0.05)


def test_locations_on_their_own_frequency_grids_share_poles():
    fa = np.linspace(100, 4000, 700)
    fb = np.geomspace(150, 3500, 500)
    Ha = synthetic_frf(fa, FN, ZETA, SHAPES[:1], noise=0.01, seed=8)[0]
    Hb = synthetic_frf(fb, FN, ZETA, SHAPES[2:], noise=0.01, seed=9)[0]
    fit = fit_modes([fa, fb], [Ha, Hb], locations=["run1:body", "run2:knee"])
    _check(fit, FN, ZETA, 0.001, 0.05)
    assert fit.freq_hz[1].size == 500


@pytest.mark.parametrize("call, match", [
    (lambda f, H: fit_modes(f[:-1], H), "equal length"),
    (lambda f, H: fit_modes(f, np.where(np.arange(f.size) == 5, np.nan, H)), "NaN"),
    (lambda f, H: fit_modes(f[:8], H[:8]), "at least 12"),
    (lambda f, H: fit_modes(f, H, band_hz=(1000, 1001)), "at least 12"),
    (lambda f, H: fit_modes(-f, H), "> 0"),
    (lambda f, H: fit_modes(f, H, method="magic"), "method"),
    (lambda f, H: fit_modes(f, H, kind="velocity"), "kind"),
    (lambda f, H: fit_modes(f, H, n_modes=0), "n_modes"),
    (lambda f, H: fit_modes(f, H, band_hz=(500, 100)), "band"),
    (lambda f, H: fit_modes(f, {"a": H, "b": H[:-1]}), "equal length"),
    (lambda f, H: fit_modes(f, np.zeros_like(H)), "zero"),
])
def test_bad_inputs_raise_input_error(call, match):
    f = np.linspace(100, 4000, 200)
    H = synthetic_frf(f, FN, ZETA, SHAPES[:1])[0]
    with pytest.raises(InputError, match=match):
        call(f, H)
