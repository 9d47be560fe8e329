"""Poles by the least-squares complex-frequency (LSCF) method, and the stabilisation diagram.

Common-denominator model for every channel ``o`` (location):
``H_o(w) = N_o(z) / D(z)``, ``z = exp(j w dt)``, ``dt = 1 / (2 f_max)``, with real
polynomial coefficients (so the model respects ``H(-w) = conj H(w)``).  The
linearised equations ``N_o(z_k) - H_o(w_k) D(z_k) = 0`` are reduced to the
denominator alone (Guillaume, Verboven, Vanlanduit et al., "A poly-reference
implementation of the least-squares complex frequency-domain estimator",
IMAC 2003; the single-reference case here).  The normal-equation blocks for
the highest order hold those of every lower order as leading sub-matrices, so
the whole stabilisation diagram costs one pass over the data.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Stabilisation", "lscf_poles", "stabilisation", "pole_to_modal", "modal_to_pole"]

#: A pole is "stable" at an order when one of the previous order lies within these.
FREQ_TOL = 0.01
DAMP_TOL = 0.05


def pole_to_modal(lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(freq_hz, damping_ratio)`` of poles ``lam = -zeta wn + j wn sqrt(1 - zeta^2)``."""
    lam = np.asarray(lam, dtype=complex)
    wn = np.abs(lam)
    return wn / (2 * np.pi), -lam.real / np.where(wn > 0, wn, 1.0)


def modal_to_pole(freq_hz: np.ndarray, damping_ratio: np.ndarray) -> np.ndarray:
    """The upper-half-plane pole of a mode (inverse of :func:`pole_to_modal`)."""
    wn = 2 * np.pi * np.asarray(freq_hz, dtype=float)
    z = np.asarray(damping_ratio, dtype=float)
    return wn * (-z + 1j * np.sqrt(np.clip(1 - z ** 2, 0.0, None)))


@dataclass
class Stabilisation:
    """A stabilisation diagram, as data.

    Attributes (one entry per pole, poles of all orders flattened)
    ----------
    order:
        Model (denominator polynomial) order the pole came from.
    freq_hz, damping_ratio:
        The pole's modal values.
    status:
        0 new, 1 frequency stable (within ``FREQ_TOL`` of a pole of the previous
        order), 2 frequency and damping stable (also within ``DAMP_TOL``).
    orders:
        The orders computed.
    chosen_hz:
        Frequencies of the poles chosen from the diagram (filled by the fit).
    """

    order: np.ndarray
    freq_hz: np.ndarray
    damping_ratio: np.ndarray
    status: np.ndarray
    orders: np.ndarray
    chosen_hz: np.ndarray = field(default_factory=lambda: np.zeros(0))
    band_hz: tuple[float, float] = (0.0, np.inf)
    poles_by_order: dict = field(default_factory=dict, repr=False)

    def to_dict(self) -> dict:
        return {"orders": self.orders.tolist(), "n_poles": int(self.order.size),
                "n_stable": int(np.sum(self.status == 2)), "chosen_hz": self.chosen_hz.tolist()}


def _mapping(channels) -> tuple[float, float]:
    """Zoom: centre ``wc`` and sampling step ``dt`` mapping the data's band onto an arc of the unit circle.

    ``z = exp(j (w - wc) dt)`` sends ``[w_lo, w_hi]`` to angles ``[-ZOOM pi, ZOOM pi]``
    whatever the unit, the band's width or its offset from zero: a +-1 %
    band around 1 GHz is conditioned exactly like a decade around 1 kHz.
    The model's coefficients are then complex (the band no longer contains
    its own mirror image at negative frequencies).
    """
    w_lo = min(float(np.min(c[0])) for c in channels)
    w_hi = max(float(np.max(c[0])) for c in channels)
    wc = 0.5 * (w_lo + w_hi)
    hw = max(0.5 * (w_hi - w_lo), 1e-300)
    return wc, ZOOM * np.pi / hw


#: Fraction of the half circle the band is mapped onto (the rest keeps its two ends apart).
ZOOM = 0.8


