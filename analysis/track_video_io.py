"""Reading video frames with their own timestamps, and reading ROI/mask arguments.

Every frame's time comes from the container (``CAP_PROP_POS_MSEC``), never
from the nominal frame rate: real cameras drop and delay frames, and the
nominal rate of a file is often rounded. Only when a container carries no
timestamps at all (every ``POS_MSEC`` is 0) does the reader fall back to the
nominal rate, and says so (``Frames.timestamps_source``).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from labkit.errors import InputError


@dataclass
class VideoInfo:
    """What the container says about a video (nominal values, for the record only)."""

    path: str
    width: int
    height: int
    frame_count: int
    fps_nominal: float
    fourcc: str
    raw_jpeg: bool = False   # Motion-JPEG read as packets and decoded straight to grey


def open_video(path: str | Path, *, grey: bool = True):
    """Open a video with OpenCV's FFmpeg backend; InputError if missing, unreadable or empty.

    With ``grey`` (the tracker), :func:`iter_frames` yields grey frames; else BGR.

    Returns ``(capture, VideoInfo)``.
    """
    import cv2

    path = Path(path)
    if not path.is_file():
        raise InputError("no such video file", file=path)
    # OpenCV's own warning on an unreadable file would precede our one-line message: silence it
    log = cv2.utils.logging
    level = log.getLogLevel()
    log.setLogLevel(log.LOG_LEVEL_ERROR)
    try:
        cap = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
    finally:
        log.setLogLevel(level)
    if not cap.isOpened():
        cap.release()
        raise InputError("not a readable video (OpenCV/FFmpeg cannot open it)", file=path,
                         expected="a video file such as .avi/.mkv/.mp4")
    code = int(cap.get(cv2.CAP_PROP_FOURCC))
    fourcc = "".join(chr((code >> (8 * i)) & 0xFF) for i in range(4)).strip("\x00")
    info = VideoInfo(str(path), int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)),
                     int(cap.get(cv2.CAP_PROP_FRAME_COUNT)), float(cap.get(cv2.CAP_PROP_FPS) or 0.0), fourcc)
    if fourcc.upper() == "MJPG" and grey:
        # each Motion-JPEG packet is a JPEG image: decoding only its luma with imdecode is about
        # 3x faster than FFmpeg's decode + BGR conversion + grey conversion, and the container
        # still gives each packet's timestamp
        info.raw_jpeg = bool(cap.set(cv2.CAP_PROP_FORMAT, -1))
    return cap, info


def _grey(frame: np.ndarray, info: VideoInfo) -> np.ndarray | None:
    import cv2

    if info.raw_jpeg:
        return cv2.imdecode(frame.reshape(-1), cv2.IMREAD_GRAYSCALE)
    return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame


def iter_frames(cap, info: VideoInfo) -> Iterator[tuple[np.ndarray, float]]:
    """Yield ``(grey uint8 frame, t_s)`` with each frame's own container timestamp.

    (Frames from a capture opened with ``grey=False`` are converted to grey too.)"""
    import cv2

    while True:
        ok, frame = cap.read()
        if not ok or frame is None:
            return
        t_ms = cap.get(cv2.CAP_PROP_POS_MSEC)
        frame = _grey(frame, info)
        if frame is None:
            raise InputError("a frame could not be decoded", file=info.path)
        yield frame, t_ms / 1000.0


def check_timestamps(t_s: np.ndarray, fps_nominal: float, path: str) -> tuple[np.ndarray, str, np.ndarray]:
    """Validate container timestamps; fall back to the nominal rate only when there are none.

    Returns ``(t_s, source, faulty)``: ``faulty`` marks frames whose timestamp
    does not exceed every earlier one (a camera's duplicated or reordered
    frame); the tracker flags them lost rather than guess their time.
    """
    t_s = np.asarray(t_s, float)
    if t_s.size > 1 and np.all(t_s == t_s[0]):
        if fps_nominal <= 0:
            raise InputError("the video carries no timestamps and no frame rate", file=path)
        return np.arange(t_s.size) / fps_nominal, "nominal_fps", np.zeros(t_s.size, bool)
    faulty = np.zeros(t_s.size, bool)
    if t_s.size > 1:
        faulty[1:] = t_s[1:] <= np.maximum.accumulate(t_s)[:-1]
    if faulty.sum() > t_s.size // 2:
        raise InputError(f"{int(faulty.sum())} of {t_s.size} frame timestamps do not increase", file=path)
    return t_s, "container", faulty


def read_sample_frames(cap, info: VideoInfo, count: int) -> list[np.ndarray]:
    """Up to ``count`` grey frames spread over the video (by seeking), then rewind."""
    import cv2

    n = info.frame_count
    out: list[np.ndarray] = []
    if n <= 0:
        return out
    for idx in np.unique(np.linspace(0, n - 1, min(count, n)).round().astype(int)):
        cap.set(cv2.CAP_PROP_POS_FRAMES, int(idx))
        ok, frame = cap.read()
        if ok and frame is not None:
            g = _grey(frame, info)
            if g is not None:
                out.append(g)
    cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
    return out


def parse_roi(text: str | tuple | None, width: int, height: int, *, source: str = "--roi") -> tuple[int, int, int, int]:
    """``"x,y,w,h"`` (pixels) -> a tuple inside the frame; InputError otherwise."""
    if text is None:
        return (0, 0, width, height)
    try:
        vals = [int(round(float(v))) for v in (text.split(",") if isinstance(text, str) else text)]
    except ValueError:
        vals = []
    if len(vals) != 4:
        raise InputError(f"bad region of interest {text!r}", key=source, expected="x,y,w,h in pixels")
    x, y, w, h = vals
    if w < 8 or h < 8 or x < 0 or y < 0 or x + w > width or y + h > height:
        raise InputError(f"region of interest {text!r} is not inside the {width}x{height} frame",
                         key=source, expected="x,y,w,h with x+w <= width, y+h <= height, w,h >= 8")
    return (x, y, w, h)


def load_mask(mask, width: int, height: int) -> np.ndarray | None:
    """A mask image path or array (non-zero = search here) -> bool array of the frame's size."""
    if mask is None:
        return None
    if isinstance(mask, (str, Path)):
        import cv2

        img = cv2.imread(str(mask), cv2.IMREAD_GRAYSCALE) if Path(mask).is_file() else None
        if img is None:
            raise InputError("cannot read the mask image", file=mask, expected="a PNG, non-zero = search")
        mask = img
    mask = np.asarray(mask)
    if mask.shape[:2] != (height, width):
        raise InputError(f"mask is {mask.shape[1]}x{mask.shape[0]}", key="mask",
                         expected=f"the video's size {width}x{height}")
    return mask.astype(bool) if mask.ndim == 2 else mask[..., 0].astype(bool)
