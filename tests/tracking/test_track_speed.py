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


@pytest.mark.parametrize("phi", [0.0, 0.7])
def test_interval_covers_white_and_correlated_noise(phi):
    """95 % intervals hold the true mean speed of an arc in ~95 % of noisy tracks.

    The noise is white (stroboscopic jitter) or AR(1) with coefficient 0.7 (a block
    structure: correlated over ~3 frames), which a white-noise propagation would
    under-cover (about 75 % here)."""
    rng = np.random.default_rng(7)
    t = np.arange(0, 3, 1 / 30)
    r, v = 8.0, 2.0
    x0, y0 = r * np.sin(v * t / r), r * (1 - np.cos(v * t / r))
    v_mean = np.array([x0[-1] - x0[0], y0[-1] - y0[0]]) / (t[-1] - t[0])     # the true mean velocity
    hits, vhits, n, z = 0, 0, 120, []
    for _ in range(n):
        e = 0.05 * rng.standard_normal((t.size, 2))
        for i in range(1, t.size):
            e[i] = phi * e[i - 1] + np.sqrt(1 - phi ** 2) * e[i]
        res = speed_analysis(t, x0 + e[:, 0], y0 + e[:, 1])
        lo, hi = res.speed_ci_mm_s
        hits += lo <= v <= hi
        (ax, bx), (ay, by) = res.velocity_ci_mm_s
        vhits += int(ax <= v_mean[0] <= bx) + int(ay <= v_mean[1] <= by)
        z.append((res.mean_speed_mm_s - v) / res.meta["uncertainty"]["speed_std_mm_s"])
    print(f"AR(1) {phi}: {hits} of {n} speed intervals hold the truth (velocity components: {vhits} of {2 * n}); "
          f"z rms {np.sqrt(np.mean(np.square(z))):.2f}")
    assert hits >= 0.9 * n and vhits >= 0.85 * 2 * n
    assert 0.75 < np.sqrt(np.mean(np.square(z))) < 1.3          # neither too narrow nor too wide
    assert abs(np.mean(z)) < 0.3                                # no bias (the arc's smoothing bias is removed)


def test_interval_includes_scale_and_timestamp_uncertainty():
    rng = np.random.default_rng(3)
    t = np.arange(0, 8, 1 / 30)
    y = 2.0 * t
    x = 0.02 * rng.standard_normal(t.size)
    y_n = y + 0.02 * rng.standard_normal(t.size)
    a = speed_analysis(t, x, y_n)
    b = speed_analysis(t, x, y_n, mm_per_px_rel_std=0.02)
    wa = a.speed_ci_mm_s[1] - a.speed_ci_mm_s[0]
    wb = b.speed_ci_mm_s[1] - b.speed_ci_mm_s[0]
    # the position noise along the path, propagated: about sqrt(2) end windows of 30 frames
    assert 0.001 < wa < 0.02
    assert wb == pytest.approx(2 * 1.96 * np.hypot(0.02 * a.mean_speed_mm_s, wa / 3.92), rel=0.01)
    assert a.speed_ci_mm_s[0] < 2.0 < a.speed_ci_mm_s[1]
    # frame times known to +-2 ms only (a camera's clock): the timestamp part appears
    tj = t + rng.uniform(-0.002, 0.002, t.size)
    c = speed_analysis(tj, x, y + 0 * tj)
    unc = c.meta["uncertainty"]
    assert unc["timestamp_jitter_s"] == pytest.approx(0.002 / np.sqrt(3), rel=0.3)
    assert unc["timestamp_part_mm_s"] > 0


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


def test_a_far_off_position_is_left_out():
    rng = np.random.default_rng(5)
    t = np.arange(90) / 30
    x, y = 0.01 * rng.standard_normal(90), 2.0 * t + 0.01 * rng.standard_normal(90)
    y_bad = y.copy()
    y_bad[40] += 4.0              # a frame on a tweezer's prong that no gate caught
    res = speed_analysis(t, x, y_bad)
    assert res.meta["outliers_dropped"] == 1 and res.frames_used == 89
    assert res.mean_speed_mm_s == pytest.approx(2.0, rel=0.005)
    assert speed_analysis(t, x, y).meta["outliers_dropped"] == 0


def test_block_bootstrap_shapes_and_mean():
    rng = np.random.default_rng(4)
    s = rng.standard_normal((100, 2)) + [3.0, -1.0]
    m = block_bootstrap_means(s, np.ones(100), 10, 500, rng)
    assert m.shape == (500, 2)
    assert np.allclose(m.mean(axis=0), s.mean(axis=0), atol=0.03)
