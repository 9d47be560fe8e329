"""Speed, velocity, path length, heading and turning rate from a track, with honest uncertainty.

Why a smoothed path is the headline
-----------------------------------
Frames are stroboscopic samples of a robot vibrating at hundreds of hertz, so
each measured position carries a vibration jitter of up to a few pixels that
is independent from frame to frame. Three estimates of "mean speed" are
reported:

* ``frame_to_frame_speed_mm_s`` -- the sum of distances between consecutive
  frames over the time. Jitter adds a random step to every frame, so this
  *overstates* the speed (by ~ jitter / (speed * frame interval)).
* ``net_speed_mm_s`` -- straight-line distance start to end over the time.
  Immune to jitter but *understates* the speed on any curved path.
* ``mean_speed_mm_s`` (headline) -- the time average of ``|v(t)|``, ``v`` the
  derivative of a local polynomial (Savitzky-Golay) fit to the positions over
  a window ``window_s`` long, at the frames' real (possibly uneven) times. The
  window averages the jitter down (the derivative's noise falls as
  ``window^-1.5``) while a quadratic follows the curvature of a turning path.

Motion that changes
-------------------
A start, a stop, a pause or a collision is a kink in the path that a window
straddling it would round off (the speed there misjudged, and the kink's
frames taken for outliers). :func:`change_points` finds them (one quadratic
against two lines either side, in noise sigmas) and no smoothing window
crosses them. Outliers are judged against the motion on each side
(:func:`one_sided_scores`): a position is left out only if it fits neither
the frames before it nor those after it. Two speeds are reported, both
labelled: ``mean_speed_mm_s`` over the whole clip (pauses included) and
``moving_speed_mm_s`` over its moving part (:func:`moving_part`, the
stretches in ``moving_stretches_s``, total ``moving_s``).

The smoother's own bias on a turning path (a quadratic through an arc) is
removed sample by sample, exactly for a circular arc, from the measured course
rate.

The confidence interval (the mean speed over the frames used)
-----------------------------------------------------------
The mean speed is, to first order, a *linear* function of the measured
positions: ``S = sum_j g_j . z_j`` with ``g_j`` from the fit's weights and
each sample's direction of travel. Its standard uncertainty combines, in
quadrature:

1. **Position noise** -- per axis, from the residuals about the smoothed path
   (``sum r^2 / (n - 2 tr H + tr H'H)`` for the smoother ``H``), propagated
   through ``g``: ``var = sigma^2 g' R g``.
2. **Block structure** -- ``R`` is the residuals' correlation, modelled as
   AR(1). The smoother absorbs part of any correlated noise, so the coefficient
   is the one whose noise, passed through the same smoother, reproduces the
   residuals' lag-1 correlation (simulated on a grid); the noise level is
   rescaled the same way. Correlated noise (blur, flicker, a wobble over a few
   frames) widens the interval as it should; white noise (stroboscopic jitter)
   leaves ``R = I``.
3. **Timestamp jitter** -- the frame times' scatter about the frame grid
   (dropped frames allowed), robust sigma; a frame's time off by ``dt`` moves its
   position by ``v dt`` along the path: ``sigma_t^2 sum_j (g_j . v_j)^2``. (That
   scatter also shows in the residuals, so it is counted on the safe side.)
4. **Scale** -- the image scale's relative uncertainty times the speed.

:func:`track_speed` adds the systematic parts a track shows or its user declares (scale across
the field, illumination, rolling shutter, the clock's accuracy), each by name:
:mod:`~labkit.analysis.tracking.budget`.

The noise's bias on ``|v|`` (``E|v + e| > |v|``) is subtracted; where the
speed is within three noise sigmas of zero (a robot vibrating in place) the
correction is ``sqrt(|v|^2 - var)`` and counts as uncertain by its whole size.
The interval is ``S +- z sigma`` (normal quantile), its lower end at least 0. Coverage is measured, not assumed:
``tests/tracking/test_track_speed.py`` (white and AR(1) noise on an arc) and
``tests/tracking/test_track_scenes.py`` (24 rendered videos) count how often
the 95 % interval holds the truth. The interval is for this recording's mean
speed; how much the speed varies along the track is ``speed_mm_s`` itself.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from statistics import NormalDist
from typing import Any

import numpy as np

from labkit.errors import InputError


@dataclass
class SpeedResult:
    """Smoothed path and the summary figures (mm, s, rad)."""

    t_s: np.ndarray
    x_mm: np.ndarray
    y_mm: np.ndarray
    vx_mm_s: np.ndarray
    vy_mm_s: np.ndarray
    speed_mm_s: np.ndarray
    heading_rad: np.ndarray
    turn_rate_rad_s: np.ndarray
    mean_speed_mm_s: float
    speed_ci_mm_s: tuple[float, float]
    mean_velocity_mm_s: tuple[float, float]
    velocity_ci_mm_s: tuple[tuple[float, float], tuple[float, float]]
    frame_to_frame_speed_mm_s: float
    net_speed_mm_s: float
    path_length_mm: float
    path_length_frame_to_frame_mm: float
    net_displacement_mm: float
    mean_turn_rate_rad_s: float
    duration_s: float
    window_s: float
    frames_used: int
    ci_level: float
    block_len: int
    meta: dict = field(default_factory=dict)
    # over the moving part only (see :func:`moving_part`): the clip's figures above count the pauses
    moving_speed_mm_s: float = float("nan")
    moving_speed_ci_mm_s: tuple[float, float] = (float("nan"), float("nan"))
    moving_s: float = float("nan")
    moving_stretches_s: list = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        """The scalar figures, JSON-ready."""
        d = {k: v for k, v in asdict(self).items() if not isinstance(v, np.ndarray)}
        d.pop("meta")
        return d


def poly_fit_weights(t: np.ndarray, window_s: float, order: int = 2, breaks: list[int] | None = None,
                     shared: bool = True) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """The local polynomial fit as a linear operator: per sample ``(a, value_weights, slope_weights)``.

    The smoothed value at ``t_i`` is ``value_weights @ z[a:a + m]`` and its slope
    ``slope_weights @ z[a:a + m]`` (``m`` = the weights' length); see
    :func:`local_poly_fit` for the window. Having the weights lets the speed's
    uncertainty be propagated exactly from the position noise. ``breaks``
    (sample indices, from :func:`change_points`) cut the data into stretches
    no window crosses: a break's sample ends one stretch and starts the next
    (``shared``: a position is continuous there) or only ends it (a velocity's
    direction is not).
    """
    t = np.asarray(t, float)
    n = t.size
    need = order + 2
    if n < need:
        raise ValueError(f"need at least {need} samples for an order-{order} fit")
    edges = [0, *sorted(b for b in (breaks or []) if 0 < b < n - 1), n - 1]
    seg_lo = np.zeros(n, int)
    seg_hi = np.full(n, n - 1)
    for a_i, b_i in zip(edges[:-1], edges[1:]):
        seg_lo[a_i + (a_i > 0):b_i + 1] = a_i + (a_i > 0 and not shared)
        seg_hi[a_i + (a_i > 0):b_i + 1] = b_i
    lo_t, hi_t = t[seg_lo], t[seg_hi]
    # window [t_i - w/2, t_i + w/2], shifted to stay inside the stretch near its ends
    a_t = np.clip(t - window_s / 2, lo_t, np.maximum(hi_t - window_s, lo_t))
    eps = 1e-9 * max(window_s, 1.0)
    lo = np.maximum(np.searchsorted(t, a_t - eps, side="left"), seg_lo)
    hi = np.minimum(np.searchsorted(t, a_t + window_s + eps, side="right"), seg_hi + 1)
    out = []
    for i in range(n):
        a, b = int(lo[i]), int(hi[i])
        if b - a < need:
            c = min(max(i - need // 2, 0), n - need)
            a, b = c, c + need
        dt = t[a:b] - t[i]
        scale = max(np.abs(dt).max(), 1e-12)
        P = np.linalg.pinv(np.vander(dt / scale, order + 1, increasing=True))
        out.append((a, P[0], P[1] / scale))
    return out


def change_points(t: np.ndarray, z: np.ndarray, window_s: float, sigma: np.ndarray, min_frames: int = 4,
                  threshold: float = 30.0) -> list[int]:
    """Samples where the velocity changes abruptly (a start, a stop, a collision): the smoother's breaks.

    At each sample ``k`` one quadratic through the frames either side (``window_s
    / 2`` or 8 frames, the shorter, each) is compared with two separate lines, one per side
    (``k`` in both): ``score = (RSS_quadratic - RSS_lines) /
    sigma^2`` summed over both axes, ``sigma`` the position noise per axis
    (robust, from the residuals about the smoothed path: correlated noise is
    not mistaken for kinks as it would be from frame-to-frame differences). A smooth turn fits a quadratic as
    well as two lines (score ~ 0 or below); a kink does not. The highest score
    above ``threshold`` is a break, its neighbourhood (one side's length) is
    cleared, and so on.
    """
    n = t.size
    if n < 2 * min_frames + 1:
        return []
    zn = z / np.maximum(sigma, 1e-12 * max(float(np.abs(z).max()), 1.0))
    # short sides (at most 8 frames): two changes a pause apart are then seen one by one
    half = min(window_s / 2, 8 * float(np.median(np.diff(t))))
    score = np.full(n, -np.inf)

    def rss(idx: np.ndarray, deg: int) -> float:
        dt = t[idx] - t[idx].mean()
        A = np.vander(dt / max(float(np.abs(dt).max()), 1e-12), deg + 1)
        r = zn[idx] - A @ np.linalg.lstsq(A, zn[idx], rcond=None)[0]
        return float(np.sum(r * r))

    lo = np.searchsorted(t, t - half, side="left")
    hi = np.searchsorted(t, t + half, side="right")
    for k in range(n):
        left, right = np.arange(lo[k], k + 1), np.arange(k, hi[k])
        if left.size < min_frames or right.size < min_frames:
            continue
        both = np.arange(lo[k], hi[k])
        score[k] = rss(both, 2) - rss(left, 1) - rss(right, 1)
    breaks: list[int] = []
    while True:
        k = int(np.argmax(score))
        if not score[k] > threshold:
            break
        breaks.append(k)
        score[np.abs(t - t[k]) < half] = -np.inf
    return sorted(breaks)


def local_poly_fit(t: np.ndarray, z: np.ndarray, window_s: float, order: int = 2,
                   weights: list[tuple[int, np.ndarray, np.ndarray]] | None = None,
                   breaks: list[int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Savitzky-Golay smoothing and first derivative on uneven sample times.

    At each sample a polynomial of ``order`` in ``(t - t_i)`` is fitted by least
    squares to the samples within ``window_s`` (a window shifted to stay inside
    the data near the ends, as SciPy's ``mode="interp"``); its value and slope at
    ``t_i`` are returned. On even times this is exactly Savitzky-Golay.

    Parameters
    ----------
    t : (N,) increasing times (s). z : (N,) or (N, M) samples.
    weights : the operator of :func:`poly_fit_weights` for these ``t`` (computed if None).

    Returns
    -------
    smoothed, derivative : arrays shaped like ``z``.
    """
    t = np.asarray(t, float)
    z = np.asarray(z, float)
    zz = z.reshape(t.size, -1)
    ops = weights if weights is not None else poly_fit_weights(t, window_s, order, breaks)
    out = np.empty_like(zz)
    der = np.empty_like(zz)
    for i, (a, c0, c1) in enumerate(ops):
        seg = zz[a:a + c0.size]
        out[i] = c0 @ seg
        der[i] = c1 @ seg
    return out.reshape(z.shape), der.reshape(z.shape)


def one_sided_scores(t: np.ndarray, z: np.ndarray, sigma: np.ndarray, half_s: float, frames: int = 4) -> np.ndarray:
    """How far each sample lies from its neighbours' motion, in ``sigma`` units, allowing the motion to change.

    Two lines are fitted by least squares, one to the ``frames`` samples before
    ``t_i`` and one to those after it (within ``half_s``; the sample itself
    left out), and each predicts ``z_i``. The score is the smaller of the two
    misfits (the larger axis, per ``sigma``): a start, a stop, a pause or a
    turn leaves one side's line through the sample, a lone wrong position
    neither. A side with fewer than 2 samples predicts nothing (score 0 when
    neither does).
    """
    n = t.size
    out = np.zeros(n)
    for i in range(n):
        best = np.inf
        for idx in (np.arange(max(i - frames, 0), i), np.arange(i + 1, min(i + 1 + frames, n))):
            idx = idx[np.abs(t[idx] - t[i]) <= half_s]
            if idx.size < 2:
                continue
            dt = t[idx] - t[i]
            A = np.column_stack([np.ones(idx.size), dt])
            coef = np.linalg.lstsq(A, z[idx], rcond=None)[0]
            best = min(best, float(np.max(np.abs(z[i] - coef[0]) / sigma)))
        out[i] = 0.0 if not np.isfinite(best) else best
    return out


def moving_part(t: np.ndarray, speed: np.ndarray, speed_std: np.ndarray) -> np.ndarray:
    """Which samples belong to the moving part: the smoothed speed above 3 of its noise sigmas and above
    half the typical moving speed.

    A start or a stop is smeared by the smoother symmetrically over its window,
    so the half-speed crossing falls on the change itself (a threshold near
    zero would count half a window of standing still as moving).
    """
    clear = speed > 3 * speed_std
    if not clear.any():
        return clear
    return clear & (speed > 0.5 * float(np.median(speed[clear])))


def _stretches(t: np.ndarray, mask: np.ndarray) -> list[list[float]]:
    """``[first, last]`` times of each run of True in ``mask``."""
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return [[float(t[a]), float(t[b - 1])] for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1))]


