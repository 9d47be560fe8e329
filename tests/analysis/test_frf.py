"""labkit.analysis.frf: demodulation, H1/H2/coherence, the sign convention, conversions."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal as ss

from labkit.analysis import frf
from labkit.errors import InputError


def test_demodulate_recovers_phasor_and_offset():
    fs, f = 50_000.0, 1234.5
    t = np.arange(3001) / fs                     # not a whole number of periods
    x = 0.3 + 2.0 * np.cos(2 * np.pi * f * t + 0.7)
    d = frf.demodulate(x, fs, f)
    assert abs(d.amplitude - 2.0 * np.exp(0.7j)) < 1e-9
    assert d.offset == pytest.approx(0.3, abs=1e-9)
    assert d.quality == pytest.approx(1.0, abs=1e-12)


def test_demodulate_lag_has_negative_phase_and_settling_is_dropped():
    fs, f = 20_000.0, 500.0
    t = np.arange(4000) / fs
    y = np.sin(2 * np.pi * f * t)                # sin lags cos by 90 degrees
    y[:400] += 5 * np.exp(-t[:400] * 1e3)         # a transient in the first 20 ms
    d = frf.demodulate(y, fs, f, settle_s=0.02)
    assert np.angle(d.amplitude) == pytest.approx(-np.pi / 2, abs=1e-9)
    assert abs(d.amplitude) == pytest.approx(1.0, abs=1e-9)
    d_all = frf.demodulate(y, fs, f)
    assert d_all.quality < d.quality


def test_demodulate_quality_and_uncertainty_follow_noise():
    rng = np.random.default_rng(1)
    fs, f, n = 10_000.0, 300.0, 2000
    t = np.arange(n) / fs
    errs, stds = [], []
    for _ in range(200):
        x = np.cos(2 * np.pi * f * t) + 0.5 * rng.standard_normal(n)
        d = frf.demodulate(x, fs, f)
        errs.append(d.amplitude.real - 1.0)
        stds.append(d.amplitude_std)
    # noise variance 0.25 against a sine variance 0.5: quality ~ 2/3
    assert 0.6 < d.quality < 0.73
    assert np.std(errs) == pytest.approx(np.mean(stds), rel=0.15)


def test_demodulate_many_channels_and_stepped_frf():
    fs, f = 40_000.0, 800.0
    t = np.arange(2000) / fs
    drive = 1.5 * np.cos(2 * np.pi * f * t)
    resp = 0.3 * np.cos(2 * np.pi * f * t - 1.0)
    d = frf.demodulate(np.vstack([drive, resp]), fs, f)
    assert d.amplitude.shape == (2,)
    H, q = frf.stepped_frf(drive, resp, fs, f)
    assert H == pytest.approx(0.2 * np.exp(-1j), abs=1e-9)
    assert q == pytest.approx(1.0)


def test_h1_h2_recover_known_filter_phase():
    fs = 20_000.0
    wn, zeta = 2 * np.pi * 1000.0, 0.05
    bd, ad = ss.bilinear([wn ** 2], [1, 2 * zeta * wn, wn ** 2], fs)
    rng = np.random.default_rng(0)
    x = rng.standard_normal(2 ** 17)
    y = ss.lfilter(bd, ad, x)
    est = frf.estimate_frf(x, y, fs, nperseg=2048)
    _, Hd = ss.freqz(bd, ad, worN=est.freq_hz, fs=fs)
    band = (est.freq_hz > 100) & (est.freq_hz < 3000)
    err = np.abs(est.h1[band] - Hd[band]) / np.abs(Hd[band])
    assert np.median(err) < 0.02
    # the continuous system lags 90 degrees at resonance: -pi/2, not +pi/2
    k = np.argmin(np.abs(est.freq_hz - 1000.0))
    assert np.angle(est.h1[k]) == pytest.approx(-np.pi / 2, abs=0.15)
    assert np.angle(est.h2[k]) == pytest.approx(-np.pi / 2, abs=0.15)
    assert np.median(est.coherence[band]) > 0.95
    f1, H1 = frf.h1(x, y, fs, nperseg=2048)
    np.testing.assert_allclose(H1, est.h1)


def test_h1_unbiased_by_output_noise_h2_by_input_noise():
    fs = 10_000.0
    rng = np.random.default_rng(2)
    x = rng.standard_normal(2 ** 16)
    y = 2.0 * x
    noisy_y = y + 2.0 * rng.standard_normal(x.size)
    e = frf.estimate_frf(x, noisy_y, fs, nperseg=1024)
    assert np.median(np.abs(e.h1)) == pytest.approx(2.0, rel=0.03)
    assert np.median(np.abs(e.h2)) > 2.3                 # H2 biased up by output noise
    assert np.median(e.coherence) == pytest.approx(0.5, abs=0.05)
    noisy_x = x + 0.5 * rng.standard_normal(x.size)
    e2 = frf.estimate_frf(noisy_x, y, fs, nperseg=1024)
    assert np.median(np.abs(e2.h2)) == pytest.approx(2.0, rel=0.03)
    assert np.median(np.abs(e2.h1)) < 1.8                # H1 biased down by input noise


def test_stepped_frf_matches_freqresp_of_lti():
    """A continuous lti simulated with lsim: stepped-sine demodulation gives freqresp's phase."""
    sys_ = ss.lti([1.0e3], [1.0, 1.0e3])               # first-order low pass, corner 159 Hz
    fs, f = 50_000.0, 159.155
    t = np.arange(int(0.2 * fs)) / fs
    u = np.cos(2 * np.pi * f * t)
    _, y, _ = ss.lsim(sys_, u, t)
    H, q = frf.stepped_frf(u, y, fs, f, settle_s=0.05)
    _, Hc = ss.freqresp(sys_, w=[2 * np.pi * f])
    assert H == pytest.approx(Hc[0], abs=2e-3)
    assert np.angle(H) == pytest.approx(-np.pi / 4, abs=3e-3)
    assert q > 0.999