def _powers(w: np.ndarray, n: int, wc: float, dt: float) -> np.ndarray:
    """``E[k, i] = z_k^i`` for ``i = 0..n``, ``z = exp(j (w - wc) dt)``: successive products (one complex
    multiply per entry, not an exp), re-anchored every 16 powers."""
    E = np.empty((w.size, n + 1), dtype=complex)
    E[:, 0] = 1.0
    if n > 0:
        z = np.exp(1j * (w - wc) * dt)
        for i in range(1, n + 1):
            E[:, i] = np.exp(1j * (w - wc) * dt * i) if i % 16 == 0 else E[:, i - 1] * z
    return E


def _blocks(channels: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]], n_max: int, wc: float, dt: float):
    """Reduced normal matrix pieces R_o, S_o, T_o (complex) for order ``n_max``, each stacked over
    the channels ``o``.

    With ``X = diag(wt) E`` and ``Y = -diag(H wt) E`` (``E[k, i] = z_k^i``, ``|z_k| = 1``) every
    block is ``E^H diag(d) E``, whose entry ``(i, j)`` is the moment ``sum_k d_k z_k^(j - i)``: a
    Toeplitz matrix of ``2 n + 1`` moments, O(lines x order) instead of O(lines x order^2).
    """
    from scipy.linalg import toeplitz

    out = []
    E, w_prev = np.zeros((0, 0), complex), np.zeros(0)
    for w, H, wt in channels:
        if not (w is w_prev or (w.shape == w_prev.shape and np.array_equal(w, w_prev))):
            E, w_prev = _powers(w, n_max, wc, dt), w
        w2 = wt.astype(float) ** 2
        D = np.column_stack([w2, -H * w2, np.abs(H) ** 2 * w2])          # R, S, T
        up = D.T @ E                                                     # moments z^l, l = 0..n
        down = (D.conj().T @ E).conj()                                   # moments z^-l (no conjugated E)
        out.append(tuple(toeplitz(down[i], up[i]) for i in range(3)))
    # stacked over channels, (channels, n + 1, n + 1) each: one batched solve per order
    return tuple(np.array([o[i] for o in out]) for i in range(3))


def _poles_for_order(blocks, n: int, wc: float, dt: float) -> np.ndarray:
    m = n + 1
    Rn, Sn, Tn = (b[:, :m, :m] for b in blocks)
    try:
        X = np.linalg.solve(Rn, Sn)
    except np.linalg.LinAlgError:
        X = np.array([np.linalg.lstsq(r, s, rcond=None)[0] for r, s in zip(Rn, Sn)])
    M = np.sum(Tn - np.conj(np.swapaxes(Sn, 1, 2)) @ X, axis=0)
    # Constraint: highest coefficient = 1.
    alpha = np.ones(m, dtype=complex)
    alpha[:n] = np.linalg.lstsq(M[:n, :n], -M[:n, n], rcond=None)[0]
    roots = _roots(alpha)
    roots = roots[np.abs(roots) > 0]
    return np.log(roots) / dt + 1j * wc


def _roots(alpha: np.ndarray) -> np.ndarray:
    """Roots of ``sum_i alpha[i] z^i`` (``alpha[-1] != 0``): the eigenvalues of its companion matrix, as
    :func:`numpy.roots` finds them, but by LAPACK's ``zgeev`` called once with its minimal workspace
    (numpy queries the workspace and pays for it: half the time at the orders of a diagram)."""
    from scipy.linalg.lapack import zgeev

    n = alpha.size - 1
    if n < 1 or not np.all(np.isfinite(alpha)):
        return np.roots(alpha[::-1]).astype(complex)
    C = np.zeros((n, n), dtype=complex, order="F")
    C[0, :] = -alpha[-2::-1] / alpha[-1]
    C[np.arange(1, n), np.arange(n - 1)] = 1.0
    w, _, _, info = zgeev(C, compute_vl=0, compute_vr=0, overwrite_a=1)
    return w if info == 0 else np.roots(alpha[::-1]).astype(complex)


def _physical(lam: np.ndarray, band_w: tuple[float, float], max_damping: float) -> np.ndarray:
    f, z = pole_to_modal(lam)
    w = 2 * np.pi * f
    keep = (lam.imag > 0) & (lam.real < 0) & (w >= band_w[0]) & (w <= band_w[1]) & (z < max_damping)
    return lam[keep]


