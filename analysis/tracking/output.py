"""Write a track: HDF5 (kind ``"track"``), CSV, an overlay video and a PNG of the path.

HDF5 layout (``schema_version`` 1)::

    /  attrs: kind="track", mean_speed_mm_s, speed_ci_mm_s (2), mm_per_px, mm_per_px_std,
              scale_method, frames, lost_frames, source_video, timestamps_source,
              heading_sense, roi_px (x, y, w, h), frame_size_px (w, h), summary_json
       t_s [s], x_mm [mm], y_mm [mm], heading_rad [rad], quality [label],
       u_px [px], v_px [px], area_px [px^2]                     (one row per frame)
    /smoothed  t_s, x_mm, y_mm, vx_mm_s, vy_mm_s, speed_mm_s, heading_rad,
               turn_rate_rad_s                                  (frames used for speed)

``x_mm``/``y_mm`` are measured from the frame's bottom-left corner, ``y`` up;
``heading_rad`` is 0 towards +y, counter-clockwise positive. Lost frames hold NaN.
"""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from labkit.analysis.tracking.speed import SpeedResult
from labkit.analysis.tracking.tracker import QUALITY_LABELS, QUALITY_LOST, QUALITY_OK, Track


def summary(track: Track, speed: SpeedResult | None) -> dict[str, Any]:
    """The figures a user (and ``--json``) wants, units in the names."""
    out: dict[str, Any] = {
        "source_video": track.source, "frames": track.frames, "lost_frames": track.lost_frames,
        "degraded_frames": int(np.sum((track.quality != QUALITY_OK) & (track.quality != QUALITY_LOST))),
        "timestamps_source": track.timestamps_source,
        "timestamp_faults": int(track.meta.get("timestamp_faults", 0)),
        "mean_frame_interval_s": float(np.mean(np.diff(track.t_s))) if track.frames > 1 else None,
        "mm_per_px": track.mm_per_px, "mm_per_px_std": track.scale.mm_per_px_std if track.scale else None,
        "scale_method": track.scale.method if track.scale else None,
        "robot_length_px": track.length_px, "heading_sense": track.heading_sense,
        "undecodable_frames": int(track.meta.get("undecodable_frames", 0)),
        "lost_stretches_s": [list(p) for p in track.meta.get("lost_stretches_s", [])],
        "robot_contrast": track.meta.get("robot_contrast"), "contrast_found": track.meta.get("contrast_found"),
        "min_contrast": track.meta.get("min_contrast"),
        "pixel_noise": track.meta.get("noise"),
        "warnings": list(track.meta.get("warnings", [])),
    }
    if speed is not None:
        out.update(speed.summary())
        out["outliers_dropped"] = int(speed.meta.get("outliers_dropped", 0))
        if out["outliers_dropped"]:
            out["warnings"].append(f"{out['outliers_dropped']} position(s) far off the smoothed path (> 8 robust "
                                   f"sigmas) left out of the speed")
        out["change_points_s"] = list(speed.meta.get("change_points_s", []))
        if "budget" in speed.meta:
            out["error_budget"] = speed.meta["budget"]
            out["warnings"].extend(speed.meta.get("budget_warnings", []))
        unc = speed.meta.get("uncertainty", {})
        out["speed_uncertainty"] = {k: unc[k] for k in ("speed_std_mm_s", "noise_part_mm_s", "timestamp_part_mm_s",
                                                         "scale_part_mm_s", "noise_bias_mm_s", "position_noise_mm",
                                                         "timestamp_jitter_s", "noise_ar1") if k in unc}
    return out


