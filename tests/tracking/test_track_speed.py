"""Speed from a track: the smoothing, the three estimates and the bootstrap interval."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import savgol_filter

from labkit.analysis.tracking.speed import block_bootstrap_means, local_poly_fit, speed_analysis
from labkit.errors import InputError


def test_local_poly_fit_is_savitzky_golay_on_even_times():
    t = np.arange(120) / 30
    z = np.sin(2 * t) + 0.02 * np.random.default_rng(0).standard_normal(t.size)
    s, d = local_poly_fit(t, z, window_s=14 / 30, order=2)       # 15 samples
    assert np.allclose(s, savgol_filter(z, 15, 2, mode="interp"), atol=1e-12)
    assert np.allclose(d, savgol_filter(z, 15, 2, deriv=1, delta=1 / 30, mode="interp"), atol=1e-10)


def test_local_poly_fit_exact_on_uneven_times():
    t = np.sort(np.random.default_rng(1).uniform(0, 3, 70))
    z = np.column_stack([1 + 2 * t + 0.5 * t ** 2, -t ** 2])
    s, d = local_poly_fit(t, z, window_s=0.6, order=2)
    assert np.allclose(s, z, atol=1e-10)
    assert np.allclose(d, np.column_stack([2 + t, -2 * t]), atol=1e-9)


def test_three_estimates_on_a_jittered_arc():
    rng = np.random.default_rng(2)
    t = np.arange(0, 6, 1 / 30)
    r, v = 8.0, 2.0
    ph = v * t / r
    x, y = r * np.sin(ph), r * (1 - np.cos(ph))
    jit = 0.1 * np.sin(rng.uniform(0, 2 * np.pi, (t.size, 2)))     # 2 px at 0.05 mm/px
    res = speed_analysis(t, x + jit[:, 0], y + jit[:, 1])
    assert res.mean_speed_mm_s == pytest.approx(v, rel=0.01)
    assert res.frame_to_frame_speed_mm_s > 1.3 * v
    chord = 2 * r * np.sin(ph[-1] / 2) / t[-1]
    assert res.net_speed_mm_s == pytest.approx(chord, rel=0.01) and chord < 0.95 * v
    assert res.path_length_mm == pytest.approx(v * t[-1], rel=0.01)
    lo, hi = res.speed_ci_mm_s
    assert lo < res.mean_speed_mm_s < hi
    vx, vy = res.mean_velocity_mm_s
    assert vx == pytest.approx(x[-1] / t[-1], rel=0.03) and vy == pytest.approx(y[-1] / t[-1], rel=0.05)
    # course turning: v / r
    assert res.mean_turn_rate_rad_s == pytest.approx(v / r, rel=0.03)


def test_interval_covers_and_includes_scale_uncertainty():
    rng = np.random.default_rng(3)
    t = np.arange(0, 8, 1 / 30)
    # speed varies slowly along the walk (as a robot's does): 2 mm/s +- 0.1
    speed = 2 + 0.1 * np.sin(2 * np.pi * t / 3.1 + 1)
    y = np.cumsum(speed) / 30
    x = 0.02 * rng.standard_normal(t.size)
    a = speed_analysis(t, x, y, seed=1)
    b = speed_analysis(t, x, y, mm_per_px_rel_std=0.02, seed=1)
    wa = a.speed_ci_mm_s[1] - a.speed_ci_mm_s[0]
    wb = b.speed_ci_mm_s[1] - b.speed_ci_mm_s[0]
    assert wa > 0.01                                  # the speed's own variation is seen
    assert wb > wa * 1.5                              # 2 % scale uncertainty widens it
    assert wb == pytest.approx(2 * 1.96 * np.hypot(0.02 * a.mean_speed_mm_s, wa / 3.92), rel=0.35)
    assert a.speed_ci_mm_s[0] < np.mean(speed) < a.speed_ci_mm_s[1]


def test_bad_frames_left_out_and_too_few_frames_refused():
    t = np.arange(40) / 20
    x, y = np.zeros(40), 1.5 * t
    q = np.zeros(40, int)
    y_bad = y.copy()
    y_bad[10:15] = 99.0          # degraded frames with a wrong position
    q[10:15] = 1
    res = speed_analysis(t, x, y_bad, quality=q)
    assert res.frames_used == 35 and res.mean_speed_mm_s == pytest.approx(1.5, rel=1e-6)
    with pytest.raises(InputError, match="tracked frames"):
        speed_analysis(t[:5], x[:5], y[:5])


def test_block_bootstrap_shapes_and_mean():
    rng = np.random.default_rng(4)
    s = rng.standard_normal((100, 2)) + [3.0, -1.0]
    m = block_bootstrap_means(s, np.ones(100), 10, 500, rng)
    assert m.shape == (500, 2)
    assert np.allclose(m.mean(axis=0), s.mean(axis=0), atol=0.03)
