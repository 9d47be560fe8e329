"""A fast robot over a mottled tray: every frame tracked, whatever the noise seed.

The virtual lab's fastest demo robot walks 32.5 mm/s: at 30 fps and 0.05 mm/px that is 22 px a
frame, about a body length in 4.5 frames, so in a half-second clip (15 frames, all of them the
static scene's samples) it lies over any spot of its path in 4-6 samples. The tray's mottling has
dimples a few per cent darker than their surroundings, dark in every sample at the 4 % threshold.
Judged by its mean darkness over the samples, such a dimple crossed by the robot looked like dust
(the robot's 60 % darkness in 6 of 15 samples averages to over 15 %) and was masked: the robot was
lost over it (7 of 15 frames kept on one seed in CI). Its own darkness is the one it has in most
samples. Scenes from :mod:`render_scenes` (written independently of labkit), 16 seeds each, two
mottling strengths, with the static scene's model at half resolution (the default at 640 x 480)
and at full resolution.
"""
from __future__ import annotations

import numpy as np
import pytest
from render_scenes import Scene, render, write_avi

from labkit.analysis.tracking import measure, track_speed, track_video
from labkit.analysis.tracking.measure import static_objects
from labkit.analysis.tracking.tracker import QUALITY_OK

SEEDS = range(16)


def _scene(mottling: float, seed: int) -> Scene:
    return Scene(n=15, fps=30.0, speed_mm_s=32.5, turn_rad_s=0.0, heading0_rad=0.0, start_px=(319.5, 400.0),
                 mottling=mottling, blur_px=0.7, jitter_px=0.3, noise=2.0, seed=seed)


@pytest.mark.parametrize("halved", [True, False], ids=["halved-model", "full-model"])
@pytest.mark.parametrize("mottling", [0.03, 0.05])
def test_fast_robot_over_mottling_tracked_in_every_frame(tmp_path, monkeypatch, mottling, halved):
    if not halved:
        monkeypatch.setattr(measure, "DECIMATE_FROM_PX", 10 ** 12)
    failures = []
    for seed in SEEDS:
        frames, truth = render(_scene(mottling, seed))
        path = write_avi(tmp_path / f"fast_{seed}.avi", frames, 30.0)
        trk = track_video(path)            # no scale: the lab's clips are measured by the robot's length
        err = np.hypot(trk.u_px - truth.u_px, trk.v_px - truth.v_px)
        if not (np.all(trk.quality == QUALITY_OK) and float(np.max(err)) < 0.3 and not trk.meta["static_objects"]):
            failures.append((seed, int(np.sum(trk.quality == QUALITY_OK)), trk.meta["static_objects"]))
            continue
        # the speed in mm/s from the robot's measured length: within 2 % of the truth
        assert track_speed(trk).mean_speed_mm_s == pytest.approx(32.5, rel=0.02)
    assert failures == [], f"(seed, frames ok of 15, static objects set aside): {failures}"


def _ratios() -> list[np.ndarray]:
    """Fifteen samples relative to the tray: a static dimple (40 x 30 px) 6 % dark on the robot's path,
    crossed by the robot (60 % dark, 100 x 40 px, 22 px a frame), and a static dust speck (40 % dark,
    40 x 30 px) beside the path."""
    out = []
    for k in range(15):
        r = np.ones((480, 640), np.float32)
        r[200:230, 300:340] -= 0.06
        r[200:230, 450:490] -= 0.40
        v = 400 - 22 * k
        r[v - 50:v + 50, 300:340] = 0.4
        out.append(r)
    return out


def test_a_dimple_crossed_by_the_robot_is_not_dust_but_dust_is():
    # the dimple is under the robot in 6 of 15 samples: its mean darkness over the samples is over
    # the 0.15 of a clearly dark object (and the tray around it dark in under a quarter of them),
    # but in most samples it is 0.06
    ratios = _ratios()
    assert sum(r[200:230, 300:340].min() < 0.5 for r in ratios) == 6
    assert 1 - np.mean([r[200:230, 300:340].mean() for r in ratios]) > 0.15
    boxes = static_objects(ratios, 0.04, 40.0, np.ones((480, 640), np.uint8))[1]
    assert boxes == [(450, 200, 40, 30)]          # the dust speck only
