"""Burnt-in overlays: a timestamp whose digits change every frame and a static scale bar, drawn by
``overlay_scenes`` (written from what cameras burn into video, not from the tracker) onto scenes of
``issue_scenes``. The digits are as dark as the robot and about its size: without the static scene's
model the tracker follows them."""
from __future__ import annotations

import numpy as np
import pytest
from issue_scenes import Camera, Leg, Robot, render
from overlay_scenes import burn_in
from render_scenes import write_avi

from labkit.analysis.tracking import track_speed, track_video
from labkit.analysis.tracking.measure import Segmentation, burnt_in_overlays

SIZE = (1.2, 0.6)
CAM = Camera(n=60, mm_per_px=0.05)
DIGIT_PX = (14, 24, 5)          # a digit 14 x 24 px, strokes 5 px: a "0" is 0.7 x 1.2 mm here, like the robot


def _scene(legs: list[Leg]):
    return render(CAM, Robot(length_mm=SIZE[0], width_mm=SIZE[1], start_mm=(-3.0, -1.0), heading0_rad=-1.2,
                             legs=legs), seed=1)


@pytest.mark.parametrize("dark,box", [(True, False), (True, True), (False, True)],
                         ids=["dark-digits", "dark-digits-on-a-box", "bright-digits-on-a-box"])
def test_burnt_in_timestamp_and_scale_bar_are_set_aside(tmp_path, dark, box):
    frames, truth = _scene([Leg(10, 2.0, 0.1)])
    path = write_avi(tmp_path / "ov.avi", burn_in(frames, CAM.fps, dark=dark, box=box, digit_px=DIGIT_PX), CAM.fps)
    for kw in ({"mm_per_px": CAM.mm_per_px, "robot_size_mm": SIZE}, {"robot_size_mm": SIZE},
               {"mm_per_px": CAM.mm_per_px, "robot_size_mm": "learn"}):
        trk = track_video(path, **kw)
        err = np.hypot(trk.u_px - truth.u_px, trk.v_px - truth.v_px)
        assert trk.lost_frames == 0 and np.max(err) < 0.2, (kw, np.max(err))
        assert track_speed(trk).mean_speed_mm_s == pytest.approx(truth.speed_mm_s, rel=0.005)
        assert any("burnt-in overlay" in w for w in trk.meta["warnings"]), trk.meta["warnings"]
    if dark:
        # the trap is real: without the static scene's model the dark digits are taken for the robot
        bare = track_video(path, mm_per_px=CAM.mm_per_px, robot_size_mm=SIZE, static_mask=False)
        assert np.nanmax(np.hypot(bare.u_px - truth.u_px, bare.v_px - truth.v_px)) > 50


def _ratios(frames: np.ndarray) -> tuple[list[np.ndarray], Segmentation]:
    seg = Segmentation.for_frame(CAM.width, CAM.height, SIZE[1] / CAM.mm_per_px, None)
    return [seg.ratio(f) for f in frames[::4]], seg


def test_the_overlay_box_holds_the_timestamp_and_not_the_robot():
    frames, truth = _scene([Leg(10, 2.0, 0.1)])
    ratios, seg = _ratios(burn_in(frames, CAM.fps, dark=True, digit_px=DIGIT_PX))
    mask, boxes = burnt_in_overlays(ratios, 0.05, seg.body_width_px)
    assert mask is not None and len(boxes) == 1
    x, y, w, h = boxes[0]
    # the text: 12 characters of 14 + 5 px from x = 8, y = 10, 24 px high (overlay_scenes.burn_in)
    assert x <= 8 and x + w >= 8 + 12 * 19 - 5 and y <= 10 and y + h >= 34
    assert not mask[np.rint(truth.v_px).astype(int), np.rint(truth.u_px).astype(int)].any()


@pytest.mark.parametrize("vib_mm", [0.0, 0.03])
def test_a_still_robot_is_not_an_overlay(vib_mm):
    """A robot that never moves (shaken or not) is one mark, not a line of text: not set aside as one."""
    frames, _ = render(CAM, Robot(length_mm=SIZE[0], width_mm=SIZE[1], legs=[Leg(10, 0.0)], vib_mm=vib_mm), seed=2)
    ratios, seg = _ratios(frames)
    assert burnt_in_overlays(ratios, 0.05, seg.body_width_px) == (None, [])
