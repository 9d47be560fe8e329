"""The renderer's truth is exact: the tracker's tests stand on it."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from labkit.lab.render import ROBOT_REFLECTANCE, TEFLON_LEVEL, render_frames, robot_polygons_mm, write_video


def _polygon_area_mm2() -> float:
    polys = robot_polygons_mm()
    body = polys[0]
    area = np.ptp(body[:, 0]) * np.ptp(body[:, 1])
    for p in polys[1:]:   # legs overlap the body by 1e-3 mm (no gap): count only outside
        area += (np.ptp(p[:, 0]) - 1e-3) * np.ptp(p[:, 1])
    return float(area)


def test_darkness_centroid_and_axis_match_truth():
    rng = np.random.default_rng(3)
    n = 12
    t = np.arange(n) / 30
    y, x, h = rng.uniform(-4, 4, n), rng.uniform(-6, 6, n), rng.uniform(-np.pi, np.pi, n)
    frames, truth = render_frames(y, x, h, t, noise=0.0, return_truth=True)
    assert frames.shape == (n, 480, 640) and frames.dtype == np.uint8
    vv, uu = np.mgrid[:480, :640]
    for k in range(n):
        w = (TEFLON_LEVEL - frames[k].astype(float)) / (TEFLON_LEVEL * (1 - ROBOT_REFLECTANCE))
        m = w.sum()
        cu, cv = (w * uu).sum() / m, (w * vv).sum() / m
        assert abs(cu - truth.u_px[k]) < 0.05 and abs(cv - truth.v_px[k]) < 0.05   # uint8 rounding
        mu20, mu02 = (w * (uu - cu) ** 2).sum(), (w * (vv - cv) ** 2).sum()
        mu11 = (w * (uu - cu) * (vv - cv)).sum()
        axis_world = -0.5 * np.arctan2(2 * mu11, mu20 - mu02) - np.pi / 2
        d = np.angle(np.exp(2j * (axis_world - h[k]))) / 2      # compare modulo 180 degrees
        assert abs(np.degrees(d)) < 0.1
        # area coverage is exact: the rasterised area is the polygons' area
        assert m == pytest.approx(_polygon_area_mm2() / 0.05 ** 2, rel=3e-3)


def test_nuisances_change_what_they_should():
    t = np.arange(30) / 30
    y = 3 * t
    clean, tc = render_frames(y, None, 0.0, t, noise=0.0, return_truth=True)
    jit, tj = render_frames(y, None, 0.0, t, noise=0.0, jitter_px=2.0, return_truth=True, seed=4)
    shift = np.hypot(tj.u_px - tj.u_world_px, tj.v_px - tj.v_world_px)
    assert shift.max() <= 2 * np.sqrt(2) + 1e-9 and shift.std() > 0.3
    assert np.allclose(tj.u_world_px, tc.u_px) and np.allclose(tj.v_world_px, tc.v_px)
    hidden, th = render_frames(y, None, 0.0, t, noise=0.0, occlusion=[(0.3, 0.5)], return_truth=True)
    gone = (t >= 0.3) & (t <= 0.5)
    assert np.array_equal(~th.visible, gone)
    assert hidden[gone].min() > 150 and hidden[~gone].min() < 60      # no chip while hidden
    drift = render_frames(y, None, 0.0, t, noise=0.0, lighting_drift=0.3)
    means = drift.reshape(30, -1).mean(axis=1)
    assert np.ptp(means) > 30            # a slow brightness change of tens of grey levels
    rim = render_frames(y[:1], None, 0.0, t[:1], noise=0.0, tray_rect_px=(0, 0, 500, 480))
    assert rim[0, :, 505:].mean() < 0.5 * rim[0, :, :450].mean()
    tex = render_frames(y[:1], None, 0.0, t[:1], noise=0.0, texture=0.05)
    assert tex[0, :100, :100].std() > 3 and clean[0, :100, :100].std() == 0


def test_write_video_roundtrip(tmp_path):
    t = np.arange(20) / 25
    frames = render_frames(2 * t, None, 0.3, t, noise=1.0)
    # Motion-JPEG .avi: every frame back, timestamps k / fps from the container
    p = write_video(tmp_path / "a.avi", frames, 25.0)
    cap = cv2.VideoCapture(str(p))
    ts, n = [], 0
    while True:
        ok, f = cap.read()
        if not ok:
            break
        ts.append(cap.get(cv2.CAP_PROP_POS_MSEC) / 1000)
        assert np.abs(cv2.cvtColor(f, cv2.COLOR_BGR2GRAY).astype(int) - frames[n]).mean() < 1.0
        n += 1
    assert n == 20 and np.allclose(ts, t, atol=1e-6)
    # lossless FFV1: bit exact
    p = write_video(tmp_path / "b.avi", frames, 25.0, lossless=True)
    cap = cv2.VideoCapture(str(p))
    for k in range(20):
        ok, f = cap.read()
        assert ok and np.array_equal(cv2.cvtColor(f, cv2.COLOR_BGR2GRAY), frames[k])
    # uneven timestamps in Matroska: each frame keeps its own time (to 1 ms)
    tu = np.cumsum(np.r_[0, np.random.default_rng(0).uniform(0.02, 0.07, 19)])
    p = write_video(tmp_path / "c.mkv", frames, 25.0, t_s=tu)
    cap = cv2.VideoCapture(str(p))
    got = []
    while cap.read()[0]:
        got.append(cap.get(cv2.CAP_PROP_POS_MSEC) / 1000)
    assert len(got) == 20 and np.abs(np.array(got) - tu).max() <= 0.0005 + 1e-9
    with pytest.raises(ValueError, match="mkv"):
        write_video(tmp_path / "d.avi", frames, 25.0, t_s=tu)
