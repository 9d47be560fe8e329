"""Rendered test videos with known truth, shared by the tracking tests."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from labkit.lab.render import render_frames, write_video

MM_PER_PX = 0.05


def path_of(kind: str, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(y_mm, x_mm, heading_rad) of a robot walking front first (front = (-sin h, cos h))."""
    if kind == "straight":          # 3 mm/s along +y
        return 3.0 * t, np.zeros_like(t), np.zeros_like(t)
    if kind == "curve":             # 3 mm/s on a 6 mm radius, turning left (0.5 rad/s)
        r, w = 6.0, 0.5
        h = w * t
        return r * np.sin(h), -r * (1 - np.cos(h)), h
    if kind == "turn":              # 3 mm/s on a 3 mm radius (1 rad/s); the axis crosses 90 degrees
        r, h0 = 3.0, np.radians(30)
        h = h0 + 1.0 * t
        return r * (np.sin(h) - np.sin(h0)), r * (np.cos(h) - np.cos(h0)), h
    raise ValueError(kind)


def true_speed_mm_s(y: np.ndarray, x: np.ndarray, t: np.ndarray) -> float:
    """Time-averaged speed of the true (jitter-free) path."""
    return float(np.mean(np.hypot(np.gradient(x, t), np.gradient(y, t))))


def make_video(folder: Path, name: str, kind: str = "straight", n: int = 60, fps: float = 30.0,
               suffix: str = ".avi", t_s: np.ndarray | None = None, **render_kw):
    """Render and write a clip; returns (path, truth, (y, x, heading))."""
    t = np.arange(n) / fps if t_s is None else np.asarray(t_s, float)
    y, x, h = path_of(kind, t)
    frames, truth = render_frames(y, x, h, t, mm_per_px=MM_PER_PX, return_truth=True, **render_kw)
    path = Path(folder) / f"{name}{suffix}"
    write_video(path, frames, fps, t_s=t if suffix == ".mkv" else None)
    return path, truth, (y, x, h)


def errors(track, truth, ok=None):
    """(RMS position error px, max |heading error| deg) over the frames flagged ok."""
    ok = track.quality == 0 if ok is None else ok
    e = np.hypot(track.u_px - truth.u_px, track.v_px - truth.v_px)[ok]
    dh = np.angle(np.exp(1j * (track.heading_rad - truth.heading_rad)))[ok]
    return float(np.sqrt(np.mean(e ** 2))), float(np.degrees(np.abs(dh).max()))
