"""The fit tells the truth about its errors: under purely relative noise (the quiet lines' residual
is the loud lines' noise carried by the parameters) no misfit warning; under a model that misses
something (a smooth ripple no pole-residue model holds) the warning, and uncertainties scaled for
the correlated residual that still cover the truth.  Truth: the synthetic FRF's own modes."""
from __future__ import annotations

import numpy as np

from labkit.analysis.modal.fit import MISFIT_WARN, fit_modes
from labkit.analysis.modal.synth import synthetic_frf


def test_purely_relative_noise_gives_no_misfit_warning_and_covered_modes():
    f = np.linspace(50, 5000, 3000)
    fn = np.array([438.0, 1200.0, 3400.0])
    zeta = np.array([0.002, 0.003, 0.002])
    clean = synthetic_frf(f, fn, zeta, noise=0.0, kind="receptance")[0]      # dynamic range ~1e4
    covered, worst = [], []
    for seed in range(10):
        rng = np.random.default_rng(seed)
        H = clean * (1 + 0.05 * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) / np.sqrt(2))
        fit = fit_modes(f, H, kind="receptance")
        got = np.array([[m.freq_hz, m.freq_hz_std] for m in fit.modes])
        assert got.shape[0] == 3, got
        covered += list(np.abs(got[:, 0] - fn) <= 2 * got[:, 1])
        worst.append(max(fit.misfit_to_noise.values()))
        assert not any("misfit" in w for w in fit.warnings), fit.warnings
    assert max(worst) < MISFIT_WARN and min(worst) > 0.7, worst
    assert np.mean(covered) >= 0.9, np.mean(covered)


def test_a_model_that_misses_something_is_warned_and_its_uncertainty_scaled():
    covered = []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        f = np.linspace(800, 1200, 400)
        H = synthetic_frf(f, [1000.0], [0.01], noise=0.01, seed=seed)[0]
        ripple = 0.03 * np.max(np.abs(H)) * np.exp(1j * (2 * np.pi * f / rng.uniform(40, 80) + rng.uniform(0, 6)))
        fit = fit_modes(f, H + ripple)
        assert max(fit.misfit_to_noise.values()) > MISFIT_WARN
        assert any("correlated from line to line" in w for w in fit.warnings), fit.warnings
        m = [x for x in fit.modes if abs(x.freq_hz - 1000) < 20]
        covered.append(len(m) == 1 and abs(m[0].freq_hz - 1000) <= 2 * m[0].freq_hz_std)
    assert np.mean(covered) >= 0.9, np.mean(covered)
