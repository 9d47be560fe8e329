"""Real footage with human labels: a dark mouse on a light open field (DeepLabCut's example, LGPL-3.0;
``tests/data/dlc_openfield/README.md`` says what was taken and changed).

A mouse is a soft body: it curls, stretches and hugs the walls. The tracker must keep its frames
(no rejection "by shape" or "by area" because the body changes), and its centroid must follow the
labelled trunk (the midpoint of the ears' midpoint and the tail base)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from labkit.analysis.tracking import track_video

DATA = Path(__file__).resolve().parents[1] / "data" / "dlc_openfield"


def test_mouse_tracked_in_nearly_every_frame_and_on_its_labels():
    trk = track_video(DATA / "m4s1_labelled_frames.mp4", mm_per_px=1.0, robot_size_mm="learn")
    lab = np.genfromtxt(DATA / "labels_half_scale.csv", delimiter=",", skip_header=3)
    assert trk.frames == lab.shape[0] == 116
    ok = trk.quality == 0
    assert ok.sum() >= 110 and trk.lost_frames <= 1            # (21 of 116 were rejected by shape before)
    trunk = ((lab[:, 3:5] + lab[:, 5:7]) / 2 + lab[:, 7:9]) / 2
    have = ok & np.isfinite(trunk).all(axis=1)
    dist = np.hypot(trk.u_px - trunk[:, 0], trk.v_px - trunk[:, 1])[have]
    body = np.hypot(*(lab[:, 1:3] - lab[:, 7:9]).T)[have]        # snout to tail base
    # the darkness centroid of a curled mouse is not its trunk's midpoint, but near it: a few % of its length
    assert np.median(dist / body) < 0.06 and np.percentile(dist / body, 90) < 0.15
    # the path through consecutive frames both have: within the labels' own jitter (a few %)
    both = have[1:] & have[:-1]
    ours = np.hypot(np.diff(trk.u_px), np.diff(trk.v_px))[both].sum()
    theirs = np.hypot(*np.diff(trunk, axis=0).T)[both].sum()
    assert abs(ours / theirs - 1) < 0.05
