"""Cameras: OpenCV capture with every frame's own timestamp, and file replay.

Frame rates are far below the vibration frequencies, so frames are
stroboscopic samples and speed comes from the slow drift of position: the
time of each frame matters, the nominal frame rate does not. Every frame is
returned with its own time from ``CAP_PROP_POS_MSEC`` (the backend's capture
or presentation timestamp); only if the backend gives none (0 or not
increasing) does a live camera fall back to the host's monotonic clock, and
says so in :meth:`OpenCVCamera.snapshot`.

:meth:`Camera.record` writes a video and, beside it, the frames' true times
(``<video>.timestamps.csv``); :class:`FileCamera` replays a video with the
same interface, using that file's times when present.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from labkit.errors import InputError, InstrumentError


@runtime_checkable
class CameraProtocol(Protocol):
    """What the experiment runner needs from a camera (live, file or virtual)."""

    def read(self) -> tuple[np.ndarray, float]: ...

    def record(self, path: str | Path, duration_s: float) -> dict[str, Any]: ...


def timestamps_path(video: str | Path) -> Path:
    """Where :meth:`Camera.record` writes the frames' times for ``video``."""
    video = Path(video)
    return video.with_name(video.name + ".timestamps.csv")


def _fourcc_for(path: Path) -> str:
    return "mp4v" if path.suffix.lower() in (".mp4", ".m4v", ".mov") else "MJPG"


class Camera:
    """Base: ``read() -> (frame, t_s)``, :meth:`record`, context manager."""

    name = "camera"

    def read(self) -> tuple[np.ndarray, float]:
        raise NotImplementedError

    def close(self) -> None:
        pass

    def safe_off(self) -> None:
        pass

    def snapshot(self) -> dict[str, Any]:
        return {"model": type(self).__name__, "name": self.name}

    def nominal_fps(self) -> float:
        """The rate written into recorded containers (metadata only)."""
        import cv2

        cap = getattr(self, "_cap", None)
        fps = cap.get(cv2.CAP_PROP_FPS) if cap is not None else 0.0
        return float(fps) if fps and fps > 0 else 30.0

    def record(self, path: str | Path, duration_s: float) -> dict[str, Any]:
        """Record ``duration_s`` seconds (by the frames' own times) to ``path``.

        Returns ``{"path", "frames", "timestamps_s"}`` with times from the first
        frame. Frames are streamed to disk; the container's FPS is only nominal
        metadata, the true times go to :func:`timestamps_path`.
        """
        import cv2

        if not duration_s > 0:
            raise InputError(f"record duration_s must be > 0, got {duration_s!r}", key="duration_s")
        path = Path(path)
        times: list[float] = []
        writer = None
        t0 = None
        try:
            while True:
                try:
                    frame, t = self.read()
                except EOFError:
                    break
                if t0 is None:
                    t0 = t
                    h, w = frame.shape[:2]
                    # frames are streamed to disk, so the container gets the nominal rate;
                    # the true times go to the timestamps file
                    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*_fourcc_for(path)),
                                             self.nominal_fps(), (w, h), frame.ndim == 3)
                    if not writer.isOpened():
                        raise InstrumentError(f"cannot write video {path}", instrument=self.name,
                                              command="record")
                if t - t0 > duration_s:
                    break
                assert writer is not None      # opened with the first frame
                writer.write(frame)
                times.append(t - t0)
        finally:
            if writer is not None:
                writer.release()
        if not times:
            raise InstrumentError("no frames recorded", instrument=self.name, command="record")
        np.savetxt(timestamps_path(path), np.asarray(times), fmt="%.6f", header="t_s",
                   comments="")
        return {"path": str(path), "frames": len(times), "timestamps_s": times}

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class OpenCVCamera(Camera):
    """A live camera through ``cv2.VideoCapture``.

    Parameters
    ----------
    index:
        Device index (or a device path / URL OpenCV accepts).
    fourcc, size_px, fps:
        Requested in this order (FOURCC, then size, then FPS: some drivers
        reset the rate when the format changes), each read back; the values
        the camera actually took are in :meth:`snapshot`.
    exposure:
        Fixed exposure (backend units); auto-exposure lowers the frame rate.
        None leaves it alone.
    manual_exposure_mode:
        Value of ``CAP_PROP_AUTO_EXPOSURE`` meaning manual (V4L2: 1; some
        backends: 0.25).
    """

    def __init__(self, index: int | str = 0, *, fourcc: str = "MJPG",
                 size_px: tuple[int, int] = (1280, 720), fps: float = 30.0,
                 exposure: float | None = None, manual_exposure_mode: float = 1.0,
                 api: int | None = None, name: str | None = None) -> None:
        import cv2

        self.name = name or f"camera {index}"
        self._cap = cv2.VideoCapture(index) if api is None else cv2.VideoCapture(index, api)
        if not self._cap.isOpened():
            raise InstrumentError(f"cannot open camera {index!r}", instrument=self.name,
                                  command="open")
        self.requested = {"fourcc": fourcc, "size_px": list(size_px), "fps": fps,
                          "exposure": exposure}
        self._cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc(*fourcc))
        self._cap.set(cv2.CAP_PROP_FRAME_WIDTH, size_px[0])
        self._cap.set(cv2.CAP_PROP_FRAME_HEIGHT, size_px[1])
        self._cap.set(cv2.CAP_PROP_FPS, fps)
        if exposure is not None:
            self._cap.set(cv2.CAP_PROP_AUTO_EXPOSURE, manual_exposure_mode)
            self._cap.set(cv2.CAP_PROP_EXPOSURE, exposure)
        code = int(self._cap.get(cv2.CAP_PROP_FOURCC))
        self.actual = {
            "fourcc": "".join(chr((code >> (8 * i)) & 0xFF) for i in range(4)) if code else "",
            "size_px": [int(self._cap.get(cv2.CAP_PROP_FRAME_WIDTH)),
                        int(self._cap.get(cv2.CAP_PROP_FRAME_HEIGHT))],
            "fps_nominal": float(self._cap.get(cv2.CAP_PROP_FPS)),
            "exposure": float(self._cap.get(cv2.CAP_PROP_EXPOSURE)),
            "auto_exposure": float(self._cap.get(cv2.CAP_PROP_AUTO_EXPOSURE)),
        }
        self.timestamp_source = "CAP_PROP_POS_MSEC"
        self._last_t: float | None = None

    def read(self) -> tuple[np.ndarray, float]:
        """The next frame and its own time in seconds."""
        import cv2

        ok, frame = self._cap.read()
        host_t = time.monotonic()
        if not ok or frame is None:
            raise InstrumentError("frame grab failed", instrument=self.name, command="read")
        t = self._cap.get(cv2.CAP_PROP_POS_MSEC) / 1000.0
        if self.timestamp_source == "CAP_PROP_POS_MSEC" and self._last_t is not None \
                and not t > self._last_t:
            # the backend gives no usable per-frame time: use the host clock from now on
            self.timestamp_source = "host monotonic clock"
        if self.timestamp_source != "CAP_PROP_POS_MSEC":
            t = host_t
        self._last_t = t
        return frame, t

    def snapshot(self) -> dict[str, Any]:
        return {**super().snapshot(), "requested": self.requested, "actual": self.actual,
                "timestamp_source": self.timestamp_source}

    def close(self) -> None:
        self._cap.release()


