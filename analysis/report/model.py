"""The fitted pole-residue model on a fine frequency grid, rebuilt from a ``modal_fit`` file.

A ``modal_fit`` file stores the poles (``modes/freq_hz``, ``modes/damping_ratio``) and the
model evaluated at the measured lines (``locations/<loc>/model``), not the residual terms.
The model is linear in its residues and residual terms once the poles are fixed
(:func:`labkit.analysis.modal.refine.basis`), so those are recovered exactly by linear
least squares on the stored model values; the rebuild is accepted only if it reproduces
them to 1e-6 of their largest magnitude (otherwise the report says so and draws the model
at the lines only). Drawing the model between the lines matters: a polyline through the
lines cuts the anti-resonance dips, which are narrower than the line spacing.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: Residual-term powers by FRF kind, as the fit uses them (labkit.analysis.modal.fit.DEFAULT_RESIDUALS).
RESIDUAL_POWERS_TRY: tuple[tuple[int, ...], ...] = ((-1, 0, 1), (0, 2), (-2, 0), (0,), ())


@dataclass
class FineModel:
    """A location's fitted model on a fine grid (``freq_hz``, complex ``frf``) and how it was rebuilt."""

    freq_hz: np.ndarray
    frf: np.ndarray
    residual_powers: tuple[int, ...]
    rebuild_error: float            # max |rebuilt - stored| / max |stored| at the measured lines


def fine_grid(freq_hz: np.ndarray, n: int = 4000) -> np.ndarray:
    """``n`` log-spaced frequencies spanning the measured lines."""
    f = np.asarray(freq_hz, float)
    f = f[np.isfinite(f) & (f > 0)]
    return np.geomspace(f.min(), f.max(), n)


def rebuild_model(freq_hz: np.ndarray, model_frf: np.ndarray, mode_freq_hz: Sequence[float],
                  damping_ratio: Sequence[float], *, powers: Sequence[Sequence[int]] = RESIDUAL_POWERS_TRY,
                  tol: float = 1e-6, n: int = 4000) -> FineModel | None:
    """The stored model of one location on a fine grid, or None if no residual set reproduces it.

    Parameters
    ----------
    freq_hz, model_frf:
        The measured lines and the model the fit stored at them.
    mode_freq_hz, damping_ratio:
        The fitted poles.
    powers:
        Residual-term power sets to try (the fit's default for the FRF kind first is
        fastest, but the first one that reproduces the stored model is taken).
    """
    from labkit.analysis.modal.lscf import modal_to_pole
    from labkit.analysis.modal.refine import basis

    f = np.asarray(freq_hz, float)
    h = np.asarray(model_frf, complex)
    ok = np.isfinite(f) & np.isfinite(h)
    f, h = f[ok], h[ok]
    if f.size < 3:
        return None
    lam = modal_to_pole(np.asarray(mode_freq_hz, float), np.asarray(damping_ratio, float))
    scale = float(np.max(np.abs(h))) or 1.0
    w = 2 * np.pi * f
    for pw in powers:
        b = basis(w, lam, tuple(pw))
        if b.shape[1] > 2 * f.size:
            continue
        # real parameters: stack real and imaginary parts
        a = np.vstack([b.real, b.imag])
        y = np.concatenate([h.real, h.imag])
        p, *_ = np.linalg.lstsq(a, y, rcond=None)
        err = float(np.max(np.abs(b @ p - h))) / scale
        if err <= tol:
            fg = fine_grid(f, n)
            return FineModel(fg, basis(2 * np.pi * fg, lam, tuple(pw)) @ p, tuple(pw), err)
    return None


def local_minimum(freq_hz: np.ndarray, mag: np.ndarray, near_hz: float, rel_window: float = 0.2
                  ) -> tuple[float, float]:
    """The smallest ``mag`` within ``near_hz * (1 +- rel_window)``: ``(freq_hz, value)``."""
    f = np.asarray(freq_hz, float)
    m = np.asarray(mag, float)
    sel = np.abs(f - near_hz) <= rel_window * near_hz
    if not sel.any():
        raise ValueError(f"no line within {rel_window:.0%} of {near_hz:g} Hz")
    i = np.flatnonzero(sel)[np.argmin(m[sel])]
    return float(f[i]), float(m[i])