def lscf_poles(channels, n: int, band_hz: tuple[float, float], *, max_damping: float = 0.9) -> np.ndarray:
    """Physical poles (upper half plane, stable, in band) of an order-``n`` LSCF model.

    ``channels`` is a sequence of ``(omega_rad_s, frf, weight)`` triples.
    """
    wc, dt = _mapping(channels)
    blocks = _blocks(channels, n, wc, dt)
    return _physical(_poles_for_order(blocks, n, wc, dt), (2 * np.pi * band_hz[0], 2 * np.pi * band_hz[1]),
                     max_damping)


def stabilisation(channels, n_max: int, band_hz: tuple[float, float], *, n_min: int = 1, step: int = 1,
                  max_damping: float = 0.9, freq_tol: float = FREQ_TOL, damp_tol: float = DAMP_TOL,
                  previous: Stabilisation | None = None) -> Stabilisation:
    """Poles for every order ``n_min, n_min + step, ..., n_max`` and their stability status.

    Frequency stability is judged relative to ``min(f, band width)``, so a
    narrow (zoomed) band is held to the same standard as a wide one.
    ``previous``: a diagram of the same data and band to a lower order, whose
    poles are reused (an order's poles do not depend on the highest order).
    """
    wc, dt = _mapping(channels)
    reuse = {} if previous is None else previous.poles_by_order
    blocks = _blocks(channels, n_max, wc, dt) if any(int(n) not in reuse for n in
                                                     range(n_min, n_max + 1, step)) else ()
    band_w = (2 * np.pi * band_hz[0], 2 * np.pi * band_hz[1])
    width_hz = band_hz[1] - band_hz[0]
    orders = np.arange(n_min, n_max + 1, step)
    rec_o, rec_f, rec_z, rec_s = [], [], [], []
    by_order: dict[int, np.ndarray] = {}
    prev_f = prev_z = None
    for n in orders:
        lam = reuse[int(n)] if int(n) in reuse else _physical(_poles_for_order(blocks, int(n), wc, dt), band_w,
                                                              max_damping)
        f, z = pole_to_modal(lam)
        order_ix = np.argsort(f)
        lam, f, z = lam[order_ix], f[order_ix], z[order_ix]
        by_order[int(n)] = lam
        status = np.zeros(f.size, dtype=np.int8)
        if prev_f is not None and prev_z is not None and prev_f.size and f.size:
            k = np.argmin(np.abs(f[:, None] - prev_f[None, :]), axis=1)
            df = np.abs(f - prev_f[k]) / np.minimum(f, width_hz)
            dz = np.abs(z - prev_z[k]) / np.maximum(z, 1e-12)
            status[df < freq_tol] = 1
            status[(df < freq_tol) & (dz < damp_tol)] = 2
        rec_o.append(np.full(f.size, n))
        rec_f.append(f)
        rec_z.append(z)
        rec_s.append(status)
        prev_f, prev_z = f, z
    def cat(xs: list[np.ndarray], dt_: type) -> np.ndarray:
        return np.concatenate(xs).astype(dt_) if xs else np.zeros(0, dt_)

    return Stabilisation(cat(rec_o, int), cat(rec_f, float), cat(rec_z, float), cat(rec_s, np.int8),
                         orders, band_hz=(float(band_hz[0]), float(band_hz[1])), poles_by_order=by_order)


