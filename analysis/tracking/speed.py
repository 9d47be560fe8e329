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

The confidence interval comes from a moving-block bootstrap (replicates centred on the estimate) of the
instantaneous smoothed speed (blocks of at least two windows, since speeds
within a window are correlated), each replicate multiplied by a draw of the
image scale's relative uncertainty, so the interval holds both the
variability along the track and the scale's calibration.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
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

    def summary(self) -> dict[str, Any]:
        """The scalar figures, JSON-ready."""
        d = {k: v for k, v in asdict(self).items() if not isinstance(v, np.ndarray)}
        d.pop("meta")
        return d


def local_poly_fit(t: np.ndarray, z: np.ndarray, window_s: float, order: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Savitzky-Golay smoothing and first derivative on uneven sample times.

    At each sample a polynomial of ``order`` in ``(t - t_i)`` is fitted by least
    squares to the samples within ``window_s`` (a window shifted to stay inside
    the data near the ends, as SciPy's ``mode="interp"``); its value and slope at
    ``t_i`` are returned. On even times this is exactly Savitzky-Golay.

    Parameters
    ----------
    t : (N,) increasing times (s). z : (N,) or (N, M) samples.

    Returns
    -------
    smoothed, derivative : arrays shaped like ``z``.
    """
    t = np.asarray(t, float)
    z = np.asarray(z, float)
    zz = z.reshape(t.size, -1)
    n = t.size
    need = order + 2
    if n < need:
        raise ValueError(f"need at least {need} samples for an order-{order} fit")
    # window [t_i - w/2, t_i + w/2], shifted to stay inside the data near the ends
    a_t = np.clip(t - window_s / 2, t[0], max(t[-1] - window_s, t[0]))
    eps = 1e-9 * max(window_s, 1.0)
    lo = np.searchsorted(t, a_t - eps, side="left")
    hi = np.searchsorted(t, a_t + window_s + eps, side="right")
    out = np.empty_like(zz)
    der = np.empty_like(zz)
    for i in range(n):
        a, b = lo[i], hi[i]
        if b - a < need:
            c = min(max(i - need // 2, 0), n - need)
            a, b = c, c + need
        dt = t[a:b] - t[i]
        scale = max(np.abs(dt).max(), 1e-12)
        V = np.vander(dt / scale, order + 1, increasing=True)
        coef, *_ = np.linalg.lstsq(V, zz[a:b], rcond=None)
        out[i] = coef[0]
        der[i] = coef[1] / scale
    return out.reshape(z.shape), der.reshape(z.shape)


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
    x = np.asarray(x_mm, float)
    y = np.asarray(y_mm, float)
    ok = np.isfinite(t) & np.isfinite(x) & np.isfinite(y)
    if quality is not None:
        ok &= np.asarray(quality) == 0
    if heading_rad is not None:
        hd_all = np.asarray(heading_rad, float)
    t, x, y = t[ok], x[ok], y[ok]
    if t.size < 8:
        raise InputError(f"only {t.size} clearly tracked frames", key="track",
                         expected="at least 8 frames with the robot fully in view")
    duration = float(t[-1] - t[0])
    frame_dt = float(np.median(np.diff(t)))
    if window_s is None:
        window_s = min(max(1.0, 7 * frame_dt), duration / 2)
    window_s = float(max(window_s, (order + 1) * frame_dt))
    xy_s, v = local_poly_fit(t, np.column_stack([x, y]), window_s, order)
    speed = np.hypot(v[:, 0], v[:, 1])
    wts = _time_weights(t)
    mean_speed = float(np.sum(speed * wts) / np.sum(wts))
    mean_vel = (float(np.sum(v[:, 0] * wts) / wts.sum()), float(np.sum(v[:, 1] * wts) / wts.sum()))
    steps = np.hypot(np.diff(x), np.diff(y))
    path_ff = float(steps.sum())
    net = float(np.hypot(xy_s[-1, 0] - xy_s[0, 0], xy_s[-1, 1] - xy_s[0, 1]))

    if heading_rad is not None and np.isfinite(hd_all[ok]).sum() >= order + 2:
        hd = hd_all[ok]
        good = np.isfinite(hd)
        hs, hr = local_poly_fit(t[good], hd[good], window_s, order)
        head_s = np.interp(t, t[good], hs)
        turn = np.interp(t, t[good], hr)
        mean_turn = float((hs[-1] - hs[0]) / max(t[good][-1] - t[good][0], 1e-12))
    else:
        head_s = np.unwrap(np.arctan2(-v[:, 0], v[:, 1]))   # course, in the heading convention
        _, turn = local_poly_fit(t, head_s, window_s, order)
        mean_turn = float((head_s[-1] - head_s[0]) / max(duration, 1e-12))

    # block bootstrap: blocks of >= 2 smoothing windows (speeds within a window are correlated)
    rng = np.random.default_rng(seed)
    per_window = max(int(round(window_s / frame_dt)), 1)
    block = int(min(max(2 * per_window, round(t.size ** (1 / 3))), max(t.size // 3, 1)))
    series = np.column_stack([speed, v])
    boot = block_bootstrap_means(series, wts, block, n_boot, rng)
    if mm_per_px_rel_std > 0:
        boot = boot * (1 + mm_per_px_rel_std * rng.standard_normal(n_boot))[:, None]
    alpha = (1 - ci_level) / 2
    # centre the replicates on the estimate: the moving-block bootstrap under-samples both ends
    # of the series, which shifts its mean when the ends differ (start/stop, end effects)
    point = np.array([mean_speed, mean_vel[0], mean_vel[1]])
    q = np.quantile(boot - boot.mean(axis=0) + point, [alpha, 1 - alpha], axis=0)
    return SpeedResult(
        t_s=t, x_mm=xy_s[:, 0], y_mm=xy_s[:, 1], vx_mm_s=v[:, 0], vy_mm_s=v[:, 1], speed_mm_s=speed,
        heading_rad=head_s, turn_rate_rad_s=turn, mean_speed_mm_s=mean_speed,
        speed_ci_mm_s=(float(q[0, 0]), float(q[1, 0])), mean_velocity_mm_s=mean_vel,
        velocity_ci_mm_s=((float(q[0, 1]), float(q[1, 1])), (float(q[0, 2]), float(q[1, 2]))),
        frame_to_frame_speed_mm_s=path_ff / duration if duration > 0 else float("nan"),
        net_speed_mm_s=net / duration if duration > 0 else float("nan"),
        path_length_mm=mean_speed * duration, path_length_frame_to_frame_mm=path_ff, net_displacement_mm=net,
        mean_turn_rate_rad_s=mean_turn, duration_s=duration, window_s=window_s, frames_used=int(t.size),
        ci_level=ci_level, block_len=block,
        meta={"order": order, "n_boot": n_boot, "mm_per_px_rel_std": mm_per_px_rel_std,
              "blocks": int(np.ceil(t.size / block))})


def track_speed(track, **kw) -> SpeedResult:
    """:func:`speed_analysis` of a :class:`labkit.analysis.tracking.tracker.Track`.

    The track's scale uncertainty is included.
    """
    rel = 0.0
    if track.scale is not None and track.scale.mm_per_px > 0:
        rel = track.scale.mm_per_px_std / track.scale.mm_per_px
    return speed_analysis(track.t_s, track.x_mm, track.y_mm, track.heading_rad, track.quality,
                          mm_per_px_rel_std=rel, **kw)
