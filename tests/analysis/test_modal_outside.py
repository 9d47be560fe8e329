"""A strong mode just outside the fitted band: the modes inside stay unbiased (their stated
uncertainty covers the truth), the one outside is fitted from its tail and reported as outside.
Truth: the pole-residue model the synthetic FRFs are made from (:mod:`labkit.analysis.modal.synth`)."""
from __future__ import annotations

import numpy as np
import pytest

from labkit.analysis.modal.fit import fit_modes
from labkit.analysis.modal.synth import synthetic_frf

LO, HI = 300.0, 1500.0
F_IN = np.array([470.0, 900.0, 1200.0])


@pytest.mark.parametrize("outside", [HI * 1.03, LO * 0.95], ids=["3%_above", "5%_below"])
def test_in_band_frequencies_covered_with_a_strong_mode_just_outside(outside):
    fn = np.r_[F_IN, outside]
    zeta = np.array([0.02, 0.015, 0.01, 0.01])
    f = np.arange(200, 2000, 0.5)                      # measured wider; only 300-1500 Hz is fitted
    covered, reported = [], 0
    for seed in range(30):
        rng = np.random.default_rng(seed)
        R = np.r_[rng.uniform(0.5, 1.0, 3), 10.0] * 2 * zeta * 2 * np.pi * fn    # outside: 10x the peak
        H = synthetic_frf(f, fn, zeta, R[None, :], noise=0.01, seed=seed)[0]
        fit = fit_modes(f, H, band_hz=(LO, HI))
        inside = [m for m in fit.modes if m.in_band]
        for true in F_IN:                               # a missed mode counts as not covered
            near = [m for m in inside if abs(m.freq_hz / true - 1) < 0.01]
            covered.append(len(near) == 1 and abs(near[0].freq_hz - true) <= 2 * near[0].freq_hz_std)
        out = [m for m in fit.modes if not m.in_band]
        if out and abs(out[0].freq_hz / outside - 1) < 0.01:
            reported += 1
            assert any("outside the band" in w for w in fit.warnings)
    assert np.mean(covered) >= 0.9, np.mean(covered)
    assert reported >= 27, reported
