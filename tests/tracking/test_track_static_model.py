"""The static scene's model of a 640 x 480 frame, computed on halved samples, against what was drawn.

Frames drawn here with NumPy and OpenCV's rectangle filling (no labkit code): a tray lit by a
ring light falling off to 85 % at the corners, a dark rim along the left edge, a static dust
speck, a chip (100 x 40 px) at a different place in every sample, and Gaussian pixel noise of
2 grey levels. The model must find the rim and the speck where they were drawn, measure the
noise, and give the lighting's shape as its flat field.
"""
from __future__ import annotations

import cv2
import numpy as np

from labkit.analysis.tracking import measure
from labkit.analysis.tracking.measure import Segmentation, background_model

W, H = 640, 480
DUST = (420, 80, 40, 40)          # x, y, w, h
RIM_PX = 18
NOISE = 2.0


def _light() -> np.ndarray:
    yy, xx = np.mgrid[0:H, 0:W]
    r2 = ((xx - W / 2) / (W / 2)) ** 2 + ((yy - H / 2) / (H / 2)) ** 2
    return 1.0 - 0.075 * r2           # 85 % at the corners (r2 = 2)


def _samples(n: int = 15) -> list[np.ndarray]:
    rng = np.random.default_rng(3)
    light = _light()
    out = []
    for k in range(n):
        img = np.full((H, W), 200.0) * light
        img[:, :RIM_PX] = 40.0
        x, y, w, h = DUST
        img[y:y + h, x:x + w] = 90.0
        cx, cy = 120 + 25 * k, 300 - 8 * k                 # the chip walks: never twice on the same pixels
        cv2.rectangle(img, (cx, cy), (cx + 99, cy + 39), 70.0, thickness=-1)
        img += rng.normal(0, NOISE, img.shape)
        out.append(np.clip(img, 0, 255).astype(np.uint8))
    return out


def test_halved_model_finds_what_was_drawn():
    seg = Segmentation.for_frame(W, H, 40.0, None)
    assert W * H >= measure.DECIMATE_FROM_PX and seg.body_width_px >= 32    # the halved path is the one taken
    sc = background_model(_samples(), seg)
    assert sc.rim is not None and sc.rim.shape == (H, W)
    assert sc.rim[:, :RIM_PX].mean() > 0.97                  # the rim drawn is masked ...
    assert not sc.rim[:, RIM_PX + 4:].any()                  # ... and nothing beyond it (plus a few px)
    assert len(sc.object_boxes) == 1
    bx, by, bw, bh = sc.object_boxes[0]
    x, y, w, h = DUST
    assert abs(bx - x) <= 4 and abs(by - y) <= 4 and abs(bw - w) <= 6 and abs(bh - h) <= 6
    assert sc.objects is not None and sc.objects[y:y + h, x:x + w].all()
    assert 0.7 < sc.noise / (NOISE / 200) < 1.4             # relative pixel noise, at full resolution
    assert sc.flat is not None and sc.flat.shape == (H, W)
    light = _light()
    tray = np.ones((H, W), bool)
    tray[:, :RIM_PX + 10] = False
    tray[y - 10:y + h + 10, x - 10:x + w + 10] = False
    ratio = sc.flat[tray] / light[tray]
    assert np.ptp(np.percentile(ratio, [1, 99])) / np.median(ratio) < 0.02   # the ring light's shape, within 2 %


def test_tray_level_from_histogram_equals_numpy_order_statistics():
    """The rim's tray level of an 8-bit frame, taken from its histogram, is NumPy's own
    ``median(sub[sub > 0.75 * percentile(sub, 99)])`` (linear percentile), value for value."""
    rng = np.random.default_rng(7)
    cases = [_samples(1)[0][::4, ::4],
             rng.integers(0, 256, 997).astype(np.uint8),                       # odd count
             rng.choice(np.array([0, 10, 128, 200, 201, 255], np.uint8), 1000),  # ties, even count
             np.clip(rng.normal(60, 25, (40, 50)), 0, 255).astype(np.uint8)]
    for sub in cases:
        want = float(np.median(sub[sub > 0.75 * np.percentile(sub, 99)]))
        assert measure._tray_level(sub) == want
    deep = rng.uniform(0, 4095, (30, 30)).astype(np.float32)                   # a 12-bit frame's floats
    assert measure._tray_level(deep) == float(np.median(deep[deep > 0.75 * np.percentile(deep, 99)]))
