"""Writing frames to a video file (Motion-JPEG, lossless FFV1, or Matroska with per-frame times).

Below both the virtual lab (its camera writes the videos an experiment records) and the
analysis (the tracker's overlay video): a base module, importing no labkit layer.
"""
from __future__ import annotations

import itertools
from collections.abc import Iterable
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["write_video"]


def write_video(path: str | Path, frames: np.ndarray | Iterable[np.ndarray], fps: float, *,
                t_s: ArrayLike | None = None, lossless: bool = False, quality: int = 100) -> Path:
    """Write frames (grey ``(H,W)`` or BGR ``(H,W,3)`` uint8, an array or any iterable) to a video.

    * Default: Motion-JPEG at ``quality`` in the container the suffix names
      (``.avi`` recommended): small, fast to decode, what bench cameras write.
    * ``lossless=True``: FFV1 (``.avi`` recommended), bit-exact, ~4x slower to decode.
    * ``t_s`` given: frames carry these timestamps (a variable frame rate, as a
      real camera's dropped or late frames give); needs ``.mkv`` (Matroska keeps
      per-frame presentation times, to 1 ms) and uses Motion-JPEG packets.

    Frames are streamed (never all held in memory). Every reader should take
    each frame's time from ``CAP_PROP_POS_MSEC``. Returns the path.
    """
    import cv2

    path = Path(path)
    it = iter(frames)
    try:
        first = np.asarray(next(it))
    except StopIteration:
        raise ValueError("write_video: no frames") from None
    h, w = first.shape[:2]
    color = first.ndim == 3
    if t_s is not None:
        if path.suffix.lower() != ".mkv":
            raise ValueError("write_video: per-frame timestamps need a .mkv file")
        ts = np.asarray(t_s, float)
        pts = np.rint((ts - ts[0]) * 1000.0)
        if np.any(np.diff(pts) <= 0):
            raise ValueError("write_video: t_s must increase by at least 1 ms per frame")
        # raw mode: we hand over encoded JPEG packets and set each one's presentation time in
        # units of 1/fps, so fps = 1000 gives a 1 ms time base
        vw = cv2.VideoWriter(str(path), cv2.CAP_FFMPEG, cv2.VideoWriter.fourcc(*"MJPG"), 1000.0, (w, h),
                             [cv2.VIDEOWRITER_PROP_RAW_VIDEO, 1])
        if not vw.isOpened():
            raise OSError(f"write_video: cannot open {path} for writing")
        n = 0
        try:
            for f in itertools.chain([first], it):
                if n >= pts.size:
                    raise ValueError("write_video: more frames than timestamps")
                ok, buf = cv2.imencode(".jpg", np.asarray(f), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
                vw.set(cv2.VIDEOWRITER_PROP_PTS, float(pts[n]))
                vw.write(buf.reshape(1, -1))
                n += 1
        finally:
            vw.release()
        if n != pts.size:
            raise ValueError(f"write_video: {n} frames but {pts.size} timestamps")
        return path
    fourcc = "FFV1" if lossless else "MJPG"
    vw = cv2.VideoWriter(str(path), cv2.CAP_FFMPEG, cv2.VideoWriter.fourcc(*fourcc), float(fps), (w, h), color)
    if not vw.isOpened():
        raise OSError(f"write_video: cannot open {path} for writing ({fourcc})")
    try:
        if not lossless:
            vw.set(cv2.VIDEOWRITER_PROP_QUALITY, float(quality))
        for f in itertools.chain([first], it):
            vw.write(np.asarray(f))
    finally:
        vw.release()
    return path
