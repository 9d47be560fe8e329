"""Real resonators: NPL's Q-factor data (tests/data/npl_qfactor, CC0; NPL report MAT 58), fitted
automatically as S-parameters.  The reported 2 sigma intervals must cover the published loaded
frequency f_L and loaded Q_L, or the fit must say (a misfit warning) why they do not.

Conversion: MAT 58's model ``a + b / (1 + 2 j Q_L (f / f_L - 1))`` has its pole at
``f_L (1 + j / (2 Q_L))``; ours at ``-zeta wn + j wn sqrt(1 - zeta^2)``: so
``f_L = f_n sqrt(1 - zeta^2)`` and ``Q_L = sqrt(1 - zeta^2) / (2 zeta)``.  The references are
written to a limited number of digits; half a unit of the last one (uniform: / sqrt 3) is added
to the comparison's variance.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from labkit.analysis.modal.fit import MISFIT_WARN, fit_modes

DATA = Path(__file__).resolve().parents[1] / "data" / "npl_qfactor"
#: file: (f_L Hz, last digit of f_L Hz, Q_L, last digit of Q_L) as in skrf/tests/test_qfactor.py
REF = {"Figure6b.txt": (3.987848e9, 1e3, 7454.0, 1.0),
       "Table6c27.txt": (3.65293800e9, 10.0, 708.0, 1.0),
       "Figure23.txt": (9.76015571e9, 10.0, 4760.04, 0.01),
       "Figure27.txt": (6.07225567e9, 10.0, 56019.85, 0.01)}


def _fit(name: str):
    a = np.loadtxt(DATA / name, comments="%")
    f, S = a[:, 0] * 1e9, a[:, 1] + 1j * a[:, 2]
    fit = fit_modes(f, S, kind="scattering")
    m = max(fit.modes, key=lambda x: np.max(x.peak))          # the resonance (the strongest mode)
    sq = np.sqrt(1 - m.damping_ratio ** 2)
    f_l, f_l_std = m.freq_hz * sq, m.freq_hz_std * sq
    q_l = sq / (2 * m.damping_ratio)
    q_l_std = q_l * m.damping_ratio_std / m.damping_ratio
    return fit, f_l, f_l_std, q_l, q_l_std


def _sigmas(name: str) -> tuple[float, float, object]:
    fit, f_l, f_std, q_l, q_std = _fit(name)
    f_ref, f_digit, q_ref, q_digit = REF[name]
    zf = (f_l - f_ref) / np.hypot(f_std, 0.5 * f_digit / np.sqrt(3))
    zq = (q_l - q_ref) / np.hypot(q_std, 0.5 * q_digit / np.sqrt(3))
    return float(zf), float(zq), fit


@pytest.mark.parametrize("name", ["Figure6b.txt", "Table6c27.txt", "Figure23.txt"])
def test_resonators_2_sigma_intervals_cover_the_published_f_and_q(name):
    zf, zq, fit = _sigmas(name)
    assert abs(zf) <= 2 and abs(zq) <= 2, (zf, zq, fit.warnings)


def test_the_notch_resonator_is_not_covered_and_the_fit_says_why():
    """An absorption (notch) resonance over a band barely wider than its bandwidth, with a line delay:
    fitted automatically (no background, no delay) its Q is far off, and the misfit warning says so."""
    zf, zq, fit = _sigmas("Figure27.txt")
    assert abs(zq) > 2                                              # not covered (Q about 7000, not 56000)
    assert max(fit.misfit_to_noise.values()) > MISFIT_WARN
    assert any("misfit" in w and "delay" in w for w in fit.warnings), fit.warnings
