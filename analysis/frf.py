"""Frequency response functions from records: stepped-sine demodulation, H1/H2, coherence.

Sign and conjugation convention (used everywhere in labkit)
-----------------------------------------------------------
A sinusoid is written ``x(t) = offset + Re{X exp(+j 2 pi f t)}``: its *complex
amplitude* ``X = A exp(j phi)`` is the phasor of ``A cos(2 pi f t + phi)``, with
``t`` measured from ``t0_s`` (the time of the first sample by default 0).
A transfer function is output over input, ``H = Y / X``: a response that lags
its drive by 90 degrees has ``angle(H) = -pi/2``.  This is the convention of
``scipy.signal`` (``freqresp``, ``freqz``: ``H(s)`` evaluated at
``s = +j 2 pi f``) and of ``numpy.fft`` (forward transform with
``exp(-j 2 pi f t)``), so a filter's ``freqz`` and these estimates agree
without any conjugation.  ``h1`` uses ``scipy.signal.csd(x, y)``, which is
``conj(X) Y`` averaged, hence ``H1 = Pxy / Pxx = Y / X`` in this convention.

Derivatives in this convention are multiplications by ``j omega``:
velocity = ``j omega`` displacement, acceleration = ``j omega`` velocity, which
:func:`convert` uses for mobility (velocity/force), receptance
(displacement/force) and accelerance (acceleration/force).
"""
from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from labkit.errors import InputError

__all__ = ["Demodulated", "demodulate", "stepped_frf", "FRFEstimate", "estimate_frf", "h1", "h2",
           "coherence", "convert", "transmissibility", "velocity_from_displacement",
           "sdof_transmissibility", "KINDS"]

#: FRF kinds and the power of ``j omega`` that takes a receptance to them.
KINDS = {"receptance": 0, "mobility": 1, "accelerance": 2}


class Demodulated(NamedTuple):
    """Result of :func:`demodulate` (a tuple: ``amp, quality, *_ = demodulate(...)``).

    Attributes
    ----------
    amplitude:
        Complex amplitude ``X`` of the fundamental, ``x ~ offset + Re{X exp(j 2 pi f t)}``
        (units of the signal; ``abs`` is the peak amplitude, not peak-to-peak).
    quality:
        ``1 - SS_res / SS_tot`` of the sine fit (the fraction of the signal's
        variance about its mean that the sine explains): 1 for a clean sine,
        near 0 when noise or distortion dominate.
    offset:
        Fitted constant (DC) level.
    residual_rms:
        RMS of what the sine plus offset does not explain.
    amplitude_std:
        Standard uncertainty of the real and of the imaginary part of
        ``amplitude`` (each), from the residual variance and the regression,
        assuming white residuals.
    """

    amplitude: Any
    quality: Any
    offset: Any
    residual_rms: Any
    amplitude_std: Any


def _as_float_array(a: Any, name: str, *, ndim: tuple[int, ...] = (1,), complex_ok: bool = False) -> np.ndarray:
    try:
        arr = np.asarray(a, dtype=complex if complex_ok else float)
    except (TypeError, ValueError):
        raise InputError(f"{name}: not numeric", expected="an array of numbers") from None
    if arr.ndim not in ndim:
        raise InputError(f"{name}: has {arr.ndim} dimensions", expected=f"{' or '.join(map(str, ndim))}-D array")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name}: holds NaN or infinite values", expected="finite numbers")
    return arr