def test_conversions_round_trip_and_sign():
    f = np.array([10.0, 100.0, 1000.0])
    rec = np.array([1 + 0j, 2j, -3.0])
    mob = frf.convert(f, rec, "receptance", "mobility")
    np.testing.assert_allclose(mob, 2j * np.pi * f * rec)
    acc = frf.convert(f, mob, "mobility", "accelerance")
    np.testing.assert_allclose(acc, -(2 * np.pi * f) ** 2 * rec)
    np.testing.assert_allclose(frf.convert(f, acc, "accelerance", "receptance"), rec)
    with pytest.raises(InputError):
        frf.convert([0.0, 1.0, 2.0], rec, "mobility", "receptance")
    with pytest.raises(InputError, match="frm"):
        frf.convert(f, rec, "velocity", "mobility")


def test_transmissibility_of_sdof_base_excitation():
    f = np.linspace(50, 1000, 50)
    tray_disp_um = 25.0 * np.ones(f.size)
    T_true = frf.sdof_transmissibility(f, 240.0, 0.1)
    robot_v = frf.velocity_from_displacement(f, tray_disp_um * 1e-3) * T_true
    T, q = frf.transmissibility(robot_v, frf.velocity_from_displacement(f, tray_disp_um * 1e-3),
                                robot_quality=np.full(f.size, 0.9))
    np.testing.assert_allclose(T, T_true)
    assert np.all(q == 0.9)
    assert abs(frf.sdof_transmissibility(0.0, 240.0, 0.1)) == pytest.approx(1.0)
    # at resonance the robot lags the tray by nearly 90 degrees for light damping
    assert np.angle(frf.sdof_transmissibility(240.0, 240.0, 0.01)) == pytest.approx(-np.pi / 2, abs=0.03)


@pytest.mark.parametrize("call", [
    lambda: frf.h1(np.ones(100), np.ones(99), 1000.0),
    lambda: frf.h1(np.r_[np.ones(99), np.nan], np.ones(100), 1000.0),
    lambda: frf.h1(np.ones(10), np.ones(10), 1000.0),
    lambda: frf.demodulate(np.ones(5), 1000.0, 100.0),
    lambda: frf.demodulate(np.r_[np.ones(99), np.inf], 1000.0, 100.0),
    lambda: frf.demodulate(np.ones(100), 1000.0, 600.0),
    lambda: frf.demodulate(np.ones(100), 1000.0, 100.0, settle_s=1.0),
    lambda: frf.stepped_frf(np.ones(100), np.ones(90), 1000.0, 100.0),
    lambda: frf.transmissibility(np.ones(3), np.ones(4)),
])
def test_bad_inputs_raise_input_error(call):
    with pytest.raises(InputError):
        call()


def test_demodulate_linear_detrend_removes_a_drifting_baseline():
    fs, f = 10_000.0, 250.0
    t = np.arange(1234) / fs
    x = 0.8 * np.cos(2 * np.pi * f * t - 0.3) + 0.5 + 40.0 * t          # baseline drifts by 5 V
    d = frf.demodulate(x, fs, f, detrend="linear")
    assert abs(d.amplitude - 0.8 * np.exp(-0.3j)) < 1e-9
    assert d.quality > 0.999999
    assert frf.demodulate(x, fs, f).quality < 0.5                           # an offset alone cannot follow it
    with pytest.raises(InputError, match="detrend"):
        frf.demodulate(x, fs, f, detrend="quadratic")
