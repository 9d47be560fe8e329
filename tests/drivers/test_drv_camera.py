"""Cameras on real video files: per-frame timestamps, record, replay."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from labkit.drivers.camera import CameraProtocol, FileCamera, OpenCVCamera, timestamps_path
from labkit.errors import InputError, InstrumentError


def _video(path: Path, n: int = 20, fps: float = 25.0) -> Path:
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (64, 48))
    assert w.isOpened()
    for i in range(n):
        frame = np.full((48, 64, 3), 200, np.uint8)
        frame[10:20, i:i + 10] = 20
        w.write(frame)
    w.release()
    return path


def test_file_camera_frames_carry_their_own_time(tmp_path):
    cam = FileCamera(_video(tmp_path / "a.avi", n=20, fps=25.0))
    assert isinstance(cam, CameraProtocol)
    times = [t for _, t in cam.frames()]
    assert len(times) == 20
    np.testing.assert_allclose(times, np.arange(20) / 25.0, atol=1e-6)
    with pytest.raises(EOFError):
        cam.read()
    cam.close()


def test_record_writes_video_and_true_times_then_replays_them(tmp_path):
    src = _video(tmp_path / "src.avi", n=30, fps=10.0)
    with FileCamera(src) as cam:
        rec = cam.record(tmp_path / "out.avi", duration_s=1.45)
    assert rec["frames"] == 15 and rec["timestamps_s"][-1] == pytest.approx(1.4)
    assert timestamps_path(rec["path"]).is_file()
    # the recorded file's container rate is nominal; replay uses the stored true times
    with FileCamera(rec["path"]) as again:
        times = [t for _, t in again.frames()]
        assert again.snapshot()["timestamp_source"] == "timestamps.csv"
    np.testing.assert_allclose(times, np.arange(15) / 10.0, atol=1e-6)


def test_opencv_camera_reads_back_settings_and_timestamps(tmp_path):
    # a file opened through VideoCapture exercises the live code path without hardware
    src = _video(tmp_path / "live.avi", n=10, fps=20.0)
    cam = OpenCVCamera(str(src), fourcc="MJPG", size_px=(64, 48), fps=20.0)
    snap = cam.snapshot()
    assert snap["actual"]["size_px"] == [64, 48]
    assert snap["requested"]["fps"] == 20.0
    t = [cam.read()[1] for _ in range(5)]
    np.testing.assert_allclose(t, np.arange(5) / 20.0, atol=1e-6)
    assert cam.snapshot()["timestamp_source"] == "CAP_PROP_POS_MSEC"
    for _ in range(5):
        cam.read()
    with pytest.raises(InstrumentError, match="frame grab failed"):
        cam.read()
    cam.close()


def test_missing_camera_and_file(tmp_path):
    with pytest.raises(InstrumentError) as ei:
        OpenCVCamera(str(tmp_path / "no_such_device"))
    assert ei.value.command == "open"
    with pytest.raises(InputError, match="not found"):
        FileCamera(tmp_path / "none.avi")
    (tmp_path / "bad.avi").write_bytes(b"not a video")
    with pytest.raises(InputError):
        FileCamera(tmp_path / "bad.avi")
