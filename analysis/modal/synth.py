"""Synthetic FRFs with known modes: for tests, benchmarks and checking a fit's honesty."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["synthetic_frf"]


def synthetic_frf(freq_hz: np.ndarray, mode_freq_hz: Sequence[float], damping_ratio: Sequence[float],
                  shapes: np.ndarray | Sequence[Sequence[float]] | None = None, *, kind: str = "mobility",
                  noise: float = 0.0, noise_model: str = "relative", seed: int | None = None) -> np.ndarray:
    """FRFs of a proportionally damped structure, one row per location.

    ``H_o(w) = (j w)^p sum_i shapes[o, i] / (wn_i^2 - w^2 + 2 j zeta_i wn_i w)`` with
    ``p`` = 0, 1, 2 for receptance, mobility, accelerance.

    Parameters
    ----------
    shapes:
        ``(locations, modes)`` modal constants (default one location, all ones,
        scaled by ``wn_i^2`` so every mode's static receptance is 1).
    noise:
        Standard deviation of complex Gaussian noise: relative to ``|H|`` at each
        line (``noise_model="relative"``) or to the channel's largest ``|H|``
        (``"additive"``).
    """
    f = np.asarray(freq_hz, dtype=float)
    fn = np.asarray(mode_freq_hz, dtype=float)
    z = np.asarray(damping_ratio, dtype=float)
    wn = 2 * np.pi * fn
    if shapes is None:
        shapes = (wn ** 2)[None, :]
    A = np.atleast_2d(np.asarray(shapes, dtype=float))
    w = 2 * np.pi * f
    den = wn[None, :] ** 2 - w[:, None] ** 2 + 2j * z[None, :] * wn[None, :] * w[:, None]   # (N, modes)
    H = (A @ (1.0 / den).T) * (1j * w) ** {"receptance": 0, "mobility": 1, "accelerance": 2}[kind]
    if noise > 0:
        rng = np.random.default_rng(seed)
        e = (rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape)) * (noise / np.sqrt(2))
        scale = np.abs(H) if noise_model == "relative" else np.max(np.abs(H), axis=1, keepdims=True)
        H = H + e * scale
    return H