def choose_poles(stab: Stabilisation, n_modes: int | None, *, band_hz: tuple[float, float] | None = None,
                 min_fraction: float = 0.3, cluster_tol: float = 0.005) -> np.ndarray:
    """Pick physical poles from a stabilisation diagram.

    Poles that are frequency-stable are clustered in frequency (relative
    tolerance ``cluster_tol``, at most one pole per order in a cluster); a
    cluster's weight is the number of orders it spans.  With ``n_modes`` the
    ``n_modes`` heaviest clusters are taken, otherwise every cluster seen in at
    least ``min_fraction`` of the orders (and at least 3).  Returns the clusters'
    median poles, sorted by frequency.
    """
    keep = stab.status >= 1
    f, z, o = stab.freq_hz[keep], stab.damping_ratio[keep], stab.order[keep]
    lo, hi = band_hz if band_hz is not None else stab.band_hz
    width = hi - lo if np.isfinite(hi - lo) else np.inf
    ix = np.argsort(f)
    f, z, o = f[ix], z[ix], o[ix]
    clusters: list[list[int]] = []
    stats: list[tuple[float, float]] = []           # per cluster: mean frequency and damping (running)
    seen: list[set[int]] = []                       # per cluster: the orders it holds
    f_l, z_l, o_l = f.tolist(), z.tolist(), o.tolist()
    # Join a pole to the nearest open cluster of similar frequency *and* damping (a spurious,
    # heavily damped pole next to a light mode starts its own cluster instead of splitting the
    # mode's), at most one pole per order in a cluster.
    log3 = float(np.log(3.0))
    for i, (fi, zi, oi) in enumerate(zip(f_l, z_l, o_l)):
        best, best_d = -1, np.inf
        for k in range(len(clusters) - 1, -1, -1):
            fc, zc = stats[k]
            scale = min(fc, width)
            if (fi - fc) / scale > 2 * max(cluster_tol, 0.5 * max(zc, zi) * fc / scale):
                break                                   # clusters further down are further away
            tol = max(cluster_tol, 0.25 * min(zc, zi) * fc / scale)
            d = abs(fi - fc) / scale
            similar = abs(math.log(max(zi, 1e-12) / max(zc, 1e-12))) < log3
            if d < tol and similar and d < best_d and oi not in seen[k]:
                best, best_d = k, d
        if best >= 0:
            clusters[best].append(i)
            seen[best].add(oi)
            n = len(clusters[best])
            fc, zc = stats[best]
            stats[best] = (fc + (fi - fc) / n, zc + (zi - zc) / n)
        else:
            clusters.append([i])
            seen.append({oi})
            stats.append((float(fi), float(zi)))
    # Poles within 1 % (of the frequency or of the band's width) of a band edge, or whose half-power
    # band reaches past it, stand in for modes outside the band.
    def inside(c: list[int]) -> bool:
        fc, zc = float(np.median(f[c])), float(np.median(z[c]))
        margin = max(0.01 * min(fc, width), zc * fc) if np.isfinite(width) else 0.0
        return lo + margin < fc < hi - margin

    # A physical pole settles as the order grows; one that keeps drifting (typically towards a band
    # edge, standing in for what lies outside) does not: judge the spread over the higher half of orders.
    # The spread is robust (twice the normal-consistent median absolute deviation): a spurious pole
    # that joined the cluster at one order does not unsettle a mode seen at every other.
    def settled(c: list[int]) -> bool:
        oc = o[c]
        top = f[c][oc >= np.median(oc)]
        fc, zc = float(np.median(f[c])), float(np.median(z[c]))
        spread = 2 * 1.4826 * float(np.median(np.abs(top - np.median(top))))
        return spread <= max(0.001 * min(fc, width), 0.5 * zc * fc)

    n_orders = max(len(stab.orders), 1)
    thresh = max(3, int(np.ceil(min_fraction * n_orders))) if n_modes is None else 1
    picked = _heaviest(clusters, n_modes, thresh, lambda c: inside(c) and settled(c))
    fz = [(float(np.median(f[c])), float(np.median(z[c]))) for c in picked]
    fz = _merge(sorted(fz))
    return modal_to_pole(np.array([a for a, _ in fz]), np.array([b for _, b in fz]))


def _heaviest(clusters: list[list[int]], n_modes: int | None, thresh: int,
              ok: Callable[[list[int]], bool]) -> list[list[int]]:
    """The clusters of at least ``thresh`` poles that pass ``ok``, heaviest first (ties in order of
    frequency), at most ``n_modes``.  ``ok`` is asked only until enough are found: most clusters are
    single spurious poles, and its medians cost more than the clustering."""
    picked: list[list[int]] = []
    for c in sorted((c for c in clusters if len(c) >= thresh), key=lambda c: -len(c)):
        if n_modes is not None and len(picked) == n_modes:
            break
        if ok(c):
            picked.append(c)
    return picked


def _merge(fz: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Merge picks closer than a quarter of their damping (a heavily damped mode that wandered)."""
    out: list[tuple[float, float]] = []
    for f, z in fz:
        if out and abs(f - out[-1][0]) / f < min(0.03, 0.5 * min(z, out[-1][1])):
            continue
        out.append((f, z))
    return out
