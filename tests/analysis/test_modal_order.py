"""The automatic model order finds every mode the data hold: no fixed cap on the stabilisation
diagram's order, robust clustering of its stable poles, and a residual check that adds what is
still missing.  Checked against the truth the synthetic FRFs were made from (the pole-residue
model of :mod:`labkit.analysis.modal.synth`), over many noise draws."""
from __future__ import annotations

import numpy as np
import pytest

from labkit.analysis.modal.fit import fit_modes
from labkit.analysis.modal.synth import synthetic_frf

#: bench/fit_bench.py's 7-mode, 6-location case (the robot's parts each dominated by one mode)
FN7 = np.array([438.0, 830.0, 1200.0, 1800.0, 2450.0, 3400.0, 4200.0])
ZETA7 = np.array([0.05, 0.02, 0.02, 0.03, 0.015, 0.015, 0.01])


def _seven(seed: int) -> tuple[np.ndarray, np.ndarray]:
    f = np.linspace(100.0, 5000.0, 3000)
    rng = np.random.default_rng(1)
    shapes = rng.uniform(0.2, 1.0, (6, 7)) * rng.choice([-1, 1], (6, 7))
    for k in range(6):
        shapes[k, k] = 1.5
    shapes *= (2 * np.pi * FN7) ** 2 / 1e3
    return f, synthetic_frf(f, FN7, ZETA7, shapes, kind="receptance", noise=0.01, seed=seed)


def test_seven_modes_found_in_every_one_of_30_noise_draws():
    found, covered = [], []
    for seed in range(30):
        f, H = _seven(seed)
        fit = fit_modes(f, list(H), kind="receptance")
        got = np.array([m.freq_hz for m in fit.modes])
        found.append(got.size == 7 and bool(np.all(np.abs(got / FN7 - 1) < 2e-3)))
        if got.size == 7:
            covered += list(np.abs(got - FN7) <= 2 * np.array([m.freq_hz_std for m in fit.modes]))
    assert all(found), [i for i, ok in enumerate(found) if not ok]
    assert np.mean(covered) >= 0.9, np.mean(covered)


@pytest.mark.parametrize("seed", [0, 4])
def test_fourteen_modes_in_the_band_are_all_found(seed):
    """More modes than the old fixed order (24 with complex coefficients) could hold with room to spare."""
    f = np.linspace(100.0, 3000.0, 2000)
    fn = np.geomspace(150, 2800, 14)
    rng = np.random.default_rng(seed)
    shapes = rng.uniform(0.3, 1.0, (2, 14)) * rng.choice([-1, 1], (2, 14)) * 2 * np.pi * fn * 0.02
    H = synthetic_frf(f, fn, np.full(14, 0.01), shapes, noise=0.01, seed=seed)
    fit = fit_modes(f, list(H))
    got = np.array([m.freq_hz for m in fit.modes])
    assert got.size == 14, got
    np.testing.assert_array_less(np.abs(got / fn - 1), 1e-3)
    assert fit.stabilisation is not None and fit.stabilisation.orders.max() > 24    # grown past the old cap
    assert max(fit.misfit_to_noise.values()) < 2.0


def test_twenty_two_modes_on_7950_lines_without_n_modes():
    """As bench/fit_bench.py's large case, with modes spaced geometrically (closer at the low end)."""
    rng = np.random.default_rng(7)
    f = np.arange(50, 8000) * 1.0
    fn = np.geomspace(120, 7800, 22)
    zeta = rng.uniform(0.003, 0.02, 22)
    signs = rng.choice([-1, 1], (3, 22))
    H = synthetic_frf(f, fn, zeta, rng.uniform(0.3, 1.0, (3, 22)) * signs * (2 * np.pi * fn) ** 2 / 1e3,
                      kind="receptance", noise=0.01, seed=8)
    fit = fit_modes(f, list(H), kind="receptance")
    got = np.array([m.freq_hz for m in fit.modes])
    assert got.size == 22, got
    np.testing.assert_array_less(np.abs(got / fn - 1), 1e-4)
