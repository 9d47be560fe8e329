"""Mode shapes across locations: residues as shapes, MAC, and which mode dominates where.

With several locations fitted with common poles
(:func:`~labkit.analysis.modal.fit.fit_modes`), mode ``i``'s complex residues
``R_oi`` over the locations ``o`` are its shape (scaled by the drive, which is
common to all locations of one excitation).  The modal assurance criterion

    ``MAC(a, b) = |a^H b|^2 / ((a^H a) (b^H b))``

is 1 for shapes that differ by a complex factor and 0 for orthogonal ones:
between the modes of one fit it shows whether two modes are really distinct
(close to 0) or one mode fitted twice (close to 1); between two fits (two
runs, two boundary conditions) it pairs their modes.

>>> table = shape_table(fit)            # per mode: shape, |shape| normalised, dominant location
>>> mac(fit.shapes(), other.shapes())   # (modes of fit) x (modes of other)
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from labkit.errors import InputError

__all__ = ["mac", "auto_mac", "pair_modes", "shape_table", "normalised"]


def _as_shapes(x: Any, name: str) -> np.ndarray:
    a = np.asarray(x.shapes() if hasattr(x, "shapes") else x, dtype=complex)
    if a.ndim == 1:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] == 0:
        raise InputError(f"{name} has shape {a.shape}", expected="(modes, locations) shapes or a ModalFit")
    return a


def mac(a: Any, b: Any | None = None) -> np.ndarray:
    """MAC between the rows (modes) of ``a`` and of ``b`` (default ``a``): ``(modes_a, modes_b)`` in [0, 1].

    ``a`` and ``b`` are ``(modes, locations)`` complex shapes or fits (their
    :meth:`~labkit.analysis.modal.fit.ModalFit.shapes`); they must have the
    same locations in the same order.
    """
    A = _as_shapes(a, "a")
    B = A if b is None else _as_shapes(b, "b")
    if A.shape[1] != B.shape[1]:
        raise InputError(f"shapes over {A.shape[1]} and {B.shape[1]} locations",
                         expected="the same locations in both")
    num = np.abs(A.conj() @ B.T) ** 2
    den = np.outer(np.sum(np.abs(A) ** 2, axis=1), np.sum(np.abs(B) ** 2, axis=1))
    return np.divide(num, den, out=np.zeros_like(num), where=den > 0)


def auto_mac(fit: Any) -> np.ndarray:
    """MAC between the modes of one fit (1 on the diagonal)."""
    return mac(fit)


def pair_modes(a: Any, b: Any, *, min_mac: float = 0.8) -> list[tuple[int, int, float]]:
    """Pairs ``(mode of a, mode of b, MAC)`` matched one to one by the largest MAC (greedy), MAC >= ``min_mac``."""
    M = mac(a, b).copy()
    out = []
    while M.size and M.max() >= min_mac:
        i, j = np.unravel_index(int(np.argmax(M)), M.shape)
        out.append((int(i), int(j), float(M[i, j])))
        M[i, :] = -1
        M[:, j] = -1
    return sorted(out)


def normalised(shape: np.ndarray) -> np.ndarray:
    """A shape rotated and scaled so that its largest component is +1 (real modes come out real)."""
    s = np.asarray(shape, dtype=complex)
    k = int(np.argmax(np.abs(s)))
    return s / s[k] if s[k] != 0 else s


def shape_table(fit: Any, locations: Sequence[str] | None = None) -> list[dict[str, Any]]:
    """Per mode: frequency, the normalised shape per location (magnitude and phase in degrees),
    and the location it dominates (largest own peak ``|R| / (zeta wn)``, as ``Mode.dominant_location``)."""
    locs = list(locations) if locations is not None else list(fit.locations)
    out = []
    for m in fit.modes:
        s = normalised(m.amplitude)
        out.append({"freq_hz": m.freq_hz, "dominant_location": m.dominant_location,
                    "shape": {loc: {"magnitude": float(abs(v)), "phase_deg": float(np.degrees(np.angle(v)))}
                              for loc, v in zip(locs, s)}})
    return out
