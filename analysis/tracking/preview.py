"""``labkit track --preview FRAME``: one frame with the segmentation drawn, to see why a video fails.

The PNG shows the frame as the tracker sees it, with

* the region of interest (grey rectangle),
* what is never searched (the tray's rim, static dust, outside the mask): tinted blue,
* every pixel darker than the tray by more than the contrast threshold: tinted red,
* each dark object's outline: green when it could be the robot (size and shape),
  orange when it is refused, with its contrast against the tray,
* a caption with the threshold, the pixel noise and the strongest contrast found.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from labkit.analysis.tracking.tracker import Scale, prepare_scene, robot_size, scale_given
from labkit.errors import InputError


def preview_frame(source: str | Path, frame: int, out_png: str | Path, *, scale: Scale | None = None,
                  mm_per_px: float | None = None, roi: Any = None, mask: Any = None,
                  min_contrast: float | None = None, fps: float | None = None,
                  timestamps: str | Path | None = None, bayer: str = "auto",
                  robot_size_mm: Any = None) -> dict[str, Any]:
    """Write the preview PNG of frame ``frame`` (0-based); returns what it shows (JSON-ready)."""
    import cv2

    from labkit.analysis.tracking.video_io import iter_frames, open_source

    if frame < 0:
        raise InputError(f"bad frame {frame}", key="--preview", expected="a frame number >= 0")
    cap, info = open_source(source, fps=fps, timestamps=timestamps, bayer=bayer)
    size = robot_size(robot_size_mm)
    try:
        if scale is None and mm_per_px is not None:
            scale = scale_given(mm_per_px)
        scene = prepare_scene(cap, info, roi=roi, mask=mask, scale=scale, min_contrast=min_contrast, size=size)
        img = None
        t_s = float("nan")
        for k, (g, t) in enumerate(iter_frames(cap, info)):
            if k == frame:
                img, t_s = g, t
                break
    finally:
        cap.release()
    if img is None:
        raise InputError(f"the video has no frame {frame} (it holds {info.frame_count})", file=source,
                         key="--preview", expected=f"a frame number below {info.frame_count}")
    x, y, w, h = scene.roi
    win = img[y:y + h, x:x + w]
    flat = None if scene.flat is None else scene.flat[y:y + h, x:x + w]
    ratio = scene.seg.ratio(win, flat)
    thr = scene.seg.min_contrast
    valid = np.ones((h, w), bool) if scene.valid is None else scene.valid[y:y + h, x:x + w]
    dark = (ratio < 1 - thr) & valid
    out = cv2.cvtColor(np.clip(img, 0, 255).astype(np.uint8), cv2.COLOR_GRAY2BGR).astype(np.float32)
    sub = out[y:y + h, x:x + w]
    sub[~valid] = 0.55 * sub[~valid] + 0.45 * np.array([255, 120, 0], np.float32)
    sub[dark] = 0.5 * sub[dark] + 0.5 * np.array([0, 0, 255], np.float32)
    out = np.clip(out, 0, 255).astype(np.uint8)
    cv2.rectangle(out, (x, y), (x + w - 1, y + h - 1), (128, 128, 128), 1)
    expected = size.area_mm2 / scale.mm_per_px ** 2 if scale is not None and size.area_mm2 else None
    contours, _ = cv2.findContours(dark.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    objects = []
    for c in contours:
        area = float(cv2.contourArea(c))
        if area < 20:
            continue
        m = np.zeros((h, w), np.uint8)
        cv2.drawContours(m, [c], -1, 1, -1)
        inner = cv2.erode(m, np.ones((5, 5), np.uint8))     # clear of the blurred edge
        contrast = 1.0 - float(cv2.mean(ratio, mask=inner if inner.any() else m)[0])
        mo = cv2.moments(c)
        a20, a02, a11 = (mo[k] / max(mo["m00"], 1e-9) for k in ("mu20", "mu02", "mu11"))
        com = np.sqrt(((a20 - a02) / 2) ** 2 + a11 ** 2)
        elong = float(np.sqrt(((a20 + a02) / 2 + com) / max((a20 + a02) / 2 - com, 1e-9)))
        size_ok = expected is None or 0.45 * expected < area < 1.7 * expected
        robot_like = size_ok and 1.4 < elong < 5.0
        bx, by, bw, bh = cv2.boundingRect(c)
        objects.append({"x": bx + x, "y": by + y, "w": bw, "h": bh, "area_px": round(area, 1),
                        "contrast": round(contrast, 4), "robot_like": bool(robot_like)})
        color = (0, 200, 0) if robot_like else (0, 140, 255)
        cv2.drawContours(out, [c + np.array([x, y], np.int32)], -1, color, 2)
        cv2.putText(out, f"{100 * contrast:.0f}%", (bx + x, max(by + y - 4, 12)), cv2.FONT_HERSHEY_SIMPLEX,
                    0.45, color, 1, cv2.LINE_AA)
    noise = scene.seg.noise
    best = max((o["contrast"] for o in objects), default=0.0)
    caption = (f"frame {frame}  t={t_s:.3f}s  threshold {100 * thr:.1f}%"
               f"{' (auto)' if scene.seg.auto else ''}  noise {100 * noise:.2f}%  strongest {100 * best:.1f}%  "
               f"robot-like {sum(o['robot_like'] for o in objects)}")
    cv2.rectangle(out, (0, 0), (out.shape[1] - 1, 22), (255, 255, 255), -1)
    cv2.putText(out, caption, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    if not cv2.imwrite(str(out_png), out):
        raise InputError("cannot write the preview image", file=out_png, expected="a writable .png path")
    return {"preview_png": str(out_png), "frame": frame, "t_s": t_s, "min_contrast": thr,
            "pixel_noise": noise, "strongest_contrast": best, "objects": objects,
            "robot_like": int(sum(o["robot_like"] for o in objects)), "warnings": scene.warnings}