def demodulate(signal: Any, fs_hz: float, freq_hz: float, *, settle_s: float = 0.0,
               t0_s: float = 0.0, detrend: str = "constant") -> Demodulated:
    """Complex amplitude of a sinusoid at a known frequency by a least-squares sine fit.

    Fits ``offset [+ slope t] + a cos(w t) + b sin(w t)`` to the samples taken
    after ``settle_s`` and returns ``X = a - j b`` (so that the fitted sine is
    ``Re{X exp(j w t)}``).  Unlike a single-bin DFT this is exact for any
    record length, not only whole periods.

    Parameters
    ----------
    signal:
        Samples, shape ``(n,)`` or ``(channels, n)`` (channels share the time base
        and are fitted at once, e.g. drive and response).
    fs_hz:
        Sampling rate.
    freq_hz:
        The known drive frequency.
    settle_s:
        Samples before this time (from the first sample) are dropped: the
        transient while the response settles.
    t0_s:
        Time of the first sample; phases refer to ``t = 0``.  Irrelevant for
        ratios of channels recorded together.
    detrend:
        ``"constant"`` (fit an offset) or ``"linear"`` (offset and slope, for drifting
        baselines).

    Returns
    -------
    Demodulated
        Scalars for a 1-D signal, arrays of length ``channels`` otherwise.

    Raises
    ------
    InputError
        Non-finite samples, non-positive rate or frequency, a frequency above
        Nyquist, or fewer than 3 periods / 8 samples left after ``settle_s``.
    """
    x = _as_float_array(signal, "signal", ndim=(1, 2))
    one = x.ndim == 1
    x2 = np.atleast_2d(x)
    if not (np.isfinite(fs_hz) and fs_hz > 0):
        raise InputError(f"fs_hz = {fs_hz!r}", expected="a sampling rate > 0")
    if not (np.isfinite(freq_hz) and 0 < freq_hz < fs_hz / 2):
        raise InputError(f"freq_hz = {freq_hz!r}", expected=f"0 < freq_hz < fs_hz/2 = {fs_hz / 2:g}")
    if detrend not in ("constant", "linear"):
        raise InputError(f"detrend = {detrend!r}", expected="'constant' or 'linear'")
    start = int(np.ceil(max(settle_s, 0.0) * fs_hz - 1e-9))
    n = x2.shape[1] - start
    if n < 8 or n / fs_hz * freq_hz < 1.0:
        raise InputError(f"only {max(n, 0)} samples ({max(n, 0) / fs_hz * freq_hz:.2f} periods) after "
                         f"settle_s = {settle_s:g} s", expected="at least 8 samples and one period")
    t = t0_s + (start + np.arange(n)) / fs_hz
    w = 2 * np.pi * freq_hz
    cols = [np.cos(w * t), np.sin(w * t), np.ones(n)]
    if detrend == "linear":
        cols.append(t - t.mean())
    A = np.column_stack(cols)
    y = x2[:, start:].T                                   # (n, channels)
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    resid = y - A @ coef
    ss_res = np.sum(resid ** 2, axis=0)
    ss_tot = np.sum((y - y.mean(axis=0)) ** 2, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        quality = np.where(ss_tot > 0, 1.0 - ss_res / np.where(ss_tot > 0, ss_tot, 1.0), 0.0)
    dof = max(n - A.shape[1], 1)
    var = ss_res / dof
    # Cov(a, b) = var (A^T A)^-1; for many periods both diagonal terms are ~2/n.
    inv = np.linalg.pinv(A.T @ A)
    amp_std = np.sqrt(var * 0.5 * (inv[0, 0] + inv[1, 1]))
    amp = coef[0] - 1j * coef[1]
    out = Demodulated(amp, np.clip(quality, 0.0, 1.0), coef[2], np.sqrt(ss_res / n), amp_std)
    if one:
        return Demodulated(*(complex(v[0]) if i == 0 else float(v[0]) for i, v in enumerate(out)))
    return out


def stepped_frf(drive: Any, response: Any, fs_hz: float, freq_hz: float, *,
                settle_s: float = 0.0, detrend: str = "constant") -> tuple[complex, float]:
    """One stepped-sine FRF point ``H = Y / X`` from drive and response records.

    Returns ``(H, quality)``; ``quality`` is the smaller of the two channels'
    sine-fit qualities (see :func:`demodulate`).

    Raises
    ------
    InputError
        Records of different lengths, or a drive with zero amplitude.
    """
    d = np.asarray(drive)
    r = np.asarray(response)
    if d.shape != r.shape or d.ndim != 1:
        raise InputError(f"drive has shape {d.shape}, response {r.shape}", expected="two 1-D records of one length")
    dem = demodulate(np.vstack([d, r]), fs_hz, freq_hz, settle_s=settle_s, detrend=detrend)
    if abs(dem.amplitude[0]) == 0:
        raise InputError("the drive record has zero amplitude at the drive frequency",
                         expected="a drive sine at freq_hz")
    return complex(dem.amplitude[1] / dem.amplitude[0]), float(min(dem.quality))


class FRFEstimate(NamedTuple):
    """Spectral FRF estimates on one frequency grid (see :func:`estimate_frf`)."""

    freq_hz: np.ndarray
    h1: np.ndarray
    h2: np.ndarray
    coherence: np.ndarray


def _pair(x: Any, y: Any, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    xa = _as_float_array(x, "x")
    ya = _as_float_array(y, "y")
    if xa.shape != ya.shape:
        raise InputError(f"x has {xa.size} samples, y has {ya.size}", expected="records of equal length")
    if not (np.isfinite(fs_hz) and fs_hz > 0):
        raise InputError(f"fs_hz = {fs_hz!r}", expected="a sampling rate > 0")
    if xa.size < 16:
        raise InputError(f"only {xa.size} samples", expected="at least 16 samples")
    return xa, ya


def _segment(n: int, nperseg: int | None) -> int:
    if nperseg is None:
        nperseg = min(n, max(256, n // 8))          # ~15 averages with 50% overlap
    if nperseg > n or nperseg < 8:
        raise InputError(f"nperseg = {nperseg} for {n} samples", expected="8 <= nperseg <= record length")
    return int(nperseg)


def estimate_frf(x: Any, y: Any, fs_hz: float, *, nperseg: int | None = None, window: str = "hann",
                 noverlap: int | None = None, detrend: str | bool = "constant") -> FRFEstimate:
    """H1, H2 and coherence of output ``y`` over input ``x`` (Welch averaging).

    ``H1 = Pxy / Pxx`` (unbiased by output noise), ``H2 = Pyy / Pyx`` (unbiased
    by input noise), ``coherence = |Pxy|^2 / (Pxx Pyy) = H1 / H2``.  Cross
    spectra come from ``scipy.signal.csd``, whose ``Pxy`` is ``conj(X) Y``, so
    ``H = Y / X`` in the convention stated in the module docstring.
    """
    from scipy import signal as ss

    xa, ya = _pair(x, y, fs_hz)
    nps = _segment(xa.size, nperseg)
    kw = dict(fs=fs_hz, window=window, nperseg=nps, noverlap=noverlap, detrend=detrend)
    f, pxx = ss.welch(xa, **kw)
    _, pyy = ss.welch(ya, **kw)
    _, pxy = ss.csd(xa, ya, **kw)
    tiny = np.finfo(float).tiny
    with np.errstate(invalid="ignore", divide="ignore"):
        H1 = pxy / np.where(pxx > tiny, pxx, np.nan)
        H2 = pyy / np.where(np.abs(pxy) > tiny, np.conj(pxy), np.nan)
        coh = np.abs(pxy) ** 2 / np.where(pxx * pyy > tiny, pxx * pyy, np.nan)
    return FRFEstimate(f, H1, H2, np.clip(coh, 0.0, 1.0))


def h1(x: Any, y: Any, fs_hz: float, **kw: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(freq_hz, H1)`` with ``H1 = Pxy / Pxx`` (see :func:`estimate_frf` for options)."""
    e = estimate_frf(x, y, fs_hz, **kw)
    return e.freq_hz, e.h1


def h2(x: Any, y: Any, fs_hz: float, **kw: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(freq_hz, H2)`` with ``H2 = Pyy / Pyx`` (see :func:`estimate_frf`)."""
    e = estimate_frf(x, y, fs_hz, **kw)
    return e.freq_hz, e.h2


def coherence(x: Any, y: Any, fs_hz: float, **kw: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(freq_hz, gamma^2)``, the ordinary coherence of ``x`` and ``y``."""
    e = estimate_frf(x, y, fs_hz, **kw)
    return e.freq_hz, e.coherence


def convert(freq_hz: Any, frf: Any, frm: str, to: str) -> np.ndarray:
    """Convert between receptance, mobility and accelerance (multiply by ``(j w)^k``).

    Parameters
    ----------
    freq_hz:
        Frequencies, shape ``(n,)``; must be > 0 when dividing by ``j w``.
    frf:
        FRF, shape ``(n,)`` or ``(..., n)``.
    frm, to:
        ``"receptance"`` (displacement/force), ``"mobility"`` (velocity/force),
        ``"accelerance"`` (acceleration/force).

    Notes
    -----
    Units follow the physical quantities (m -> m/s -> m/s^2); convert mm or um
    yourself.
    """
    for name, k in (("frm", frm), ("to", to)):
        if k not in KINDS:
            raise InputError(f"{name} = {k!r}", expected=f"one of {', '.join(KINDS)}")
    f = _as_float_array(freq_hz, "freq_hz")
    H = _as_float_array(frf, "frf", ndim=(1, 2), complex_ok=True)
    if H.shape[-1] != f.size:
        raise InputError(f"frf has {H.shape[-1]} lines, freq_hz {f.size}", expected="equal lengths")
    power = KINDS[to] - KINDS[frm]
    if power < 0 and np.any(f <= 0):
        raise InputError("freq_hz holds values <= 0", expected="frequencies > 0 to integrate (divide by j w)")
    return H * (2j * np.pi * f) ** power


def velocity_from_displacement(freq_hz: Any, displacement: Any) -> np.ndarray:
    """Velocity phasor ``j w d`` from displacement phasor ``d`` (um -> mm/s: multiply by 1e-3)."""
    f = _as_float_array(freq_hz, "freq_hz", ndim=(0, 1))
    return 2j * np.pi * f * np.asarray(displacement, dtype=complex)


def transmissibility(robot: Any, tray: Any, *, robot_quality: Any = None,
                     tray_quality: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Base-excitation transmissibility ``T = robot velocity / tray velocity``.

    Both are complex amplitudes (phasors) in the same units, e.g. from
    :func:`demodulate` of the vibrometer on the robot and on the tray.  Returns
    ``(T, quality)`` with quality the elementwise minimum of the given
    qualities (1 where none are given).  A rigidly attached body has ``T = 1``.
    """
    r = _as_float_array(robot, "robot", ndim=(0, 1), complex_ok=True)
    t = _as_float_array(tray, "tray", ndim=(0, 1), complex_ok=True)
    if r.shape != t.shape:
        raise InputError(f"robot has shape {r.shape}, tray {t.shape}", expected="equal shapes")
    if np.any(np.abs(t) == 0):
        raise InputError("tray velocity is zero at some points", expected="a moving tray")
    q = np.ones(r.shape)
    for qq in (robot_quality, tray_quality):
        if qq is not None:
            q = np.minimum(q, np.asarray(qq, dtype=float))
    return r / t, q


def sdof_transmissibility(freq_hz: Any, fn_hz: float, damping_ratio: float) -> np.ndarray:
    """Absolute transmissibility of a viscously damped SDOF on a moving base.

    ``T = (1 + 2 j zeta r) / (1 - r^2 + 2 j zeta r)``, ``r = f / fn`` (the same for
    displacement, velocity and acceleration ratios).
    """
    r = np.asarray(freq_hz, dtype=float) / fn_hz
    return (1 + 2j * damping_ratio * r) / (1 - r ** 2 + 2j * damping_ratio * r)
