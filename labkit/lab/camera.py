"""The virtual stereoscope camera: the simulated robot's top view, written to a video file.

The robot's motion comes from the hybrid simulator for the current shaker
drive (the same cached ``simulate`` run the scope uses): its walking speed
(mean over the settled part of the run), its small lateral oscillation and its
yaw. A clip longer than the simulation continues the walk at that mean speed,
with the oscillation repeated (stroboscopic frames at tens of hertz cannot
tell). On top: a slow turn (``turn_deg_s``), timing jitter of the frames,
sensor noise and vibration blur, through :func:`labkit.lab.render.render_frames`.
In-chip, or with the output off, the robot does not walk.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

MM_PER_PX = 0.05
SIZE_PX = (640, 480)
TURN_DEG_S = 1.5
FRAME_JITTER_S = 0.002


@dataclass
class Recording:
    """One clip the virtual camera filmed: where, the frame times and the robot's true path."""

    path: str
    frames: int
    timestamps_s: list[float]
    speed_mm_s: float
    y_mm: np.ndarray
    x_mm: np.ndarray
    heading_rad: np.ndarray


def robot_path(sim: Any, t_s: np.ndarray, move_s: float = float("inf")
               ) -> tuple[np.ndarray, np.ndarray, float]:
    """(y_mm, heading_rad, mean speed mm/s) of the robot at the frame times ``t_s``.

    ``sim`` is the hybrid simulator's result for the present shaker drive
    (``t_s``, ``body_y_um``, ``body_angles_rad``), or None when the robot does
    not walk (in-chip, output off, no simulator). After ``move_s`` (the end of
    a triggered burst) the robot stands where it got to.
    """
    t_s = np.minimum(np.asarray(t_s, float), max(0.0, move_s))
    speed = 0.0
    y_osc = np.zeros(len(t_s))
    yaw = np.zeros(len(t_s))
    if sim is not None:
        t_sim = np.asarray(sim.t_s, float)
        y_sim = np.asarray(sim.body_y_um, float) * 1e-3
        yaw_sim = np.asarray(sim.body_angles_rad, float)[:, 2]
        settled = t_sim >= t_sim[-1] / 3
        ts, ys = t_sim[settled], y_sim[settled]
        speed = float(np.polyfit(ts, ys, 1)[0]) if len(ts) > 2 else 0.0
        resid = ys - (ys[0] + speed * (ts - ts[0]))
        span = ts[-1] - ts[0]
        phase = ts[0] + np.mod(t_s, span) if span > 0 else np.full(len(t_s), ts[0])
        y_osc = np.interp(phase, ts, resid)
        yaw = np.interp(phase, ts, yaw_sim[settled] - yaw_sim[settled][0])
    turn = np.deg2rad(TURN_DEG_S) * t_s
    heading = yaw + turn
    # walking follows the heading: integrate the speed along the slowly turning front direction
    y = speed * t_s + y_osc
    return y, heading, speed


def record(path: str | Path, duration_s: float, *, fps: float, seed: int, take: int, sim: Any,
           shaking: bool, move_s: float = float("inf")) -> Recording:
    """Render ``duration_s`` of video at ``fps`` to ``path``.

    Everything the camera needs is passed in (the lab owns the state): ``sim``
    the simulator's result for the present drive (None: the robot stands),
    ``move_s`` how long into the clip the drive lasts (a triggered burst),
    ``shaking`` whether the tray vibrates (vibration blur), ``seed`` and
    ``take`` (a counter) make the frame jitter and noise reproducible.
    """
    from labkit.lab.render import render_frames, write_video

    path = Path(path)
    if not path.parent.is_dir():
        raise ValueError(f"no such directory: {path.parent}")
    fps = float(fps)
    rng = np.random.default_rng([seed, 7, take])
    n = max(1, int(round(duration_s * fps)))
    t = np.arange(n) / fps + rng.uniform(-FRAME_JITTER_S, FRAME_JITTER_S, n)
    t[0] = 0.0
    t = np.maximum.accumulate(t + np.arange(n) * 1e-6)
    y, heading, speed = robot_path(sim, t, move_s)
    # the front direction is (-sin h, cos h): walking along it
    dy = np.gradient(y, t) if n > 1 else np.zeros(1)
    x = np.concatenate([[0.0], np.cumsum(-np.sin(heading[1:]) * dy[1:] * np.diff(t))]) if n > 1 else np.zeros(1)
    yy = np.concatenate([[0.0], np.cumsum(np.cos(heading[1:]) * dy[1:] * np.diff(t))]) if n > 1 else np.zeros(1)
    blur = 1.5 if shaking else 0.0
    frames = render_frames(yy, x, heading, t, size_px=SIZE_PX, mm_per_px=MM_PER_PX, noise=2.0,
                           blur_px=blur, jitter_px=0.3 if blur else 0.0, lighting_drift=0.02,
                           texture=0.03, seed=int(rng.integers(0, 2 ** 31)))
    ts = t if path.suffix.lower() == ".mkv" else None
    write_video(path, frames, fps, t_s=ts)
    timestamps = t if ts is not None else np.arange(n) / fps
    return Recording(str(path), int(n), [float(v) for v in timestamps], speed, yy, x, heading)