def _time_weights(t: np.ndarray) -> np.ndarray:
    """Trapezoid weights so a weighted mean is a time average over uneven samples."""
    w = np.empty_like(t)
    d = np.diff(t)
    w[0], w[-1] = d[0] / 2, d[-1] / 2
    w[1:-1] = (d[:-1] + d[1:]) / 2
    return w


def block_bootstrap_means(series: np.ndarray, weights: np.ndarray, block_len: int, n_boot: int,
                          rng: np.random.Generator) -> np.ndarray:
    """Moving-block bootstrap of a weighted mean; ``series`` is (N,) or (N, M). Returns (n_boot, ...)."""
    n = series.shape[0]
    b = int(min(max(block_len, 1), n))
    nblocks = int(np.ceil(n / b))
    starts = rng.integers(0, n - b + 1, size=(n_boot, nblocks))
    idx = (starts[:, :, None] + np.arange(b)[None, None, :]).reshape(n_boot, -1)[:, :n]
    w = weights[idx]
    s = series[idx]
    if s.ndim == 3:
        return (s * w[..., None]).sum(axis=1) / w.sum(axis=1)[:, None]
    return (s * w).sum(axis=1) / w.sum(axis=1)


_PHI_GRID = np.r_[0.0, np.linspace(0.1, 0.95, 18)]


