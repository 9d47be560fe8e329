"""Motion that changes: starts, stops, pauses, turns and a soft body are kept, not thrown out as outliers.

Scenes from ``issue_scenes`` (an independent renderer). Each asserts that every frame is used,
that the clip's speed and the moving part's speed match the truth (rendered path length over
the clip's duration and over the time spent moving), and that the 95 % interval holds them.
"""
from __future__ import annotations

import numpy as np
import pytest
from issue_scenes import Camera, Leg, Robot, render
from render_scenes import write_avi

from labkit.analysis.tracking import track_speed, track_video
from labkit.analysis.tracking.speed import change_points, speed_analysis

MOTIONS = {
    "start": [Leg(1.0, 0.0), Leg(10, 3.0, 0.2)],
    "stop": [Leg(1.5, 3.0), Leg(10, 0.0)],
    "pause_and_turn": [Leg(0.8, 3.0), Leg(0.5, 0.0), Leg(10, 2.0, -0.4)],
}


@pytest.mark.parametrize("name", list(MOTIONS))
def test_starts_stops_and_pauses_are_kept(tmp_path, name):
    cam = Camera(n=90)
    frames, truth = render(cam, Robot(legs=MOTIONS[name]), seed=3)
    path = write_avi(tmp_path / f"{name}.avi", frames, cam.fps)
    sp = track_speed(track_video(path, mm_per_px=cam.mm_per_px))
    assert sp.frames_used == cam.n and sp.meta["outliers_dropped"] == 0
    assert sp.mean_speed_mm_s == pytest.approx(truth.speed_mm_s, rel=0.005)
    lo, hi = sp.speed_ci_mm_s
    assert lo <= truth.speed_mm_s <= hi
    # the moving part, labelled apart: the stretches' total within a frame of the truth
    assert sp.moving_speed_mm_s == pytest.approx(truth.moving_speed_mm_s, rel=0.005)
    assert abs(sp.moving_s - truth.moving_s) <= 1.01 / cam.fps
    assert sp.moving_speed_ci_mm_s[0] <= truth.moving_speed_mm_s <= sp.moving_speed_ci_mm_s[1]


def test_a_soft_body_is_not_rejected_by_shape(tmp_path):
    """A body whose length swings +-30 % (a mouse, a curling soft robot) is tracked in every frame."""
    cam = Camera(n=90)
    rb = Robot(legs=[Leg(10, 3.0, 0.2)], breathe=(0.3, 0.7))
    frames, truth = render(cam, rb, seed=4)
    path = write_avi(tmp_path / "soft.avi", frames, cam.fps)
    trk = track_video(path, mm_per_px=cam.mm_per_px)
    assert trk.lost_frames == 0 and trk.meta["unlike_frames"] == 0
    err = np.hypot(trk.u_px - truth.u_px, trk.v_px - truth.v_px)
    assert np.max(err) < 0.3
    sp = track_speed(trk)
    assert sp.frames_used == cam.n and sp.mean_speed_mm_s == pytest.approx(truth.speed_mm_s, rel=0.01)


def test_change_points_found_where_the_drive_switches():
    """Kinks in a noisy path are found to the frame; a smooth arc and correlated noise give none."""
    rng = np.random.default_rng(2)
    t = np.arange(120) / 30
    y = np.where(t < 1.0, 0.0, 3.0 * (t - 1.0))
    y = np.where(t < 2.5, y, 4.5)
    z = np.column_stack([0.005 * rng.standard_normal(120), y + 0.005 * rng.standard_normal(120)])
    assert [round(float(t[k]), 3) for k in change_points(t, z, 1.0, np.array([0.005, 0.005]))] == [1.0, 2.5]
    arc = np.column_stack([10 * np.cos(0.3 * t), 10 * np.sin(0.3 * t)]) + 0.005 * rng.standard_normal((120, 2))
    assert change_points(t, arc, 1.0, np.array([0.005, 0.005])) == []


def test_a_spike_is_dropped_but_a_stop_is_not():
    rng = np.random.default_rng(6)
    t = np.arange(90) / 30
    y = np.minimum(2.0 * t, 3.0) + 0.01 * rng.standard_normal(90)    # stops at 1.5 s
    x = 0.01 * rng.standard_normal(90)
    y[70] += 1.0                                                      # a prong's frame
    res = speed_analysis(t, x, y)
    assert res.meta["outliers_dropped"] == 1 and res.frames_used == 89
    assert res.mean_speed_mm_s == pytest.approx(3.0 / t[-1], rel=0.01)
    assert res.moving_speed_mm_s == pytest.approx(2.0, rel=0.01)
