"""A slow or still robot among real dust specks: tracked, never set aside as dust.

A robot that walks only a few pixels over a short clip overlaps itself in every
sample frame of the static scene's model, like dust. The videos come from
``render_scenes`` (OpenCV polygon filling and NumPy, no labkit code): the 5 x 2 mm
chip on a 320 x 240 field at 0.1 mm/px (50 x 20 px), 15 frames at 30 fps (the
virtual lab's half-second clips), with specks of dust of several sizes: small
round ones (needing no mask) and a large elongated one, darker than the chip.
"""
from __future__ import annotations

import numpy as np
import pytest
from render_scenes import Scene, render, write_mkv

from labkit.analysis.tracking import track_speed, track_video
from labkit.analysis.tracking.measure import Segmentation, drifts
from labkit.analysis.tracking.tracker import QUALITY_LOST

S = 0.1
N = 15
FPS = 30.0
HEADING = 0.0     # rad: walking up, along an image axis
# (u, v, semi-axis a, semi-axis b (px), angle (deg), reflectance): specks as seen on a tray
DUST = [(60.0, 50.0, 3.0, 2.5, 0.0, 0.3), (250.0, 200.0, 4.0, 3.0, 30.0, 0.25), (270.0, 40.0, 2.0, 2.0, 0.0, 0.4),
        (70.0, 190.0, 28.0, 7.0, 20.0, 0.15)]


def _clip(tmp_path, move_px: float, seed: int):
    span = (N - 1) / FPS
    sc = Scene(width=320, height=240, mm_per_px=S, n=N, fps=FPS, speed_mm_s=move_px * S / span, turn_rad_s=0.0,
               heading0_rad=HEADING, start_px=(160.0, 125.0), blur_px=0.8, noise=2.0, dust=DUST, seed=seed)
    frames, truth = render(sc)
    return write_mkv(tmp_path / f"slow_{move_px:g}_{seed}.mkv", frames, truth.t_s), truth


def _on_robot(box: tuple[int, int, int, int], truth) -> bool:
    x, y, w, h = box
    return bool(np.any((x <= truth.u_px) & (truth.u_px <= x + w) & (y <= truth.v_px) & (truth.v_px <= y + h)))


@pytest.mark.parametrize("move_px,seed", [(3.0, 1), (5.0, 2), (12.0, 3), (25.0, 4)])
@pytest.mark.parametrize("scaled", [False, True])
def test_a_slow_robot_is_tracked_not_set_aside_as_dust(tmp_path, move_px, seed, scaled):
    path, truth = _clip(tmp_path, move_px, seed)
    track = track_video(path, mm_per_px=S if scaled else None)
    assert not np.any(track.quality == QUALITY_LOST)
    err = np.hypot(track.u_px - truth.u_px, track.v_px - truth.v_px)
    assert np.sqrt(np.mean(err ** 2)) <= 0.3
    assert not any(_on_robot(b, truth) for b in track.meta["static_objects"])
    # the large speck (robot-sized, static) is set aside; the small ones need no mask
    assert any(_on_robot(b, type(truth)(**{**truth.__dict__, "u_px": np.array([70.0]), "v_px": np.array([190.0])}))
               for b in track.meta["static_objects"])
    assert track.scale.mm_per_px == pytest.approx(S, rel=0.03)
    lo, hi = track_speed(track).speed_ci_mm_s
    assert lo <= truth.speed_mm_s <= hi


def test_a_still_robot_without_a_scale_is_the_robot(tmp_path):
    # never moving: only its outline (the declared 5 x 2 mm chip's proportions) tells it from the
    # dust; the long speck (7 x 1.4 mm, a fibre) is not shaped like it
    path, truth = _clip(tmp_path, 0.0, 5)
    track = track_video(path)
    assert any("hardly moved" in w for w in track.meta["warnings"])
    assert np.nanmax(np.hypot(track.u_px - truth.u_px, track.v_px - truth.v_px)) <= 0.3
    assert track.scale.mm_per_px == pytest.approx(S, rel=0.03)
    lo, hi = track_speed(track).speed_ci_mm_s
    assert lo == 0.0 and hi < 0.5


def _dark_disc(shape, u: float, v: float, r: float) -> np.ndarray:
    vv, uu = np.mgrid[:shape[0], :shape[1]]
    return np.where(np.hypot(uu - u, vv - v) <= r, 0.3, 1.0).astype(np.float32)


def test_drift_of_a_walk_and_not_of_dust_touched_late():
    # the rule on its own: a disc walking 4 px moves; a still disc that something dark touches in
    # the last samples (a robot walking into dust) does not; a still one shaken by 0.5 px does not
    shape = (80, 80)
    region = np.ones(shape, np.uint8)
    walk = [_dark_disc(shape, 40 + 4 * k / 14, 40, 12) for k in range(15)]
    assert drifts(walk, region, 0.1)
    rng = np.random.default_rng(0)
    shaken = [_dark_disc(shape, 40 + rng.uniform(-0.5, 0.5), 40 + rng.uniform(-0.5, 0.5), 12) for _ in range(15)]
    assert not drifts(shaken, region, 0.1)
    touched = [np.minimum(_dark_disc(shape, 40, 40, 12), _dark_disc(shape, 40 + 24 - k / 3, 40, 3) if k > 10 else 1.0)
               for k in range(15)]
    assert not drifts(touched, region, 0.1)
    assert Segmentation.for_frame(80, 80, 20.0, None).body_width_px == pytest.approx(20.0)