def save_track_h5(path: str | Path, track: Track, speed: SpeedResult | None) -> Path:
    """Write the track (and its speed analysis) as an HDF5 file of kind ``"track"``."""
    import h5py

    from labkit.h5io import label_dimensions, put, put_json, stamp

    path = Path(path)
    with h5py.File(path, "w") as f:
        stamp(f, "track")
        put(f, "t_s", track.t_s, "s")
        put(f, "x_mm", track.x_mm, "mm")
        put(f, "y_mm", track.y_mm, "mm")
        put(f, "heading_rad", track.heading_rad, "rad")
        put(f, "quality", track.quality, "label", labels=QUALITY_LABELS)
        put(f, "u_px", track.u_px, "px")
        put(f, "v_px", track.v_px, "px")
        put(f, "area_px", track.area_px, "px^2")
        summ = summary(track, speed)
        f.attrs["mm_per_px"] = track.mm_per_px
        f.attrs["mm_per_px_std"] = track.scale.mm_per_px_std if track.scale else np.nan
        f.attrs["scale_method"] = track.scale.method if track.scale else ""
        put_json(f, "scale_detail_json", track.scale.detail if track.scale else {})
        f.attrs["frames"] = track.frames
        f.attrs["lost_frames"] = track.lost_frames
        f.attrs["source_video"] = track.source
        f.attrs["timestamps_source"] = track.timestamps_source
        f.attrs["heading_sense"] = track.heading_sense
        f.attrs["roi_px"] = np.asarray(track.roi, int)
        f.attrs["frame_size_px"] = np.asarray(track.frame_size, int)
        f.attrs["mean_speed_mm_s"] = speed.mean_speed_mm_s if speed else np.nan
        f.attrs["speed_ci_mm_s"] = np.asarray(speed.speed_ci_mm_s if speed else (np.nan, np.nan), float)
        put_json(f, "summary_json", summ)
        if speed is not None:
            g = f.create_group("smoothed")
            g.attrs["window_s"] = speed.window_s
            put(g, "t_s", speed.t_s, "s")
            put(g, "x_mm", speed.x_mm, "mm")
            put(g, "y_mm", speed.y_mm, "mm")
            put(g, "vx_mm_s", speed.vx_mm_s, "mm/s")
            put(g, "vy_mm_s", speed.vy_mm_s, "mm/s")
            put(g, "speed_mm_s", speed.speed_mm_s, "mm/s")
            put(g, "heading_rad", speed.heading_rad, "rad")
            put(g, "turn_rate_rad_s", speed.turn_rate_rad_s, "rad/s")
        label_dimensions(f)         # t_s as the coordinate (xarray, HDFView)
    return path


def save_track_csv(path: str | Path, track: Track, speed: SpeedResult | None = None) -> Path:
    """One row per frame; smoothed columns are empty for frames not used for the speed."""
    path = Path(path)
    cols = {"t_s": track.t_s, "x_mm": track.x_mm, "y_mm": track.y_mm, "heading_rad": track.heading_rad,
            "quality": track.quality.astype(float), "u_px": track.u_px, "v_px": track.v_px}
    n = track.frames
    if speed is not None:
        pos = np.searchsorted(track.t_s, speed.t_s)
        for name in ("x_mm", "y_mm", "speed_mm_s", "heading_rad"):
            col = np.full(n, np.nan)
            col[pos] = getattr(speed, name)
            cols[f"smoothed_{name}"] = col
    header = ",".join(cols)
    data = np.column_stack(list(cols.values()))
    with open(path, "w") as fh:
        head = f"# labkit track of {track.source}; mm_per_px={track.mm_per_px:.6g}; "
        if speed is not None:
            lo, hi = speed.speed_ci_mm_s
            head += f"mean_speed_mm_s={speed.mean_speed_mm_s:.6g}; speed_ci_mm_s={lo:.6g},{hi:.6g}; "
        fh.write(f"{head}quality: {QUALITY_LABELS}\n")
        fh.write(header + "\n")
        for row in data:
            fh.write(",".join("" if not np.isfinite(v) else (f"{int(v)}" if k == "quality" else f"{v:.6f}")
                              for k, v in zip(cols, row)) + "\n")
    return path


