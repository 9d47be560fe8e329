"""The noise level of an FRF estimated from the data alone, and a fit's misfit against it.

A fit whose residual is well above the noise is missing something (a mode,
a background, a delay); the fit's ``nrmse`` cannot tell that apart from
noisy data, the ratio here can.

Estimator: for complex noise of variance ``s^2`` on neighbouring lines, the
second difference ``d_k = H_{k-1} - 2 H_k + H_{k+1}`` has variance ``6 s^2``
and ``|d_k|^2 / (6 s^2)`` is exponentially distributed (median ``ln 2``),
while a smooth FRF contributes little to it.  A running median of
``|d_k|^2 / (6 ln 2)`` over :data:`WINDOW` lines gives a local noise variance
that follows a noise level varying along the sweep and ignores the few lines
where a sharp resonance itself curves strongly.
"""
from __future__ import annotations

import numpy as np

__all__ = ["noise_variance", "misfit_to_noise", "WINDOW"]

#: Lines in the running median of the local noise variance.
WINDOW = 21


def noise_variance(H: np.ndarray, *, window: int = WINDOW) -> np.ndarray:
    """Local complex noise variance ``E|noise|^2`` at every line of ``H`` (same length)."""
    H = np.asarray(H, dtype=complex)
    n = H.size
    if n < 5:
        return np.full(n, np.nan)
    d2 = np.abs(H[:-2] - 2 * H[1:-1] + H[2:]) ** 2 / (6 * np.log(2))
    from scipy.ndimage import median_filter

    win = int(min(window, d2.size)) | 1                       # odd
    v = median_filter(d2, size=win, mode="nearest")           # the ends: the edge values repeated
    v = np.concatenate([[v[0]], v, [v[-1]]])
    # Floor: rounding of the numbers as stored (noise-free synthetic data would give 0).
    return np.maximum(v, (1e-14 * np.abs(H)) ** 2 + 1e-300)


def misfit_to_noise(H: np.ndarray, model: np.ndarray, n_params: float = 0.0,
                    model_var: np.ndarray | None = None, noise_var: np.ndarray | None = None) -> float:
    """``sqrt(mean(|model - H|^2 / (s^2 + u^2)))`` with ``s^2`` from :func:`noise_variance` and ``u^2``
    the model's own variance at each line (``model_var``, from the parameters' covariance; 0 if not
    given), corrected for the ``n_params`` real parameters fitted to this FRF; about 1 when the
    model fits to the noise.  With ``u^2``, quiet lines whose residual is the loud lines' noise carried
    by the parameters (relative noise) do not read as misfit.  ``noise_var``: ``noise_variance(H)``
    when the caller has it already."""
    H = np.asarray(H, dtype=complex)
    r2 = np.abs(np.asarray(model) - H) ** 2
    v = (noise_variance(H) if noise_var is None else np.asarray(noise_var, dtype=float)) + (
        0.0 if model_var is None else np.asarray(model_var, dtype=float))
    n_real = 2 * H.size
    corr = n_real / max(n_real - n_params, 1.0)
    return float(np.sqrt(np.mean(r2 / v) * corr))
