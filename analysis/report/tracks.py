"""Tracked paths and a video frame for the report's tracking section.

A track file (read by ``labkit.open``; layout: :mod:`labkit.analysis.tracking.output`) holds the path in world
millimetres (``x_mm``, ``y_mm``) and, when it came from a video, in image pixels
(``u_px``, ``v_px``); the frame is read from the tracked video with the tracker's own
reader (:mod:`labkit.analysis.tracking.video_io`).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from labkit.errors import InputError


def load_track_path(path: str | Path) -> dict[str, Any]:
    """``t_s``, ``x_mm``, ``y_mm`` and, if present, ``u_px``, ``v_px`` of a track file (``labkit.open``)."""
    from labkit.analysis.report.inputs import open_kind

    path = Path(path)
    cols = open_kind(path, ("track", "track_csv"), "a track file (labkit track --out TRACK.h5)").columns
    out: dict[str, Any] = {"file": str(path)}
    for key in ("t_s", "x_mm", "y_mm"):
        if key not in cols:
            raise InputError("missing dataset", file=path, key=key, expected="a track path (t_s, x_mm, y_mm)")
        out[key] = np.asarray(cols[key], float)
    for key in ("u_px", "v_px"):
        if key in cols:
            out[key] = np.asarray(cols[key], float)
    ok = np.isfinite(out["x_mm"]) & np.isfinite(out["y_mm"])
    for key in ("t_s", "x_mm", "y_mm", "u_px", "v_px"):
        if key in out:
            out[key] = out[key][ok]
    return out


def read_frame_at(video: str | Path, t_s: float) -> np.ndarray:
    """The grey frame of ``video`` at (or just before) time ``t_s`` (the last frame if the video
    is shorter). InputError if the video cannot be read."""
    from labkit.analysis.tracking.video_io import iter_frames, open_video

    cap, info = open_video(video, grey=True)
    try:
        last = None
        for frame, t in iter_frames(cap, info):
            if last is not None and t > t_s + 1e-9:
                break
            last = frame
    finally:
        cap.release()
    if last is None:
        raise InputError("the video holds no frame", file=video)
    return last