def plot_path(path: str | Path, track: Track, speed: SpeedResult | None = None) -> Path:
    """PNG: the path in mm (raw points, smoothed path, heading ticks, lost stretches) and speed vs time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4.8), gridspec_kw={"width_ratios": [1.2, 1]})
    ok = track.quality == QUALITY_OK
    ax.plot(track.x_mm[ok], track.y_mm[ok], ".", ms=2.5, color="0.6", label="measured")
    bad = (track.quality != QUALITY_OK) & np.isfinite(track.x_mm)
    if bad.any():
        ax.plot(track.x_mm[bad], track.y_mm[bad], "x", ms=4, color="tab:orange", label="degraded")
    if speed is not None:
        ax.plot(speed.x_mm, speed.y_mm, "-", color="tab:blue", lw=1.5, label="smoothed")
        step = max(len(speed.t_s) // 15, 1)
        h = speed.heading_rad[::step]
        L = 0.06 * max(np.ptp(speed.x_mm), np.ptp(speed.y_mm), 1.0)
        ax.quiver(speed.x_mm[::step], speed.y_mm[::step], -np.sin(h) * L, np.cos(h) * L, angles="xy",
                  scale_units="xy", scale=1, color="tab:red", width=0.004, label="heading")
        ax2.plot(speed.t_s, speed.speed_mm_s, color="tab:blue", label="smoothed speed")
        ax2.axhline(speed.mean_speed_mm_s, color="k", lw=1,
                    label=f"mean {speed.mean_speed_mm_s:.3g} mm/s "
                          f"[{speed.speed_ci_mm_s[0]:.3g}, {speed.speed_ci_mm_s[1]:.3g}]")
        ax2.axhline(speed.frame_to_frame_speed_mm_s, color="tab:orange", ls="--", lw=1,
                    label=f"frame-to-frame {speed.frame_to_frame_speed_mm_s:.3g}")
        ax2.axhline(speed.net_speed_mm_s, color="tab:green", ls=":", lw=1,
                    label=f"net displacement {speed.net_speed_mm_s:.3g}")
    lost = track.quality == QUALITY_LOST
    if lost.any():
        ax2.plot(track.t_s[lost], np.zeros(lost.sum()), "|", color="tab:red", label="lost frames")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(Path(track.source).name)
    ax.legend(fontsize=8, loc="best")
    ax2.set_xlabel("time (s)")
    ax2.set_ylabel("speed (mm/s)")
    ax2.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_overlay(video_path: str | Path, track: Track, out_path: str | Path,
                  speed: SpeedResult | None = None, *, fps: float | None = None,
                  timestamps: str | Path | None = None, bayer: str = "auto") -> Path:
    """Re-read the video and draw the trajectory so far, the centroid and the heading on each frame.

    Written as Motion-JPEG (``.avi`` recommended) at the video's nominal rate.
    ``video_path`` may be an image sequence (``fps``/``timestamps`` as for the tracker).
    """
    import cv2

    from labkit.analysis.tracking.video_io import iter_frames, open_source
    from labkit.video import write_video

    cap, info = open_source(video_path, fps=fps, timestamps=timestamps, bayer=bayer)
    out_path = Path(out_path)
    px_per_mm = 1.0 / track.mm_per_px if track.mm_per_px > 0 else 1.0
    arrow = 0.45 * (track.length_px if np.isfinite(track.length_px) else 60.0)
    pts = np.column_stack([track.u_px, track.v_px])
    fps = info.fps_nominal if info.fps_nominal > 0 else 30.0

    finite = np.isfinite(pts).all(axis=1)

    def drawn() -> Iterator[np.ndarray]:
        # The trajectory grows one segment a frame on a layer of its own, so a long video
        # costs linear, not quadratic, drawing.
        trail: np.ndarray | None = None
        last: np.ndarray | None = None
        for k, (gray, _t) in enumerate(iter_frames(cap, info)):
            if k >= track.frames:
                break
            img = cv2.cvtColor(np.clip(gray, 0, 255).astype(np.uint8), cv2.COLOR_GRAY2BGR)
            x, y, w, h = track.roi
            cv2.rectangle(img, (x, y), (x + w - 1, y + h - 1), (128, 128, 128), 1)
            if trail is None:
                trail = np.zeros_like(img)
            if finite[k]:
                if last is not None:
                    a, b = np.round(last * 16).astype(np.int32), np.round(pts[k] * 16).astype(np.int32)
                    cv2.line(trail, (int(a[0]), int(a[1])), (int(b[0]), int(b[1])), (255, 160, 0), 1,
                             cv2.LINE_AA, 4)
                last = pts[k]
            on_trail = trail.any(axis=2)
            img[on_trail] = trail[on_trail]
            q = int(track.quality[k])
            if q != QUALITY_LOST:
                u, v, hd = track.u_px[k], track.v_px[k], track.heading_rad[k]
                tip = (u - arrow * np.sin(hd), v - arrow * np.cos(hd))
                color = (0, 200, 0) if q == QUALITY_OK else (0, 165, 255)
                cv2.arrowedLine(img, (int(round(u)), int(round(v))), (int(round(tip[0])), int(round(tip[1]))),
                                color, 2, cv2.LINE_AA, 0, 0.25)
                cv2.circle(img, (int(round(u * 16)), int(round(v * 16))), 3 * 16, (0, 0, 255), 1, cv2.LINE_AA, 4)
                label = f"t={track.t_s[k]:.3f}s"
            else:
                label = f"t={track.t_s[k]:.3f}s  LOST"
            if speed is not None:
                label += f"  mean {speed.mean_speed_mm_s:.3f} mm/s"
            cv2.putText(img, label, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 255), 1, cv2.LINE_AA)
            sb = int(round(px_per_mm))
            if 4 < sb < img.shape[1] // 3:
                cv2.line(img, (8, img.shape[0] - 12), (8 + sb, img.shape[0] - 12), (0, 0, 0), 2)
                cv2.putText(img, "1 mm", (12 + sb, img.shape[0] - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                            (0, 0, 0), 1, cv2.LINE_AA)
            yield img

    try:
        if out_path.suffix.lower() == ".mkv":
            return write_video(out_path, drawn(), fps, t_s=track.t_s)
        return write_video(out_path, drawn(), fps)
    finally:
        cap.release()