def _ar1_from_residuals(rho1: float, ops: list[tuple[int, np.ndarray, np.ndarray]], n: int,
                        sims: int = 6, seed: int = 12345) -> tuple[float, float]:
    """AR(1) coefficient of the noise whose smoothing residuals have lag-1 correlation ``rho1``.

    Returns ``(phi, gain)``: ``gain`` = the residuals' mean square per unit noise
    variance for that ``phi`` (so sigma^2 = mean(r^2) / gain)."""
    rng = np.random.default_rng(seed)
    innov = rng.standard_normal((n, sims))
    from scipy.signal import lfilter

    cols = []
    for phi in _PHI_GRID:
        # stationary start: the first sample has the process's variance
        x0 = innov.copy()
        x0[0] /= np.sqrt(1 - phi ** 2) if phi < 1 else 1.0
        cols.append(lfilter([np.sqrt(1 - phi ** 2)], [1.0, -phi], x0, axis=0, zi=np.zeros((1, sims)))[0]
                    if phi > 0 else innov)
    big = np.concatenate(cols, axis=1)
    smooth = np.empty_like(big)
    for i, (a, c0, _c1) in enumerate(ops):
        smooth[i] = c0 @ big[a:a + c0.size]
    res = (big - smooth).reshape(n, _PHI_GRID.size, sims)
    ms = (res ** 2).mean(axis=(0, 2))
    r1 = (res[:-1] * res[1:]).mean(axis=(0, 2)) / ms
    if rho1 <= r1[0]:
        return 0.0, float(ms[0])
    if rho1 >= r1[-1]:
        return float(_PHI_GRID[-1]), float(ms[-1])
    phi = float(np.interp(rho1, r1, _PHI_GRID))
    return phi, float(np.interp(phi, _PHI_GRID, ms))


