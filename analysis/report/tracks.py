"""Tracked paths and a video frame for the report's tracking section.

A track file (read by ``labkit.open``; layout: :mod:`labkit.analysis.tracking.output`) holds the path in world
millimetres (``x_mm``, ``y_mm``) and, when it came from a video, in image pixels
(``u_px``, ``v_px``); the frame is read from the tracked video with the tracker's own
reader (:mod:`labkit.analysis.tracking.video_io`).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from labkit.errors import InputError


@dataclass(frozen=True)
class TrackPath:
    """A track's path in world millimetres (finite points only) and, if it holds them, in image pixels."""

    file: str
    t_s: np.ndarray
    x_mm: np.ndarray
    y_mm: np.ndarray
    u_px: np.ndarray | None = None
    v_px: np.ndarray | None = None


def load_track_path(path: str | Path) -> TrackPath:
    """The path of a track file (``labkit.open``: HDF5 or CSV)."""
    from labkit.analysis.report.inputs import open_kind

    path = Path(path)
    cols = open_kind(path, ("track", "track_csv"), "a track file (labkit track --out TRACK.h5)").columns
    for key in ("t_s", "x_mm", "y_mm"):
        if key not in cols:
            raise InputError("missing dataset", file=path, key=key, expected="a track path (t_s, x_mm, y_mm)")
    x, y = np.asarray(cols["x_mm"], float), np.asarray(cols["y_mm"], float)
    ok = np.isfinite(x) & np.isfinite(y)

    def px(key: str) -> np.ndarray | None:
        return np.asarray(cols[key], float)[ok] if key in cols else None

    return TrackPath(str(path), np.asarray(cols["t_s"], float)[ok], x[ok], y[ok], px("u_px"), px("v_px"))


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
