"""Burnt-in overlays drawn onto rendered frames, written from what stereoscope and microscope cameras
put on their video, not from the tracker: a timestamp that changes every frame (seven-segment digits,
milliseconds included) and a static scale bar with end ticks.

Nothing here comes from labkit: the digits are drawn segment by segment from their own table.
"""
from __future__ import annotations

import numpy as np

#: seven-segment digits: which of the segments a (top), b (top right), c (bottom right), d (bottom),
#: e (bottom left), f (top left), g (middle) are lit
SEGMENTS = {"0": "abcdef", "1": "bc", "2": "abdeg", "3": "abcdg", "4": "bcfg", "5": "acdfg", "6": "acdefg",
            "7": "abc", "8": "abcdefg", "9": "abcdfg"}


def _digit(img: np.ndarray, ch: str, x: int, y: int, w: int, h: int, t: int, value: float) -> None:
    """One character at (x, y), ``w`` x ``h`` pixels, strokes ``t`` thick, painted ``value``."""
    if ch == ":":
        img[y + h // 3: y + h // 3 + t, x + w // 2 - t // 2: x + w // 2 + t - t // 2] = value
        img[y + 2 * h // 3: y + 2 * h // 3 + t, x + w // 2 - t // 2: x + w // 2 + t - t // 2] = value
        return
    if ch == ".":
        img[y + h - t: y + h, x + w // 2 - t // 2: x + w // 2 + t - t // 2] = value
        return
    m = y + h // 2 - t // 2
    boxes = {"a": (x, y, w, t), "d": (x, y + h - t, w, t), "g": (x, m, w, t),
             "f": (x, y, t, h // 2), "b": (x + w - t, y, t, h // 2),
             "e": (x, y + h // 2, t, h - h // 2), "c": (x + w - t, y + h // 2, t, h - h // 2)}
    for s in SEGMENTS[ch]:
        bx, by, bw, bh = boxes[s]
        img[by:by + bh, bx:bx + bw] = value


def timestamp_text(t_s: float) -> str:
    """``hh:mm:ss.fff`` of a clock that started at 09:59:58.000."""
    ms = int(round((35998.0 + t_s) * 1000))
    return f"{ms // 3600000:02d}:{ms // 60000 % 60:02d}:{ms // 1000 % 60:02d}.{ms % 1000:03d}"


def burn_in(frames: np.ndarray, fps: float, *, dark: bool = True, box: bool = False,
            digit_px: tuple[int, int, int] | None = None) -> np.ndarray:
    """The frames (n, H, W) uint8 with a timestamp at the top left and a scale bar at the bottom right.

    ``dark``: dark digits on the scene (as dark as a robot); otherwise bright ones. ``box``: the digits
    on a filled box of the opposite brightness (many cameras' style). ``digit_px``: a digit's width,
    height and stroke in pixels (default from the frame's size).
    """
    out = frames.copy()
    n, H, W = out.shape[:3]
    ink, paper = (20.0, 235.0) if dark else (245.0, 15.0)
    cw, ch, st = digit_px or (max(W // 40, 6), max(H // 14, 12), max(W // 160, 2))
    x0, y0 = W // 40, H // 24
    for k in range(n):
        img = out[k]
        text = timestamp_text(k / fps)
        if box:
            img[y0 - st: y0 + ch + st, x0 - st: x0 + len(text) * (cw + st) + st] = paper
        for i, c in enumerate(text):
            _digit(img, c, x0 + i * (cw + st), y0, cw, ch, st, ink)
        # the scale bar: a bar with end ticks, the same in every frame
        bx1, by = W - W // 20, H - H // 12
        bx0 = bx1 - W // 5
        img[by - st: by + st, bx0:bx1] = ink
        img[by - 3 * st: by + 3 * st, bx0: bx0 + st] = ink
        img[by - 3 * st: by + 3 * st, bx1 - st: bx1] = ink
    return out