class FileCamera(Camera):
    """Replay a video file with the camera interface (``read`` raises EOFError at the end).

    Frame times come from ``<video>.timestamps.csv`` when it exists (written by
    :meth:`Camera.record`), else from the file's own ``CAP_PROP_POS_MSEC``.
    """

    def __init__(self, path: str | Path, *, name: str | None = None) -> None:
        import cv2

        self.path = Path(path)
        self.name = name or f"file camera {self.path.name}"
        if not self.path.is_file():
            raise InputError("video file not found", file=self.path)
        self._cap = cv2.VideoCapture(str(self.path))
        if not self._cap.isOpened():
            raise InputError("cannot decode video", file=self.path, expected="a video OpenCV reads")
        ts = timestamps_path(self.path)
        self._times = np.loadtxt(ts, skiprows=1, ndmin=1) if ts.is_file() else None
        self._i = 0

    def read(self) -> tuple[np.ndarray, float]:
        import cv2

        ok, frame = self._cap.read()
        if not ok or frame is None:
            raise EOFError(str(self.path))
        if self._times is not None and self._i < len(self._times):
            t = float(self._times[self._i])
        else:
            t = self._cap.get(cv2.CAP_PROP_POS_MSEC) / 1000.0
        self._i += 1
        return frame, t

    def frames(self):
        """Iterate ``(frame, t_s)`` to the end of the file."""
        while True:
            try:
                yield self.read()
            except EOFError:
                return

    def snapshot(self) -> dict[str, Any]:
        return {**super().snapshot(), "path": str(self.path),
                "timestamp_source": "timestamps.csv" if self._times is not None
                else "CAP_PROP_POS_MSEC"}

    def close(self) -> None:
        self._cap.release()