def speed_uncertainty(t: np.ndarray, z: np.ndarray, z_s: np.ndarray, v: np.ndarray, wts: np.ndarray,
                      ops: list[tuple[int, np.ndarray, np.ndarray]], window_s: float, *,
                      mm_per_px_rel_std: float = 0.0) -> dict[str, Any]:
    """Standard uncertainty of the mean speed and mean velocity (see the module docstring).

    ``z`` (N, 2) measured and ``z_s`` smoothed positions, ``v`` the smoothed
    velocity, ``wts`` the time weights, ``ops`` the fit's linear operator
    (:func:`poly_fit_weights`). Returns the parts (mm/s) and their inputs.
    """
    n = t.size
    wn = wts / wts.sum()
    sp = np.hypot(v[:, 0], v[:, 1])
    unit = np.divide(v, sp[:, None], out=np.zeros_like(v), where=sp[:, None] > 0)
    # sensitivities: d(mean speed)/d(position j) = g[j] (2-vector); d(mean velocity)/d(z_j) = gv[j]
    g = np.zeros((n, 2))
    gv = np.zeros(n)
    tr_h = tr_hh = 0.0
    c1sq = np.empty(n)
    for i, (a, c0, c1) in enumerate(ops):
        m = c0.size
        g[a:a + m] += wn[i] * c1[:, None] * unit[i][None, :]
        gv[a:a + m] += wn[i] * c1
        tr_h += float(c0[i - a]) if a <= i < a + m else 0.0
        tr_hh += float(c0 @ c0)
        c1sq[i] = float(c1 @ c1)
    # position noise per axis from the residuals; a linear smoother's residuals have
    # E[sum r^2] = sigma^2 (n - 2 tr H + tr H'H)
    r = z - z_s
    dof = max(n - 2 * tr_h + tr_hh, 1.0)
    sig2 = (r ** 2).sum(axis=0) / dof
    # block structure: the residuals are modelled as AR(1) noise. A smoother absorbs part of any
    # correlated noise, so the residuals' own lag-1 correlation understates it: the AR
    # coefficient phi is the one whose noise, passed through the same smoother, gives the
    # residuals' observed lag-1 correlation (found by simulation on a grid, common random
    # numbers); the noise level is rescaled the same way.
    frame_dt = float(np.median(np.diff(t)))
    rho1 = float(np.sum(r[:-1] * r[1:]) / max(float(np.sum(r * r)), 1e-300))
    phi, gain = _ar1_from_residuals(rho1, ops, n)
    sig2 = (r ** 2).sum(axis=0) / dof if phi == 0.0 else (r ** 2).sum(axis=0) / n / gain
    max_lag = int(np.ceil(np.log(1e-3) / np.log(phi))) if phi > 0 else 0
    max_lag = min(max_lag, n - 1)
    rho = phi ** np.arange(1, max_lag + 1)

    def quad(col: np.ndarray) -> float:
        """col' R col for the AR(1) correlation R of the position noise."""
        acc = float(col @ col)
        for k in range(1, max_lag + 1):
            acc += 2 * rho[k - 1] * float(col[:-k] @ col[k:])
        return acc

    var_noise = float(sig2[0] * quad(g[:, 0]) + sig2[1] * quad(g[:, 1]))
    var_vel = (float(sig2[0] * quad(gv)), float(sig2[1] * quad(gv)))
    # timestamp jitter: each frame's time off by dt_j moves its position along the path by v dt_j
    d = np.diff(t)
    e = d - np.maximum(np.round(d / frame_dt), 1) * frame_dt
    sig_t = float(1.4826 * np.median(np.abs(e - np.median(e))) / np.sqrt(2)) if e.size > 4 else 0.0
    sig_t = max(sig_t, float(np.std(e)) / np.sqrt(2) if e.size > 4 else 0.0)
    var_time = sig_t ** 2 * float(np.sum((g * v).sum(axis=1) ** 2))
    var_time_vel = sig_t ** 2 * float(np.sum((gv * sp) ** 2))
    # noise bias of |v|: E|v + e| ~ |v| + var(e across the path) / (2 |v|) per sample; where the
    # speed is within 3 noise sigmas of 0 (a robot vibrating in place) E|v + e|^2 = |v|^2 + var(e)
    # is used instead, and that correction counts as uncertain by its whole size
    white = float(sig2[0] * (g[:, 0] @ g[:, 0]) + sig2[1] * (g[:, 1] @ g[:, 1]))
    infl = var_noise / white if white > 0 else 1.0
    perp = sig2[0] * unit[:, 1] ** 2 + sig2[1] * unit[:, 0] ** 2
    var_tot = c1sq * sig2.sum() * infl
    usable = sp > 3 * np.sqrt(var_tot)
    b_hi = np.where(usable, c1sq * perp * infl / (2 * np.maximum(sp, 1e-30)), 0.0)
    b_lo = np.where(usable, 0.0, sp - np.sqrt(np.maximum(sp ** 2 - var_tot, 0.0)))
    bias = float(np.sum(wn * (b_hi + b_lo)))
    var_noise += float(np.sum(wn * b_lo)) ** 2
    mean_speed = float(np.sum(wn * sp)) - bias
    var_scale = (mm_per_px_rel_std * mean_speed) ** 2
    mv = (float(np.sum(wn * v[:, 0])), float(np.sum(wn * v[:, 1])))
    total = var_noise + var_time + var_scale
    return {"speed_std_mm_s": float(np.sqrt(total)),
            "velocity_std_mm_s": tuple(float(np.sqrt(var_vel[a] + var_time_vel + (mm_per_px_rel_std * mv[a]) ** 2))
                                       for a in range(2)),
            "noise_part_mm_s": float(np.sqrt(var_noise)), "timestamp_part_mm_s": float(np.sqrt(var_time)),
            "scale_part_mm_s": float(np.sqrt(var_scale)), "noise_bias_mm_s": bias,
            "position_noise_mm": [float(np.sqrt(sig2[0])), float(np.sqrt(sig2[1]))],
            "timestamp_jitter_s": sig_t, "residual_lag1_corr": rho1, "noise_ar1": phi,
            "sample_speed_std_mm_s": np.sqrt(var_tot),
            "timestamp_sensitivity_mm_s2": float(np.sqrt(np.sum((g * v).sum(axis=1) ** 2))),
            "max_lag": max_lag, "residual_dof": dof}


