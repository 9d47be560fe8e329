"""Single-mode estimators: peak picking with half-power bandwidth, and the circle fit.

Both work on the *mobility* form of the FRF (velocity over force), where a
viscously damped mode is exactly ``Y = D / (1 + j x)`` with
``x = (w^2 - wn^2) / (2 zeta wn w)``: its magnitude peaks at ``wn``, its
half-power points satisfy ``w2 - w1 = 2 zeta wn`` exactly, and it traces a
circle in the Nyquist plane on which the angle about the centre is
``psi0 - 2 arctan(x)``.  The caller converts other FRF kinds first.
"""
from __future__ import annotations

import numpy as np

__all__ = ["indicator", "pick_peaks", "half_power", "circle_fit", "CircleAtBound"]


class CircleAtBound(ValueError):
    """The circle fit's optimum lies on a bound of its search box: the data hold no such circle there."""


def indicator(mob: list[np.ndarray], weights: list[float]) -> np.ndarray:
    """Root of the weighted sum of squared magnitudes over locations (channels on one grid)."""
    return np.sqrt(sum((wt * np.abs(h)) ** 2 for h, wt in zip(mob, weights)))


def pick_peaks(f: np.ndarray, a: np.ndarray, n_modes: int | None, *, min_prominence: float = 0.1,
               floor: float = 0.0) -> np.ndarray:
    """Indices of resonance peaks of the magnitude ``a``.

    Peaks are ranked by prominence in ``log10(a)``; with ``n_modes`` the top
    ``n_modes`` are kept, otherwise those with prominence above
    ``min_prominence`` decades.  Peaks not above ``floor`` (e.g. a few times
    the noise level: in log scale noise alone has prominent peaks) are never
    taken.  Returned sorted by frequency.
    """
    from scipy.signal import find_peaks

    la = np.log10(np.maximum(a, np.finfo(float).tiny))
    idx, props = find_peaks(la, prominence=0.0)
    prom = props["prominences"]
    if floor > 0:
        # In linear scale too: a peak must stand out from its surroundings by more than the floor.
        lin = find_peaks(a, prominence=0.0)
        lin_prom = dict(zip(lin[0].tolist(), lin[1]["prominences"].tolist()))
        above = np.array([a[i] > floor and lin_prom.get(int(i), 0.0) > floor for i in idx], dtype=bool)
        idx, prom = idx[above], prom[above]
    order = np.argsort(-prom)
    if n_modes is None:
        order = order[prom[order] >= min_prominence]
    else:
        order = order[:n_modes]
    return np.sort(idx[order])


def _interp_peak(f: np.ndarray, a: np.ndarray, k: int) -> tuple[float, float]:
    """Peak frequency and height by a parabola through the log magnitude at ``k-1, k, k+1``."""
    if k <= 0 or k >= f.size - 1:
        return float(f[k]), float(a[k])
    y = np.log(a[k - 1:k + 2])
    x = f[k - 1:k + 2]
    c = np.polyfit(x - x[1], y, 2)
    if c[0] >= 0:
        return float(f[k]), float(a[k])
    xp = -c[1] / (2 * c[0])
    if abs(xp) > max(x[2] - x[1], x[1] - x[0]):
        return float(f[k]), float(a[k])
    return float(x[1] + xp), float(np.exp(np.polyval(c, xp)))


def half_power(f: np.ndarray, a: np.ndarray, k: int) -> tuple[float, float]:
    """``(fn_hz, damping_ratio)`` from the peak at index ``k`` of mobility magnitude ``a``.

    The half-power frequencies are interpolated linearly where ``a`` crosses
    ``peak / sqrt(2)``; a missing side is mirrored from the other.  NaN damping
    when neither side crosses inside the data.
    """
    fn, peak = _interp_peak(f, a, k)
    level = peak / np.sqrt(2)
    f1 = f2 = np.nan
    i = k
    while i > 0 and a[i] > level:
        i -= 1
    if a[i] <= level < a[i + 1]:
        f1 = f[i] + (level - a[i]) * (f[i + 1] - f[i]) / (a[i + 1] - a[i])
    j = k
    while j < f.size - 1 and a[j] > level:
        j += 1
    if a[j] <= level < a[j - 1]:
        f2 = f[j - 1] + (a[j - 1] - level) * (f[j] - f[j - 1]) / (a[j - 1] - a[j])
    if np.isnan(f1) and not np.isnan(f2):
        f1 = fn ** 2 / f2                        # mobility half-power points satisfy f1 f2 = fn^2
    if np.isnan(f2) and not np.isnan(f1):
        f2 = fn ** 2 / f1
    return fn, float((f2 - f1) / (2 * fn))


def circle_fit(f: np.ndarray, mob: np.ndarray, fn0: float, zeta0: float, *, span: float = 1.0,
               min_points: int = 7) -> tuple[float, float]:
    """``(fn_hz, damping_ratio)`` of one mode from its circle in the Nyquist plane of a mobility.

    Points within ``fn0 (1 +- span * 2 zeta0)`` (at least ``min_points`` nearest)
    are fitted with a circle (algebraic least squares), then the angles about
    the centre with ``psi0 - 2 arctan((w^2 - wn^2) / (2 zeta wn w))``.
    """
    from scipy.optimize import least_squares

    half = max(span * 2 * zeta0 * fn0, 1e-12 * fn0)
    sel = np.flatnonzero(np.abs(f - fn0) <= half)
    if sel.size < min_points:
        sel = np.sort(np.argsort(np.abs(f - fn0))[:min_points])
    fs, Y = f[sel], mob[sel]
    x, y = Y.real, Y.imag
    A = np.column_stack([x, y, np.ones_like(x)])
    D, E, F = np.linalg.lstsq(A, -(x ** 2 + y ** 2), rcond=None)[0]
    centre = complex(-D / 2, -E / 2)
    psi = np.unwrap(np.angle(Y - centre))
    k0 = int(np.argmin(np.abs(fs - fn0)))
    w = 2 * np.pi * fs

    def resid(p):
        psi0, fn, z = p
        wn = 2 * np.pi * fn
        return psi - (psi0 - 2 * np.arctan((w ** 2 - wn ** 2) / (2 * z * wn * w)))

    p0 = [psi[k0] + 2 * np.arctan((w[k0] ** 2 - (2 * np.pi * fn0) ** 2) / (2 * zeta0 * 2 * np.pi * fn0 * w[k0])),
          fn0, max(zeta0, 1e-10)]
    lo, hi = [-np.inf, 0.5 * fn0, 1e-12], [np.inf, 1.5 * fn0, 0.95]
    # x_scale in the problem's own units: the same steps whatever the frequency unit.
    sol = least_squares(resid, p0, bounds=(lo, hi), x_scale=[1.0, max(fn0 * zeta0, 1e-12 * fn0), max(zeta0, 1e-10)])
    fn, z = float(sol.x[1]), float(sol.x[2])
    for name, v, a, b in (("frequency", fn, lo[1], hi[1]), ("damping ratio", z, lo[2], hi[2])):
        if abs(v - a) <= 1e-6 * abs(a) or abs(v - b) <= 1e-6 * abs(b):
            what = ("frequency search (+-50 % of the peak's)" if name == "frequency" else
                    f"damping ratio ({v:.3g}; search {a:.3g}..{b:.3g})")
            raise CircleAtBound(f"the circle fit near {fn0:.6g} ended at the bound of its {what}")
    return fn, z