@dataclass
class _PathFit:
    """The positions used and their local polynomial fit (the smoothed path and its velocity)."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    window_s: float
    order: int
    breaks: list[int] = field(default_factory=list)
    ops: list = field(default_factory=list)
    xy_s: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    v: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    @property
    def z(self) -> np.ndarray:
        return np.column_stack([self.x, self.y])

    def refit(self) -> None:
        """Fit again (after dropping a position or finding change points)."""
        self.ops = poly_fit_weights(self.t, self.window_s, self.order, self.breaks or None)
        self.xy_s, self.v = local_poly_fit(self.t, self.z, self.window_s, self.order, weights=self.ops)

    def residual_sigma(self) -> np.ndarray:
        """Robust sigma of the residuals about the smoothed path, per axis."""
        r = self.z - self.xy_s
        return 1.4826 * np.median(np.abs(r - np.median(r, axis=0)), axis=0)

    def drop_outliers(self, ok: np.ndarray, max_drops: int = 20) -> int:
        """A safety net behind the tracker's gates, judged against a motion that may change.

        A position is an outlier only if it is far (> 8 robust sigmas) from BOTH short lines
        fitted to the frames just before it and just after it -- a start, a stop or a turn fits
        one side, a spike neither. The worst is left out (also from ``ok``) and the test repeated
        (at most ``max_drops`` times). Returns how many were dropped."""
        dropped = 0
        while dropped < max_drops and self.t.size > 8:
            score = one_sided_scores(self.t, self.z, np.maximum(self.residual_sigma(), 1e-12), self.window_s / 2)
            worst = int(np.argmax(score))
            if score[worst] <= 8:
                break
            ok[np.flatnonzero(ok)[worst]] = False
            keep = np.arange(self.t.size) != worst
            self.t, self.x, self.y = self.t[keep], self.x[keep], self.y[keep]
            self.refit()
            dropped += 1
        return dropped

    def arc_corrected_speed(self) -> np.ndarray:
        """Each sample's speed (and, in place, velocity) corrected for the polynomial's error on an arc.

        A polynomial through a stretch of an arc misjudges the speed there (a quadratic at the
        window's centre shortens it by ~ (w omega)^2 / 40, near a shifted window's edge it
        lengthens it): on a circle z = R exp(i omega t) the fit's slope at t_i is
        R |sum_j c1_ij exp(i omega (t_j - t_i))| instead of R omega, so each sample's speed is
        divided by that ratio at the measured course rate omega (exact for a circular arc).
        Where the robot stands still the course is the noise's and its rate means nothing: no
        correction."""
        t, v, ops = self.t, self.v, self.ops
        speed = np.hypot(v[:, 0], v[:, 1])
        course = np.unwrap(np.arctan2(v[:, 1], v[:, 0]))
        # (a break's sample carries the velocity before it: the course after it starts at the next one)
        _, course_rate = local_poly_fit(t, course, self.window_s, self.order,
                                        weights=poly_fit_weights(t, self.window_s, self.order, self.breaks,
                                                                 shared=False) if self.breaks else ops)
        om = np.maximum(np.abs(course_rate), 1e-4)
        shrink = np.ones(t.size)
        sig_v = np.array([np.sqrt(float(c1 @ c1)) for _a, _c0, c1 in ops]) * float(
            np.sqrt(np.sum(self.residual_sigma() ** 2)))
        for i, (a, _c0, c1) in enumerate(ops):
            if speed[i] > 5 * sig_v[i]:
                shrink[i] = abs(np.sum(c1 * np.exp(1j * om[i] * (t[a:a + c1.size] - t[i])))) / om[i]
        shrink = np.clip(shrink, 0.5, 2.0)
        self.v = v / shrink[:, None]
        return speed / shrink

    def time_weights(self) -> np.ndarray:
        """Each sample's share of the time; a break's sample carries the speed before it, the half
        interval after it goes to the next sample (which carries the speed after it)."""
        wts = _time_weights(self.t)
        for k in self.breaks:
            half = (self.t[k + 1] - self.t[k]) / 2
            wts[k] -= half
            wts[k + 1] += half
        return wts

    def turning(self, hd: np.ndarray | None, duration: float) -> tuple[np.ndarray, np.ndarray, float]:
        """(smoothed heading, turn rate, mean turn rate): from the heading ``hd`` at the samples used
        if it is known often enough, else from the course."""
        t, w, o = self.t, self.window_s, self.order
        if hd is not None and np.isfinite(hd).sum() >= o + 2:
            good = np.isfinite(hd)
            hs, hr = local_poly_fit(t[good], hd[good], w, o)
            return (np.interp(t, t[good], hs), np.interp(t, t[good], hr),
                    float((hs[-1] - hs[0]) / max(t[good][-1] - t[good][0], 1e-12)))
        head_s = np.unwrap(np.arctan2(-self.v[:, 0], self.v[:, 1]))   # course, in the heading convention
        _, turn = local_poly_fit(t, head_s, w, o)
        return head_s, turn, float((head_s[-1] - head_s[0]) / max(duration, 1e-12))


def speed_analysis(t_s: np.ndarray, x_mm: np.ndarray, y_mm: np.ndarray, heading_rad: np.ndarray | None = None,
                   quality: np.ndarray | None = None, *, window_s: float | None = None, order: int = 2,
                   mm_per_px_rel_std: float = 0.0, ci_level: float = 0.95, n_boot: int = 2000,
                   seed: int = 0) -> SpeedResult:
    """Speed and turning of a tracked robot (see the module docstring for the choices).

    Parameters
    ----------
    t_s, x_mm, y_mm, heading_rad:
        Per-frame track; frames with NaN or ``quality != 0`` are left out.
    window_s:
        Smoothing window; default ``1.0`` s, but at least 7 frame intervals and at
        most half the track's duration.
    mm_per_px_rel_std:
        Relative standard uncertainty of the image scale, folded into the intervals.
    """
    t = np.asarray(t_s, float)
    ok = np.isfinite(t) & np.isfinite(np.asarray(x_mm, float)) & np.isfinite(np.asarray(y_mm, float))
    if quality is not None:
        ok &= np.asarray(quality) == 0
    if ok.sum() < 8:
        raise InputError(f"only {int(ok.sum())} clearly tracked frames", key="track",
                         expected="at least 8 frames with the robot fully in view")
    t = t[ok]
    duration = float(t[-1] - t[0])
    frame_dt = float(np.median(np.diff(t)))
    if window_s is None:
        window_s = min(max(1.0, 7 * frame_dt), duration / 2)
    fit = _PathFit(t, np.asarray(x_mm, float)[ok], np.asarray(y_mm, float)[ok],
                   float(max(window_s, (order + 1) * frame_dt)), order)
    fit.refit()
    del seed, n_boot      # kept in the signature for callers of the bootstrap version
    outliers = fit.drop_outliers(ok)
    # starts, stops and collisions: the smoother's windows do not cross them (a window across a
    # kink rounds it off and misjudges the path's length there)
    fit.breaks = change_points(fit.t, fit.z, fit.window_s, fit.residual_sigma())
    if fit.breaks:
        fit.refit()
    speed = fit.arc_corrected_speed()
    return _speed_result(fit, speed, ok, None if heading_rad is None else np.asarray(heading_rad, float)[ok],
                         SpeedOptions(mm_per_px_rel_std, ci_level, outliers))


@dataclass
class SpeedOptions:
    """What :func:`_speed_result` needs besides the fit."""

    mm_per_px_rel_std: float
    ci_level: float
    outliers: int


def _speed_result(fit: _PathFit, speed: np.ndarray, ok: np.ndarray, hd: np.ndarray | None,
                  opt: SpeedOptions) -> SpeedResult:
    """The means, their intervals, the moving part and the path's lengths, from the corrected fit."""
    t, x, y, xy_s, v = fit.t, fit.x, fit.y, fit.xy_s, fit.v
    duration = float(t[-1] - t[0])
    wts = fit.time_weights()
    mean_speed = float(np.sum(speed * wts) / np.sum(wts))
    mean_vel = (float(np.sum(v[:, 0] * wts) / wts.sum()), float(np.sum(v[:, 1] * wts) / wts.sum()))
    path_ff = float(np.hypot(np.diff(x), np.diff(y)).sum())
    net = float(np.hypot(xy_s[-1, 0] - xy_s[0, 0], xy_s[-1, 1] - xy_s[0, 1]))
    head_s, turn, mean_turn = fit.turning(hd, duration)
    # the interval: the estimator is linear in the positions (up to |v|), so the position noise
    # measured from the residuals is propagated exactly (see :func:`speed_uncertainty`)
    unc = speed_uncertainty(t, fit.z, xy_s, v, wts, fit.ops, fit.window_s, mm_per_px_rel_std=opt.mm_per_px_rel_std)
    mean_speed -= unc["noise_bias_mm_s"]
    zq = NormalDist().inv_cdf(0.5 + opt.ci_level / 2)
    sd, sdv = unc["speed_std_mm_s"], unc["velocity_std_mm_s"]
    q = np.array([[max(mean_speed - zq * sd, 0.0), mean_vel[0] - zq * sdv[0], mean_vel[1] - zq * sdv[1]],
                  [mean_speed + zq * sd, mean_vel[0] + zq * sdv[0], mean_vel[1] + zq * sdv[1]]])
    block = int(unc["max_lag"]) + 1
    sample_sd = unc.pop("sample_speed_std_mm_s")
    moving = moving_part(t, speed, sample_sd)
    moving_s = float(np.sum(wts[moving]))
    # the same path over the time spent moving (its interval scaled alike)
    k_mov = duration / moving_s if moving_s > 0 else float("nan")
    return SpeedResult(
        t_s=t, x_mm=xy_s[:, 0], y_mm=xy_s[:, 1], vx_mm_s=v[:, 0], vy_mm_s=v[:, 1], speed_mm_s=speed,
        heading_rad=head_s, turn_rate_rad_s=turn, mean_speed_mm_s=mean_speed,
        speed_ci_mm_s=(float(q[0, 0]), float(q[1, 0])), mean_velocity_mm_s=mean_vel,
        velocity_ci_mm_s=((float(q[0, 1]), float(q[1, 1])), (float(q[0, 2]), float(q[1, 2]))),
        frame_to_frame_speed_mm_s=path_ff / duration if duration > 0 else float("nan"),
        net_speed_mm_s=net / duration if duration > 0 else float("nan"),
        path_length_mm=mean_speed * duration, path_length_frame_to_frame_mm=path_ff, net_displacement_mm=net,
        mean_turn_rate_rad_s=mean_turn, duration_s=duration, window_s=fit.window_s, frames_used=int(t.size),
        ci_level=opt.ci_level, block_len=block,
        meta={"order": fit.order, "mm_per_px_rel_std": opt.mm_per_px_rel_std, "uncertainty": unc,
              "outliers_dropped": opt.outliers, "change_points_s": [float(t[b]) for b in fit.breaks]},
        moving_speed_mm_s=mean_speed * k_mov, moving_speed_ci_mm_s=(float(q[0, 0]) * k_mov, float(q[1, 0]) * k_mov),
        moving_s=moving_s, moving_stretches_s=_stretches(t, moving))


def _track_xy(track, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Image positions -> world mm (as :attr:`Track.x_mm`, :attr:`Track.y_mm`)."""
    return (u + 0.5) * track.mm_per_px, (track.frame_size[1] - 0.5 - v) * track.mm_per_px


def track_speed(track, *, line_time_s: float | None = None, line_time_std_s: float = 0.0,
                timestamp_std_s: float | None = None, budget: bool = True, **kw) -> SpeedResult:
    """:func:`speed_analysis` of a :class:`labkit.analysis.tracking.tracker.Track`, with its error budget.

    The interval holds the random part and every systematic part of
    :mod:`~labkit.analysis.tracking.budget` (scale, scale across the field,
    illumination, rolling shutter, timestamps), each in ``meta["budget"]``.
    ``line_time_s``: a rolling shutter's delay per row (the frame times are
    corrected at the robot's row), uncertain by ``line_time_std_s``;
    ``timestamp_std_s``: the clock's declared accuracy per frame.
    ``budget=False``: the random part and the scale only.
    """
    from labkit.analysis.tracking.budget import error_budget

    rel = 0.0
    if track.scale is not None and track.scale.mm_per_px > 0:
        rel = track.scale.mm_per_px_std / track.scale.mm_per_px
    if line_time_s is not None and not (line_time_s >= 0 and line_time_std_s >= 0):
        raise InputError(f"bad line time {line_time_s}", key="--line-time-us", expected="a delay per row >= 0")

    def run(lt: float | None, u: np.ndarray, v: np.ndarray, heading: Any = None, **extra: Any) -> SpeedResult:
        t = track.t_s + track.v_px * lt if lt else track.t_s
        x, y = _track_xy(track, u, v)
        return speed_analysis(t, x, y, heading, track.quality, mm_per_px_rel_std=rel, **{**kw, **extra})

    sp = run(line_time_s, track.u_px, track.v_px, track.heading_rad)
    if not budget:
        return sp
    same = {"window_s": sp.window_s}
    alt = float("nan")
    if track.u_alt_px is not None:
        alt = run(line_time_s, track.u_alt_px, track.v_alt_px, **same).mean_speed_mm_s
    rs_part = rs_bound = 0.0
    if line_time_s is not None and line_time_std_s > 0:
        rs_part = abs(run(line_time_s + line_time_std_s, track.u_px, track.v_px, **same).mean_speed_mm_s
                      - sp.mean_speed_mm_s)
    if line_time_s is None and track.frames > 2:
        longest = float(np.median(np.diff(track.t_s))) / max(track.frame_size[1], 1)
        rs_bound = abs(run(longest, track.u_px, track.v_px, **same).mean_speed_mm_s - sp.mean_speed_mm_s)
    eb = error_budget(track, sp, alt_speed_mm_s=alt, rs_bound_mm_s=rs_bound, line_time_s=line_time_s,
                      rs_part_mm_s=rs_part, timestamp_std_s=timestamp_std_s)
    zq = NormalDist().inv_cdf(0.5 + sp.ci_level / 2)
    s = sp.mean_speed_mm_s
    sp.speed_ci_mm_s = (max(s - zq * eb.total_std_mm_s, 0.0), s + zq * eb.total_std_mm_s)
    k = sp.moving_speed_mm_s / s if s > 0 else float("nan")
    sp.moving_speed_ci_mm_s = (sp.speed_ci_mm_s[0] * k, sp.speed_ci_mm_s[1] * k)
    sp.meta["budget"] = eb.as_dict()
    sp.meta["budget_warnings"] = eb.warnings
    return sp
